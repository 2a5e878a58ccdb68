"""`samba db ...`: create, fill, inspect, repair and query pose stores."""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np
from samba.db.errors import QueryError
from samba.db.store import PoseStore
from samba.db.cli import add_tree_command
from samba.ingest.batch import import_paths
from samba.ingest.bvh_take import BvhImportOptions
from samba.ingest.normalize import UNITS, UP_AXES
from samba.ingest.rigs import BUILTIN_RIGS, RigMap, rig_by_name

from samba.base.errors import InputError
from samba.body.skeleton import MARKER_JOINTS, MARKER_NAMES


def register(parser: argparse.ArgumentParser) -> None:
    """Add the `db` subcommands to `parser`."""
    sub = parser.add_subparsers(dest="db_command", required=True, metavar="ACTION")

    p = sub.add_parser("init", help="create an empty pose store")
    p.add_argument("store", help="directory to create")
    p.add_argument(
        "--scale-by-tibia",
        action="store_true",
        help="index poses scaled to a common tibia length (finds poses of other body sizes)",
    )
    p.set_defaults(run=_init)

    p = sub.add_parser("import", help="import BVH files or folders of them, or .mcap takes")
    p.add_argument("store", help="pose store directory")
    p.add_argument(
        "paths",
        nargs="+",
        help="BVH files, recorded .mcap takes, and/or folders (searched recursively for both)",
    )
    p.add_argument("--mirror", action="store_true", help="also store left/right mirror images")
    p.add_argument(
        "--min-change",
        type=float,
        default=0.0,
        metavar="M",
        help="drop consecutive poses where no joint moved more than M meters",
    )
    p.add_argument("--fps", type=float, default=30.0, help="database frame rate (default 30)")
    p.add_argument(
        "--skip-frames",
        type=int,
        default=0,
        metavar="N",
        help="drop the first N frames of every file",
    )
    p.add_argument("--skip-tpose", action="store_true", help="drop leading T-pose frames")
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
    p.add_argument("--rig", help=f"force a built-in rig ({rigs})")
    p.add_argument("--map", metavar="FILE.toml", help="joint mapping file for other rigs")
    p.add_argument("--subject", default="", help="subject label for every take")
    p.add_argument("--action", default="", help="action label for every take")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=_import)

    p = sub.add_parser("ls", help="list takes")
    p.add_argument("store")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=_ls)

    p = sub.add_parser("show", help="show one take")
    p.add_argument("store")
    p.add_argument("take", help="take id or name")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=_show)

    p = sub.add_parser("label", help="set a take's subject, action or tags")
    p.add_argument("store")
    p.add_argument("take", help="take id or name")
    p.add_argument("--subject")
    p.add_argument("--action")
    p.add_argument(
        "--tag",
        action="append",
        dest="tags",
        metavar="TAG",
        help="tag (repeat for several; replaces the take's tags)",
    )
    p.set_defaults(run=_label)

    p = sub.add_parser("rm", help="delete takes (with their mirrors)")
    p.add_argument("store")
    p.add_argument("takes", nargs="+", help="take ids or names")
    p.set_defaults(run=_rm)

    p = sub.add_parser("verify", help="check catalog, pose data and index")
    p.add_argument("store")
    p.set_defaults(run=_verify)

    p = sub.add_parser("stats", help="counts and sizes")
    p.add_argument("store")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=_stats)

    add_tree_command(sub)

    p = sub.add_parser("query", help="k nearest poses to a marker observation")
    p.add_argument("store")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--markers",
        metavar="X,Y,Z;...",
        help=f"8 marker positions in meters ({', '.join(MARKER_NAMES)}); nan = missing",
    )
    src.add_argument(
        "--pose",
        metavar="TAKE:FRAME",
        help="use the markers of a stored pose (take id or name : frame number)",
    )
    p.add_argument(
        "--drop",
        default="",
        metavar="MARKER,...",
        help="treat these markers as missing (e.g. l_wrist,r_knee)",
    )
    p.add_argument("-k", type=int, default=10, help="number of neighbours (default 10)")
    p.add_argument(
        "--eps", type=float, default=0.0, help="approximate search tolerance (0 = exact, default)"
    )
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=_query)


def _init(args: argparse.Namespace) -> int:
    store = PoseStore.create(args.store, scale_by_tibia=args.scale_by_tibia)
    scaled = " (index scales poses by tibia length)" if store.scale_by_tibia else ""
    print(f"created empty pose store {store.path}{scaled}")
    return 0


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
        )
    except ValueError as exc:
        raise InputError("flags", str(exc)) from exc
    if args.min_change < 0:
        raise InputError("--min-change", f"must be >= 0, got {args.min_change}")
    store = PoseStore.open(args.store)
    results = import_paths(
        store,
        args.paths,
        options,
        mirror=args.mirror,
        min_change=args.min_change,
        progress=False if args.no_progress else None,
    )
    if not results:
        raise InputError(" ".join(args.paths), "no .bvh files found")
    print(f"{'file':40} {'status':9} {'frames in':>9} {'kept':>6}  {'rig':9} takes / notes")
    for r in results:
        name = r.path if len(r.path) <= 40 else "..." + r.path[-37:]
        note = r.error or "; ".join(r.warnings)
        ids = ",".join(map(str, r.take_ids))
        print(
            f"{name:40} {r.status:9} {r.frames_in:9d} {r.frames_kept:6d}  {r.rig:9} "
            f"{ids} {note}".rstrip()
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


def _ls(args: argparse.Namespace) -> int:
    store = PoseStore.open(args.store)
    if args.json:
        print(json.dumps([t.to_dict() for t in store.takes], indent=1))
        return 0
    print(
        f"{'id':>4} {'name':32} {'rig':9} {'frames':>6} {'fps':>5} {'subject':8} {'action':10} tags"
    )
    for t in store.takes:
        print(
            f"{t.id:4d} {t.name[:32]:32} {t.rig:9} {t.frame_count:6d} {t.fps:5.0f} "
            f"{t.subject[:8]:8} {t.action[:10]:10} {','.join(t.tags)}"
        )
    print(f"{len(store.takes)} takes, {len(store)} poses")
    return 0


def _show(args: argparse.Namespace) -> int:
    store = PoseStore.open(args.store)
    info = store.take(args.take)
    data = info.to_dict()
    poses = store.take_poses(info.id)
    data["height_range_m"] = [
        round(float(poses[..., 1].min()), 3),
        round(float(poses[..., 1].max()), 3),
    ]
    if args.json:
        print(json.dumps(data, indent=1))
        return 0
    for key, value in data.items():
        print(f"{key:15} {value}")
    return 0


def _label(args: argparse.Namespace) -> int:
    store = PoseStore.open(args.store)
    info = store.label(args.take, subject=args.subject, action=args.action, tags=args.tags)
    print(
        f"take {info.id} {info.name}: subject={info.subject!r} action={info.action!r} "
        f"tags={list(info.tags)}"
    )
    return 0


def _rm(args: argparse.Namespace) -> int:
    store = PoseStore.open(args.store)
    removed = store.remove(args.takes)
    print(
        f"removed takes {', '.join(map(str, removed))}; "
        f"{len(store.takes)} takes, {len(store)} poses remain"
    )
    return 0


def _verify(args: argparse.Namespace) -> int:
    store = PoseStore.open(args.store)
    report = store.verify()
    for note in report.notes:
        print(f"note: {note}")
    for problem in report.problems:
        print(f"problem: {problem}")
    print(
        f"{store.path}: {'ok' if report.ok else 'DAMAGED'} "
        f"({len(store.takes)} takes, {len(store)} poses)"
    )
    return 0 if report.ok else 1


def _stats(args: argparse.Namespace) -> int:
    stats = PoseStore.open(args.store).stats()
    if args.json:
        print(json.dumps(stats, indent=1))
    else:
        for key, value in stats.items():
            print(f"{key:15} {value}")
    return 0


def _query(args: argparse.Namespace) -> int:
    store = PoseStore.open(args.store)
    if args.pose:
        take_ref, _, frame_text = args.pose.rpartition(":")
        if not take_ref or not frame_text.isdigit():
            raise InputError("--pose", f"expected TAKE:FRAME, got {args.pose!r}")
        info = store.take(take_ref)
        rows = np.flatnonzero(store.frames[info.rows.start : info.rows.stop] == int(frame_text))
        if not len(rows):
            raise InputError(
                "--pose", f"take {info.name} has no frame {frame_text} (it has {info.frame_count})"
            )
        markers = store.poses[info.first_row + rows[0]][list(MARKER_JOINTS)].astype(np.float64)
    else:
        markers = _parse_markers(args.markers)
    for name in filter(None, args.drop.split(",")):
        if name not in MARKER_NAMES:
            raise InputError(
                "--drop", f"unknown marker {name!r}; markers are {', '.join(MARKER_NAMES)}"
            )
        markers[MARKER_NAMES.index(name)] = np.nan
    try:
        dist, rows = store.query(markers, k=args.k, eps=args.eps)
    except QueryError as exc:
        flag = f"-{exc.source}" if len(exc.source) == 1 else f"--{exc.source}"  # -k, --eps
        raise InputError(flag, exc.problem) from exc
    by_id = {t.id: t for t in store.takes}
    hits = [
        {
            "rank": i + 1,
            "distance_m": round(float(d), 4),
            "row": int(r),
            "take": by_id[int(store.take_ids[r])].name,
            "take_id": int(store.take_ids[r]),
            "frame": int(store.frames[r]),
        }
        for i, (d, r) in enumerate(zip(dist, rows, strict=True))
    ]
    if args.json:
        print(json.dumps(hits, indent=1))
        return 0
    present = int((~np.isnan(markers).any(axis=1)).sum())
    print(f"{args.k} nearest of {len(store)} poses ({present} of 8 markers present)")
    print(f"{'rank':>4} {'dist (cm)':>9} {'take':32} {'frame':>6}")
    for h in hits:
        print(f"{h['rank']:4d} {100 * h['distance_m']:9.2f} {h['take'][:32]:32} {h['frame']:6d}")
    return 0


def _parse_markers(text: str) -> np.ndarray:
    parts = [p for p in text.replace(" ", "").split(";") if p]
    if len(parts) != 8:
        raise InputError(
            "--markers", f"expected 8 'x,y,z' groups separated by ';', got {len(parts)}"
        )
    try:
        markers = np.array([[float(v) for v in p.split(",")] for p in parts])
    except ValueError as exc:
        raise InputError("--markers", f"not a number: {exc}") from exc
    if markers.shape != (8, 3):
        raise InputError("--markers", "every marker needs exactly 3 coordinates")
    if np.isinf(markers).any():
        raise InputError("--markers", "infinite coordinate")
    return markers
