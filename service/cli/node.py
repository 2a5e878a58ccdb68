"""`samba node`: one camera node of the live service (`samba.service.node`).

Reads frames from exactly one source (a video file, an image folder, a webcam or one
camera of the synthetic rig, filming a built-in motion or the real markers of a C3D
file), detects and tracks the 8 markers and sends one UDP packet
per frame to the server. With `--mode silhouette` the node is markerless: one ordinary
camera, the subject's silhouette tracked over the shape tree of `--db`
(`samba.service.silhouette_node`), one pose packet per frame to a session whose input is
"poses". `--camera N` is both the packet's camera id and the camera's
place in the calibration file: the N-th camera table of the file, counted from 0.
The run ends when the source does (never with `--loop` or a webcam) or on Ctrl-C, and
prints a one-line summary.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time

import numpy as np

from samba import LAUNCHED_AT
from samba.base import InputError, address, finite_float, natural, positive_float
from samba.body import KINDS, N_MARKERS
from samba.cameras import read_calibration
from samba.db import stored_tree
from samba.db.cli import chosen_body, chosen_home
from samba.ingest import MarkerSet
from samba.ingest.cli import add_marker_set_argument
from samba.service.marker_motion import is_marker_file
from samba.service.node import (
    DEFAULT_FPS,
    DEFAULT_PORT,
    START_DELAY_SECONDS,
    PacketSender,
    SubjectStart,
    run_node,
)
from samba.service.node_sources import (
    DEFAULT_SYNTHETIC_SECONDS,
    SOURCES,
    NodeSource,
    open_marker_node,
    open_silhouette_node,
)
from samba.service.packet import MIN_KEY_BYTES, MarkerPacket, read_key_file
from samba.silhouette import SilhouetteView
from samba.synthetic import MOTIONS

_SCOPES: dict[str, tuple[str, ...]] = {
    "seconds": ("synthetic",),
    "seed": ("synthetic",),
    "start_at": ("synthetic",),
    "marker_set": ("synthetic",),
    "start_x": ("video", "images", "webcam"),
    "start_z": ("video", "images", "webcam"),
    "heading": ("video", "images", "webcam"),
    "height": ("video", "images", "webcam"),
    "no_pace": ("video", "images", "synthetic"),
    "loop": ("video", "images", "synthetic"),
    "background": ("video", "images", "webcam"),
    "empty_frames": ("video", "images", "webcam"),
}
"""Flags that apply to some sources only -> those sources."""
_MODE_FLAGS: dict[str, tuple[str, ...]] = {
    "markers": ("threshold", "start_x", "start_z", "heading"),
    "silhouette": ("db", "tree", "body", "kind", "home", "background", "empty_frames"),
}
"""Flags of one mode only."""


def register(parser: argparse.ArgumentParser) -> None:
    """Add the `node` arguments to `parser`."""
    parser.add_argument(
        "--server",
        type=address,
        default=("127.0.0.1", DEFAULT_PORT),
        metavar="HOST:PORT",
        help=f"where the server listens for camera packets (default 127.0.0.1:{DEFAULT_PORT})",
    )
    parser.add_argument(
        "--camera",
        type=_camera_id,
        required=True,
        metavar="ID",
        help="this camera's id, 0..65535: the ID-th camera table of the calibration file "
        "(0 = the first)",
    )
    parser.add_argument(
        "--calib", required=True, metavar="FILE", help="calibration file of the capture stage"
    )
    source = parser.add_argument_group("source (exactly one)").add_mutually_exclusive_group(
        required=True
    )
    source.add_argument("--video", metavar="FILE", help="a video file")
    source.add_argument(
        "--images", metavar="DIR", help="a folder of images, frames in file-name order"
    )
    source.add_argument("--webcam", type=natural, metavar="INDEX", help="an OpenCV camera index")
    source.add_argument(
        "--synthetic",
        type=_synthetic_motion,
        metavar="MOTION",
        help="this camera of the synthetic rig filming a built-in motion "
        f"({', '.join(MOTIONS)}) or the real markers of a C3D file (FILE.c3d), after a 1-s "
        "standing lead-in",
    )
    parser.add_argument(
        "--session",
        type=_session,
        default="",
        metavar="NAME",
        help="session id put in every packet: up to 16 of [A-Za-z0-9._-] (default none)",
    )
    parser.add_argument(
        "--key-file",
        metavar="FILE",
        help=f"this node's key (the file's raw bytes, at least {MIN_KEY_BYTES}) to sign "
        "packets with (HMAC); the server's keys file (samba serve --keys) lists it for this "
        "camera (default: "
        "unsigned packets)",
    )
    timing = parser.add_argument_group("timing")
    timing.add_argument(
        "--fps",
        type=positive_float,
        metavar="N",
        help=f"frame rate (default: a video's own, {DEFAULT_FPS:g} for images and the "
        "synthetic rig, the webcam's own; asked of a webcam)",
    )
    timing.add_argument(
        "--no-pace",
        action="store_true",
        default=None,
        help="files and the synthetic rig: go as fast as possible instead of in real time",
    )
    timing.add_argument(
        "--loop",
        action="store_true",
        default=None,
        help="files and the synthetic rig: play again and again (the subject starts in "
        "the standard pose each time)",
    )
    timing.add_argument(
        "--start-sequence",
        type=_sequence,
        default=0,
        metavar="N",
        help="sequence number of the first packet (default 0; wraps after 2^32 - 1)",
    )
    synthetic = parser.add_argument_group("synthetic rig")
    synthetic.add_argument(
        "--seconds",
        type=positive_float,
        metavar="S",
        help=f"length of the motion (default {DEFAULT_SYNTHETIC_SECONDS:g}; a C3D file: all of it)",
    )
    synthetic.add_argument(
        "--seed", type=natural, metavar="N", help="seed of the motion and noise (default 0)"
    )
    synthetic.add_argument(
        "--start-at",
        type=finite_float,
        metavar="T",
        help="UNIX time of frame 0, not before the node starts unless --no-pace; frame i is "
        "captured at "
        f"T + i / fps (default: {START_DELAY_SECONDS:g} s after the node is ready). Nodes "
        "given the same motion, seed and T film the same instants, e.g. T=$(( $(date +%%s) "
        "+ 10 ))",
    )
    add_marker_set_argument(synthetic)
    subject = parser.add_argument_group(
        "subject start (video, images, webcam): where the subject stands in the standard "
        "pose when capture begins"
    )
    subject.add_argument(
        "--start-x", type=finite_float, metavar="M", help="hip midpoint x, m (default 0)"
    )
    subject.add_argument(
        "--start-z", type=finite_float, metavar="M", help="hip midpoint z, m (default 0)"
    )
    subject.add_argument(
        "--heading",
        type=finite_float,
        metavar="DEG",
        help="facing +Z turned towards +X, degrees (default 0)",
    )
    subject.add_argument(
        "--height", type=positive_float, metavar="M", help="stature, m (default 1.70)"
    )
    parser.add_argument(
        "--threshold",
        type=positive_float,
        metavar="LEVEL",
        help="fixed marker threshold, grey level (default: automatic per frame)",
    )
    parser.add_argument(
        "--mode",
        choices=("markers", "silhouette"),
        default="markers",
        help="markers (default) or silhouette: markerless, one camera, pose packets",
    )
    markerless = parser.add_argument_group(
        "silhouette mode (the subject's --height picks the body model, and a video's or "
        "webcam's subject is tracked at that stature)"
    )
    markerless.add_argument(
        "--db", metavar="STORE", help="pose store holding the shape tree (needed; no default)"
    )
    markerless.add_argument(
        "--tree", metavar="NAME", help="shape tree name in the store (default CAMERA-BODY)"
    )
    markerless.add_argument(
        "--body", metavar="NAME", help="body model name (default: nearest to --height)"
    )
    markerless.add_argument(
        "--kind",
        choices=KINDS,
        help="with --height: men, women or children (default: the nearest of all)",
    )
    markerless.add_argument(
        "--home",
        metavar="X,Z",
        help="floor point (m) the subject stands on (default: where the camera looks)",
    )
    markerless.add_argument(
        "--background",
        metavar="DIR_OR_VIDEO",
        help="video or images of the empty stage (default: --empty-frames)",
    )
    markerless.add_argument(
        "--empty-frames",
        type=natural,
        metavar="N",
        help="the first N frames show the empty stage (default: --background)",
    )
    parser.add_argument(
        "--verbose",
        action="store_true",
        help="print a status line to stderr every few seconds",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Open the node on its one source and send a packet per frame to `--server` until the
    source ends (or Ctrl-C); print the run's summary."""
    kind = _source_of(args)
    if args.start_at is not None and not args.no_pace:
        _check_ahead(args.start_at, LAUNCHED_AT, time.time())
    cameras = read_calibration(args.calib)
    if args.camera >= len(cameras):
        raise InputError(
            args.calib,
            f"has {len(cameras)} cameras (ids 0..{len(cameras) - 1}); no camera {args.camera}",
        )
    camera = cameras[args.camera]
    marker_set = MarkerSet.named(args.marker_set)
    source = NodeSource(
        kind,
        getattr(args, kind),
        args.fps,
        pace=not args.no_pace,
        loop=bool(args.loop),
        seconds=args.seconds,
        seed=args.seed,
        start_at=args.start_at,
        marker_set=marker_set,
    )
    key = read_key_file(args.key_file) if args.key_file is not None else None
    host, port = args.server
    with PacketSender(host, port, args.camera, args.session, key) as sender:
        if args.mode == "silhouette":
            view, body = SilhouetteView(camera, chosen_home(args)), chosen_body(args)
            tree = stored_tree(args.db, args.tree, view, body)
            node, captures = open_silhouette_node(
                source, camera, tree, body, args.height, args.background, args.empty_frames
            )
        else:
            start = SubjectStart(
                args.start_x or 0.0,
                args.start_z or 0.0,
                args.heading or 0.0,
                args.height or SubjectStart.height,
            )
            threshold = args.threshold if args.threshold is not None else "auto"
            node, captures = open_marker_node(source, camera, args.camera, threshold, start)
        with contextlib.closing(captures):
            summary = run_node(
                node,
                captures,
                sender,
                args.start_sequence,
                status=sys.stderr if args.verbose else None,
            )
    print(summary.describe())
    return 0


def _source_of(args: argparse.Namespace) -> str:
    """The one source flag given (argparse allows exactly one); InputError for a flag of
    another source or mode."""
    source = next(name for name in SOURCES if getattr(args, name) is not None)
    for name, sources in _SCOPES.items():
        if name == "height" and args.mode == "silhouette":
            continue  # there it picks the body model, whatever the source
        if getattr(args, name) is not None and source not in sources:
            flag = "--" + name.replace("_", "-")
            raise InputError(flag, f"does not apply to --{source}")
    for mode, names in _MODE_FLAGS.items():
        for name in names:
            if getattr(args, name) is not None and args.mode != mode:
                flag = "--" + name.replace("_", "-")
                raise InputError(flag, f"applies to --mode {mode} only")
    marker_file = source == "synthetic" and is_marker_file(args.synthetic)
    if args.marker_set is not None and not marker_file:
        raise InputError("--marker-set", "applies to a C3D file (--synthetic FILE.c3d) only")
    if args.mode == "silhouette":
        if marker_file:
            raise InputError(args.synthetic, "a C3D file plays in --mode markers only")
        if args.db is None:
            raise InputError("--mode silhouette", "needs --db STORE (its shape tree)")
        if source != "synthetic" and (args.background is None) == (args.empty_frames is None):
            raise InputError("--mode silhouette", "give --background PATH or --empty-frames N")
    return source


def _check_ahead(start_at: float, launched: float, now: float) -> None:
    """InputError naming `--start-at` when `start_at` (UNIX seconds) is before `launched`,
    when the node was started (`samba.LAUNCHED_AT`): every frame of a paced capture would
    be late. A time the node's own start-up passed (before `now`) is its start-up's."""
    if start_at < launched:
        raise InputError(
            f"--start-at {start_at:.1f}",
            f"is {now - start_at:,.1f} s in the past (every frame would be late); give a time "
            "ahead of the clock, e.g. T=$(( $(date +%s) + 10 ))",
        )


def _synthetic_motion(text: str) -> str:
    """`--synthetic`: a built-in motion's name or a C3D file's path (read later)."""
    if text in MOTIONS or is_marker_file(text):
        return text
    raise argparse.ArgumentTypeError(
        f"{text!r} is neither a built-in motion ({', '.join(MOTIONS)}) nor a C3D file (.c3d)"
    )


def _camera_id(text: str) -> int:
    """A camera id 0..65535 from a command-line word."""
    value = natural(text)
    if value > 0xFFFF:
        raise argparse.ArgumentTypeError(f"must be 0..65535, got {value}")
    return value


def _sequence(text: str) -> int:
    """A packet sequence number 0..2^32 - 1 from a command-line word."""
    value = natural(text)
    if value >= 2**32:
        raise argparse.ArgumentTypeError(f"must be 0..{2**32 - 1}, got {value}")
    return value


def _session(text: str) -> str:
    """A packet session id from a command-line word (checked as `MarkerPacket` does)."""
    try:
        MarkerPacket(0, 0, 0.0, np.full((N_MARKERS, 2), np.nan), text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text
