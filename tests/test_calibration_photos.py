"""Tests of board detection on real photos, its plausibility check, outlier images, and
`samba calibrate --intrinsics-only` / `--convert`.

The real photos are the Pose2Sim lab session's (../shared/data/pose2sim): seven hand-held
phone photos per camera of a 4 x 7 checkerboard of 6 cm squares, checked against the
lab's own Qualisys calibration (`Calib.qca.txt`). The rest renders a 9x6 board
(`samba.cameras.board_render`) seen by one 640x480 camera with lens distortion.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import shared_data_dir

from samba.cameras import (
    board_poses,
    read_calibration,
    render_board,
    stage_cameras,
    write_calibration,
)
from samba.cameras.calibration import calibrate_intrinsics
from samba.cameras.calibration_board import Board, BoardView, parse_board
from samba.cameras.camera import Camera, CameraGroup
from samba.cameras.corner_grid import grid_problem
from samba.cameras.recordings import CameraFrames, RecordingCalibration
from samba.cli import main

PHOTO_BOARD = "checkerboard:4x7:0.06"
BOARD = "checkerboard:9x6:0.08"
MAX_FOCAL_ERROR = 0.015
"""Focal lengths within 1.5% of the lab's (measured: 0.42% for cam01, 0.12% for cam02)."""
MAX_CENTRE_PX = 40.0
"""Principal point within 40 px of the lab's (measured: 33.9 and 33.2 px)."""


@pytest.fixture(scope="module")
def lab() -> Path:
    """The Pose2Sim lab session of the shared data; skips the test when it is absent."""
    data = shared_data_dir()
    if data is None or not (data / "pose2sim" / "calibration" / "intrinsics").is_dir():
        pytest.skip(
            "real Pose2Sim lab photos not found: set SAMBA_DATA or put ../shared/data/pose2sim "
            "beside the project"
        )
    return data / "pose2sim" / "calibration"


@pytest.mark.parametrize("camera", ["cam01", "cam02"])
def test_phone_photos_calibrate_like_the_lab(
    lab: Path, camera: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    photos = lab / "intrinsics" / f"int_{camera}_img"
    output = tmp_path / f"{camera}.toml"
    argv = ["calibrate", str(photos), "--board", PHOTO_BOARD, "--intrinsics-only", "-v"]
    assert main([*argv, "-o", str(output)]) == 0
    printed = capsys.readouterr().out
    found = [
        line for line in printed.splitlines() if line.startswith(f"int_{camera}_img  {camera}_")
    ]
    assert len(found) == 7, printed  # -v: one line per photo
    assert sum("no board found" not in line and "rejected" not in line for line in found) >= 6
    assert "reprojection error per image" in printed and f"{camera}_01_int.jpg 0." in printed
    (lens,) = read_calibration(output)
    reference = read_calibration(lab / "Calib.qca.txt")[camera]
    focal_error = np.abs(lens.matrix[[0, 1], [0, 1]] / reference.matrix[[0, 1], [0, 1]] - 1)
    assert focal_error.max() < MAX_FOCAL_ERROR, focal_error
    centre = np.linalg.norm(lens.matrix[:2, 2] - reference.matrix[:2, 2])
    assert centre < MAX_CENTRE_PX, centre
    assert lens.size == (1088, 1920) and lens.name == f"int_{camera}_img"
    np.testing.assert_array_equal(lens.rotation, 0.0)
    np.testing.assert_array_equal(lens.translation, 0.0)


# --- the plausibility check -----------------------------------------------------------


def _true_grid(board: Board) -> np.ndarray:
    """A board's corners (n, 2) as a tilted camera with lens distortion sees them."""
    camera = Camera.look_at("c", (0.4, 0.3, -1.2), (0.2, 0.1, 0.0), (640, 480), 60.0, (0, -1, 0))
    camera = Camera(
        "c", camera.size, camera.matrix, camera.rotation, camera.translation,
        np.array([-0.2, 0.05, 0.0, 0.0, 0.0]),
    )  # fmt: skip
    return camera.project(board.object_points)


def test_the_plausibility_check_refuses_bad_grids() -> None:
    board = parse_board(BOARD)
    xy, ids, columns = board.object_points[:, :2], np.arange(54), board.corner_grid[0]
    pixels = _true_grid(board)
    assert grid_problem(xy, ids, pixels, columns) == ""
    moved = pixels.copy()
    moved[20] += (50.0, 0.0)
    problem = grid_problem(xy, ids, moved, columns)
    assert "corner grid not a projective image of the board" in problem
    assert "px off a homography" in problem
    swapped = pixels.copy()
    swapped[[20, 21]] = swapped[[21, 20]]  # two neighbours numbered the wrong way round
    assert "not a projective image" in grid_problem(xy, ids, swapped, columns)
    shuffled = pixels[np.random.default_rng(0).permutation(54)]
    assert "not a projective image" in grid_problem(xy, ids, shuffled, columns)
    part = ids[ids % columns < 4]  # a partial (ChArUco-like) view is checked as well
    assert grid_problem(xy, part, pixels[part], columns) == ""
    assert "not a projective image" in grid_problem(xy, part, moved[part], columns)


@pytest.fixture(scope="module")
def rendered() -> tuple[Board, Camera, list[np.ndarray]]:
    """A 9x6 board in 10 poses seen by one 640x480 camera with lens distortion."""
    board = parse_board(BOARD)
    (camera,) = stage_cameras(1, [(-0.12, 0.03, 0.0, 0.0, 0.0)])
    rng = np.random.default_rng(5)
    poses = board_poses(board, [camera], 10, rng)
    return board, camera, [render_board(camera, board, pose, rng) for pose in poses]


def test_a_refused_grid_is_reported_and_the_next_detector_tried(
    rendered: tuple[Board, Camera, list[np.ndarray]], monkeypatch: pytest.MonkeyPatch
) -> None:
    board, _, images = rendered
    good = board.find(images[0])
    assert good.view is not None and good.summary == "sb"
    from samba.cameras import calibration_board

    real = calibration_board.checkerboard_corners

    def wrong_first(grey: np.ndarray, grid: tuple[int, int], detector: str) -> np.ndarray | None:
        corners = real(grey, grid, detector)
        if detector == "sb" and corners is not None:
            corners = corners.copy()
            corners[20] += (50.0, 0.0)  # one corner off by 50 px
        return corners

    monkeypatch.setattr(calibration_board, "checkerboard_corners", wrong_first)
    detection = board.find(images[0])
    assert detection.view is not None and detection.view.detector == "sb-exhaustive"
    assert detection.summary.startswith("sb-exhaustive (sb rejected: corner grid not a projective")
    np.testing.assert_allclose(detection.view.pixels, good.view.pixels, atol=0.05)

    def always_wrong(grey: np.ndarray, grid: tuple[int, int], detector: str) -> np.ndarray:
        return real(grey, grid, "sb")[np.random.default_rng(1).permutation(54)]

    monkeypatch.setattr(calibration_board, "checkerboard_corners", always_wrong)
    refused = board.find(images[0])
    assert refused.view is None
    assert refused.summary.startswith("rejected: corner grid not a projective image of the board")
    assert "(sb)" in refused.summary and "(classic)" in refused.summary
    monkeypatch.undo()
    assert board.find(np.full((480, 640), 128, np.uint8)).summary == "no board found"


# --- outlier images ---------------------------------------------------------------------


def test_an_outlier_image_is_dropped_and_said_so(
    rendered: tuple[Board, Camera, list[np.ndarray]],
) -> None:
    board, camera, images = rendered
    views = {n: board.detect(image) for n, image in enumerate(images)}
    assert all(view is not None for view in views.values())
    clean = calibrate_intrinsics(board, views, camera.size)
    assert clean.dropped == () and max(clean.view_rms_px.values()) < 0.5
    noisy = views[4].pixels + np.random.default_rng(2).normal(scale=4.0, size=(54, 2))
    views[4] = BoardView(views[4].ids, noisy, views[4].detector)
    lens = calibrate_intrinsics(board, views, camera.size)
    assert lens.dropped == (4,) and lens.used == [0, 1, 2, 3, 5, 6, 7, 8, 9]
    assert lens.view_rms_px[4] > lens.limit_px > max(clean.view_rms_px.values())
    assert abs(lens.matrix[0, 0] / camera.matrix[0, 0] - 1) < 0.01
    without = calibrate_intrinsics(board, {n: v for n, v in views.items() if n != 4}, camera.size)
    np.testing.assert_allclose(lens.matrix, without.matrix)  # the same as never seeing it

    from samba.cameras.calibration import calibrate_lens

    result = calibrate_lens(board, views, camera.size, "phone")
    frames = CameraFrames(
        "phone",
        camera.size,
        {n: f"img{n}.png" for n in views},
        {n: board.find(image) for n, image in enumerate(images)},
    )
    report = RecordingCalibration(result, [frames]).report()
    assert "phone: dropped img4.png as an outlier" in report
    assert "lens solved again on 9 images" in report
    assert result.views[0] == 9


# --- the command line -------------------------------------------------------------------


def test_intrinsics_only_writes_one_camera_at_the_origin(
    rendered: tuple[Board, Camera, list[np.ndarray]],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    _, camera, images = rendered
    folder = tmp_path / "webcam"
    folder.mkdir()
    for n, image in enumerate(images):
        cv2.imwrite(str(folder / f"frame{n}.png"), image)
    output = tmp_path / "webcam.toml"
    argv = ["calibrate", str(folder), "--board", BOARD, "--intrinsics-only", "-o", str(output)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "webcam: frame0.png 0.0" in printed and "intrinsics only" in printed
    (lens,) = read_calibration(output)
    assert lens.name == "webcam" and lens.size == camera.size
    assert abs(lens.matrix[0, 0] / camera.matrix[0, 0] - 1) < 0.01
    np.testing.assert_array_equal(lens.center, 0.0)
    assert main(argv) == 1  # never overwritten without --force
    assert capsys.readouterr().err.strip() == (
        f"samba: error: {output}: already exists; --force overwrites"
    )


def test_convert_writes_ours(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cameras = CameraGroup(tuple(stage_cameras(2, [(-0.1, 0.02, 0.0, 0.0, 0.0)])))
    source = tmp_path / "zup.toml"
    write_calibration(source, cameras, units="mm", up="+z")
    output = tmp_path / "ours.toml"
    assert main(["calibrate", "--convert", str(source), "-o", str(output)]) == 0
    printed = capsys.readouterr().out
    assert "cam0" in printed and "640x480" in printed and f"wrote {output}" in printed
    again = read_calibration(output)
    points = np.random.default_rng(3).uniform((-1, 0, -1), (1, 2, 1), (20, 3))
    np.testing.assert_allclose(again.project(points), cameras.project(points), atol=1e-6)


def test_convert_of_the_lab_qca_projects_as_the_qca(
    lab: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = lab / "Calib.qca.txt"
    output = tmp_path / "lab.toml"
    assert main(["calibrate", "--convert", str(source), "-o", str(output)]) == 0
    printed = capsys.readouterr().out
    assert "cam01" in printed and "1088x1920" in printed and "1681.2" in printed
    points = np.random.default_rng(4).uniform((-1.5, 0.0, -1.5), (1.5, 2.0, 1.5), (30, 3))
    np.testing.assert_allclose(
        read_calibration(output).project(points),
        read_calibration(source).project(points),
        atol=1e-6,
    )


def test_wrong_combinations_give_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    malformed = tmp_path / "lab.qca.txt"
    malformed.write_text("<calibration><cameras><camera")
    missing = tmp_path / "nowhere.qca"
    good = tmp_path / "good.toml"
    write_calibration(good, CameraGroup(tuple(stage_cameras(1))))
    out = str(tmp_path / "out.toml")
    a, b = str(tmp_path / "a"), str(tmp_path / "b")
    cases = [
        ([a, b, "--board", BOARD, "--intrinsics-only"], "--intrinsics-only: takes one camera's"),
        (["--convert", str(missing)], f"{missing}: No such file or directory"),
        (["--convert", str(malformed)], f"{malformed}: not a Qualisys calibration"),
        (["--convert", str(good), a], "--convert: takes no images or videos"),
        (["--convert", str(good), "--board", BOARD], "--board: does not apply to --convert"),
        ([a], "--board: required"),
        (["--board", BOARD], "IMAGES_OR_VIDEO: give a folder of images or a video per camera"),
        ([a, "--board", BOARD, "--intrinsics-only", "--world", "camera0"], "--world: does not"),
    ]
    for args, message in cases:
        assert main(["calibrate", *args, "-o", out]) == 1, args
        err = capsys.readouterr().err
        assert err.startswith(f"samba: error: {message}") and err.count("\n") == 1, err
    assert not Path(out).exists()
    argv = [sys.executable, "-m", "samba.cli", "calibrate", "--convert", str(malformed)]
    done = subprocess.run([*argv, "-o", out], capture_output=True, text=True, timeout=120)
    assert done.returncode == 1 and len(done.stderr.splitlines()) == 1, done.stderr
