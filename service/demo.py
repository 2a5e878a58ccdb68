"""`samba demo`: a whole live capture on this machine, start to finish, in one command.

1. A pose database: built from the built-in synthetic motions (or `--db STORE`).
2. The live server (`samba.service.serve.LiveServer`) on loopback: UDP for camera packets, the
   viewer and control API on HTTP, VMC to `--vmc` (default the VMC marionette port
   39539, where VSeeFace / EVMC4U listen) and to a receiver of its own that counts what
   arrives.
3. Two simulated camera nodes, each its own UDP socket, playing a held-out synthetic
   motion (or `--motion FILE.bvh`) in real time: the markers projected into two
   640x480 cameras with 0.3 px noise and 2% dropout, as a camera node's tracker reports
   them.
4. A take recorded while they play, then exported to USD and glTF on the default
   mannequin; a summary of frames, latency, accuracy against the truth and files written.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import sys
import tempfile
import time
import webbrowser
from pathlib import Path

import numpy as np

from samba.base import address, positive_float
from samba.cameras import write_calibration
from samba.db import PoseStore, build_synthetic_store
from samba.export import load_avatar, retarget, write_export
from samba.ingest import BvhImportOptions, load_bvh_take, read_take
from samba.service.serve import LiveServer
from samba.service.session import CaptureSession
from samba.service.session_config import SessionConfig
from samba.service.synthetic_capture import SyntheticCapture, play
from samba.service.udp_input import UdpInput
from samba.service.vmc import MARIONETTE_PORT
from samba.synthetic import MOTIONS

SESSION = "demo"
DRAIN_S = 10.0
"""How long the demo waits, after the last packet, for the server to finish the frames."""


def register(parser: argparse.ArgumentParser) -> None:
    """Add the demo's flags to `parser`."""
    parser.add_argument("--out", help="folder for the database, take and exports (default: temp)")
    parser.add_argument("--db", help="use this pose store instead of building one")
    parser.add_argument(
        "--motion",
        type=_motion,
        default="walk",
        help=f"built-in motion ({', '.join(MOTIONS)}) or a BVH file to play (default: walk)",
    )
    parser.add_argument("--seconds", type=positive_float, default=8.0, help="capture length")
    parser.add_argument("--fps", type=positive_float, default=60.0, help="camera frame rate")
    parser.add_argument(
        "--vmc",
        type=address,
        default=("127.0.0.1", MARIONETTE_PORT),
        metavar="HOST:PORT",
        help=f"also stream VMC here (default 127.0.0.1:{MARIONETTE_PORT})",
    )
    parser.add_argument("--open", action="store_true", help="open the viewer in a browser")
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    parser.set_defaults(run=run)


def _motion(value: str) -> str:
    """`--motion`: a built-in motion's name or an existing file, checked before the demo
    builds anything."""
    if value in MOTIONS or Path(value).is_file():
        return value
    raise argparse.ArgumentTypeError(
        f"{value!r} is neither a built-in motion ({', '.join(MOTIONS)}) nor a BVH file"
    )


def run(args: argparse.Namespace) -> int:
    """Run the demo in `--out` or a temporary folder; prints what it did."""
    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        return asyncio.run(_demo(Path(args.out), args))
    with tempfile.TemporaryDirectory(prefix="samba-demo-") as folder:
        return asyncio.run(_demo(Path(folder), args))


async def _demo(folder: Path, args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    if args.db:
        store = PoseStore.open(args.db)
        where = args.db
    else:
        where = folder / "store"
        store = await asyncio.to_thread(build_synthetic_store, where, 3, 6.0, args.seed)
    print(
        f"1. pose database: {len(store)} poses, {len(store.takes)} takes in {where} "
        f"({time.perf_counter() - t0:.1f} s)"
    )

    capture, motion_name = _capture(args)
    calibration = folder / "cameras.toml"
    write_calibration(calibration, capture.cameras)
    counter = _VmcCounter()
    config = SessionConfig.from_mapping(
        {
            "name": SESSION,
            "calibration": str(calibration),
            "database": str(where),
            "fps": args.fps,
            "vmc": [f"{h}:{p}" for h, p in (args.vmc, counter.address)],
        },
        "samba demo",
    )
    live = LiveServer(
        [config], folder / "takes", udp=("127.0.0.1", 0), http=("127.0.0.1", 0), workers=1
    )
    async with live:
        assert live.server is not None
        session = live.server.session(SESSION)
        viewer = f"{live.http_url}/viewer/{SESSION}"
        host, port = live.udp_address
        print(f"2. server: camera packets on udp {host}:{port}; VMC -> {args.vmc[0]}:{args.vmc[1]}")
        print(f"   live viewer: {viewer}   control API: {live.http_url}/api/health")
        if args.open and _has_display():
            webbrowser.open(viewer)
        take = session.start_take(f"demo_{motion_name}")
        print(
            f"3. two camera nodes play {capture.frames} frames of {motion_name} "
            f"({capture.frames / args.fps:.1f} s at {args.fps:g} fps), recording take {take.name}"
        )
        start_at = time.time() + 0.5
        counter.start()
        await asyncio.gather(
            *(play(capture, live.udp_address, start_at, SESSION, cameras=[c]) for c in (0, 1))
        )
        deadline = time.time() + DRAIN_S
        while not _all_out(session, capture.frames) and time.time() < deadline:
            await asyncio.sleep(0.05)
        await asyncio.sleep(0.1)  # the last VMC bundles reach the counter
        counter.close()
        take = session.stop_take()
        metrics = live.server.metrics()["sessions"][SESSION]
    _report(metrics, counter.frames, capture, take.path, folder)
    return 0


def _all_out(session: CaptureSession, frames: int) -> bool:
    """Whether every frame played has come out of `session`, or been skipped or lost."""
    done = session.frames_out + session.frames_failed + session.sync.counts.skipped
    return done >= frames


def _capture(args: argparse.Namespace) -> tuple[SyntheticCapture, str]:
    """The motion the camera nodes play and its name: a built-in one (a seed the database
    never saw) or a BVH file, `--seconds` of it."""
    if args.motion in MOTIONS:
        capture = SyntheticCapture.film(
            args.motion, args.seconds, args.fps, dropout=0.02, seed=10_000 + args.seed
        )
        return capture, args.motion
    path = Path(args.motion)
    take = load_bvh_take(path, BvhImportOptions(fps=args.fps))
    take.poses = take.poses[: round(args.seconds * args.fps)]
    return SyntheticCapture.of_take(take, dropout=0.02, seed=args.seed), path.stem


def _report(
    metrics: dict, vmc_frames: int, capture: SyntheticCapture, take_path: Path, folder: Path
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
    truth = capture.take.poses[: len(recorded)]
    error = np.linalg.norm(recorded.poses - truth, axis=-1) * 100
    print(
        f"   joint error against the truth: mean {error.mean():.1f} cm, markers "
        f"{error[:, [1, 2, 5, 6, 9, 10, 11, 12]].mean():.1f} cm, other joints "
        f"{error[:, [0, 3, 4, 7, 8]].mean():.1f} cm"
    )
    avatar = load_avatar(None)
    motion = retarget(recorded.poses, avatar.rig, recorded.fps)
    outputs = [folder / "exports" / f"{take_path.stem}.{s}" for s in ("usda", "glb")]
    outputs[0].parent.mkdir(exist_ok=True)
    for out, fmt in zip(outputs, ("usd", "glb"), strict=True):
        write_export(fmt, out, motion, avatar.mesh, "m")
    print(f"4. files: take {take_path} ({take_path.stat().st_size / 1e3:.0f} kB)")
    for out in outputs:
        print(f"   export {out} ({out.stat().st_size / 1e3:.0f} kB, {len(motion)} frames)")
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
