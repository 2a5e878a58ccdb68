"""The live server under forged camera packets, over real UDP on loopback (issue 41, items
2 and 3): a recorded signed capture replayed in any order, with sequence numbers shifted,
or signed with another node's key, adds no frame and a node restart is still picked up;
spoofed far-future timestamps do not stall the output; marker pixels outside the image
never reach the take."""

from __future__ import annotations

import asyncio
import base64
import json
import random
import socket
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from live_fixtures import WAIT_MS, config, until
from mcap.reader import make_reader

from samba.ingest.mcap_take import read_take
from samba.service.errors import PacketError
from samba.service.node_keys import NodeKey, NodeKeys
from samba.service.packet import MarkerPacket, decode, encode, random_epoch
from samba.service.serve import LiveServer
from samba.service.synthetic_capture import SyntheticCapture

KEYS = {0: b"camera 0 node key, 32 bytes long", 1: b"camera 1 node key, 32 bytes long"}
"""Each camera's node key."""
SHIFTS = (-(2**31), -1000, -200, -1, 1, 7, 300, 2**31)
"""Sequence offsets of the forged copies."""

POINT = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("marker", "<u4")])
"""A point of the takes' `/markers` point clouds."""


async def send_live(
    capture: SyntheticCapture,
    address: tuple[str, int],
    start_at: float,
    epochs: dict[int, int],
    change: Callable[[int, MarkerPacket], MarkerPacket] = lambda _frame, packet: packet,
    keys: dict[int, bytes] | None = KEYS,
) -> list[bytes]:
    """Send every frame of `capture` at its capture time as two nodes would, camera c in
    `epochs[c]`, each packet first passed through `change(frame, packet)` and signed with
    its camera's key (unsigned without `keys`); returns the datagrams sent."""
    sent = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for frame in range(capture.frames):
            await asyncio.sleep(max(0.0, start_at + frame / capture.fps - time.time()))
            for camera, epoch in epochs.items():
                packet = change(frame, capture.packet(camera, frame, start_at, "stage", 0, epoch))
                data = encode(packet, None if keys is None else keys[camera])
                sock.sendto(data, address)
                sent.append(data)
    return sent


async def send_spread(address: tuple[str, int], datagrams: list[bytes], seconds: float) -> None:
    """Send `datagrams` in their order, spread evenly over `seconds`."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for data in datagrams:
            sock.sendto(data, address)
            await asyncio.sleep(seconds / len(datagrams))


def forgeries(recorded: list[MarkerPacket], rng: random.Random) -> list[bytes]:
    """What an attacker makes of a recorded capture: every packet again byte for byte;
    camera 0's signed by node 1 (its own key) with the sequence shifted; and camera 0's
    signed with camera 0's own key (as if it leaked), the sequence shifted, in a fresh
    epoch, with the old timestamps. In a random order."""
    forged = [encode(p, KEYS[p.camera]) for p in recorded]
    for packet in (p for p in recorded if p.camera == 0):
        shifted = replace(packet, sequence=(packet.sequence + rng.choice(SHIFTS)) % 2**32)
        forged.append(encode(shifted, KEYS[1]))
        forged.append(encode(replace(shifted, epoch=random_epoch()), KEYS[0]))
    rng.shuffle(forged)
    return forged


@pytest.mark.slow
def test_a_replayed_signed_capture_adds_no_frame_and_a_restart_is_picked_up(
    live_store: Path, live_calibration: Path, live_capture: SyntheticCapture, tmp_path: Path
) -> None:
    """Item 2: the nodes film a capture, restart and film another while an attacker
    replays the first, shuffled and shifted: the take holds exactly the two captures'
    frames, each complete, and the restarted nodes' first frame comes out in under 1 s."""
    keys = NodeKeys(
        NodeKey(key, frozenset({camera}), "stage", f"node {camera}") for camera, key in KEYS.items()
    )
    n = live_capture.frames
    restart_taken: list[float] = []

    async def run() -> tuple[dict, int, float]:
        cfg = config(live_calibration, live_store, wait_ms=WAIT_MS)
        bind = {"udp": ("127.0.0.1", 0), "http": None}
        async with LiveServer([cfg], tmp_path / "takes", **bind, keys=keys) as live:
            assert live.server is not None
            session = live.server.session("stage")
            session.start_take("two-runs")
            first = {camera: random_epoch() for camera in KEYS}
            recorded = await send_live(live_capture, live.udp_address, time.time() + 0.2, first)
            await until(lambda: session.frames_out == n)
            attack = forgeries([decode_signed(d) for d in recorded], random.Random(41))
            start_b = time.time() + 0.3
            second = {camera: random_epoch() for camera in KEYS}

            async def watch_restart() -> None:
                await until(lambda: session.frames_out > n, timeout=5.0)
                restart_taken.append(time.time())

            await asyncio.gather(
                send_live(live_capture, live.udp_address, start_b, second),
                send_spread(live.udp_address, attack, n / live_capture.fps),
                watch_restart(),
            )
            await until(lambda: session.frames_out == 2 * n)
            await asyncio.sleep(0.2)  # anything still in flight is counted
            session.stop_take()
            return live.server.metrics(), len(attack), start_b

    metrics, attacks, start_b = asyncio.run(run())
    stage = metrics["sessions"]["stage"]
    sync = stage["sync"]
    assert sync["packets"] == 4 * n, sync  # the two runs' packets and not one forged
    assert sync["complete"] == stage["frames_out"] == 2 * n and sync["restarts"] == 2, sync
    dropped = metrics["dropped"]
    assert dropped["total"] == attacks, dropped
    assert set(dropped) <= {"total", "duplicate", "replayed", "off clock", "bad tag"}, dropped
    assert dropped["bad tag"] == n  # node 1's key speaks for camera 0: refused
    assert len(read_take(tmp_path / "takes" / "stage" / "two-runs.mcap")) >= 2 * n
    assert restart_taken and restart_taken[0] - start_b < 1.0  # picked up at once


def decode_signed(data: bytes) -> MarkerPacket:
    """The packet of a datagram the test signed itself."""
    for key in KEYS.values():
        try:
            packet = decode(data, key)
        except PacketError:  # the other camera's key
            continue
        assert isinstance(packet, MarkerPacket)
        return packet
    raise AssertionError("not signed by a node key")


def test_spoofed_far_future_timestamps_do_not_stall_the_output(
    live_store: Path, live_calibration: Path, live_capture: SyntheticCapture, tmp_path: Path
) -> None:
    """Item 3: ten spoofed packets per camera, stamped far in the future or past, in the
    nodes' own epoch with the next sequence numbers or in new epochs, cut no frame."""
    n = live_capture.frames

    async def run() -> dict:
        cfg = config(live_calibration, live_store, wait_ms=WAIT_MS)
        bind = {"udp": ("127.0.0.1", 0), "http": None}
        async with LiveServer([cfg], tmp_path / "takes", **bind) as live:
            assert live.server is not None
            session = live.server.session("stage")
            start = time.time() + 0.2
            epochs = {camera: random_epoch() for camera in (0, 1)}
            spoofs = []
            for camera, k in ((c, k) for c in (0, 1) for k in range(10)):
                packet = live_capture.packet(camera, 10 + 6 * k, start, "stage", 0, epochs[camera])
                stamp = start + (1e6 if k % 2 else -1e6)
                epoch = epochs[camera] if k < 5 else random_epoch()
                spoofs.append(encode(replace(packet, timestamp=stamp, epoch=epoch)))

            async def spoof() -> None:
                await asyncio.sleep(max(0.0, start + 0.1 - time.time()))
                await send_spread(live.udp_address, spoofs, 1.0)

            await asyncio.gather(
                send_live(live_capture, live.udp_address, start, epochs, keys=None), spoof()
            )
            await until(lambda: session.frames_out == n)
            return live.server.metrics()

    metrics = asyncio.run(run())
    sync = metrics["sessions"]["stage"]["sync"]
    assert sync["complete"] == n and sync["skipped"] == 0 and sync["late"] == 0, sync
    assert metrics["dropped"] == {"total": 20, "off clock": 20}


def mcap_messages(path: Path, topic: str) -> list[dict]:
    """The JSON messages of one topic of an MCAP take."""
    with path.open("rb") as f:
        return [
            json.loads(message.data)
            for _, _, message in make_reader(f).iter_messages(topics=[topic])
        ]


def test_marker_pixels_outside_the_image_never_reach_the_take(
    live_store: Path, live_calibration: Path, live_capture: SyntheticCapture, tmp_path: Path
) -> None:
    """Item 3: a node (broken, or spoofed) sends 3e38 px and -5e4 px markers for a second:
    they are dropped and counted, and every recorded marker stays on the stage."""
    n = live_capture.frames
    bad = range(30, 90)

    def damage(frame: int, packet: MarkerPacket) -> MarkerPacket:
        if packet.camera != 0 or frame not in bad:
            return packet
        markers = packet.markers.copy()
        markers[0] = [3e38, 3e38]
        markers[1] = [-5e4, 200.0]
        return replace(packet, markers=markers, blobs=np.array([[1e30, 5.0]]))

    async def run() -> dict:
        cfg = config(live_calibration, live_store, wait_ms=WAIT_MS)
        bind = {"udp": ("127.0.0.1", 0), "http": None}
        async with LiveServer([cfg], tmp_path / "takes", **bind) as live:
            assert live.server is not None
            session = live.server.session("stage")
            session.start_take("damaged")
            epochs = {camera: random_epoch() for camera in (0, 1)}
            start = time.time() + 0.2
            await send_live(live_capture, live.udp_address, start, epochs, damage, keys=None)
            await until(lambda: session.frames_out == n)
            session.stop_take()
            return live.server.metrics()

    metrics = asyncio.run(run())
    stage = metrics["sessions"]["stage"]
    assert stage["outside_image"] == {"markers": 2 * len(bad), "blobs": len(bad)}
    path = tmp_path / "takes" / "stage" / "damaged.mcap"
    for message in mcap_messages(path, "/markers"):
        points = np.frombuffer(base64.b64decode(message["data"]), dtype=POINT)
        xyz = np.stack([points[axis] for axis in "xyz"], axis=-1)
        assert np.abs(xyz).max(initial=0.0) < 5.0  # meters: on the stage
    for message in mcap_messages(path, "/camera/0/markers"):
        pixels = np.array([m for m in message["markers"] if m is not None], dtype=float)
        assert (np.abs(pixels) < 1000).all()
    take = read_take(path)
    assert np.abs(take.poses).max() < 5.0
