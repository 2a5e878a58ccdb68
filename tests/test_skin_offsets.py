"""Markers on the skin: segment frames, skin offsets, their calibration and removal."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from samba.body import MARKER_JOINTS, joint_frames, markers_of, standard_pose, trunk_frames
from samba.db import PoseIndex
from samba.ingest import load_bvh_take
from samba.reconstruct import (
    SkinMarkerReconstructor,
    SkinOffsets,
    calibrate_skin_offsets,
    method,
)

OFFSETS = np.array(
    [
        [0.0, 0.06, 0.0],  # acromion: above the shoulder joint
        [0.0, 0.06, 0.0],
        [0.0, 0.0, 0.0],  # the wrist markers' midpoint: at the wrist
        [0.0, 0.0, 0.0],
        [0.06, 0.0, 0.0],  # lateral epicondyle
        [-0.06, 0.0, 0.0],
        [0.045, 0.0, 0.0],  # lateral malleolus
        [-0.045, 0.0, 0.0],
    ]
)
"""Skin offsets (m, segment frames) like real markers' (x to the left, y up the segment)."""
TEST_TAKE, DATABASE = "cgspeed_131_01", ("cgspeed_131_02", "cgspeed_131_03", "iclone_002_01")


def on_the_skin(poses: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Markers (n, 8, 3) of poses (n, 13, 3) moved off their joints by segment-frame offsets."""
    frames = joint_frames(poses)[:, list(MARKER_JOINTS)]
    return markers_of(poses) + np.einsum("nmij,mj->nmi", frames, offsets)


def test_the_standard_pose_trunk_frame_is_the_world_frame() -> None:
    frames = joint_frames(standard_pose()[None])[0]
    for joint in (0, 1, 2, 7, 8, 9, 10, 11, 12):  # trunk, and legs hanging straight down
        assert np.allclose(frames[joint], np.eye(3), atol=1e-12)


def test_segment_frames_are_rotations_that_turn_with_the_body() -> None:
    rng = np.random.default_rng(0)
    poses = standard_pose()[None] + rng.normal(scale=0.05, size=(50, 13, 3))
    frames = joint_frames(poses)
    assert np.allclose(frames @ frames.swapaxes(-1, -2), np.eye(3), atol=1e-9)
    assert np.allclose(np.linalg.det(frames), 1.0)
    turn = Rotation.from_euler("yx", [70, 20], degrees=True).as_matrix()
    turned = joint_frames(poses @ turn.T + [1.0, 0.0, -2.0])
    assert np.allclose(turned, turn @ frames, atol=1e-9)
    limb = frames[:, 9]  # the thigh frame's y axis points from the knee up to the hip
    up_the_thigh = poses[:, 7] - poses[:, 9]
    up_the_thigh /= np.linalg.norm(up_the_thigh, axis=-1, keepdims=True)
    assert np.allclose(limb[:, :, 1], up_the_thigh)
    assert np.allclose(trunk_frames(poses), frames[:, 0])


def test_an_arm_pointing_straight_up_still_has_a_frame() -> None:
    pose = standard_pose()
    pose[3] = pose[1] + [0.0, 0.3, 0.0]  # upper arm straight up
    frame = joint_frames(pose[None])[0, 3]
    assert np.isfinite(frame).all()
    assert np.allclose(frame @ frame.T, np.eye(3))
    assert np.allclose(frame[:, 1], [0.0, -1.0, 0.0])  # y towards the parent: down


def test_known_offsets_take_skin_markers_back_to_the_joints() -> None:
    rng = np.random.default_rng(1)
    poses = standard_pose()[None] + rng.normal(scale=0.05, size=(20, 13, 3))
    skin = on_the_skin(poses, OFFSETS)
    assert np.allclose(SkinOffsets(OFFSETS).joints(skin, poses), markers_of(poses))
    skin[3, 2] = np.nan
    assert np.isnan(SkinOffsets(OFFSETS).joints(skin, poses)[3, 2]).all()


def test_offsets_survive_their_json_form_and_bad_forms_are_refused() -> None:
    offsets = SkinOffsets(OFFSETS, frames=60)
    again = SkinOffsets.from_dict(offsets.as_dict())
    assert np.allclose(again.offsets, OFFSETS, atol=1e-5) and again.frames == 60
    assert "l_knee" in offsets.report() and "+6.0" in offsets.report()
    with pytest.raises(ValueError, match="offsets_m"):
        SkinOffsets.from_dict({"offsets_m": {"l_knee": [0, 0, 0]}})
    broken = offsets.as_dict()
    broken["offsets_m"]["l_knee"] = [0.0, float("nan"), 0.0]  # type: ignore[index]
    with pytest.raises(ValueError, match="finite"):
        SkinOffsets.from_dict(broken)


@pytest.fixture(scope="module")
def skin_take(cmu_dir: Path) -> tuple[np.ndarray, np.ndarray, PoseIndex]:
    """A real CMU take (20 s at 30 fps) with markers placed on the skin by `OFFSETS`, and
    a pose index of three other real takes."""
    truth = load_bvh_take(cmu_dir / f"{TEST_TAKE}.bvh").poses[:600].astype(np.float64)
    database = np.concatenate([load_bvh_take(cmu_dir / f"{n}.bvh").poses for n in DATABASE])
    return truth, on_the_skin(truth, OFFSETS), PoseIndex.build(database)


def test_calibration_finds_the_skin_offsets_and_brings_the_joints_back(skin_take) -> None:
    truth, skin, index = skin_take
    reconstructor = method("samba").build(index)

    def error_cm(r: object, markers: np.ndarray) -> float:
        r.reset()  # type: ignore[attr-defined]
        poses = r.reconstruct(markers).poses  # type: ignore[attr-defined]
        return float(np.linalg.norm(poses - truth, axis=-1).mean() * 100.0)

    at_joints = error_cm(reconstructor, markers_of(truth))
    raw = error_cm(reconstructor, skin)
    found = calibrate_skin_offsets(reconstructor, skin[:60])  # the first 2 s
    calibrated = error_cm(SkinMarkerReconstructor(reconstructor, found), skin)
    off_cm = np.linalg.norm(found.offsets - OFFSETS, axis=1) * 100.0
    assert raw > at_joints + 1.5  # markers on the skin cost centimetres ...
    assert calibrated < at_joints + 0.5 * (raw - at_joints)  # ... and calibration wins most back
    assert np.median(off_cm) < 2.0, off_cm
    assert found.frames == 60


def test_the_live_path_removes_the_offsets_frame_by_frame(skin_take) -> None:
    truth, skin, index = skin_take
    subject = SkinMarkerReconstructor(method("samba").build(index), SkinOffsets(OFFSETS))
    subject.reset()
    live = np.stack([subject.step(frame).pose for frame in skin[:90]])
    subject.reset()
    batch = subject.reconstruct(skin[:90]).poses
    live_cm = np.linalg.norm(live - truth[:90], axis=-1).mean() * 100.0
    batch_cm = np.linalg.norm(batch - truth[:90], axis=-1).mean() * 100.0
    assert live_cm < batch_cm + 0.5  # the predicted pose's frames are nearly as good


def test_calibration_needs_a_frame_it_can_reconstruct(skin_take) -> None:
    index = skin_take[2]
    with pytest.raises(ValueError, match="enough markers"):
        calibrate_skin_offsets(method("nn").build(index), np.full((10, 8, 3), np.nan))
