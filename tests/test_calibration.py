"""Tests of board detection, camera calibration and `samba calibrate` on rendered boards.

The scene (`samba.cameras.board_render`): three 640x480 cameras about 3 m from the middle
of the stage, two of them with lens distortion, film a 9x6 checkerboard of 8 cm squares
lying on the floor (frame 0, corner 0 at the world origin) and then waved through the
stage in 20 poses (frames 1..20).
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest

from samba.base.errors import InputError
from samba.cameras import board_poses, floor_pose, render_board, stage_cameras
from samba.cameras.calibration import MIN_VIEWS, calibrate, calibrate_intrinsics
from samba.cameras.calibration_board import Board, BoardView, parse_board
from samba.cameras.calibration_file import read_calibration
from samba.cameras.camera import Camera, CameraGroup
from samba.cli import main

BOARD = "checkerboard:9x6:0.08"
DISTORTIONS = ((-0.12, 0.03, 0.0, 0.0, 0.0), (0.0,) * 5, (-0.05, 0.01, 5e-4, -5e-4, 0.0))


@dataclass
class Scene:
    board: Board
    cameras: list[Camera]
    poses: list[tuple[np.ndarray, np.ndarray]]
    images: list[list[np.ndarray]]  # [camera][frame]
    detections: list[dict[int, BoardView]]

    def calibrate(self, cameras: tuple[int, ...] = (0, 1, 2), **options: object):
        return calibrate(
            self.board,
            [self.detections[i] for i in cameras],
            [self.cameras[i].size for i in cameras],
            [self.cameras[i].name for i in cameras],
            **options,
        )

    def truth(self, camera: int, frame: int) -> np.ndarray:
        rotation, translation = self.poses[frame]
        return self.cameras[camera].project(self.board.object_points @ rotation.T + translation)


@pytest.fixture(scope="module")
def scene() -> Scene:
    board = parse_board(BOARD)
    cameras = stage_cameras(3, DISTORTIONS)
    rng = np.random.default_rng(11)
    poses = [floor_pose(), *board_poses(board, cameras, 20, rng)]
    images = [[render_board(c, board, pose, rng) for pose in poses] for c in cameras]
    detections = []
    for frames in images:
        found = {n: board.detect(image) for n, image in enumerate(frames)}
        detections.append({n: view for n, view in found.items() if view is not None})
    return Scene(board, cameras, poses, images, detections)


def _assert_recovered(result, truth: list[Camera], centre_cm: float = 1.0) -> None:
    """The acceptance: focal lengths within 1%, centres within 1 cm, reprojection < 0.5 px."""
    for camera, true in zip(result.cameras, truth, strict=True):
        focal_error = np.abs(camera.matrix[[0, 1], [0, 1]] / true.matrix[[0, 1], [0, 1]] - 1)
        assert focal_error.max() < 0.01, (camera.name, focal_error)
        centre_error = np.linalg.norm(camera.center - true.center)
        assert centre_error < centre_cm / 100.0, (camera.name, centre_error)
    assert (result.rms_px < 0.5).all(), result.rms_px


@pytest.mark.slow
def test_detected_corners_match_the_truth(scene: Scene) -> None:
    errors = []
    for c, detections in enumerate(scene.detections):
        assert 0 in detections, f"{scene.cameras[c].name} misses the board on the floor"
        assert len(detections) >= 15
        for frame, view in detections.items():
            np.testing.assert_array_equal(view.ids, np.arange(54))
            errors.append(np.linalg.norm(view.pixels - scene.truth(c, frame), axis=1))
    errors = np.concatenate(errors)
    assert errors.max() < 0.5  # a wrongly numbered board would be off by whole squares
    assert np.sqrt(np.mean(errors**2)) < 0.15


def test_calibration_recovers_known_cameras(scene: Scene) -> None:
    distances = [np.linalg.norm(c.center - [0.3, 0.7, 0.2]) for c in scene.cameras]
    assert np.allclose(distances, 3.0, atol=0.01)  # "within 1 cm at 3 m"
    result = scene.calibrate()
    _assert_recovered(result, scene.cameras)
    assert result.world == "board" and result.floor_frame == 0
    assert result.cameras.names == ("cam0", "cam1", "cam2")
    assert (result.views == [len(d) for d in scene.detections]).all()
    np.testing.assert_allclose(result.cameras[0].distortion[:2], DISTORTIONS[0][:2], atol=0.02)
    for camera, true in zip(result.cameras, scene.cameras, strict=True):
        np.testing.assert_allclose(camera.matrix[:2, 2], true.matrix[:2, 2], atol=2.0)


def test_world_from_the_first_camera(scene: Scene) -> None:
    result = scene.calibrate(world="camera0")
    first = result.cameras[0]
    np.testing.assert_allclose(first.center, 0.0, atol=1e-9)
    np.testing.assert_allclose(first.rotation_matrix, np.diag([1.0, -1.0, -1.0]), atol=1e-9)
    assert result.floor_frame is None
    true_first = scene.cameras[0]
    for camera, true in zip(result.cameras[1:], scene.cameras[1:], strict=True):
        relative = camera.rotation_matrix @ first.rotation_matrix.T
        true_relative = true.rotation_matrix @ true_first.rotation_matrix.T
        np.testing.assert_allclose(relative, true_relative, atol=2e-3)
        distance = np.linalg.norm(camera.center - first.center)
        assert distance == pytest.approx(np.linalg.norm(true.center - true_first.center), abs=0.01)


def test_joint_refinement_of_the_intrinsics(scene: Scene) -> None:
    result = scene.calibrate(cameras=(0, 2), refine_intrinsics=True)
    _assert_recovered(result, [scene.cameras[0], scene.cameras[2]])


def test_checkerboard_numbering_survives_a_half_turn(scene: Scene) -> None:
    rotation, translation = scene.poses[3]
    centre = scene.board.object_points.mean(axis=0)
    half_turn = np.diag([-1.0, -1.0, 1.0])  # about the board's normal through its centre
    turned = (rotation @ half_turn, translation + rotation @ (centre - half_turn @ centre))
    camera = scene.cameras[1]
    for pose in (scene.poses[3], turned):
        image = render_board(camera, scene.board, pose, np.random.default_rng(0))
        view = scene.board.detect(image)
        truth = camera.project(scene.board.object_points @ pose[0].T + pose[1])
        assert view is not None
        assert np.abs(view.pixels - truth).max() < 0.5


def test_charuco_board(scene: Scene) -> None:
    board = parse_board("charuco:7x5:0.1:0.075:4x4_50")
    camera = scene.cameras[0]
    rng = np.random.default_rng(3)
    near = camera.center + 1.5 * camera.rotation_matrix[2]  # 1.5 m along the optical axis
    poses = board_poses(board, [camera], 12, rng, centre=near, spread=0.2, max_tilt_deg=45.0)
    views = []
    for rotation, translation in poses:
        view = board.detect(render_board(camera, board, (rotation, translation), rng))
        assert view is not None and len(view.ids) >= 6
        truth = camera.project(board.object_points[view.ids] @ rotation.T + translation)
        assert np.abs(view.pixels - truth).max() < 0.5
        views.append(view)
    lens = calibrate_intrinsics(board, views, camera.size)
    matrix, rms = lens.matrix, lens.rms_px
    focal_error = np.abs(matrix[[0, 1], [0, 1]] / camera.matrix[[0, 1], [0, 1]] - 1)
    assert focal_error.max() < 0.01 and rms < 0.5
    blank = np.full((480, 640), 128, np.uint8)
    assert board.detect(blank) is None and scene.board.detect(blank) is None


def test_board_specs() -> None:
    board = parse_board("checkerboard:9x6:0.04")
    assert (board.kind, board.corner_grid, board.square) == ("checkerboard", (9, 6), 0.04)
    assert board.object_points.shape == (54, 3)
    np.testing.assert_allclose(board.object_points[10], [0.04, 0.04, 0.0])
    charuco = parse_board("ChArUco:7x5:0.08:0.06:DICT_5X5_100")
    assert charuco.dictionary == "5X5_100" and charuco.corner_grid == (6, 4)
    np.testing.assert_allclose(charuco.object_points[0], [0.08, 0.08, 0.0])
    assert parse_board(charuco.spec) == charuco
    for spec, problem in (
        ("checkerboard:9x6", "cannot read"),
        ("checkerboard:9by6:0.04", "cannot read"),
        ("checkerboard:9x6:abc", "cannot read"),
        ("chess:9x6:0.04", "cannot read"),
        ("checkerboard:8x6:0.04", "one even and one odd"),
        ("checkerboard:9x2:0.04", "at least 3x3"),
        ("checkerboard:9x6:-1", "positive"),
        ("charuco:7x5:0.08:0.09:4X4_50", "smaller than the square"),
        ("charuco:7x5:0.08:0.06:9X9_50", "unknown ArUco dictionary"),
        ("charuco:12x12:0.08:0.06:4X4_50", "needs 72 markers"),
    ):
        with pytest.raises(InputError, match=problem) as caught:
            parse_board(spec)
        assert caught.value.source == "--board"


def test_calibration_errors_name_the_camera_or_frame(scene: Scene) -> None:
    few = dict(list(scene.detections[1].items())[: MIN_VIEWS - 1])
    with pytest.raises(InputError, match="found in 3 image") as caught:
        calibrate(scene.board, [scene.detections[0], few], [(640, 480)] * 2, ["cam0", "cam1"])
    assert caught.value.source == "cam1"
    apart = {frame + 1000: view for frame, view in scene.detections[2].items()}
    with pytest.raises(InputError, match="never saw the board in the same frame") as caught:
        calibrate(scene.board, [scene.detections[0], apart], [(640, 480)] * 2, ["a", "b"])
    assert caught.value.source == "b"
    with pytest.raises(InputError, match="no camera sees the board"):
        scene.calibrate(floor_frame=99)


def _write_frames(folder: Path, images: list[np.ndarray]) -> Path:
    folder.mkdir()
    for n, image in enumerate(images):
        cv2.imwrite(str(folder / f"frame{n}.png"), image)
    return folder


@pytest.mark.slow
def test_cli_calibrates_folders_and_videos(
    scene: Scene, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folders = [
        _write_frames(tmp_path / name, scene.images[i]) for i, name in ((0, "left"), (1, "mid"))
    ]
    video = tmp_path / "right.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (640, 480))
    for image in scene.images[2]:
        writer.write(cv2.cvtColor(image, cv2.COLOR_GRAY2BGR))
    writer.release()
    output = tmp_path / "calib.toml"
    status = main(
        ["calibrate", *map(str, folders), str(video), "--board", BOARD, "-o", str(output)]
    )
    printed = capsys.readouterr().out
    assert status == 0, printed
    assert "left" in printed and "right" in printed and f"wrote {output}" in printed
    group = read_calibration(output)
    assert group.names == ("left", "mid", "right")
    for camera, true in zip(group, scene.cameras, strict=True):
        assert np.linalg.norm(camera.center - true.center) < 0.01
        assert abs(camera.matrix[0, 0] / true.matrix[0, 0] - 1) < 0.01


def test_cli_errors(scene: Scene, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = _write_frames(tmp_path / "good", scene.images[0][:6])
    blank = _write_frames(tmp_path / "blank", [np.full((480, 640), 128, np.uint8)] * 3)
    corrupt = _write_frames(tmp_path / "corrupt", scene.images[1][:2])
    (corrupt / "frame2.png").write_bytes(b"not a png")
    (tmp_path / "empty").mkdir()
    (tmp_path / "text.mp4").write_text("not a video")
    out = str(tmp_path / "c.toml")
    cases = [
        ([str(good), "--board", "checkerboard:9x6"], "--board: cannot read"),
        ([str(tmp_path / "nowhere"), "--board", BOARD], "no such file or folder"),
        ([str(tmp_path / "empty"), "--board", BOARD], "folder holds no images"),
        ([str(good), str(blank), "--board", BOARD], "was not found in any of its 3 frames"),
        ([str(good), str(corrupt), "--board", BOARD], "frame2.png: cannot be read as an image"),
        ([str(good), str(tmp_path / "text.mp4"), "--board", BOARD], "cannot be opened as a video"),
        ([str(good), "--board", BOARD, "--world", "camera0", "--floor-frame", "0"], "applies to"),
    ]
    for args, message in cases:
        assert main(["calibrate", *args, "-o", out]) == 1
        assert message in capsys.readouterr().err
    assert main(["calibrate", str(good), "--board", BOARD, "-o", str(tmp_path / "no/c.toml")]) == 1
    assert "does not exist" in capsys.readouterr().err
    assert not Path(out).exists()


def test_a_file_that_is_not_a_video_gives_one_line_and_no_ffmpeg_noise(tmp_path: Path) -> None:
    # FFmpeg prints its own "moov atom not found" on stderr unless silenced.
    fake = tmp_path / "fake.mp4"
    fake.write_text("not a video")
    argv = [sys.executable, "-m", "samba.cli", "calibrate", str(fake), "--board", BOARD]
    out = str(tmp_path / "c.toml")
    done = subprocess.run([*argv, "-o", out], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1
    assert done.stderr.splitlines() == [f"samba: error: {fake}: cannot be opened as a video"]


def test_cameras_in_the_group_keep_their_order(scene: Scene) -> None:
    result = scene.calibrate(cameras=(2, 0))
    assert isinstance(result.cameras, CameraGroup)
    assert result.cameras.names == ("cam2", "cam0")
    _assert_recovered(result, [scene.cameras[2], scene.cameras[0]])
