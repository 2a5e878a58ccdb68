"""`samba node`: frames in, one UDP marker packet per frame out, received on 127.0.0.1."""

from __future__ import annotations

import io
import re
import socket
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest

import samba.service.cli.node
import samba.service.node
import samba.service.node_summary
from samba.body.skeleton import markers_of
from samba.cameras.calibration_file import write_calibration
from samba.cameras.camera import Camera, CameraGroup
from samba.cameras.frame_io import write_images, write_video
from samba.cli import main
from samba.markers.lead_in import LeadIn
from samba.markers.observation import spread_cameras
from samba.service.errors import PacketError
from samba.service.node import (
    START_DELAY_SECONDS,
    CameraNode,
    Capture,
    PacketSender,
    SubjectStart,
    SyntheticFeed,
    grid_captures,
    run_node,
    synthetic_lead_in,
)
from samba.service.packet import MarkerPacket, decode

MOTION, SECONDS, FPS, SEED = "walk", 1.0, 30.0, 3
FRAMES = round((1.0 + SECONDS) * FPS)
"""Frames of the synthetic take: the 1-s standing lead-in, then the motion."""
START_AT = 1000.25
FIRST_SEQUENCE = 2**32 - 3
"""Starts three frames before the sequence number wraps."""


@dataclass(frozen=True)
class Rig:
    """Two 320x240 cameras around the synthetic take, written to `calib`."""

    lead_in: LeadIn
    cameras: list[Camera]
    calib: Path


@pytest.fixture(scope="module")
def rig(tmp_path_factory: pytest.TempPathFactory) -> Rig:
    lead_in = synthetic_lead_in(MOTION, SECONDS, FPS, SEED)
    cameras = spread_cameras(lead_in.poses, 2, (320, 240))
    calib = tmp_path_factory.mktemp("rig") / "calib.toml"
    write_calibration(calib, CameraGroup(tuple(cameras)))
    return Rig(lead_in, cameras, calib)


class Receiver:
    """A UDP socket on 127.0.0.1 standing in for the server; `address` is HOST:PORT."""

    def __init__(self) -> None:
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self.socket.bind(("127.0.0.1", 0))
        self.address = f"127.0.0.1:{self.socket.getsockname()[1]}"

    def datagrams(self, idle: float = 0.3) -> list[tuple[bytes, float]]:
        """(datagram, arrival time) until none came for `idle` seconds."""
        self.socket.settimeout(idle)
        received = []
        try:
            while True:
                received.append((self.socket.recv(1024), time.time()))
        except TimeoutError:
            return received

    def packets(self, key: bytes | None = None) -> list[MarkerPacket]:
        """The decoded packets received so far."""
        return [decode(data, key) for data, _ in self.datagrams()]


@pytest.fixture
def receiver() -> Iterator[Receiver]:
    server = Receiver()
    yield server
    server.socket.close()


def node(rig: Rig, server: str, *argv: str) -> list[str]:
    """`samba node` arguments for the rig's calibration, sending to `server`."""
    return ["node", "--calib", str(rig.calib), "--server", server, *argv]


def synthetic(camera: int, *argv: str) -> list[str]:
    """Arguments of a synthetic source filming the test take with camera `camera`."""
    return [
        "--camera",
        str(camera),
        "--synthetic",
        MOTION,
        "--seconds",
        str(SECONDS),
        "--seed",
        str(SEED),
        *argv,
    ]


def run(capsys: pytest.CaptureFixture[str], argv: list[str]) -> tuple[int, str, str]:
    """Run `samba argv...` in-process; returns (exit status, stdout, stderr)."""
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def synthetic_run(rig: Rig) -> tuple[list[MarkerPacket], str]:
    """Camera 0 of the synthetic rig, unpaced: its packets and the summary line."""
    server = Receiver()
    with pytest.MonkeyPatch.context() as patch:
        out = io.StringIO()
        patch.setattr("sys.stdout", out)
        argv = synthetic(0, "--no-pace", "--start-at", str(START_AT))
        argv += ["--start-sequence", str(FIRST_SEQUENCE), "--session", "stage-1"]
        assert main(node(rig, server.address, *argv)) == 0
    packets = server.packets()
    server.socket.close()
    return packets, out.getvalue()


def test_synthetic_node_sends_the_tracked_markers(rig: Rig, synthetic_run) -> None:
    packets, out = synthetic_run
    assert len(packets) == FRAMES
    assert [p.sequence for p in packets] == [(FIRST_SEQUENCE + i) % 2**32 for i in range(FRAMES)]
    # one epoch until the sequence wraps, then another: it only increases within one
    epochs = [p.epoch for p in packets]
    assert len(set(epochs[:3])) == len(set(epochs[3:])) == 1 and epochs[2] != epochs[3]
    assert {(p.camera, p.session) for p in packets} == {(0, "stage-1")}
    times = np.array([p.timestamp for p in packets])
    np.testing.assert_allclose(times, START_AT + np.arange(FRAMES) / FPS, rtol=0, atol=1e-9)
    pixels = np.stack([p.markers for p in packets])
    truth = rig.cameras[0].project(markers_of(rig.lead_in.poses))
    error = np.linalg.norm(pixels - truth, axis=-1)
    present = ~np.isnan(error)
    assert present.mean() > 0.4
    assert present[: round(FPS / 2)].mean() > 0.8  # the standing start
    assert np.median(error[present]) < 1.0 and error[present].max() < 2.0
    assert f"camera 0: {FRAMES} frames" in out and "0 send errors" in out
    assert out.count("\n") == 1


def test_two_real_time_nodes_film_the_same_instants(
    rig: Rig, receiver: Receiver, capsys: pytest.CaptureFixture[str]
) -> None:
    start_at = time.time() + 0.5
    seconds = 0.3  # 1.3 s of frames with the lead-in
    codes: list[int] = []

    def camera_node(camera: int) -> None:
        argv = synthetic(camera, "--start-at", repr(start_at), "--seconds", str(seconds))
        codes.append(main(node(rig, receiver.address, *argv)))

    threads = [threading.Thread(target=camera_node, args=(c,)) for c in (0, 1)]
    for thread in threads:
        thread.start()
    received = receiver.datagrams(idle=1.0)
    for thread in threads:
        thread.join()
    assert codes == [0, 0]
    frames = round((1.0 + seconds) * FPS)
    by_camera: dict[int, list[tuple[MarkerPacket, float]]] = {0: [], 1: []}
    for data, arrival in received:
        packet = decode(data)
        by_camera[packet.camera].append((packet, arrival))
    assert [len(by_camera[c]) for c in (0, 1)] == [frames, frames]
    stamps = [np.array([p.timestamp for p, _ in by_camera[c]]) for c in (0, 1)]
    np.testing.assert_array_equal(stamps[0], stamps[1])
    np.testing.assert_allclose(stamps[0], start_at + np.arange(frames) / FPS, rtol=0, atol=1e-9)
    for c in (0, 1):
        assert [p.sequence for p, _ in by_camera[c]] == list(range(frames))
        delay = np.array([arrival - p.timestamp for p, arrival in by_camera[c]])
        assert delay.min() > -0.002  # never sent before the frame is captured
        assert np.median(delay) < 0.05
    out = capsys.readouterr().out
    assert sorted(re.findall(r"camera (\d): (\d+) frames in", out)) == [
        ("0", str(frames)),
        ("1", str(frames)),
    ]


def test_signed_packets_need_the_key(
    rig: Rig, receiver: Receiver, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    key = bytes(range(32))
    key_file = tmp_path / "node.key"
    key_file.write_bytes(key)
    argv = synthetic(1, "--no-pace", "--seconds", "0.2", "--key-file", str(key_file))
    assert run(capsys, node(rig, receiver.address, *argv))[0] == 0
    datagrams = [data for data, _ in receiver.datagrams()]
    assert len(datagrams) == round(1.2 * FPS)
    packets = [decode(d, key) for d in datagrams]
    # 124 bytes signed, plus a count and 8 bytes per blob the tracker left unlabelled
    sizes = [124 + (1 + 8 * len(p.blobs) if len(p.blobs) else 0) for p in packets]
    assert [len(d) for d in datagrams] == sizes
    assert [p.sequence for p in packets] == list(range(len(datagrams)))
    with pytest.raises(PacketError, match="unexpected tag"):
        decode(datagrams[0])
    with pytest.raises(PacketError, match="bad tag"):
        decode(datagrams[0], bytes(32))


@pytest.mark.parametrize("kind", ["images", "video"])
def test_recorded_frames_give_the_synthetic_pixels(
    kind: str,
    rig: Rig,
    synthetic_run,
    receiver: Receiver,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    feed = SyntheticFeed(rig.cameras[0], 0, rig.lead_in, FPS, SEED, START_AT, pace=False)
    frames = np.stack(list(feed.frames()))
    if kind == "images":
        path = tmp_path / "frames"
        write_images(frames, path)
    else:
        path = tmp_path / "take.avi"
        write_video(frames, path, FPS)
    start = SubjectStart.of(rig.lead_in)
    argv = ["--camera", "0", f"--{kind}", str(path), "--no-pace", "--start-x", repr(start.x)]
    argv += ["--start-z", repr(start.z), "--heading", repr(start.heading_deg)]
    argv += ["--height", repr(start.height)]
    code, _, err = run(capsys, node(rig, receiver.address, *argv))
    assert code == 0, err
    packets = receiver.packets()
    expected = np.stack([p.markers for p in synthetic_run[0]])
    np.testing.assert_array_equal(np.stack([p.markers for p in packets]), expected)
    times = np.array([p.timestamp for p in packets])
    np.testing.assert_allclose(np.diff(times), 1 / FPS, rtol=0, atol=1e-6)
    assert abs(times[0] - time.time()) < 10


def _bad_inputs(rig: Rig, tmp_path: Path) -> dict[str, tuple[list[str], list[str]]]:
    """Case -> (`samba node` arguments after --calib/--server, words the error must name)."""
    short_key = tmp_path / "short.key"
    short_key.write_bytes(b"12345678")
    small = tmp_path / "small"
    write_images(np.zeros((2, 48, 64), np.uint8), small)
    synthetic = ["--synthetic", MOTION, "--no-pace"]
    return {
        "missing calibration": (
            [*synthetic, "--calib", str(tmp_path / "nothere.toml")],
            ["nothere.toml"],
        ),
        "camera out of range": ([*synthetic, "--camera", "2"], [str(rig.calib), "no camera 2"]),
        "missing video": (["--video", str(tmp_path / "nothere.avi")], ["nothere.avi"]),
        "short key file": (
            [*synthetic, "--key-file", str(short_key)],
            [str(short_key), "16 bytes"],
        ),
        "wrong frame size": (["--images", str(small)], ["frame_000000.png", "64x48", "320x240"]),
        "no webcam": (["--webcam", "99"], ["webcam 99"]),
        "flag of another source": (["--webcam", "0", "--loop"], ["--loop", "--webcam"]),
    }


@pytest.mark.parametrize(
    "case",
    [
        "missing calibration",
        "camera out of range",
        "missing video",
        "short key file",
        "wrong frame size",
        "no webcam",
        "flag of another source",
    ],
)
def test_bad_inputs_are_one_line_errors(
    case: str, rig: Rig, receiver: Receiver, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    extra, named = _bad_inputs(rig, tmp_path)[case]
    camera = [] if "--camera" in extra else ["--camera", "0"]
    argv = node(rig, receiver.address, *camera, *extra)
    code, _, err = run(capsys, argv)
    assert code == 1
    assert err.startswith("samba: error: ") and err.count("\n") == 1, err
    for word in named:
        assert word in err
    assert receiver.datagrams(idle=0.05) == []


def test_two_sources_or_none_are_a_usage_error(
    rig: Rig, receiver: Receiver, capsys: pytest.CaptureFixture[str]
) -> None:
    for extra, named in (
        (["--synthetic", MOTION, "--video", "x.avi"], ["--video", "--synthetic"]),
        ([], ["one of the arguments --video --images --webcam --synthetic is required"]),
    ):
        with pytest.raises(SystemExit) as exit_:
            main(node(rig, receiver.address, "--camera", "0", *extra))
        err = capsys.readouterr().err
        assert exit_.value.code == 2 and all(word in err for word in named), err
    assert receiver.datagrams(idle=0.05) == []


def test_a_server_that_is_not_listening_only_counts_errors(
    rig: Rig, capsys: pytest.CaptureFixture[str]
) -> None:
    closed = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    closed.bind(("127.0.0.1", 0))
    address = f"127.0.0.1:{closed.getsockname()[1]}"
    closed.close()
    argv = node(rig, address, *synthetic(0, "--no-pace", "--seconds", "0.2"))
    code, out, _ = run(capsys, argv)
    assert code == 0
    errors = int(re.search(r"(\d+) send errors", out).group(1))
    assert 0 < errors <= round(1.2 * FPS)


def test_ctrl_c_ends_with_the_summary(
    rig: Rig, receiver: Receiver, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(samba.service.node_summary, "STATUS_SECONDS", 0.0)
    feed = SyntheticFeed(rig.cameras[1], 1, rig.lead_in, FPS, SEED, START_AT, pace=False)

    def interrupted_after_five() -> Iterator[Capture]:
        for i, capture in enumerate(feed.captures()):
            if i == 5:
                raise KeyboardInterrupt
            yield capture

    camera = CameraNode(rig.cameras[1], SubjectStart.of(rig.lead_in), feed.mask)
    host, port = receiver.address.split(":")
    status = io.StringIO()
    with PacketSender(host, int(port), 1) as sender:
        summary = run_node(camera, interrupted_after_five(), sender, 7, status=status)
    assert summary.interrupted and summary.frames == 5 and summary.send_errors == 0
    assert summary.paced_frames == 0 and "interrupted" in summary.describe()
    assert [p.sequence for p in receiver.packets()] == [7, 8, 9, 10, 11]
    assert len(status.getvalue().splitlines()) == 5


def test_a_start_time_before_the_node_started_is_one_line_naming_the_flag(
    rig: Rig,
    receiver: Receiver,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(samba.service.cli.node, "LAUNCHED_AT", time.time())
    past = time.time() - 100.0
    code, out, err = run(
        capsys, node(rig, receiver.address, *synthetic(0, "--start-at", str(past)))
    )
    assert code == 1 and out == ""
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"samba: error: --start-at {past:.1f}: is 1")
    assert re.search(r"is 1\d\d\.\d s in the past", err), err
    assert receiver.datagrams(idle=0.05) == []


def test_a_start_time_the_node_passed_while_starting_is_its_start_up(
    rig: Rig,
    receiver: Receiver,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    now = time.time()
    monkeypatch.setattr(samba.service.cli.node, "LAUNCHED_AT", now - 10.0)
    argv = synthetic(0, "--start-at", repr(now - 1.0), "--seconds", "0.1")
    code, out, err = run(capsys, node(rig, receiver.address, *argv))
    assert code == 0, err
    assert re.search(r"the first \d+ late while the node started", out), out
    assert len(receiver.packets()) == round(1.1 * FPS)


def with_deadlines(rig: Rig, past: list[bool]) -> list[Capture]:
    """Unpaced captures of the rig's camera 0 given deadlines: long gone where `past`
    says so, an hour ahead elsewhere."""
    feed = SyntheticFeed(rig.cameras[0], 0, rig.lead_in, FPS, SEED, START_AT, pace=False)
    ahead = time.time() + 3600.0
    captures = zip(feed.captures(), past, strict=False)
    return [replace(c, deadline=0.0 if late else ahead) for c, late in captures]


@pytest.mark.parametrize(
    ("past", "startup", "late", "says"),
    [
        (
            [True] * 3 + [False] * 7,
            3,
            0,
            "kept up with real time (7 frames on time, the first 3 late",
        ),
        ([False] * 10, 0, 0, "kept up with real time (10 frames on time)"),
        ([True, False, True] + [False] * 7, 1, 1, "fell behind real time: 1 of 10 frames late"),
    ],
)
def test_frames_late_while_the_node_starts_are_not_falling_behind(
    rig: Rig, receiver: Receiver, past: list[bool], startup: int, late: int, says: str
) -> None:
    node = CameraNode(rig.cameras[0], SubjectStart.of(rig.lead_in))
    host, port = receiver.address.split(":")
    with PacketSender(host, int(port), 0) as sender:
        summary = run_node(node, with_deadlines(rig, past), sender)
    assert (summary.startup_frames, summary.late_frames, summary.paced_frames) == (
        startup,
        late,
        len(past),
    )
    assert summary.kept_up == (late == 0)
    assert says in summary.describe()


def test_a_grid_without_a_start_begins_when_the_first_frame_is_asked_for() -> None:
    frame = np.zeros((4, 4), np.uint8)
    captures = grid_captures(lambda: [frame, frame], FPS, None, False, False, "grid")
    asked = time.time()
    first, second = captures
    assert first.timestamp >= asked + START_DELAY_SECONDS
    assert second.timestamp == first.timestamp + 1.0 / FPS
