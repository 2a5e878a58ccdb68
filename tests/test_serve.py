"""The live server end to end on loopback: synthetic camera packets in over real UDP, VMC
bundles, the recorded take, the control API and `samba serve` out."""

from __future__ import annotations

import asyncio
import dataclasses
import re
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from aiohttp import ClientSession
from live_fixtures import WAIT_MS, VmcReceiver, config, offline_poses, until

from samba.base.errors import InputError
from samba.ingest.mcap_take import read_take
from samba.service.errors import ServiceError
from samba.service.node_keys import NodeKey, NodeKeys
from samba.service.packet import encode
from samba.service.serve import CORES, LiveServer, auto_workers
from samba.service.session_config import read_sessions
from samba.service.synthetic_capture import SyntheticCapture, play

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("workers", [0, 2], ids=["in the event loop", "in worker processes"])
def test_live_path_gives_the_offline_poses_and_streams_every_frame(
    live_store: Path,
    live_calibration: Path,
    live_capture: SyntheticCapture,
    tmp_path: Path,
    workers: int,
) -> None:
    vmc = VmcReceiver()

    async def run() -> dict:
        cfg = config(live_calibration, live_store, vmc=[vmc.target], wait_ms=WAIT_MS)
        bind = {"udp": ("127.0.0.1", 0), "http": None, "workers": workers}
        async with LiveServer([cfg], tmp_path / "takes", **bind) as live:
            assert live.server is not None
            session = live.server.session("stage")
            session.start_take("walk")
            vmc.start()
            await play(live_capture, live.udp_address, time.time() + 0.2, session="stage")
            await until(lambda: session.frames_out == live_capture.frames)
            session.stop_take()
            return live.server.metrics()

    metrics = asyncio.run(run())
    stage = metrics["sessions"]["stage"]
    assert stage["frames_out"] == live_capture.frames
    assert stage["sync"]["complete"] == live_capture.frames and metrics["dropped"]["total"] == 0
    take = read_take(tmp_path / "takes" / "stage" / "walk.mcap")
    assert len(take) == live_capture.frames
    error = np.linalg.norm(take.poses - offline_poses(live_capture, live_store), axis=-1)
    assert error.max() < 0.001  # meters: the same poses within 1 mm
    vmc.drain()
    assert len(vmc.times) == live_capture.frames and np.all(np.diff(vmc.times) > 0)
    assert stage["latency"]["count"] == live_capture.frames  # speed: bench/bench_service.py


@pytest.mark.parametrize("workers", [0, 2], ids=["in the event loop", "in worker processes"])
def test_sessions_whose_packets_arrive_together_each_get_the_offline_poses(
    live_store: Path,
    live_calibration: Path,
    live_capture: SyntheticCapture,
    tmp_path: Path,
    workers: int,
) -> None:
    """Three stages on one database whose cameras share a trigger: every frame's six
    packets leave at once, the server computes the three frames together, and each
    session records the poses of the offline reconstruction."""
    names = ("a", "b", "c")

    async def run() -> dict:
        cfgs = [config(live_calibration, live_store, name=n, wait_ms=WAIT_MS) for n in names]
        bind = {"udp": ("127.0.0.1", 0), "http": None, "workers": workers}
        async with LiveServer(cfgs, tmp_path / "takes", **bind) as live:
            assert live.server is not None
            sessions = [live.server.session(n) for n in names]
            for session in sessions:
                session.start_take("walk")
            start = time.time() + 0.2
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
                for frame in range(live_capture.frames):
                    await asyncio.sleep(max(0.0, start + frame / 60.0 - time.time()))
                    for name in names:
                        for camera in range(2):
                            packet = live_capture.packet(camera, frame, start, name)
                            sock.sendto(encode(packet), live.udp_address)
            await until(lambda: all(s.frames_out == live_capture.frames for s in sessions))
            for session in sessions:
                session.stop_take()
            return live.server.metrics()

    metrics = asyncio.run(run())
    expected = offline_poses(live_capture, live_store)
    for name in names:
        assert metrics["sessions"][name]["sync"]["complete"] == live_capture.frames
        take = read_take(tmp_path / "takes" / name / "walk.mcap")
        assert np.linalg.norm(take.poses - expected, axis=-1).max() < 0.001  # meters


def test_signed_packets_and_bad_datagrams(
    live_store: Path, live_calibration: Path, live_capture: SyntheticCapture, tmp_path: Path
) -> None:
    key, other = bytes(range(32)), bytes(range(1, 33))
    keys = NodeKeys([NodeKey(key, frozenset({0})), NodeKey(other, frozenset({1}), "stage")])

    async def run() -> dict:
        cfg = config(live_calibration, live_store)
        bind = {"udp": ("127.0.0.1", 0), "http": None}
        async with LiveServer([cfg], tmp_path, **bind, keys=keys) as live:
            assert live.server is not None
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
                good = live_capture.packet(0, 0, time.time(), "stage", epoch=5)
                signed = encode(good, key)
                for data in (
                    b"",
                    b"x" * 300,
                    b"GIF89a" + bytes(94),
                    encode(good),  # unsigned while the server has keys
                    encode(good, b"wrong key, 32 bytes long........"),
                    encode(good, other),  # camera 1's key speaking for camera 0
                    signed[:-1] + bytes([signed[-1] ^ 0xFF]),  # the tag's last byte changed
                    encode(live_capture.packet(0, 1, time.time(), "other"), key),
                    encode(dataclasses.replace(good, camera=7), key),  # a camera of no key
                    signed,
                    signed,  # the same packet again
                ):
                    sock.sendto(data, live.udp_address)
            await until(lambda: live.server is not None and live.server.datagrams == 11)
            return live.server.metrics()

    metrics = asyncio.run(run())
    assert metrics["datagrams"] == 11
    assert metrics["dropped"] == {
        "total": 10,
        "bad magic": 1,
        "bad tag": 3,
        "duplicate": 1,
        "missing tag": 1,
        "no key": 2,
        "too long": 1,
        "too short": 1,
    }
    assert metrics["sessions"]["stage"]["sync"]["packets"] == 1


def test_control_api(live_store: Path, live_calibration: Path, tmp_path: Path) -> None:
    async def run() -> None:
        cfg = config(live_calibration, live_store)
        async with (
            LiveServer([cfg], tmp_path, udp=("127.0.0.1", 0), http=("127.0.0.1", 0)) as live,
            ClientSession(str(live.http_url), headers=bearer(live.token)) as http,
        ):
            async with http.get("/api/health") as r:
                assert r.status == 200 and (await r.json())["sessions"] == 1
            async with http.get("/api/sessions") as r:
                (session,) = (await r.json())["sessions"]
                assert session["name"] == "stage" and len(session["cameras"]) == 2
            async with http.post("/api/sessions/stage/takes/stop") as r:
                assert r.status == 409
            async with http.post("/api/sessions/stage/takes", json={"name": "t1"}) as r:
                assert r.status == 201 and (await r.json())["take"]["recording"]
            async with http.post("/api/sessions/stage/takes", json={"name": "t2"}) as r:
                assert r.status == 409
            async with http.post("/api/sessions/stage/takes/stop") as r:
                take = (await r.json())["take"]
                assert r.status == 200 and take["name"] == "t1" and not take["recording"]
            async with http.post("/api/sessions/stage/takes", json={"name": "t1"}) as r:
                assert r.status == 409 and "exists" in (await r.json())["error"]
            async with http.get("/api/takes") as r:
                (listed,) = (await r.json())["takes"]
                assert listed["name"] == "t1" and listed["bytes"] > 0
            body = {
                "name": "second",
                "calibration": str(live_calibration),
                "database": str(live_store),
            }
            async with http.post("/api/sessions", json=body) as r:
                assert r.status == 201
            async with http.post("/api/sessions", json=body) as r:
                assert r.status == 409
            async with http.post("/api/sessions", json={**body, "name": "x", "fps": -1}) as r:
                assert r.status == 400 and "fps" in (await r.json())["error"]
            json_type = {"Content-Type": "application/json"}
            async with http.post("/api/sessions", data=b"{not json", headers=json_type) as r:
                assert r.status == 400 and "not JSON" in (await r.json())["error"]
            async with http.get("/api/metrics") as r:
                metrics = await r.json()
                assert set(metrics["sessions"]) == {"stage", "second"}
                assert "p99_ms" in metrics["sessions"]["stage"]["latency"]
            async with http.delete("/api/sessions/second") as r:
                assert r.status == 200
            async with http.get("/api/sessions/second") as r:
                assert r.status == 404

    asyncio.run(run())


def bearer(token: str) -> dict[str, str]:
    """The header carrying an API token."""
    return {"Authorization": f"Bearer {token}"}


def test_a_token_guards_the_api(live_store: Path, live_calibration: Path, tmp_path: Path) -> None:
    token = "s3cret-token-of-the-stage"

    async def run() -> None:
        cfg = config(live_calibration, live_store)
        bind = {"udp": ("127.0.0.1", 0), "http": ("127.0.0.1", 0)}
        async with (
            LiveServer([cfg], tmp_path, **bind, token=token) as live,
            ClientSession(str(live.http_url)) as http,
        ):
            async with http.get("/api/health") as r:
                assert r.status == 401
            async with http.get("/api/health", headers=bearer(token)) as r:
                assert r.status == 200
            async with http.get(f"/api/health?token={token}") as r:
                assert r.status == 200

    asyncio.run(run())


def test_the_api_always_has_a_token(live_store: Path, live_calibration: Path) -> None:
    """Item 4 of issue 41: without one given, a token is drawn; a short one is refused."""
    cfg = config(live_calibration, live_store)
    drawn = LiveServer([cfg], "takes", http=("0.0.0.0", 8080)).token
    assert len(drawn) >= 32 and drawn != LiveServer([cfg], "takes").token
    with pytest.raises(ServiceError, match="--token: a token has at least 16 characters"):
        LiveServer([cfg], "takes", token="s3cret")


def test_camera_packets_are_not_received_beyond_loopback_without_keys(
    live_store: Path, live_calibration: Path
) -> None:
    """Item 3 of issue 41: an unsigned packet could come from anyone on the network."""
    cfg = config(live_calibration, live_store)
    with pytest.raises(ServiceError, match=r"udp 0\.0\.0\.0:9870: .*--keys FILE"):
        LiveServer([cfg], "takes", udp=("0.0.0.0", 9870), http=None)
    keys = NodeKeys([NodeKey(b"k" * 32, frozenset({0, 1}))])
    LiveServer([cfg], "takes", udp=("0.0.0.0", 9870), http=None, keys=keys)  # allowed


def test_a_port_already_in_use_is_named(
    live_store: Path, live_calibration: Path, tmp_path: Path
) -> None:
    cfg = config(live_calibration, live_store)

    async def serve(udp: tuple[str, int], http: tuple[str, int] | None) -> None:
        async with LiveServer([cfg], tmp_path, udp=udp, http=http):
            raise AssertionError("the server started on a port in use")

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        wanted = (
            f"udp 127.0.0.1:{port}: cannot receive camera packets there: Address already in use"
        )
        with pytest.raises(ServiceError, match=re.escape(wanted)):
            asyncio.run(serve(("127.0.0.1", port), None))
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        wanted = f"http 127.0.0.1:{port}: cannot serve the viewer and API there: Address already"
        with pytest.raises(ServiceError, match=re.escape(wanted)):
            asyncio.run(serve(("127.0.0.1", 0), ("127.0.0.1", port)))


def test_a_session_wanting_more_cameras_than_it_has_is_refused(
    live_store: Path, live_calibration: Path, tmp_path: Path
) -> None:
    cfg = dataclasses.replace(config(live_calibration, live_store), min_cameras=9)

    async def serve() -> None:
        async with LiveServer([cfg], tmp_path, udp=("127.0.0.1", 0), http=None):
            raise AssertionError("the session opened")

    with pytest.raises(ServiceError, match="wants min_cameras 9, but the calibration has 2"):
        asyncio.run(serve())


@pytest.mark.slow
def test_samba_serve_command(live_store: Path, live_calibration: Path, tmp_path: Path) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    argv = [sys.executable, "-m", "samba.cli", "serve", "--calib", str(live_calibration)]
    argv += ["--db", str(live_store), "--udp", f"127.0.0.1:{port}", "--no-http"]
    argv += ["--out-dir", str(tmp_path / "takes"), "--record", "first", "--duration", "2"]
    done = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    assert f"camera packets on udp 127.0.0.1:{port}" in done.stdout
    assert "frames computed in the event loop" in done.stdout  # --workers auto, 2 cameras
    assert "take first: 0 frames" in done.stdout
    assert "no latency: no frame came" in done.stdout
    assert (tmp_path / "takes" / "default" / "first.mcap").is_file()
    bad = subprocess.run(
        [
            sys.executable,
            "-m",
            "samba.cli",
            "serve",
            "--calib",
            str(tmp_path / "nope.toml"),
            "--db",
            str(live_store),
            "--no-http",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    assert bad.returncode == 1 and "nope.toml" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1
    both = [*argv[:4], "--config", str(tmp_path / "serve.toml"), "--calib", str(live_calibration)]
    conflict = subprocess.run(both, capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert conflict.returncode == 2  # a flag conflict is a usage error
    assert "samba serve: error: give either --config or --calib/--db" in conflict.stderr


def test_workers_start_only_where_the_server_labels(
    live_store: Path, live_calibration: Path, tmp_path: Path
) -> None:
    """`--workers auto`: the event loop for sessions that keep their nodes' labels (two
    cameras, or `labels = "nodes"`) and for pose sessions; one worker per core once a
    session has the server find lost labels; a bad calibration is named."""
    two = config(live_calibration, live_store)
    poses = dataclasses.replace(two, name="mk", input="poses", calibration=None, database=None)
    assert auto_workers([two, poses]) == 0
    assert auto_workers([two, dataclasses.replace(two, name="b", labels="server")]) == CORES
    broken = tmp_path / "broken.toml"
    broken.write_text("[cam_0]\nname = ")
    with pytest.raises(InputError, match=r"broken\.toml"):
        auto_workers([dataclasses.replace(two, calibration=broken)])


def test_sessions_from_a_config_file(
    live_store: Path, live_calibration: Path, tmp_path: Path
) -> None:
    path = tmp_path / "serve.toml"
    path.write_text(
        f'[[session]]\nname = "a"\ncalibration = "{live_calibration}"\ndatabase = "{live_store}"\n'
        f'vmc = ["127.0.0.1:39539"]\n\n[[session]]\nname = "b"\ncalibration = "c.toml"\n'
        f'database = "db"\nmethod = "best"\nfps = 30\n'
    )
    a, b = read_sessions(path)
    assert a.vmc == (("127.0.0.1", 39539),) and b.calibration == tmp_path / "c.toml"
    assert (b.method, b.fps) == ("best", 30.0)
    path.write_text('[[session]]\nname = "a b"\ncalibration = "c"\ndatabase = "d"\n')
    with pytest.raises(Exception, match=r"serve.toml.*name 'a b'"):
        read_sessions(path)
    path.write_text('[[session]]\nname = "a"\ncalibration = "c"\ndatabase = "d"\nfsp = 3\n')
    with pytest.raises(Exception, match="unknown key 'fsp'"):
        read_sessions(path)
    path.write_text('[[session]]\nname = "a"\ncalibration = "c"\ndatabase = "d"\nlabels = "me"\n')
    with pytest.raises(Exception, match=r"serve.toml: session 'a': labels must be one of"):
        read_sessions(path)
    path.write_text('[[session]]\nname = "a"\ninput = "poses"\ncalibration = "c"\n')
    with pytest.raises(ServiceError, match="a poses session reads no calibration"):
        read_sessions(path)
