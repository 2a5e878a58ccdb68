"""`samba db ...`: create, inspect, label, repair and query pose stores, and build their
silhouette shape trees (`samba db tree`). `samba db import` is `samba.ingest.cli`'s: the
store knows no foreign formats.

`add_camera_arguments` and the `chosen_*` functions are the camera, body model and home
point flags that `samba db tree`, `samba track-video` and `samba node --mode silhouette`
share.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np
from tqdm import tqdm

from samba.base import InputError, positive_float
from samba.body import KINDS, MARKER_JOINTS, MARKER_NAMES, BodyModel
from samba.cameras import Camera, read_calibration
from samba.db.errors import QueryError
from samba.db.shape_tree_file import tree_path, write_shape_tree
from samba.db.store import PoseStore
from samba.db.take_refs import id_text
from samba.silhouette import ShapeTree, SilhouetteView

TAKE_HELP = "take name, or id written '#3' (quoted: the shell reads # as a comment)"
"""What a TAKE argument is (`samba.db.take_refs`): a bare number is a name."""


def add_create_action(sub: Any) -> None:
    """Add `init` to the `samba db` actions `sub`."""
    p = sub.add_parser("init", help="create an empty pose store")
    p.add_argument("store", metavar="STORE", help="directory to create")
    p.add_argument(
        "--scale-by-tibia",
        action="store_true",
        help="index poses scaled to a common tibia length, which finds poses of other body "
        "sizes (default: as recorded)",
    )
    p.set_defaults(run=_init)


def add_store_actions(sub: Any) -> None:
    """Add `ls`, `show`, `label`, `rm`, `verify`, `stats`, `tree` and `query` to the
    `samba db` actions `sub`."""
    p = sub.add_parser("ls", help="list takes")
    p.add_argument("store", metavar="STORE", help="pose store directory")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=_ls)

    p = sub.add_parser("show", help="show one take")
    p.add_argument("store", metavar="STORE", help="pose store directory")
    p.add_argument("take", help=TAKE_HELP)
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=_show)

    p = sub.add_parser("label", help="set a take's subject, action or tags")
    p.add_argument("store", metavar="STORE", help="pose store directory")
    p.add_argument("take", help=TAKE_HELP)
    p.add_argument("--subject", help="subject label (default: unchanged)")
    p.add_argument("--action", help="action label (default: unchanged)")
    p.add_argument(
        "--tag",
        action="append",
        dest="tags",
        metavar="TAG",
        help="tag (repeat for several; replaces the take's tags; default: unchanged)",
    )
    p.set_defaults(run=_label)

    p = sub.add_parser("rm", help="delete takes (with their mirrors)")
    p.add_argument("store", metavar="STORE", help="pose store directory")
    p.add_argument("takes", nargs="+", help=TAKE_HELP)
    p.set_defaults(run=_rm)

    p = sub.add_parser("verify", help="check catalog, pose data and index")
    p.add_argument("store", metavar="STORE", help="pose store directory")
    p.set_defaults(run=_verify)

    p = sub.add_parser("stats", help="counts and sizes")
    p.add_argument("store", metavar="STORE", help="pose store directory")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=_stats)

    _add_tree(sub)

    p = sub.add_parser("query", help="k nearest poses to a marker observation")
    p.add_argument("store", metavar="STORE", help="pose store directory")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument(
        "--markers",
        metavar="X,Y,Z;...",
        help=f"8 marker positions in meters ({', '.join(MARKER_NAMES)}); nan = missing",
    )
    src.add_argument(
        "--pose",
        metavar="TAKE:FRAME",
        help="use the markers of a stored pose (take name, or id as '#3' : frame number)",
    )
    p.add_argument(
        "--drop",
        default="",
        metavar="MARKER,...",
        help="treat these markers as missing, e.g. l_wrist,r_knee (default: none)",
    )
    p.add_argument("-k", type=int, default=10, help="number of neighbours (default 10)")
    p.add_argument(
        "--eps", type=float, default=0.0, help="approximate search tolerance (0 = exact, default)"
    )
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(run=_query)


def _add_tree(sub: Any) -> None:
    """Add `tree` to the `samba db` actions `sub`."""
    p = sub.add_parser(
        "tree",
        help="build the silhouette shape tree of a camera and body model from the store",
        description="Render the store's poses as silhouettes of a body model seen by one "
        "camera, cluster them into the shape tree of single-camera tracking (samba "
        "track-video) and save it in STORE/shape_trees/.",
    )
    p.add_argument("store", metavar="STORE", help="pose store directory")
    p.add_argument("--calib", required=True, metavar="FILE", help="camera calibration TOML")
    add_camera_arguments(p)
    p.add_argument(
        "--headings",
        type=positive_float,
        default=15.0,
        metavar="DEG",
        help="turn every pose all round in steps of DEG degrees (default 15)",
    )
    p.add_argument("--name", help="tree name (default: CAMERA-BODY)")
    p.set_defaults(run=_tree)


def add_camera_arguments(parser: argparse.ArgumentParser) -> None:
    """The flags that pick the camera, the body model and the home point."""
    parser.add_argument(
        "--camera",
        metavar="ID",
        help="camera name, or its index in the calibration (default 0: the first)",
    )
    body = parser.add_mutually_exclusive_group()
    body.add_argument(
        "--body",
        metavar="NAME",
        help="body model name, e.g. men-L (a wrong name lists them; default: by --height)",
    )
    body.add_argument(
        "--height",
        type=positive_float,
        metavar="M",
        help="subject height in meters: nearest body model (default 1.70)",
    )
    parser.add_argument(
        "--kind",
        choices=KINDS,
        help="with --height: men, women or children (default: the nearest of all)",
    )
    parser.add_argument(
        "--home",
        metavar="X,Z",
        help="floor point (m) where the subject stands (default: where the camera looks)",
    )


def chosen_camera(calibration: str, which: str | None) -> Camera:
    """The camera `which` (name or index, default the first) of a calibration file."""
    cameras = read_calibration(calibration)
    if which is None:
        return cameras[0]
    try:
        return cameras[int(which)] if which.isdigit() else cameras[which]
    except (IndexError, KeyError):
        raise InputError("--camera", f"no camera {which!r} in {calibration}") from None


def chosen_body(args: argparse.Namespace) -> BodyModel:
    """The body model the flags name (default: the nearest to 1.70 m)."""
    if args.body:
        return BodyModel.named(args.body)
    return BodyModel.for_subject(args.height or 1.70, kind=args.kind)


def chosen_home(args: argparse.Namespace) -> np.ndarray | None:
    """The `--home X,Z` floor point (3,) in meters, None when not given."""
    if not args.home:
        return None
    try:
        x, z = (float(v) for v in args.home.split(","))
    except ValueError:
        raise InputError("--home", f"expected X,Z in meters, got {args.home!r}") from None
    return np.array([x, 0.0, z])


def chosen_view(args: argparse.Namespace) -> SilhouetteView:
    """The view of the chosen camera with the chosen home point."""
    return SilhouetteView(chosen_camera(args.calib, args.camera), chosen_home(args))


def _init(args: argparse.Namespace) -> int:
    store = PoseStore.create(args.store, scale_by_tibia=args.scale_by_tibia)
    scaled = " (index scales poses by tibia length)" if store.scale_by_tibia else ""
    print(f"created empty pose store {store.path}{scaled}")
    return 0


def _ls(args: argparse.Namespace) -> int:
    store = PoseStore.open(args.store)
    if args.json:
        print(json.dumps([t.to_dict() for t in store.takes], indent=1))
        return 0
    print(
        f"{'id':>5} {'name':32} {'rig':9} {'frames':>6} {'fps':>5} {'subject':8} {'action':10} tags"
    )
    for t in store.takes:
        print(
            f"{id_text(t.id):>5} {t.name[:32]:32} {t.rig:9} {t.frame_count:6d} {t.fps:5.0f} "
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
        f"take {id_text(info.id)} {info.name}: subject={info.subject!r} action={info.action!r} "
        f"tags={list(info.tags)}"
    )
    return 0


def _rm(args: argparse.Namespace) -> int:
    store = PoseStore.open(args.store)
    removed = store.remove(args.takes)
    print(
        f"removed takes {', '.join(map(id_text, removed))}; "
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


def _tree(args: argparse.Namespace) -> int:
    store = PoseStore.open(args.store)
    poses = np.asarray(store.poses, dtype=np.float64)
    if not len(poses):
        raise InputError(args.store, "the store holds no poses: import takes first")
    view, body = chosen_view(args), chosen_body(args)
    name = args.name or f"{view.camera.name}-{body.name}"
    start = time.perf_counter()
    with tqdm(total=1, unit="pose", desc="rendering", leave=False) as bar:

        def progress(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)

        tree = ShapeTree.build(
            poses, view, body, headings=np.arange(-180.0, 180.0, args.headings), progress=progress
        )
    seconds = time.perf_counter() - start
    path = tree_path(args.store, name)
    write_shape_tree(path, tree)
    counts = " / ".join(f"{len(level):,}" for level in tree.levels)
    print(
        f"shape tree {name}: {len(poses):,} poses -> {counts} nodes (top / middle / leaves), "
        f"body {body.name} ({body.height:.2f} m), camera {view.camera.name}, "
        f"{tree.nbytes / 2**20:.1f} MiB, built in {seconds:.1f} s -> {path}"
    )
    return 0
