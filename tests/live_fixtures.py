"""Helpers of the live service tests: session configs, a VMC receiver, waiting, and the
offline reconstruction the live path must match."""

from __future__ import annotations

import asyncio
import json
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pythonosc.osc_bundle import OscBundle

from samba.cameras.triangulation import Triangulation
from samba.db.store import PoseStore
from samba.reconstruct.methods import method
from samba.service.session_config import SessionConfig
from samba.service.synthetic_capture import SyntheticCapture

ROOT = Path(__file__).resolve().parents[1]


WAIT_MS = 2000.0
"""How long a test session's frames wait for a late camera (ms). Far above any stall a
busy machine causes, so tests that count every frame hold beside other work; on
loopback nothing is lost, so no frame waits that long (a stage's default is 50)."""
MAX_SKEW_S = 60.0
"""How far (s) a test server lets a packet's capture time lag its arrival. A node that
computes its frames (the markerless node) falls behind a real-time feed on a busy
machine, seconds by the end of a 3 s take, and a capture played again on the same grid
after waiting for the server goes out late; the default window (5 s) would drop those
packets as off clock."""


def config(calibration: Path, store: Path, **changes: object) -> SessionConfig:
    """Session "stage" on `calibration` and `store`, with other keys changed. It keeps
    the nodes' labels: `SyntheticCapture` sends every marker's true label, and the tests
    compare with the offline reconstruction of exactly those pixels."""
    values = {
        "name": "stage",
        "calibration": str(calibration),
        "database": str(store),
        "labels": "nodes",
    }
    return SessionConfig.from_mapping({**values, **changes}, "test")


class VmcReceiver:
    """A UDP socket collecting the VMC bundles sent to it (python-osc decodes them)."""

    def __init__(self) -> None:
        self.socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.socket.bind(("127.0.0.1", 0))
        self.socket.setblocking(False)
        self.times: list[float] = []
        self.hips: list[tuple[float, ...]] = []

    @property
    def target(self) -> str:
        """Its address as a session's `vmc` entry."""
        return f"127.0.0.1:{self.socket.getsockname()[1]}"

    def start(self) -> None:
        """Collect in the running event loop as bundles arrive."""
        asyncio.get_running_loop().add_reader(self.socket.fileno(), self.drain)

    def drain(self) -> None:
        """Read every bundle waiting; keep /VMC/Ext/T times and Hips poses."""
        while True:
            try:
                data = self.socket.recv(2048)
            except BlockingIOError:
                return
            for item in OscBundle(data):
                message = getattr(item, "message", item)
                if message.address == "/VMC/Ext/T":
                    self.times.append(message.params[0])
                elif message.address == "/VMC/Ext/Bone/Pos" and message.params[0] == "Hips":
                    self.hips.append(tuple(message.params[1:]))


async def until(done: Callable[[], bool], timeout: float = 20.0) -> None:
    """Wait until `done()` (polled), at most `timeout` seconds (the machine may be busy)."""
    end = time.time() + timeout
    while not done() and time.time() < end:
        await asyncio.sleep(0.02)


def offline_poses(capture: SyntheticCapture, store: Path, gate_px: float = 10.0) -> np.ndarray:
    """What the offline reconstruction makes of the same pixels."""
    views = Triangulation.from_views(
        capture.cameras.projections, capture.cameras.undistort(capture.pixels), gate_px=gate_px
    )
    reconstructor = method("samba").build(PoseStore.open(store).index)
    return reconstructor.reconstruct(views.points).poses


def free_udp_port() -> int:
    """A UDP port free on 127.0.0.1 right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@dataclass
class ServeProcess:
    """A `samba serve` subprocess: where it listens, its API token, and its process."""

    udp: tuple[str, int]
    http_url: str | None
    token: str | None
    process: subprocess.Popen[str]

    def get(self, path: str) -> dict:
        """GET a control API path with the token; the JSON answer."""
        request = urllib.request.Request(
            f"{self.http_url}{path}", headers={"Authorization": f"Bearer {self.token}"}
        )
        with urllib.request.urlopen(request, timeout=30) as answer:
            return json.load(answer)


@contextmanager
def serve_process(*args: str, http: bool = True) -> Iterator[ServeProcess]:
    """Run `samba serve ARGS` on a free UDP port (and an HTTP port chosen by the server
    unless `http` is False) until the block ends; then stop it with Ctrl-C (SIGINT)."""
    port = free_udp_port()
    argv = [sys.executable, "-m", "samba.cli", "serve", *args, "--udp", f"127.0.0.1:{port}"]
    argv += ["--http", "127.0.0.1:0"] if http else ["--no-http"]
    process = subprocess.Popen(
        argv, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        assert process.stdout is not None
        url = token = None
        for line in process.stdout:
            if "control API:" in line:
                url = line.split("control API:")[1].split()[0].rstrip(",")
                url = url.removesuffix("/api/health")
                token = line.split("Bearer ")[1].split()[0]
            if url if http else "camera packets on udp" in line:
                break
        else:
            raise AssertionError(f"samba serve did not start: {process.communicate()[1]}")
        yield ServeProcess(("127.0.0.1", port), url, token, process)
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
