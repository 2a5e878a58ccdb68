"""`samba capture-volume` end to end, in-process, on local files: four 320x240 cameras
around a synthetic stage filming a second of jumping jacks (the men's-M capsule body in
colour, `samba.silhouette.person_render`) and, as a subject that is no human, a standing pole."""

from __future__ import annotations

import errno
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
from markerless_fixtures import SENSOR_NOISE, write_image_folder
from test_track_video import _assert_one_line_error, samba

from samba.body.body_model import BodyModel, scaled_to
from samba.cameras.calibration_file import read_calibration, write_calibration
from samba.cameras.camera import Camera
from samba.ingest.bvh import read_bvh
from samba.silhouette.person_render import empty_stage_frames, person_frames, stage_background
from samba.synthetic.motions import generate
from samba.volume.visual_hull import volume_cameras
from samba.volume.voxel_grid import VoxelGrid

FPS = 15.0
VOXEL = 0.04
EMPTY_FRAMES = 6
"""Frames of the empty stage before the subject steps in (the background needs 5)."""
MARGIN = 0.35
"""Room (m) around the take's joints in the capture volume: the body's flesh and hands."""
JOINT_LIMIT_M = 0.25
"""Bound on the mean error of the 13 joints: 0.13 m measured (a 4 cm voxel grid, four
cameras of 320x240)."""
FIXED_LENGTH_REACH_M = 0.15
"""How far (m) the BVH's joints may stray out of the capture volume: its links have
the model's mean lengths, which carry limb ends past the measured ones in some frames
(a foot 0.11 m below the floor here, 0.44 m when the links were as long as the curves
between the joints)."""
POLE = np.array([[-0.15, 0.0, -0.15], [0.15, 1.7, 0.15]])
"""Corners (m) of the box-shaped pole of the non-human take."""
POLE_FRAMES = 10


@dataclass(frozen=True)
class Stage:
    """The files of the tests: the `calibration` of the four cameras, the capture
    `bounds` (2, 3) m, per camera an image folder of `EMPTY_FRAMES` frames of the empty
    stage then the jumping jacks (`videos`), of the pole (`pole`) and of the empty
    stage alone (`empty`); the `truth` poses (n, 13, 3) m and the subject's `facing`
    (x, z) in the first frame."""

    calibration: Path
    bounds: np.ndarray
    videos: list[Path]
    pole: list[Path]
    empty: list[Path]
    truth: np.ndarray
    facing: tuple[float, float]


def _pole_frames(camera: Camera, background: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """`POLE_FRAMES` frames of the red `POLE` standing still in front of `background`."""
    corners = np.stack(np.meshgrid(*POLE.T, indexing="ij"), -1).reshape(-1, 3)
    outline = cv2.convexHull(np.round(camera.project(corners)).astype(np.int32))
    frame = cv2.fillConvexPoly(background.copy(), outline, (40, 60, 150))
    return empty_stage_frames(frame, POLE_FRAMES, rng, SENSOR_NOISE)


@pytest.fixture(scope="module")
def stage(tmp_path_factory: pytest.TempPathFactory) -> Stage:
    """The stage's calibration and image folders, written once."""
    root = tmp_path_factory.mktemp("volume")
    body = BodyModel.named("men-M")
    truth = scaled_to(generate("jumping_jacks", seconds=1.0, fps=FPS, seed=1).poses, body.height)
    low, high = truth.reshape(-1, 3).min(axis=0) - MARGIN, truth.reshape(-1, 3).max(axis=0) + MARGIN
    low[1] = 0.0
    grid = VoxelGrid.from_bounds(low, high, VOXEL)
    cameras = volume_cameras(grid, 4, (320, 240))
    calibration = root / "stage.toml"
    write_calibration(calibration, cameras)
    rng = np.random.default_rng(7)
    videos, pole, empty = [], [], []
    for camera in cameras:
        background = stage_background(camera.size, rng)
        before = empty_stage_frames(background, EMPTY_FRAMES, rng, SENSOR_NOISE)
        frames = person_frames(truth, camera, body, background, rng, SENSOR_NOISE)
        folder = root / camera.name
        videos.append(write_image_folder(folder / "jacks", np.concatenate([before, frames])))
        pole.append(write_image_folder(folder / "pole", _pole_frames(camera, background, rng)))
        empty.append(write_image_folder(folder / "empty", before))
    left = truth[0, 7] - truth[0, 8]  # l_hip - r_hip; the subject's left is up x facing
    facing = np.cross(left, [0.0, 1.0, 0.0])
    return Stage(calibration, grid.bounds, videos, pole, empty, truth, (facing[0], facing[2]))


def capture(
    stage: Stage, videos: list[Path], out: Path, *flags: str | Path
) -> tuple[int, str, str]:
    """`samba capture-volume` of `videos` in the stage's volume with 4 cm voxels."""
    bounds = [f"{value:.6f}" for value in stage.bounds.ravel()]
    settings = ("--bounds", *bounds, "--voxel", VOXEL, "--fps", FPS)
    return samba(
        "capture-volume", *videos, "--calib", stage.calibration, "-o", out, *settings, *flags
    )


@dataclass(frozen=True)
class Result:
    """What one successful capture printed and wrote."""

    code: int
    printed: str
    err: str
    bvh: Path
    joints: Path


@pytest.fixture(scope="module")
def jacks(stage: Stage, tmp_path_factory: pytest.TempPathFactory) -> Result:
    """The jumping jacks captured with `--empty-frames` and `--joints`."""
    folder = tmp_path_factory.mktemp("jacks")
    bvh, joints = folder / "jacks.bvh", folder / "jacks.npz"
    facing = [f"{value:.6f}" for value in stage.facing]
    flags = ("--empty-frames", EMPTY_FRAMES, "--joints", joints, "--facing", *facing)
    code, printed, err = capture(stage, stage.videos, bvh, *flags)
    return Result(code, printed, err, bvh, joints)


def _model(printed: str) -> tuple[int, int]:
    """(branches, links) of the model a capture printed."""
    words = printed.split()
    return int(words[words.index("branches,") - 1]), int(words[words.index("links") - 1])


def test_the_capture_is_written_as_bvh_of_the_derived_skeleton(stage: Stage, jacks: Result) -> None:
    assert jacks.code == 0, jacks.err
    n = len(stage.truth)
    assert f"{n} frames (video frames {EMPTY_FRAMES}..{EMPTY_FRAMES + n - 1})" in jacks.printed
    assert "voxels per frame" in jacks.printed and "Isomap" in jacks.printed
    assert str(jacks.bvh) in jacks.printed
    motion = read_bvh(jacks.bvh)
    assert motion.n_frames == n
    assert motion.fps == pytest.approx(FPS)
    joints = [j for j in motion.joints if not j.end_site]
    ends = [j for j in motion.joints if j.end_site]
    branches, links = _model(jacks.printed)
    assert joints[0].name == "Root" and joints[0].parent == -1
    assert all(j.name.startswith("Branch") and "_Link" in j.name for j in joints[1:])
    assert len(joints) == links + 1 and len(ends) == branches
    assert all(motion.joints[end.parent].name + "_end" == end.name for end in ends)
    positions = motion.positions(list(range(len(motion.joints))))  # file units: meters
    assert np.isfinite(positions).all()
    low, high = stage.bounds
    assert (positions[:, 0] > low).all() and (positions[:, 0] < high).all()  # the root
    reach = FIXED_LENGTH_REACH_M
    assert (positions > low - reach).all() and (positions < high + reach).all()


def test_the_joints_of_a_human_model_are_near_the_truth(stage: Stage, jacks: Result) -> None:
    assert jacks.code == 0, jacks.err
    assert _model(jacks.printed)[0] == 5, jacks.printed
    assert f"13 joints -> {jacks.joints}" in jacks.printed
    with np.load(jacks.joints) as archive:
        joints = archive["joints"]
        assert archive["fps"] == FPS and archive["names"][0] == "head"
    assert joints.shape == stage.truth.shape and np.isfinite(joints).all()
    assert np.linalg.norm(joints - stage.truth, axis=-1).mean() < JOINT_LIMIT_M


def test_a_subject_without_human_shape_is_captured_without_joints(
    stage: Stage, tmp_path: Path
) -> None:
    out, joints = tmp_path / "pole.bvh", tmp_path / "pole.npz"
    flags = ("--background", *stage.empty, "--unit", "cm", "--lowpass", "3", "--joints", joints)
    code, printed, err = capture(stage, stage.pole, out, *flags)
    assert code == 0, err
    assert f"{POLE_FRAMES} frames (video frames 0..{POLE_FRAMES - 1})" in printed
    assert "not humanoid" in printed and str(joints) in printed and not joints.exists()
    motion = read_bvh(out)
    assert motion.n_frames == POLE_FRAMES
    root = motion.positions([0])[:, 0]  # file units: centimeters
    centre = 50.0 * POLE.sum(axis=0)
    assert np.abs(root[:, [0, 2]] - centre[[0, 2]]).max() < 10.0
    assert root[:, 1].min() > 0.0 and root[:, 1].max() < 100.0 * POLE[1, 1]


def test_one_video_per_camera_is_needed(stage: Stage, tmp_path: Path) -> None:
    out = tmp_path / "take.bvh"
    code, _, err = capture(stage, stage.videos[:3], out, "--empty-frames", EMPTY_FRAMES)
    _assert_one_line_error(code, err, stage.calibration, "4 cameras", "got 3 videos")
    assert not out.exists()
    flags = ("--background", *stage.empty[:2])
    code, _, err = capture(stage, stage.videos, out, *flags)
    _assert_one_line_error(code, err, stage.calibration, "4 cameras", "got 2 --background")
    assert not out.exists()


def test_a_one_camera_calibration_is_refused_before_any_work(stage: Stage, tmp_path: Path) -> None:
    one = tmp_path / "one.toml"
    write_calibration(one, list(read_calibration(stage.calibration))[:1])
    out = tmp_path / "take.bvh"
    code, _, err = samba(
        "capture-volume", stage.videos[0], "--calib", one, "-o", out, "--empty-frames", "3"
    )
    _assert_one_line_error(code, err, one, "has 1 camera; a visual hull needs at least 2")
    assert not out.exists()


def test_an_existing_output_is_left_unchanged(stage: Stage, tmp_path: Path) -> None:
    out = tmp_path / "take.bvh"
    out.write_bytes(b"an earlier capture")
    code, _, err = capture(stage, stage.videos, out, "--empty-frames", EMPTY_FRAMES)
    _assert_one_line_error(code, err, out, "already exists; --force overwrites")
    assert out.read_bytes() == b"an earlier capture"


@pytest.mark.parametrize(
    ("name", "joints", "named"), [("take.mcap", None, ".bvh"), ("take.bvh", "joints.csv", ".npz")]
)
def test_outputs_of_another_format_are_refused(
    stage: Stage, tmp_path: Path, name: str, joints: str | None, named: str
) -> None:
    out = tmp_path / name
    flags = ("--joints", tmp_path / joints) if joints else ()
    code, _, err = capture(stage, stage.videos, out, "--empty-frames", EMPTY_FRAMES, *flags)
    _assert_one_line_error(code, err, tmp_path / (joints or name), named)
    assert list(tmp_path.iterdir()) == []


def test_a_video_of_another_size_than_its_camera_is_refused(stage: Stage, tmp_path: Path) -> None:
    frames = [cv2.imread(str(p)) for p in sorted(stage.videos[2].iterdir())[: EMPTY_FRAMES + 2]]
    small = write_image_folder(
        tmp_path / "small", np.array([cv2.resize(f, (160, 120)) for f in frames])
    )
    out = tmp_path / "take.bvh"
    videos = [*stage.videos[:2], small, stage.videos[3]]
    code, _, err = capture(stage, videos, out, "--empty-frames", EMPTY_FRAMES)
    _assert_one_line_error(code, err, small, "160x120", "320x240", stage.calibration)
    assert not out.exists()


def test_a_take_nobody_walks_into_is_refused(stage: Stage, tmp_path: Path) -> None:
    out = tmp_path / "take.bvh"
    code, _, err = capture(stage, stage.empty, out, "--background", *stage.empty)
    _assert_one_line_error(code, err, *stage.empty, "nobody was seen")
    assert not out.exists()


def test_too_few_empty_frames_name_the_video(stage: Stage, tmp_path: Path) -> None:
    out = tmp_path / "take.bvh"
    code, _, err = capture(stage, stage.videos, out, "--empty-frames", "3")
    _assert_one_line_error(code, err, stage.videos[0], "at least 5 frames")
    assert not out.exists()


def test_a_failure_writing_the_joints_leaves_no_bvh(
    stage: Stage, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def full_disk(path: Path) -> None:
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr("samba.service.video_capture.atomic_path", full_disk)
    out, joints = tmp_path / "take.bvh", tmp_path / "take.npz"
    facing = [f"{value:.6f}" for value in stage.facing]
    flags = ("--empty-frames", EMPTY_FRAMES, "--joints", joints, "--facing", *facing)
    code, _, err = capture(stage, stage.videos, out, *flags)
    _assert_one_line_error(code, err, joints, "No space left")
    assert list(tmp_path.iterdir()) == []
