"""`samba reconstruct TAKE --db STORE -o OUT`: an offline reconstruction of a marker take (a
C3D file, or a take `samba serve` recorded) into a 13-joint take, written as MCAP, BVH,
USD or glTF (`samba.service.marker_reconstruction`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from samba.base import add_force_argument, check_outputs, positive_float, seconds_range
from samba.export import FORMAT_SUFFIXES, format_of, load_avatar
from samba.ingest import MarkerSet, read_marker_take
from samba.ingest.cli import add_marker_set_argument
from samba.reconstruct import METHODS, method
from samba.service.marker_reconstruction import reconstruct_marker_take, write_reconstruction
from samba.service.session_indexes import SessionIndexes

FORMATS = ("mcap", *sorted(FORMAT_SUFFIXES))
"""Output formats: a take like the live service's, or an export format."""


def register(parser: argparse.ArgumentParser) -> None:
    """Add the `reconstruct` arguments to `parser`."""
    parser.add_argument("take", help="marker take: a .c3d file or a take recorded by samba serve")
    parser.add_argument("--db", required=True, metavar="STORE", help="pose store to search")
    parser.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="FILE",
        help="file to write: .mcap (a take samba export / db import read), .bvh, .glb or "
        ".usd[a|c|z]",
    )
    add_force_argument(parser)
    parser.add_argument(
        "--format", choices=FORMATS, help="output format (default: from the suffix of FILE)"
    )
    parser.add_argument(
        "--method",
        choices=list(METHODS),
        default="best",
        help="reconstruction method (default best)",
    )
    parser.add_argument(
        "--fps",
        type=positive_float,
        default=30.0,
        metavar="N",
        help="frame rate to reconstruct and write at (default 30, the database's)",
    )
    calibration = parser.add_mutually_exclusive_group()
    calibration.add_argument(
        "--calibration",
        type=seconds_range,
        default=(0.0, 2.0),
        metavar="A:B",
        help="seconds of the take the subject's skin offsets are calibrated on (default 0:2)",
    )
    calibration.add_argument(
        "--no-calibration",
        action="store_true",
        help="take the markers as joint centres (markers the project placed itself; "
        "default: calibrate)",
    )
    add_marker_set_argument(parser)
    parser.add_argument(
        "--avatar", metavar="FILE", help="avatar for BVH / glTF / USD output (default: mannequin)"
    )
    parser.add_argument(
        "--unit", choices=["m", "cm"], default="m", help="BVH length unit (default m)"
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Reconstruct the take and write it; print the summary. A failed run writes nothing."""
    out = Path(args.output)
    fmt = args.format or ("mcap" if out.suffix.lower() == ".mcap" else format_of(out))
    check_outputs([out], args.force, [args.take, *([args.avatar] if args.avatar else [])])
    marker_set = MarkerSet.named(args.marker_set)
    avatar = load_avatar(args.avatar)
    take = read_marker_take(args.take, marker_set).resampled(args.fps)
    for warning in take.warnings:
        print(f"samba: warning: {args.take}: {warning}", file=sys.stderr)
    chosen = method(args.method)
    reconstructor = chosen.build(SessionIndexes().index(args.db, chosen.mirrored_database))
    calibration = None if args.no_calibration else args.calibration
    result = reconstruct_marker_take(take, reconstructor, calibration)
    write_reconstruction(result, out, fmt, avatar, args.unit)
    print(result.summary())
    print(f"wrote {out} ({fmt})")
    return 0
