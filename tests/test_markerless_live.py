"""The markerless node in the live service: `samba node --mode silhouette` sends pose
packets, a session whose input is "poses" streams them as VMC and records them."""

from __future__ import annotations

import asyncio
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from live_fixtures import MAX_SKEW_S, VmcReceiver, until
from markerless_fixtures import (
    BODY,
    CAMERA,
    FPS,
    HEIGHT,
    footage,
    mpjpe_cm,
    write_camera_calibration,
)

from samba.cli import main
from samba.db.shape_tree_file import read_shape_tree, tree_path, write_shape_tree
from samba.db.store import PoseStore
from samba.db.synthetic_store import build_synthetic_store
from samba.ingest.mcap_take import read_take
from samba.service.node import Capture, PacketSender, run_node
from samba.service.packet import MarkerPacket, PosePacket, decode, encode
from samba.service.serve import LiveServer
from samba.service.session_config import SessionConfig
from samba.service.silhouette_node import SilhouetteNode
from samba.silhouette.extraction import SilhouetteExtractor
from samba.silhouette.shape_tree import ShapeTree
from samba.silhouette.view import SilhouetteView

SESSION = "mk"


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small synthetic store with the shape tree of CAMERA and BODY saved in it."""
    path = tmp_path_factory.mktemp("markerless-live") / "db"
    build_synthetic_store(path, takes_per_motion=1, seconds=2.0, seed=3)
    tree = ShapeTree.build(
        np.asarray(PoseStore.open(path).poses, dtype=np.float64),
        SilhouetteView(CAMERA),
        BODY,
        headings=np.arange(-180.0, 180.0, 180.0),
    )
    write_shape_tree(tree_path(path, f"{CAMERA.name}-{BODY.name}"), tree)
    return path


class Recording:
    """A `SilhouetteNode` that keeps the poses it gives `run_node` in `sent`."""

    MISSING = SilhouetteNode.MISSING

    def __init__(self, node: SilhouetteNode) -> None:
        self.node = node
        self.sent: list[np.ndarray | None] = []

    def restart(self) -> None:
        """Restart the node."""
        self.node.restart()

    def process(self, frame: np.ndarray, name: str = "frame") -> np.ndarray | None:
        """The node's pose, kept."""
        pose = self.node.process(frame, name)
        self.sent.append(pose)
        return pose

    def unlabelled(self) -> np.ndarray:
        """The node's unlabelled blobs (none)."""
        return self.node.unlabelled()


def paced(frames: np.ndarray, start: float) -> Iterator[Capture]:
    """The frames captured in real time at FPS from `start` (UNIX seconds), as a camera
    gives them."""
    for i, frame in enumerate(frames):
        due = start + i / FPS
        time.sleep(max(0.0, due - time.time()))
        yield Capture(frame, due, due + 1 / FPS, i == 0, f"frame {i}")


def poses_config(**changes: object) -> SessionConfig:
    """A poses session called SESSION."""
    return SessionConfig.from_mapping({"name": SESSION, "input": "poses", **changes}, "test")


@pytest.mark.parametrize("workers", [0, 1], ids=["in the event loop", "in a worker process"])
def test_a_poses_session_streams_and_records_the_markerless_node(
    store: Path, tmp_path: Path, workers: int
) -> None:
    shot = footage()
    tree = read_shape_tree(tree_path(store, f"{CAMERA.name}-{BODY.name}"))
    node = SilhouetteNode(tree, SilhouetteExtractor.for_tracking(shot.empty, tree.view.size[0]))
    vmc = VmcReceiver()

    async def run() -> tuple[dict, list[np.ndarray]]:
        config = poses_config(vmc=[vmc.target], fps=FPS)
        bind = {"udp": ("127.0.0.1", 0), "http": None, "workers": workers}
        async with LiveServer([config], tmp_path / "takes", max_skew_s=MAX_SKEW_S, **bind) as live:
            assert live.server is not None
            session = live.server.session(SESSION)
            session.start_take("wave")
            vmc.start()
            captures = paced(shot.frames, time.time() + 0.2)
            recording = Recording(node)
            with PacketSender(*live.udp_address, 7, SESSION) as sender:
                summary = await asyncio.to_thread(run_node, recording, captures, sender)
            assert summary.frames == len(shot.frames) and "without a pose" in summary.describe()
            await until(lambda: session.frames_out == len(shot.frames))
            session.stop_take()
            return live.server.metrics(), recording.sent

    metrics, sent = asyncio.run(run())
    frames = len(shot.frames)
    assert metrics["sessions"][SESSION]["frames_out"] == frames
    assert metrics["dropped"]["total"] == 0
    take = read_take(tmp_path / "takes" / SESSION / "wave.mcap")
    assert take.warnings == []  # frames one period apart on the node's clock: none resampled
    np.testing.assert_allclose(take.poses, np.array(sent), atol=1e-6)  # float32 on the wire
    assert mpjpe_cm(take.poses, shot.truth).mean() < 12.0
    vmc.drain()
    assert len(vmc.times) == frames


def test_packets_of_the_other_input_are_counted_and_dropped(store: Path, tmp_path: Path) -> None:
    calibration = write_camera_calibration(tmp_path / "front.toml")
    markers_config = SessionConfig.from_mapping(  # one camera: its frames need only one
        {"name": "mk2", "calibration": str(calibration), "database": str(store), "min_cameras": 1},
        "test",
    )

    async def run() -> dict:
        async with LiveServer(
            [poses_config(), markers_config], tmp_path / "takes", udp=("127.0.0.1", 0), http=None
        ) as live:
            assert live.server is not None
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
                pose = PosePacket(0, 0, time.time(), np.zeros((13, 3)), "mk2")
                markers = MarkerPacket(0, 0, time.time(), np.full((8, 2), np.nan), SESSION)
                for packet in (pose, markers):
                    sock.sendto(encode(packet), live.udp_address)
            await until(lambda: live.server.datagrams == 2)
            return live.server.metrics()

    metrics = asyncio.run(run())
    assert metrics["dropped"] == {"total": 2, "wrong input": 2}


def test_samba_node_silhouette_sends_pose_packets(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    calibration = write_camera_calibration(tmp_path / "front.toml")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver:
        receiver.bind(("127.0.0.1", 0))
        receiver.settimeout(0.5)
        argv = ["node", "--mode", "silhouette", "--camera", "0", "--calib", str(calibration)]
        argv += ["--db", str(store), "--height", str(HEIGHT), "--synthetic", "wave"]
        argv += ["--seconds", "1", "--fps", str(FPS), "--no-pace", "--session", SESSION]
        argv += ["--server", f"127.0.0.1:{receiver.getsockname()[1]}"]
        assert main(argv) == 0
        packets = []
        while True:
            try:
                packets.append(decode(receiver.recv(512)))
            except TimeoutError:
                break
    out = capsys.readouterr().out
    assert "frames without a pose" in out
    assert packets and all(isinstance(p, PosePacket) and p.session == SESSION for p in packets)
    assert [p.sequence for p in packets] == list(range(len(packets)))
    assert len(packets) == round(FPS)  # every frame, the subject is in view from the start


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--mode", "silhouette"], "needs --db"),
        (["--mode", "silhouette", "--db", "x", "--threshold", "40"], "--threshold"),
        (["--db", "x"], "--db: applies to --mode silhouette only"),
    ],
)
def test_node_mode_flags_are_checked(
    flags: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    calibration = write_camera_calibration(tmp_path / "front.toml")
    argv = ["node", "--camera", "0", "--calib", str(calibration), "--synthetic", "wave", *flags]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert message in err and err.startswith("samba: error:") and "Traceback" not in err
