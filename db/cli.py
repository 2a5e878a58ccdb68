"""`samba db tree STORE --calib FILE ...`: build the shape tree of single-camera silhouette
tracking from a pose store's poses, for one camera and body model, and save it with the
store (`samba.db.shape_tree_file`)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
from samba.db.shape_tree_file import read_shape_tree, tree_path, write_shape_tree
from samba.db.store import PoseStore
from tqdm import tqdm

from samba.base.arguments import positive_float
from samba.base.errors import InputError
from samba.body.body_model import KINDS, BodyModel
from samba.cameras.calibration_file import read_calibration
from samba.cameras.camera import Camera
from samba.silhouette.shape_tree import ShapeTree
from samba.silhouette.view import SilhouetteView


def add_tree_command(sub: Any) -> None:
    """Add `tree` to the `samba db` subcommands `sub`."""
    p = sub.add_parser(
        "tree",
        help="build the silhouette shape tree of a camera and body model from the store",
        description="Render the store's poses as silhouettes of a body model seen by one "
        "camera, cluster them into the shape tree of single-camera tracking (samba "
        "track-video) and save it in STORE/shape_trees/.",
    )
    p.add_argument("store")
    p.add_argument("--calib", required=True, help="camera calibration TOML")
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
    parser.add_argument("--camera", help="camera name or index in the calibration (default 0)")
    body = parser.add_mutually_exclusive_group()
    body.add_argument("--body", help="body model name (see samba.body.body_model catalog)")
    body.add_argument(
        "--height", type=positive_float, help="subject height in meters: nearest body model"
    )
    parser.add_argument("--kind", choices=KINDS, help="with --height: men, women or children")
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


def tree_for(
    store: str | Path, name: str | None, view: SilhouetteView, body: BodyModel
) -> ShapeTree:
    """The store's shape tree `name` (default: CAMERA-BODY) for `view` and `body`; when
    no name is given and the tree is missing, it is built from the store's poses and
    saved first (this takes a while; `samba db tree` does it ahead). `InputError` when
    the saved tree was built for another camera or home."""
    path = tree_path(store, name or f"{view.camera.name}-{body.name}")
    if path.exists() or name:
        tree = read_shape_tree(path)
        same = (
            tree.view.size == view.size
            and np.allclose(tree.view.camera.projection, view.camera.projection)
            and np.allclose(tree.view.home, view.home, atol=1e-6)
        )
        if not same:
            raise InputError(
                str(path), "built for another camera or home point: rebuild it (samba db tree)"
            )
        return tree
    print(f"building the shape tree {path.name} once (samba db tree does this ahead)")
    poses = np.asarray(PoseStore.open(store).poses, dtype=np.float64)
    if not len(poses):
        raise InputError(str(store), "the store holds no poses: import takes first")
    tree = ShapeTree.build(poses, view, body)
    write_shape_tree(path, tree)
    return tree


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
