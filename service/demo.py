"""`samba demo`: a whole live capture on this machine, start to finish, in one command.

1. A pose database: built from the built-in synthetic motions (or `--db STORE`).
2. The live server (`samba.service.serve.LiveServer`) on loopback: UDP for camera packets,
   the viewer and control API on HTTP (the token drawn for the run, in the viewer's URL),
   VMC to `--vmc` (default the VMC marionette port 39539, where VSeeFace / EVMC4U
   listen) and to a receiver of its own that counts what arrives.
3. Two simulated camera nodes, each its own UDP socket and its own key (drawn for the
   run; the server checks each camera's packets with its node's key), playing a
   held-out synthetic motion (or `--motion FILE.bvh`, or the real markers of `--motion
   FILE.c3d`, see `samba.service.marker_motion`) in real time: the markers projected
   into two 640x480 cameras with 0.3 px noise and 2% dropout, as a camera node's
   tracker reports them.
4. A take recorded while they play, then exported to USD and glTF on the default
   mannequin; a summary of frames, latency, accuracy against the truth (for a marker
   take, which has no true joints: how high the recorded shoulders went, beside the
   take's shoulder markers) and files written.

Every file stays in the demo's folder (`./samba-demo` unless `--out-dir` names
another); a folder that holds an earlier demo's files is refused, or with `--force`
cleared of them (`demo_outputs`) first.
"""

from __future__ import annotations

import asyncio
import os
import secrets
import shutil
import sys
import time
import webbrowser
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from samba.base import FORCE_HINT, InputError
from samba.cameras import write_calibration
from samba.db import PoseStore, build_synthetic_store
from samba.export import Avatar, load_avatar, retarget, write_export
from samba.ingest import BvhImportOptions, MarkerSet, RigMap, load_bvh_take, read_take
from samba.service.marker_motion import MarkerMotion, is_marker_file
from samba.service.node_keys import NodeKey, NodeKeys
from samba.service.serve import LiveServer
from samba.service.session import CaptureSession
from samba.service.session_config import SessionConfig
from samba.service.synthetic_capture import SyntheticCapture, play
from samba.service.udp_input import UdpInput
from samba.service.vmc import MARIONETTE_PORT
from samba.synthetic import MOTIONS

SESSION = "demo"
DEFAULT_FOLDER = "samba-demo"
"""The folder, in the working directory, the demo keeps its files in by default."""
DRAIN_S = 10.0
"""How long the demo waits, after the last packet, for the server to finish the frames."""


@dataclass(frozen=True)
class DemoSettings:
    """What `run_demo` plays: `motion` (a built-in motion's name, a BVH file or a C3D
    file, its markers by the marker-set file `marker_set`, None: Plug-in-Gait's) for
    `seconds` at `fps` camera frames per second; the pose store `db` (None: built from
    the built-in motions); VMC also to `vmc` (host, port); files kept in the folder
    `out_dir`, an earlier demo's files there replaced when `force`; the viewer opened in
    a browser when `open_viewer`; `seed` of the database and the capture; `avatar` the
    avatar file streamed and exported onto; `rig_map` the joints of a BVH motion (None:
    its rig detected)."""

    motion: str = "walk"
    seconds: float = 8.0
    fps: float = 60.0
    db: str | None = None
    vmc: tuple[str, int] = ("127.0.0.1", MARIONETTE_PORT)
    out_dir: str = DEFAULT_FOLDER
    force: bool = False
    open_viewer: bool = False
    seed: int = 0
    avatar: str | None = None
    marker_set: str | None = None
    rig_map: RigMap | None = None


def run_demo(settings: DemoSettings) -> int:
    """Run the demo in `settings.out_dir`, printing each step; returns the exit status
    (0). A motion or marker-set file that cannot be read, or a folder holding an earlier
    demo's files without `settings.force`, stops it before it makes anything (`C3dError`,
    `BvhError`, `InputError`, ...)."""
    capture, motion_name = demo_capture(settings)
    folder = Path(settings.out_dir)
    if folder.exists() and not folder.is_dir():
        raise InputError(str(folder), "is a file; the demo keeps its files in a folder")
    earlier = [p for p in demo_outputs(folder, motion_name, settings.db is None) if p.exists()]
    if earlier and not settings.force:
        raise InputError(
            str(earlier[0]),
            f"already exists (an earlier demo); {FORCE_HINT} the demo's files, or give "
            "--out-dir another folder",
        )
    for path in earlier:
        shutil.rmtree(path) if path.is_dir() else path.unlink()
    folder.mkdir(parents=True, exist_ok=True)
    return asyncio.run(_demo(folder, settings, capture, motion_name))


def demo_outputs(folder: Path, motion_name: str, builds_store: bool) -> list[Path]:
    """What a demo of `motion_name` writes in `folder`: the pose store (when it builds
    one), the calibration, the take and its two exports."""
    take = _take_name(motion_name)
    return [
        *([folder / "store"] if builds_store else []),
        folder / "cameras.toml",
        folder / "takes" / SESSION / f"{take}.mcap",
        *_exports(folder, take),
    ]


def _take_name(motion_name: str) -> str:
    """The name of the take the demo records of `motion_name`."""
    return f"demo_{motion_name}"


def _exports(folder: Path, take: str) -> list[Path]:
    """The USD and glTF files the take named `take` is exported to in `folder`."""
    return [folder / "exports" / f"{take}.{suffix}" for suffix in ("usda", "glb")]


async def _demo(
    folder: Path, settings: DemoSettings, capture: SyntheticCapture, motion_name: str
) -> int:
    avatar = load_avatar(settings.avatar)  # a bad avatar file stops the demo before it builds
    t0 = time.perf_counter()
    if settings.db:
        store = PoseStore.open(settings.db)
        where = settings.db
    else:
        where = folder / "store"
        store = await asyncio.to_thread(build_synthetic_store, where, 3, 6.0, settings.seed)
    print(
        f"1. pose database: {len(store)} poses, {len(store.takes)} takes in {where} "
        f"({time.perf_counter() - t0:.1f} s)"
    )

    calibration = folder / "cameras.toml"
    write_calibration(calibration, capture.cameras)
    counter = _VmcCounter()
    config = SessionConfig.from_mapping(
        {
            "name": SESSION,
            "calibration": str(calibration),
            "database": str(where),
            "fps": settings.fps,
            "vmc": [f"{h}:{p}" for h, p in (settings.vmc, counter.address)],
            **({"avatar": settings.avatar} if settings.avatar else {}),
        },
        "samba demo",
    )
    node_keys = {camera: secrets.token_bytes(32) for camera in (0, 1)}
    keys = NodeKeys(
        NodeKey(key, frozenset({camera}), SESSION, f"demo node {camera}")
        for camera, key in node_keys.items()
    )
    live = LiveServer(
        [config],
        folder / "takes",
        udp=("127.0.0.1", 0),
        http=("127.0.0.1", 0),
        keys=keys,
        workers=1,
    )
    async with live:
        assert live.server is not None
        session = live.server.session(SESSION)
        viewer = live.viewer_url(SESSION)
        assert viewer is not None
        host, port = live.udp_address
        vmc_host, vmc_port = settings.vmc
        print(f"2. server: camera packets on udp {host}:{port}; VMC -> {vmc_host}:{vmc_port}")
        print(f"   live viewer: {viewer}")
        print(f"   control API: {live.http_url}/api/health, Authorization: Bearer {live.token}")
        if settings.open_viewer and _has_display():
            webbrowser.open(viewer)
        take = session.start_take(_take_name(motion_name))
        print(
            f"3. two camera nodes play {capture.frames} frames of {motion_name} "
            f"({capture.frames / settings.fps:.1f} s at {settings.fps:g} fps), "
            f"recording take {take.name}"
        )
        start_at = time.time() + 0.5
        counter.start()
        await asyncio.gather(
            *(
                play(capture, live.udp_address, start_at, SESSION, key, cameras=[camera])
                for camera, key in node_keys.items()
            )
        )
        deadline = time.time() + DRAIN_S
        while not _all_out(session, capture.frames) and time.time() < deadline:
            await asyncio.sleep(0.05)
        await asyncio.sleep(0.1)  # the last VMC bundles reach the counter
        counter.close()
        take = session.stop_take()
        metrics = live.server.metrics()["sessions"][SESSION]
    _report(metrics, counter.frames, capture, take.path, folder, avatar)
    return 0


def _all_out(session: CaptureSession, frames: int) -> bool:
    """Whether every frame played has come out of `session`, or been skipped or lost."""
    done = session.frames_out + session.frames_failed + session.sync.counts.skipped
    return done >= frames


def demo_capture(settings: DemoSettings) -> tuple[SyntheticCapture, str]:
    """The motion the camera nodes play and its name: a built-in one (a seed the database
    never saw), a BVH file or a C3D file's real markers, `--seconds` of it."""
    if is_marker_file(settings.motion):
        marker_set = MarkerSet.named(settings.marker_set)
        motion = MarkerMotion.read(settings.motion, settings.fps, settings.seconds, marker_set)
        capture = SyntheticCapture.of_markers(
            motion.markers, motion.fps, dropout=0.02, seed=settings.seed
        )
        return capture, motion.name
    if settings.motion in MOTIONS:
        seed = 10_000 + settings.seed
        capture = SyntheticCapture.film(
            settings.motion, settings.seconds, settings.fps, dropout=0.02, seed=seed
        )
        return capture, settings.motion
    path = Path(settings.motion)
    take = load_bvh_take(path, BvhImportOptions(fps=settings.fps, rig=settings.rig_map))
    take.poses = take.poses[: round(settings.seconds * settings.fps)]
    return SyntheticCapture.of_take(take, dropout=0.02, seed=settings.seed), path.stem


def _report(
    metrics: dict,
    vmc_frames: int,
    capture: SyntheticCapture,
    take_path: Path,
    folder: Path,
    avatar: Avatar,
) -> None:
    sync, latency = metrics["sync"], metrics["latency"]
    print(
        f"   frames out: {metrics['frames_out']} of {capture.frames} ({sync['complete']} with "
        f"both cameras, {sync['skipped']} skipped); VMC frames received: {vmc_frames}"
    )
    print(
        f"   latency, last packet in -> VMC out: mean {latency['mean_ms']} ms, "
        f"p50 {latency['p50_ms']} ms, p99 {latency['p99_ms']} ms"
    )
    recorded = read_take(take_path)
    if capture.take is None:
        shoulders, markers = recorded.poses[:, 1:3, 1], capture.markers[:, :2, 1]
        print(
            f"   a marker take has no true joints: recorded shoulders {shoulders.min():.2f} "
            f"to {shoulders.max():.2f} m high, the take's shoulder markers "
            f"{np.nanmin(markers):.2f} to {np.nanmax(markers):.2f} m"
        )
    else:
        truth = capture.take.poses[: len(recorded)]
        error = np.linalg.norm(recorded.poses - truth, axis=-1) * 100
        print(
            f"   joint error against the truth: mean {error.mean():.1f} cm, markers "
            f"{error[:, [1, 2, 5, 6, 9, 10, 11, 12]].mean():.1f} cm, other joints "
            f"{error[:, [0, 3, 4, 7, 8]].mean():.1f} cm"
        )
    motion = retarget(recorded.poses, avatar.rig, recorded.fps)
    outputs = _exports(folder, take_path.stem)
    outputs[0].parent.mkdir(exist_ok=True)
    for out, fmt in zip(outputs, ("usd", "glb"), strict=True):
        write_export(fmt, out, motion, avatar.mesh, "m")
    print(f"4. files: take {take_path} ({take_path.stat().st_size / 1e3:.0f} kB)")
    for out in outputs:
        print(f"   export {out} ({out.stat().st_size / 1e3:.0f} kB, {len(motion)} frames)")
    print(f"   all kept in {folder}/ (the next demo there needs --force or another --out-dir)")
    sys.stdout.flush()


def _has_display() -> bool:
    """Whether a browser can open a window here."""
    return sys.platform in ("darwin", "win32") or bool(
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    )


class _VmcCounter:
    """Counts the VMC frames (bundles carrying `/VMC/Ext/T`) sent to its own port."""

    def __init__(self) -> None:
        self.frames = 0
        self._input = UdpInput("127.0.0.1", 0, self._receive, max_bytes=2048)

    @property
    def address(self) -> tuple[str, int]:
        """Where to send VMC."""
        return self._input.address

    def start(self) -> None:
        """Count in the running event loop."""
        self._input.start()

    def close(self) -> None:
        """Stop counting."""
        self._input.close()

    def _receive(self, data: bytes, _arrival: float, _sender: str) -> None:
        self.frames += b"/VMC/Ext/T\x00" in data
