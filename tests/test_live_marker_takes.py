"""Real marker takes through the live path: `samba node --synthetic FILE.c3d` and `samba demo
--motion FILE.c3d` film the shared CMU take's own 8 skin markers (`samba.service.marker_motion`)."""

from __future__ import annotations

import socket
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest

from samba.body.skeleton import MARKER_JOINTS, MARKER_NAMES, markers_of, standing_pose
from samba.cameras.calibration_file import write_calibration
from samba.cameras.camera import CameraGroup
from samba.cameras.triangulation import triangulate_cameras
from samba.cli import main
from samba.ingest.c3d_take import MarkerTake, read_c3d
from samba.ingest.mcap_take import read_take
from samba.markers.observation import spread_cameras
from samba.service.marker_motion import MarkerMotion, marker_poses
from samba.service.packet import decode

FPS, SECONDS, START_AT = 50.0, 2.5, 2000.5
"""The node's rate (120 Hz resampled by interpolation: 2.4 file frames a frame), the
length played and the time of its first frame."""
LEAD_IN = round(1.0 * FPS)
"""Frames of the made-up standing start: 0.5 s held, 0.5 s into the first frame."""


def placed(take: MarkerTake, fps: float, seconds: float) -> np.ndarray:
    """The take's markers (n, 8, 3) as the stage should play them: at `fps` by linear
    interpolation in time, the first `seconds`, moved along the floor so that the
    file's mean marker position is at x = z = 0, heights kept."""
    times = np.arange(round(seconds * fps)) / fps
    file_times = np.arange(len(take)) / take.fps
    flat = take.markers.reshape(len(take), -1)
    markers = np.stack([np.interp(times, file_times, column) for column in flat.T], axis=1)
    centre = take.markers.reshape(-1, 3).mean(axis=0)
    return markers.reshape(len(times), 8, 3) - [centre[0], 0.0, centre[2]]


@dataclass(frozen=True)
class Stage:
    """Two 320x240 cameras around the placed take, written to `calib`."""

    file: Path
    take: MarkerTake
    cameras: CameraGroup
    calib: Path


@pytest.fixture(scope="module")
def stage(c3d_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Stage:
    file = c3d_dir / "85_02.c3d"
    take = read_c3d(file)
    cameras = CameraGroup(
        tuple(spread_cameras(marker_poses(placed(take, FPS, 6.0)), 2, (320, 240)))
    )
    calib = tmp_path_factory.mktemp("marker-stage") / "calib.toml"
    write_calibration(calib, cameras)
    return Stage(file, take, cameras, calib)


def node_packets(stage: Stage, camera: int, *argv: str) -> tuple[int, np.ndarray]:
    """Run `samba node` on camera `camera` of the stage, unpaced; (exit status, the
    markers (n, 8, 2) pixels of the packets it sent)."""
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    receiver.bind(("127.0.0.1", 0))
    server = f"127.0.0.1:{receiver.getsockname()[1]}"
    with receiver:
        code = main(
            [
                *("node", "--calib", str(stage.calib), "--server", server),
                *("--camera", str(camera), "--no-pace", "--start-at", str(START_AT)),
                *("--fps", str(FPS), *argv),
            ]
        )
        receiver.settimeout(0.3)
        packets = []
        try:
            while True:
                packets.append(decode(receiver.recv(1024)).markers)
        except TimeoutError:
            pass
    return code, np.array(packets).reshape(-1, 8, 2)


def test_a_node_films_the_takes_own_markers(stage: Stage, capsys) -> None:
    """Two nodes' packets triangulate to the C3D's markers, resampled and placed, after a
    standing start from the standard pose into the take's first frame."""
    argv = ["--synthetic", str(stage.file), "--seconds", str(SECONDS)]
    runs = [node_packets(stage, camera, *argv) for camera in (0, 1)]
    assert [code for code, _ in runs] == [0, 0]
    frames = LEAD_IN + round(SECONDS * FPS)
    assert [len(pixels) for _, pixels in runs] == [frames, frames]
    assert capsys.readouterr().out.count(f"{frames} frames in") == 2
    world = triangulate_cameras(list(stage.cameras), np.stack([p for _, p in runs]))

    truth = placed(stage.take, FPS, SECONDS)
    error = np.linalg.norm(world[LEAD_IN:] - truth, axis=-1)
    seen = ~np.isnan(error)
    assert seen[: round(FPS)].mean() > 0.95 and seen.mean() > 0.8  # the trackers keep up
    assert np.median(error[seen]) < 0.002 and error[seen].max() < 0.005  # meters
    motion = truth[:, :2, 1]  # the shoulders: the take's own motion, not a standing pose
    assert np.ptp(motion) > 0.05

    # the held start: the standard pose of the stature the first frame's shoulders give
    # (their rise above the feet), standing where that frame stands, facing its way
    first = truth[0]
    across = first[0] - first[1]
    heading = np.degrees(np.arctan2(-across[2], across[0]))
    rise_per_m = np.subtract(*markers_of(standing_pose())[[0, 6], 1]) / 1.7
    height = (first[:2, 1].mean() - first[6:, 1].mean()) / rise_per_m
    standard = markers_of(standing_pose(first[:, [0, 2]].mean(axis=0), heading, height))
    assert np.linalg.norm(world[: LEAD_IN // 2] - standard, axis=-1).max() < 0.005
    blend_end = world[LEAD_IN - 1]  # nearly the first frame
    assert np.nanmax(np.linalg.norm(blend_end - first, axis=-1)) < 0.05


@pytest.mark.slow
def test_the_demo_plays_the_take_and_records_real_motion(
    stage: Stage, live_store: Path, tmp_path: Path, capsys
) -> None:
    seconds, fps = 3.5, 30.0
    code = main(
        [
            *("demo", "--motion", str(stage.file), "--db", str(live_store)),
            *("--out-dir", str(tmp_path), "--seconds", str(seconds), "--fps", str(fps)),
            *("--vmc", "127.0.0.1:9"),
        ]
    )
    out = capsys.readouterr().out
    frames = round(seconds * fps)
    assert code == 0 and f"frames out: {frames} of {frames}" in out
    assert "a marker take has no true joints" in out
    recorded = read_take(tmp_path / "takes" / "demo" / "demo_85_02.mcap")
    assert recorded.poses.shape == (frames, 13, 3)

    truth = placed(stage.take, fps, seconds)
    markers = recorded.poses[:, MARKER_JOINTS]
    assert np.median(np.linalg.norm(markers - truth, axis=-1)) < 0.05
    shoulders, expected = markers[:, :2, 1].mean(axis=1), truth[:, :2, 1].mean(axis=1)
    assert np.ptp(expected) > 0.1  # the take jumps: its shoulders rise and fall
    assert (
        np.median(np.abs(shoulders - expected)) < 0.03
        and np.corrcoef(shoulders, expected)[0, 1] > 0.6
    )
    travel = np.linalg.norm(np.ptp(markers.mean(axis=1)[:, [0, 2]], axis=0))
    expected_travel = np.linalg.norm(np.ptp(truth.mean(axis=1)[:, [0, 2]], axis=0))
    assert expected_travel > 0.5 and abs(travel - expected_travel) < 0.1
    assert (tmp_path / "exports" / "demo_85_02.glb").is_file()


def _bad_c3d(tmp_path: Path) -> Path:
    path = tmp_path / "broken.c3d"
    path.write_bytes(b"\x02P" + bytes(1000))
    return path


@pytest.mark.parametrize("command", ["node", "demo"])
@pytest.mark.parametrize("case", ["bad file", "missing marker set", "labels not in the file"])
def test_bad_marker_takes_are_one_line_errors(
    command: str, case: str, stage: Stage, tmp_path: Path, capsys
) -> None:
    motion, named = str(stage.file), []
    extra: list[str] = []
    if case == "bad file":
        motion = str(_bad_c3d(tmp_path))
        named = [motion]
    elif case == "missing marker set":
        extra = ["--marker-set", str(tmp_path / "nothere.toml")]
        named = ["nothere.toml"]
    else:
        marker_set = tmp_path / "other-lab.toml"
        marker_set.write_text(
            'name = "other-lab"\n[markers]\n'
            + "".join(f'{name} = "{name.upper()}"\n' for name in ("l_shoulder", "r_shoulder"))
            + "".join(
                f'{side}_{part} = "{side.upper()}{label}"\n'
                for side in "lr"
                for part, label in (("wrist", "WRA"), ("knee", "KNE"), ("foot", "ANK"))
            )
        )
        extra = ["--marker-set", str(marker_set)]
        named = [motion, "l_shoulder", "L_SHOULDER"]
    out = tmp_path / "demo"
    argv = (
        [
            *("node", "--calib", str(stage.calib), "--camera", "0", "--synthetic", motion),
            *("--server", "127.0.0.1:9", "--no-pace"),
        ]
        if command == "node"
        else ["demo", "--motion", motion, "--out-dir", str(out), "--vmc", "127.0.0.1:9"]
    )
    code = main(argv + extra)
    err = capsys.readouterr().err
    assert code == 1
    assert err.startswith("samba: error: ") and err.count("\n") == 1, err
    for word in named:
        assert word in err
    assert not out.exists()  # the demo stops before it makes anything


def test_a_marker_set_renames_the_labels(stage: Stage, tmp_path: Path) -> None:
    """`--marker-set`: each wrist one marker (WRB) instead of Plug-in-Gait's pair."""
    marker_set = tmp_path / "one-wrist-marker.toml"
    labels = ("LSHO", "RSHO", "LWRB", "RWRB", "LKNE", "RKNE", "LANK", "RANK")
    marker_set.write_text(
        'name = "one-wrist"\n[markers]\n'
        + "".join(f'{n} = "{label}"\n' for n, label in zip(MARKER_NAMES, labels, strict=True))
    )
    argv = ["--synthetic", str(stage.file), "--seconds", "0.2", "--marker-set", str(marker_set)]
    code, pixels = node_packets(stage, 0, *argv)
    assert code == 0 and len(pixels) == LEAD_IN + round(0.2 * FPS)
    one_wrist = replace(stage.take, markers=stage.take.markers.copy())
    one_wrist.markers[:, 2:4] = np.stack([stage.take.point("LWRB"), stage.take.point("RWRB")], 1)
    camera = stage.cameras[0]
    error = np.linalg.norm(pixels[-1, 2] - camera.project(placed(one_wrist, FPS, 0.2)[-1, 2]))
    pair = np.linalg.norm(pixels[-1, 2] - camera.project(placed(stage.take, FPS, 0.2)[-1, 2]))
    assert error < 0.5 < 1.0 < pair  # pixels: the node films WRB, not the pair's midpoint


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["--synthetic", "walk", "--marker-set", "x.toml"], ["--marker-set", "C3D"]),
        (["--synthetic", "85_02.c3d", "--mode", "silhouette"], ["85_02.c3d", "--mode markers"]),
    ],
)
def test_marker_take_flags_out_of_place(
    argv: list[str], named: list[str], stage: Stage, capsys
) -> None:
    code = main(["node", "--calib", str(stage.calib), "--camera", "0", *argv])
    err = capsys.readouterr().err
    assert code == 1 and err.count("\n") == 1
    for word in named:
        assert word in err


def test_the_placement_depends_on_the_file_alone(stage: Stage) -> None:
    """A node given the demo's calibration films the take where the demo's cameras look,
    whatever the rate and the length each plays."""
    short = MarkerMotion.read(stage.file, 30.0, 1.0)
    whole = MarkerMotion.read(stage.file, 120.0)
    np.testing.assert_allclose(short.markers, whole.markers[: len(short) * 4 : 4], atol=1e-9)
    assert abs(whole.markers[..., [0, 2]].mean()) < 1e-9
    np.testing.assert_allclose(whole.markers[..., 1], stage.take.markers[..., 1], atol=1e-9)
