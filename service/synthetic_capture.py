"""A synthetic capture as camera nodes would report it, and a player that sends it live.

`SyntheticCapture.film` generates a built-in motion (`samba.synthetic.motions`), places
cameras around it (`samba.markers.observation.spread_cameras`) and projects the 8 markers into
every camera with Gaussian pixel noise and random dropout — the labelled pixels a
camera node's tracker outputs, without rendering images (which `samba node
--synthetic` does). `of_take` films any take of poses (a BVH file's), `of_markers` a real
marker take's markers themselves (`samba.service.marker_motion`), which has no true
poses. `play` sends those pixels as UDP packets on a wall-clock grid:
frame i of every camera is captured at `start_at + i / fps`, as free-running
synchronised cameras would. The demo, the service tests and the service benchmark use
them in place of real cameras.
"""

from __future__ import annotations

import asyncio
import socket
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from samba.base import InputError
from samba.body import Take, markers_of
from samba.cameras import CameraGroup
from samba.markers import spread_cameras
from samba.service.marker_motion import marker_poses
from samba.service.packet import MarkerPacket, encode, random_epoch
from samba.synthetic import generate


@dataclass(frozen=True, eq=False)
class SyntheticCapture:
    """Markers seen by calibrated cameras.

    `markers` (F, 8, 3) meters, NaN = missing: what the cameras film, at `fps` frames
    per second; `cameras` the group (camera id n = `cameras[n]`); `pixels` (c, F, 8, 2)
    the labelled marker pixels each camera reports, NaN where it misses the marker;
    `take` the true poses (F, 13, 3) meters of a built-in motion or a BVH file, None for
    a real marker take (its markers are all the truth there is).
    """

    markers: np.ndarray
    fps: float
    cameras: CameraGroup
    pixels: np.ndarray
    take: Take | None = None

    @classmethod
    def film(
        cls,
        motion: str = "walk",
        seconds: float = 5.0,
        fps: float = 60.0,
        cameras: int = 2,
        size: tuple[int, int] = (640, 480),
        noise_px: float = 0.3,
        dropout: float = 0.0,
        seed: int = 0,
    ) -> SyntheticCapture:
        """Film `seconds` of a built-in `motion` at `fps` with `cameras` cameras of `size`
        (width, height) pixels; `noise_px` Gaussian pixel noise (standard deviation),
        each marker view missing with probability `dropout`. Deterministic in `seed`."""
        return cls.of_take(
            generate(motion, seconds, fps, seed), cameras, size, noise_px, dropout, seed
        )

    @classmethod
    def of_take(
        cls,
        take: Take,
        cameras: int = 2,
        size: tuple[int, int] = (640, 480),
        noise_px: float = 0.3,
        dropout: float = 0.0,
        seed: int = 0,
    ) -> SyntheticCapture:
        """Film any take (poses in meters, e.g. a BVH file's) as `film` does."""
        markers = markers_of(take.poses.astype(np.float64))
        capture = cls.of_markers(markers, take.fps, cameras, size, noise_px, dropout, seed)
        return replace(capture, take=take)

    @classmethod
    def of_markers(
        cls,
        markers: np.ndarray,
        fps: float,
        cameras: int = 2,
        size: tuple[int, int] = (640, 480),
        noise_px: float = 0.3,
        dropout: float = 0.0,
        seed: int = 0,
    ) -> SyntheticCapture:
        """Film markers (F, 8, 3) meters at `fps` (NaN: a marker the cameras cannot see)
        as `film` does, the cameras spread around the frames that hold all 8 markers.
        `InputError` when no frame does."""
        complete = ~np.isnan(markers).any(axis=(1, 2))
        if not complete.any():
            raise InputError("markers", "no frame holds all 8 markers to place the cameras by")
        group = CameraGroup(tuple(spread_cameras(marker_poses(markers[complete]), cameras, size)))
        rng = np.random.default_rng([seed, 1])
        pixels = group.project(markers)
        pixels = pixels + rng.normal(0.0, noise_px, pixels.shape)
        outside = ~np.stack([c.in_image(p) for c, p in zip(group, pixels, strict=True)])
        pixels[outside | (rng.random(pixels.shape[:-1]) < dropout)] = np.nan
        return cls(markers, float(fps), group, pixels)

    @property
    def frames(self) -> int:
        """Number of frames F."""
        return len(self.markers)

    def packet(
        self,
        camera: int,
        frame: int,
        start_at: float,
        session: str = "",
        sequence0: int = 0,
        epoch: int = 0,
    ) -> MarkerPacket:
        """Camera `camera`'s packet of frame `frame` (sequence `sequence0 + frame`, in
        `epoch`), captured at `start_at + frame / fps` seconds."""
        return MarkerPacket(
            camera=camera,
            sequence=(sequence0 + frame) % 2**32,
            timestamp=start_at + frame / self.fps,
            markers=self.pixels[camera, frame],
            session=session,
            epoch=epoch,
        )


async def play(
    capture: SyntheticCapture,
    address: tuple[str, int],
    start_at: float,
    session: str = "",
    key: bytes | None = None,
    cameras: Sequence[int] | None = None,
    frames: range | None = None,
    sequence0: int = 0,
    sent: Callable[[int, float], None] | None = None,
    epoch: int | None = None,
) -> int:
    """Send `capture` to `address` in real time: every frame's packets (of `cameras`,
    default all, in camera order) at its capture time `start_at + i / fps` (wall clock,
    seconds), over `frames` (default all), frame i with sequence `sequence0 + i` (a
    restarted node: a negative `sequence0` so it counts from 0 again), signed with `key`
    when given. Every call is one run of the cameras' nodes: its packets carry `epoch`,
    drawn at random when None. `sent(frame, t)` is called after a frame's last packet
    left at wall-clock time t. Returns the number of datagrams sent (a datagram the
    socket buffer cannot take is not sent).
    """
    ids = list(range(len(capture.cameras))) if cameras is None else list(cameras)
    frames = range(capture.frames) if frames is None else frames
    epoch = random_epoch() if epoch is None else epoch
    count = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.setblocking(False)
        for frame in frames:
            due = start_at + frame / capture.fps
            delay = due - time.time()
            if delay > 0:
                await asyncio.sleep(delay)
            for camera in ids:
                packet = capture.packet(camera, frame, start_at, session, sequence0, epoch)
                data = encode(packet, key)
                try:
                    sock.sendto(data, address)
                    count += 1
                except BlockingIOError:
                    continue
            if sent is not None:
                sent(frame, time.time())
    return count
