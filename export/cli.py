"""`samba export`: takes (BVH files or pose-store takes) to USD, glTF binary or BVH: one
take to `-o FILE`, several into `--out-dir DIR`; existing files only with `--force`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tqdm import tqdm

from samba.base import SambaError, add_force_argument, check_outputs, positive_float
from samba.export.errors import ExportError
from samba.export.outputs import FORMAT_SUFFIXES, format_of, load_avatar, output_paths, write_export
from samba.export.retargeting import retarget
from samba.export.take_source import load_take
from samba.ingest import RigMap


def register(parser: argparse.ArgumentParser) -> None:
    """Add the `export` arguments to `parser`."""
    parser.add_argument(
        "takes",
        nargs="+",
        metavar="TAKE",
        help="BVH files, or take names / ids of the pose store given with --db",
    )
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument(
        "-o", "--output", metavar="FILE", help="the file one take is written to (.usd*, .glb, .bvh)"
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
        choices=sorted(FORMAT_SUFFIXES),
        help="usd, glb or bvh (default: from the suffix of --output; needed with --out-dir)",
    )
    parser.add_argument(
        "--db", metavar="STORE", help="pose store the TAKE names refer to (default: none)"
    )
    parser.add_argument(
        "--avatar",
        metavar="FILE",
        help="a humanoid avatar whose skeleton the takes are put on: glTF (.glb, .gltf), "
        "VRM (.vrm) or USD (.usd, .usda, .usdc, .usdz) (default: the built-in mannequin)",
    )
    parser.add_argument(
        "--fps",
        type=positive_float,
        metavar="N",
        help="output frame rate (default: the take's own)",
    )
    parser.add_argument(
        "--range",
        metavar="A:B",
        dest="frame_range",
        help="export only frames A..B-1 of each take, either end may be left out (default: all)",
    )
    parser.add_argument(
        "--skip-tpose",
        action="store_true",
        help="drop the leading T-pose frames of BVH files, as samba db import does "
        "(default: keep them)",
    )
    parser.add_argument(
        "--map",
        metavar="FILE.toml",
        help="joint mapping file for BVH files of a rig not recognised (samba db rig "
        "--write-map writes one; default: detected)",
    )
    parser.add_argument(
        "--unit",
        choices=["m", "cm"],
        default="m",
        help="BVH length unit (default m; many tools assume cm)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Export every take; returns 1 if any failed (the others are still written)."""
    fmt = _format(args)
    frames = parse_range(args.frame_range)
    targets = output_paths(
        args.takes,
        fmt,
        Path(args.output) if args.output else None,
        Path(args.out_dir) if args.out_dir else None,
    )
    if args.out_dir:
        Path(args.out_dir).mkdir(parents=True, exist_ok=True)
    inputs = [*([] if args.db else args.takes), *([args.avatar] if args.avatar else [])]
    check_outputs([out for _, out in targets], args.force, inputs)
    rig = RigMap.from_toml(args.map) if args.map else None
    avatar = load_avatar(args.avatar)
    failed = 0
    bar = tqdm(targets, unit="take", disable=len(targets) == 1 or not sys.stderr.isatty())
    for ref, out in bar:
        try:
            take = load_take(ref, args.db, skip_tpose=args.skip_tpose, rig=rig)
            for warning in take.warnings:  # a recovered take says what it lost
                tqdm.write(f"samba: warning: {ref}: {warning}", file=sys.stderr)
            poses = take.poses[frames]
            if len(poses) == 0:
                raise ExportError(
                    "--range", f"{args.frame_range} selects no frames of {ref} ({len(take)} frames)"
                )
            motion = retarget(poses, avatar.rig, take.fps)
            if args.fps:
                motion = motion.resampled(args.fps)
            write_export(fmt, out, motion, avatar.mesh, args.unit)
        except SambaError as exc:
            failed += 1
            if len(targets) == 1:
                raise
            tqdm.write(f"samba: error: {exc}", file=sys.stderr)
            continue
        tqdm.write(
            f"{ref} -> {out}: {len(motion)} frames at {motion.fps:g} fps ({motion.duration:.1f} s)"
        )
    if failed:
        print(f"samba: {failed} of {len(targets)} takes failed", file=sys.stderr)
    return 1 if failed else 0


def _format(args: argparse.Namespace) -> str:
    """The format `--format` names, else the one `--output`'s suffix implies."""
    if args.format:
        return args.format
    if args.out_dir:
        raise ExportError("--out-dir", "give --format usd|glb|bvh for the files in the folder")
    return format_of(Path(args.output))


def parse_range(text: str | None) -> slice:
    """`A:B` (either end optional, frames counted from 0) as a slice; `ExportError` naming
    --range when malformed."""
    if text is None:
        return slice(None)
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        start, stop = (int(p) if p.strip() else None for p in parts)
    except ValueError:
        raise ExportError(
            "--range", f"expected A:B with whole frame numbers, got {text!r}"
        ) from None
    if (start is not None and start < 0) or (stop is not None and stop < 0):
        raise ExportError("--range", f"frame numbers must be >= 0, got {text!r}")
    return slice(start, stop)
