"""`samba reconstruct TAKE... --db STORE (-o OUT | --out-dir DIR)`: offline reconstructions
of marker takes (C3D files, or takes `samba serve` recorded) into 13-joint takes, written
as MCAP, BVH, USD or glTF (`samba.service.marker_reconstruction`); many takes in this
process or on a Dask cluster (`samba.service.batch_reconstruction`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from samba.base import (
    InputError,
    SambaError,
    add_cluster_arguments,
    add_force_argument,
    check_outputs,
    cluster_client,
    positive_float,
    seconds_range,
)
from samba.export import FORMAT_SUFFIXES, format_of, load_avatar
from samba.ingest.cli import add_marker_set_argument
from samba.reconstruct import METHODS
from samba.service.batch_reconstruction import ReconstructionSettings, reconstruct_takes
from samba.service.marker_reconstruction import write_reconstruction

FORMATS = ("mcap", *sorted(FORMAT_SUFFIXES))
"""Output formats: a take like the live service's, or an export format."""


def register(parser: argparse.ArgumentParser) -> None:
    """Add the `reconstruct` arguments to `parser`."""
    parser.add_argument(
        "takes",
        nargs="+",
        metavar="TAKE",
        help="marker takes: .c3d files or takes recorded by samba serve",
    )
    parser.add_argument("--db", required=True, metavar="STORE", help="pose store to search")
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument(
        "-o",
        "--output",
        metavar="FILE",
        help="the file one take is written to: .mcap (a take samba export / db import "
        "read), .bvh, .glb or .usd[a|c|z]",
    )
    where.add_argument(
        "--out-dir",
        metavar="DIR",
        help="the folder several takes are written into, each as TAKE's name with the "
        "format's suffix (created when missing)",
    )
    add_force_argument(parser)
    parser.add_argument(
        "--format",
        choices=FORMATS,
        help="output format (default: from the suffix of --output; mcap with --out-dir)",
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
    add_cluster_arguments(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Reconstruct every take and write it; print each summary. A take that fails writes
    nothing and is named on stderr (one take: its error, as raised); the others are
    still written, and the exit status is 1."""
    targets = _targets(args)
    if args.out_dir:
        Path(args.out_dir).mkdir(parents=True, exist_ok=True)
    avatar_input = [args.avatar] if args.avatar else []
    check_outputs([out for _, out, _ in targets], args.force, [*args.takes, *avatar_input])
    avatar = load_avatar(args.avatar)
    settings = ReconstructionSettings(
        args.db,
        args.method,
        args.marker_set,
        args.fps,
        None if args.no_calibration else args.calibration,
    )
    written = {path: (out, fmt) for path, out, fmt in targets}
    failed = 0
    with cluster_client(args.workers, args.cluster) as client:
        for path, result in reconstruct_takes(args.takes, settings, client):
            if isinstance(result, Exception):
                if len(targets) == 1:
                    raise result
                failed += 1
                problem = result if isinstance(result, SambaError) else repr(result)
                print(f"samba: error: {path}: {problem}", file=sys.stderr)
                continue
            for warning in result.take.warnings:
                print(f"samba: warning: {path}: {warning}", file=sys.stderr)
            out, fmt = written[path]
            write_reconstruction(result, out, fmt, avatar, args.unit)
            print(result.summary())
            print(f"wrote {out} ({fmt})")
    if failed:
        print(f"samba: {failed} of {len(targets)} takes failed", file=sys.stderr)
    return 1 if failed else 0


def _targets(args: argparse.Namespace) -> list[tuple[str, Path, str]]:
    """Each take with the file it goes to and that file's format: `--output` for one
    take, else `--out-dir`/<take name><suffix>. `InputError` naming the flag when several
    takes would go to one file or two takes to the same name."""
    if args.output:
        if len(args.takes) > 1:
            raise InputError(
                "--output", f"{len(args.takes)} takes cannot go to one file; give --out-dir DIR"
            )
        out = Path(args.output)
        fmt = args.format or ("mcap" if out.suffix.lower() == ".mcap" else format_of(out))
        return [(args.takes[0], out, fmt)]
    folder = Path(args.out_dir)
    if folder.exists() and not folder.is_dir():
        raise InputError("--out-dir", f"{folder} is a file; give a folder")
    fmt = args.format or "mcap"
    suffix = ".mcap" if fmt == "mcap" else FORMAT_SUFFIXES[fmt][0]
    targets = [(take, folder / f"{Path(take).stem}{suffix}", fmt) for take in args.takes]
    names = [out for _, out, _ in targets]
    twice = [out for out in names if names.count(out) > 1]
    if twice:
        raise InputError(str(twice[0]), "two takes would be written to this one file")
    return targets
