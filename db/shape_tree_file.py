"""Shape trees saved with the pose database: `<store>/shape_trees/<name>.npz`.

A shape tree (`samba.silhouette.shape_tree.ShapeTree`) is built once per camera and body model and
takes minutes for a large database, so it is kept beside the poses it was built from.
One NumPy archive (`np.savez`, no pickles) holds the camera (intrinsics, pose,
distortion, image size), the view's home point, the body model's girths and every
level's arrays; `FORMAT` versions the layout. Files are written atomically: a crash
leaves the old tree or the new one, never a part.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from samba.base import InputError, atomic_path
from samba.body import BodyModel
from samba.cameras import Camera
from samba.db.errors import StoreError
from samba.db.store import PoseStore
from samba.silhouette import ShapeTree, SilhouetteRuns, SilhouetteView, TreeLevel

FORMAT = "samba-shape-tree/1"
TREES_FOLDER = "shape_trees"
ZIP_MAGIC = b"PK\x03\x04"
"""The first bytes of an .npz archive (a zip file)."""
_LEVEL_ARRAYS = ("offsets", "starts", "ends", "poses", "floor_offsets", "visibility", "parents")


def tree_path(store: str | Path, name: str) -> Path:
    """Where the tree `name` of the pose store at `store` lives."""
    return Path(store) / TREES_FOLDER / f"{name}.npz"


def write_shape_tree(path: str | Path, tree: ShapeTree) -> None:
    """Save `tree` to `path` (.npz) atomically, creating its folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    camera, body = tree.view.camera, tree.body
    header = {
        "format": FORMAT,
        "camera": {"name": camera.name, "size": list(camera.size)},
        "view_size": list(tree.view.size),
        "body": {
            "name": body.name,
            "kind": body.kind,
            "height": body.height,
            "chest": body.chest,
            "waist": body.waist,
            "hip": body.hip,
        },
        "levels": [list(level.silhouettes.size) for level in tree.levels],
    }
    arrays: dict[str, np.ndarray] = {
        "header": np.frombuffer(json.dumps(header).encode(), dtype=np.uint8),
        "camera_matrix": camera.matrix,
        "camera_rotation": camera.rotation,
        "camera_translation": camera.translation,
        "camera_distortion": camera.distortion,
        "home": tree.view.home,
    }
    for i, level in enumerate(tree.levels):
        runs = level.silhouettes
        values = (runs.offsets, runs.starts, runs.ends, level.poses, level.floor_offsets)
        values += (level.visibility, level.parents)
        arrays.update({f"level{i}_{key}": v for key, v in zip(_LEVEL_ARRAYS, values, strict=True)})
    with atomic_path(path) as tmp, open(tmp, "wb") as file:
        np.savez(file, **arrays)


def read_shape_tree(path: str | Path) -> ShapeTree:
    """The tree saved at `path`; `StoreError` naming the file when it is missing, not a
    shape tree, of another format version or damaged."""
    path = Path(path)
    try:
        with open(path, "rb") as file:
            if file.read(4) != ZIP_MAGIC:  # np.load would take it for a pickle and say so
                raise StoreError(str(path), "damaged shape tree: not an .npz archive")
        with np.load(path, allow_pickle=False) as archive:
            header = json.loads(bytes(archive["header"]).decode())
            if header.get("format") != FORMAT:
                raise StoreError(str(path), f"not a {FORMAT} file ({header.get('format')!r})")
            arrays = {key: archive[key] for key in archive.files}
    except FileNotFoundError:
        raise StoreError(str(path), "no such shape tree (build it with samba db tree)") from None
    except (OSError, EOFError, ValueError, TypeError, KeyError, zipfile.BadZipFile) as exc:
        raise StoreError(str(path), f"damaged shape tree: {exc}") from None
    try:
        return _tree(header, arrays)
    except (KeyError, ValueError, TypeError) as exc:
        raise StoreError(str(path), f"damaged shape tree: {exc}") from None


def _tree(header: dict, arrays: dict[str, np.ndarray]) -> ShapeTree:
    camera = Camera(
        name=header["camera"]["name"],
        size=tuple(header["camera"]["size"]),
        matrix=arrays["camera_matrix"],
        rotation=arrays["camera_rotation"],
        translation=arrays["camera_translation"],
        distortion=arrays["camera_distortion"],
    )
    view = SilhouetteView(camera, arrays["home"], size=tuple(header["view_size"]))
    body = BodyModel.from_girths(**header["body"])
    levels = []
    for i, size in enumerate(header["levels"]):
        offsets, starts, ends, poses, floor_offsets, visibility, parents = (
            arrays[f"level{i}_{key}"] for key in _LEVEL_ARRAYS
        )
        runs = SilhouetteRuns(tuple(size), offsets, starts, ends)
        if len(runs) != len(poses):
            raise ValueError(f"level {i}: {len(runs)} silhouettes for {len(poses)} poses")
        if runs.offsets[-1] != len(runs.starts):
            raise ValueError(
                f"level {i}: run offsets end at {runs.offsets[-1]}, not at the "
                f"{len(runs.starts)} runs"
            )
        for name, values in (
            ("poses", poses),
            ("floor offsets", floor_offsets),
            ("visibility", visibility),
        ):
            if not np.isfinite(values).all():
                raise ValueError(f"level {i}: {name} hold NaN or infinity")
        above = len(levels[-1].poses) if levels else 0
        if len(parents) != len(poses) or (i and not ((parents >= 0) & (parents < above)).all()):
            raise ValueError(f"level {i}: parents must name one of the {above} nodes above")
        levels.append(TreeLevel(runs, poses, floor_offsets, visibility, parents))
    return ShapeTree(view, body, tuple(levels))


def stored_tree(
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
