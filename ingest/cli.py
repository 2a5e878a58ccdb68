"""`samba db import STORE PATHS...`: BVH files of any rig and recorded takes into a pose
store (`samba.ingest.import_paths`), a table of what became of each file."""

from __future__ import annotations

import argparse
import shlex
import sys
from typing import Any

from samba.base import InputError, add_cluster_arguments, cluster_client, positive_float
from samba.db import PoseStore, id_text
from samba.ingest.batch import FileResult, ImportInterrupted, import_paths
from samba.ingest.bvh_take import BvhImportOptions
from samba.ingest.input_files import MAX_FILE_BYTES
from samba.ingest.normalize import UNITS, UP_AXES
from samba.ingest.rigs import BUILTIN_RIGS, RigMap, rig_by_name

MARKER_SET_HELP = (
    "which labels of a C3D file are the 8 markers: a TOML file ([markers] l_shoulder = "
    '"LABEL", ...; default: Plug-in-Gait\'s LSHO, LWRA/LWRB, LKNE, LANK, ...)'
)


def add_marker_set_argument(parser: Any) -> None:
    """Add `--marker-set FILE.toml` (`samba.ingest.MarkerSet.named` reads it) to a parser
    or argument group."""
    parser.add_argument("--marker-set", metavar="FILE.toml", help=MARKER_SET_HELP)


def add_import_action(sub: Any) -> None:
    """Add `import` to the `samba db` actions `sub`."""
    text = "import BVH files or folders of them, or .mcap takes"
    p = sub.add_parser(
        "import",
        help=text,
        description=f"{text.capitalize()} into a pose store: a table of what became of "
        "each file. A file already stored is a duplicate, whatever the flags: remove its "
        "take (samba db rm) to read it again with other flags.",
    )
    p.add_argument("store", metavar="STORE", help="pose store directory")
    p.add_argument(
        "paths",
        nargs="+",
        help="BVH files, recorded .mcap takes, and/or folders (searched recursively for both)",
    )
    p.add_argument(
        "--mirror",
        action="store_true",
        help="also store left/right mirror images (default: the takes as they are)",
    )
    p.add_argument(
        "--min-change",
        type=float,
        default=0.0,
        metavar="M",
        help="drop consecutive poses where no joint moved more than M meters (default 0: keep all)",
    )
    p.add_argument(
        "--fps", type=float, default=30.0, metavar="N", help="database frame rate (default 30)"
    )
    p.add_argument(
        "--skip-frames",
        type=int,
        default=0,
        metavar="N",
        help="drop the first N frames of every file (default 0)",
    )
    p.add_argument(
        "--skip-tpose", action="store_true", help="drop leading T-pose frames (default: keep)"
    )
    p.add_argument(
        "--max-file-mb",
        type=positive_float,
        default=MAX_FILE_BYTES / 1e6,
        metavar="MB",
        help=f"largest file read, in MB (default {MAX_FILE_BYTES / 1e6:g}); larger files fail",
    )
    p.add_argument(
        "--units",
        default="auto",
        choices=["auto", *UNITS],
        help="length unit of the files (default: detected from leg length)",
    )
    p.add_argument(
        "--up",
        default="auto",
        choices=["auto", *UP_AXES],
        help="up axis of the files (default: detected from the motion)",
    )
    p.add_argument(
        "--handedness",
        default="auto",
        choices=["auto", "right", "left"],
        help="coordinate handedness (default: detected from knee bending)",
    )
    rigs = ", ".join(r.name for r in BUILTIN_RIGS)
    p.add_argument(
        "--rig", metavar="NAME", help=f"force a built-in rig ({rigs}; default: detected)"
    )
    p.add_argument(
        "--map",
        metavar="FILE.toml",
        help="joint mapping file for other rigs (samba db rig --write-map writes one; "
        "default: detected)",
    )
    p.add_argument(
        "--subject",
        default="",
        help="subject label for every take (default: from CMU-style names such as 131_01)",
    )
    p.add_argument("--action", default="", help="action label for every take (default: none)")
    p.add_argument(
        "--no-progress",
        action="store_true",
        help="no progress bar (default: a bar on a terminal)",
    )
    add_cluster_arguments(p)
    p.set_defaults(run=_import)


def _import(args: argparse.Namespace) -> int:
    rig: RigMap | None = None
    if args.rig and args.map:
        raise InputError("--rig/--map", "give either a built-in rig or a mapping file, not both")
    if args.rig:
        rig = rig_by_name(args.rig)
    elif args.map:
        rig = RigMap.from_toml(args.map)
    try:
        options = BvhImportOptions(
            fps=args.fps,
            skip_frames=args.skip_frames,
            skip_tpose=args.skip_tpose,
            units=args.units,
            up=args.up,
            handedness=args.handedness,
            rig=rig,
            subject=args.subject,
            action=args.action,
            max_file_bytes=int(args.max_file_mb * 1e6),
        )
    except ValueError as exc:
        raise InputError("flags", str(exc)) from exc
    if args.min_change < 0:
        raise InputError("--min-change", f"must be >= 0, got {args.min_change}")
    store = PoseStore.open(args.store)
    try:
        with cluster_client(args.workers, args.cluster) as client:
            results = import_paths(
                store,
                args.paths,
                options,
                mirror=args.mirror,
                min_change=args.min_change,
                progress=False if args.no_progress else None,
                client=client,
            )
    except ImportInterrupted as stop:
        added = sum(r.status == "added" for r in stop.done)
        print(
            f"samba: interrupted: {len(stop.done)} of {stop.total} files done, {added} of "
            f"them added and committed; the store holds those, the rest was not imported",
            file=sys.stderr,
        )
        return 130
    if not results:
        raise InputError(" ".join(args.paths), "no .bvh or .mcap files found")
    print(f"{'file':40} {'status':9} {'frames in':>9} {'kept':>6}  {'rig':9} takes / notes")
    for r in results:
        name = r.path if len(r.path) <= 40 else "..." + r.path[-37:]
        ids = ",".join(map(id_text, r.take_ids))
        print(
            f"{name:40} {r.status:9} {r.frames_in:9d} {r.frames_kept:6d}  {r.rig:9} "
            f"{ids} {_note(r, args.store)}".rstrip()
        )
    failed = [r for r in results if r.status == "failed"]
    added = sum(r.status == "added" for r in results)
    dup = sum(r.status == "duplicate" for r in results)
    print(
        f"{added} added, {dup} already stored, {len(failed)} failed; "
        f"store now holds {len(store.takes)} takes, {len(store)} poses"
    )
    sys.stdout.flush()  # the table first, then each failure on stderr for scripts
    for r in failed:
        print(f"samba: error: {r.error}", file=sys.stderr)
    return 1 if failed else 0


def _note(result: FileResult, store: str) -> str:
    """The table's note on one file: its error, its warnings, and for a duplicate how to
    read it again (the store keeps the first reading whatever the flags)."""
    note = result.error or "; ".join(result.warnings)
    if result.status == "duplicate":
        take = id_text(result.take_ids[0])
        rm = shlex.join(["samba", "db", "rm", store, take])
        again = f"already stored as take {take}: {rm} to import it anew"
        note = f"{again}; {note}" if note else again
    return note
