"""BVH export: our reader, bvhio and our importer read the files back to the motion's joints
(within 1 mm) and the capture's bone directions (within 1°); bad input fails cleanly."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import bvhio
import numpy as np
import pytest
from export_fixtures import real_takes, synthetic_motion
from scipy.spatial.transform import Rotation

from export.bvh_writer import UNITS, euler_zxy, write_bvh
from export.errors import ExportError
from export.humanoid import CAPTURE_JOINT, N_BONES, TIP_BONES, HumanoidRig
from export.motion import HumanoidMotion
from export.retarget import bone_direction_errors, retarget
from ingest.bvh import read_bvh
from ingest.bvh_take import BvhImportOptions, load_bvh_take
from samba.take import Take

SYNTHETIC = ("walk", "kick", "turn", "jumping_jacks")
UNIT = pytest.mark.parametrize("unit", list(UNITS))
BONE_OF_JOINT = [next(b for b, j in CAPTURE_JOINT.items() if j == i) for i in range(13)]
"""The humanoid bone at each of the 13 capture joints."""


def real_motions(cmu_dir: Path) -> list[tuple[Take, HumanoidMotion]]:
    """The first take of each rig family in the shared CMU data, retargeted."""
    return [
        (take, retarget(take.poses, HumanoidRig.from_body(), take.fps))
        for take in real_takes(cmu_dir)
    ]


def read_back(path: Path, unit: str) -> tuple[np.ndarray, np.ndarray]:
    """Joint (n, 17, 3) and End Site (n, 5, 3) world positions in meters, by our reader."""
    bvh = read_bvh(path)
    rig = HumanoidRig.from_body()
    joints = [bvh.names.index(name) for name in rig.names]
    tips = [bvh.names.index(f"{rig.names[b]}_end") for b in TIP_BONES]
    positions = bvh.positions(joints + tips) / UNITS[unit]
    return positions[:, :N_BONES], positions[:, N_BONES:]


def assert_round_trip(path: Path, unit: str, take: Take, motion: HumanoidMotion) -> None:
    """Our reader gets the motion's joints and tips back within 1 mm at every frame, and the
    captured bone directions within 1°."""
    joints, tips = read_back(path, unit)
    assert joints.shape == (len(motion), N_BONES, 3)
    error = np.linalg.norm(joints - motion.world_positions(), axis=-1)
    assert error.max() < 0.001, (take.name, unit, error.max())
    tip_error = np.linalg.norm(tips - motion.tip_positions(), axis=-1)
    assert tip_error.max() < 0.001, (take.name, unit, tip_error.max())
    angles = bone_direction_errors(joints, take.poses)
    assert angles.max() < 1.0, (take.name, unit, angles.max())


def assert_bvhio_agrees(path: Path, unit: str, motion: HumanoidMotion) -> None:
    """bvhio reads as many frames and, on the first, middle and last, the same joints."""
    root = bvhio.readAsHierarchy(str(path))
    assert len(root.Keyframes) == len(motion)
    expected = motion.world_positions() * UNITS[unit]
    for frame in sorted({0, len(motion) // 2, len(motion) - 1}):
        root.loadPose(frame)
        layout = root.layout()
        assert [joint.Name for joint, _, _ in layout] == list(motion.rig.names)
        got = np.array([list(joint.PositionWorld) for joint, _, _ in layout])
        error = np.linalg.norm(got - expected[frame], axis=-1) / UNITS[unit]
        assert error.max() < 0.001, (path.name, frame, error.max())


def assert_imports_as_take(path: Path, unit: str, motion: HumanoidMotion) -> None:
    """Our importer detects the humanoid rig and gets the 13 joints back (up to the floor
    height it chooses) within 1 mm, in the right unit, upright and not mirrored."""
    take = load_bvh_take(path, BvhImportOptions(fps=None))
    assert take.rig == "humanoid"
    assert take.meta["units"] == unit
    assert take.meta["up"] == "+y"
    assert take.meta["handedness"] == "right"
    assert take.fps == pytest.approx(motion.fps, rel=1e-6)
    offset = take.poses - motion.world_positions()[:, BONE_OF_JOINT]
    floor = np.median(offset[..., 1])
    assert np.abs(offset - [0.0, floor, 0.0]).max() < 0.001


@UNIT
@pytest.mark.parametrize("name", SYNTHETIC)
def test_synthetic_takes_round_trip(tmp_path: Path, name: str, unit: str) -> None:
    take, motion = synthetic_motion(name, seed=5)
    path = tmp_path / f"{name}.bvh"
    write_bvh(path, motion, unit)
    assert_round_trip(path, unit, take, motion)
    assert_bvhio_agrees(path, unit, motion)
    assert_imports_as_take(path, unit, motion)


@UNIT
def test_real_takes_round_trip(tmp_path: Path, cmu_dir: Path, unit: str) -> None:
    for take, motion in real_motions(cmu_dir):
        path = tmp_path / f"{take.name}.bvh"
        write_bvh(path, motion, unit)
        assert_round_trip(path, unit, take, motion)
        assert_bvhio_agrees(path, unit, motion)
        assert_imports_as_take(path, unit, motion)


def test_file_layout(tmp_path: Path) -> None:
    _, motion = synthetic_motion(seed=5, seconds=0.5)
    path = tmp_path / "walk.bvh"
    write_bvh(path, motion, "cm")
    text = path.read_text()
    bvh = read_bvh(path)
    hips = bvh.joints[0]
    assert (hips.name, hips.parent, hips.offset.tolist()) == ("Hips", -1, [0.0, 0.0, 0.0])
    assert hips.channels == (
        "Xposition",
        "Yposition",
        "Zposition",
        "Zrotation",
        "Xrotation",
        "Yrotation",
    )
    joints = [j for j in bvh.joints if not j.end_site]
    assert [j.name for j in joints] == list(motion.rig.names)
    assert all(j.channels == ("Zrotation", "Xrotation", "Yrotation") for j in joints[1:])
    offsets = np.array([j.offset for j in joints[1:]])
    np.testing.assert_allclose(offsets, motion.rig.offsets[1:] * 100, atol=5e-7)
    ends = [j for j in bvh.joints if j.end_site]
    assert [bvh.joints[j.parent].name for j in ends] == [motion.rig.names[b] for b in TIP_BONES]
    np.testing.assert_allclose([j.offset for j in ends], motion.rig.tips * 100, atol=5e-7)
    np.testing.assert_allclose(bvh.motion[:, :3], motion.root * 100, atol=5e-7)
    assert bvh.n_frames == len(motion)
    assert "-0.000000" not in text
    assert text.endswith("\n")


@pytest.mark.parametrize("fps", [24.0, 29.97, 30.0, 60.0, 120.0])
def test_frame_time_keeps_the_frame_rate(tmp_path: Path, fps: float) -> None:
    _, motion = synthetic_motion(seed=5, seconds=0.2)
    path = tmp_path / "take.bvh"
    write_bvh(path, HumanoidMotion(motion.rig, motion.rotations, motion.root, fps), "m")
    assert read_bvh(path).fps == pytest.approx(fps, rel=1e-6)
    assert len(bvhio.readAsHierarchy(str(path)).Keyframes) == len(motion)


def test_euler_angles_are_exact_and_continuous_through_gimbal_lock() -> None:
    """A sweep of X through 90° (where the principal angles flip Z and Y by 180°) and a
    spin about Y over several turns come back as the angles they were made of."""
    t = np.linspace(0.0, 1.0, 200)
    sweep = np.stack([20 + 40 * t, 60 + 60 * t, -30 + 50 * t], axis=-1)
    spin = np.stack([10 * np.sin(6 * t), 5 * np.cos(4 * t), 1500 * t], axis=-1)
    angles = np.stack([sweep, spin], axis=1)
    rotations = Rotation.from_euler("ZXY", angles.reshape(-1, 3), degrees=True)
    quaternions = rotations.as_quat().reshape(len(t), 2, 4)
    out = euler_zxy(quaternions)
    rebuilt = Rotation.from_euler("ZXY", out.reshape(-1, 3), degrees=True)
    assert np.allclose(rebuilt.as_matrix(), rotations.as_matrix(), atol=1e-12)
    assert np.allclose(out, angles, atol=1e-9)


def test_exported_angles_rebuild_the_local_rotations() -> None:
    _, motion = synthetic_motion("jumping_jacks", seed=5)
    angles = euler_zxy(motion.rotations)
    rebuilt = Rotation.from_euler("ZXY", angles.reshape(-1, 3), degrees=True)
    local = Rotation.from_quat(motion.rotations.reshape(-1, 4))
    assert np.allclose(rebuilt.as_matrix(), local.as_matrix(), atol=1e-12)
    assert np.abs(np.diff(angles, axis=0)).max() < 90.0


def test_bad_unit_is_refused_before_writing(tmp_path: Path) -> None:
    _, motion = synthetic_motion(seed=5, seconds=0.1)
    path = tmp_path / "take.bvh"
    path.write_text("the previous export")
    with pytest.raises(ValueError, match="--unit must be one of m, cm, got 'mm'"):
        write_bvh(path, motion, "mm")
    assert path.read_text() == "the previous export"
    assert [p.name for p in tmp_path.iterdir()] == ["take.bvh"]


@pytest.mark.parametrize("kind", ["missing folder", "directory", "permission denied"])
def test_unwritable_path_raises_and_leaves_no_file(tmp_path: Path, kind: str) -> None:
    _, motion = synthetic_motion(seed=5, seconds=0.1)
    folder = tmp_path / "out"
    if kind == "missing folder":
        path = folder / "take.bvh"
    elif kind == "directory":
        path = folder
        folder.mkdir()
    else:
        if os.geteuid() == 0:
            pytest.skip("root may write into a read-only folder")
        folder.mkdir(mode=0o500)
        path = folder / "take.bvh"
    with pytest.raises(ExportError, match="cannot write the file") as raised:
        write_bvh(path, motion)
    assert raised.value.source == str(path)
    assert path.is_dir() if kind == "directory" else not path.exists()
    assert sorted(p.name for p in tmp_path.rglob("*")) == (["out"] if folder.exists() else [])


def test_failure_midway_leaves_existing_file_untouched(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    _, motion = synthetic_motion(seed=5, seconds=0.1)
    path = tmp_path / "take.bvh"
    path.write_text("the previous export")
    real_write = Path.write_bytes

    def disk_full(self: Path, data: bytes) -> int:
        real_write(self, data[: len(data) // 2])
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Path, "write_bytes", disk_full)
    with pytest.raises(ExportError, match="No space left"):
        write_bvh(path, motion)
    assert path.read_text() == "the previous export"
    assert [p.name for p in tmp_path.iterdir()] == ["take.bvh"]
