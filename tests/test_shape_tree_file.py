"""Tests of `samba.db.shape_tree_file`: shape trees saved with the pose database, on the small
tree of `silhouette_fixtures`."""

from __future__ import annotations

import dataclasses
import io
import json
from pathlib import Path

import numpy as np
import pytest
from silhouette_fixtures import BODY, CAMERA, build_small_tree

from samba.body.body_model import BodyModel
from samba.db.errors import StoreError
from samba.db.shape_tree_file import FORMAT, read_shape_tree, tree_path, write_shape_tree
from samba.silhouette.distance import SilhouetteWeights, downsampled
from samba.silhouette.evaluation import observed_silhouettes, staged
from samba.silhouette.runs import RowSums
from samba.silhouette.shape_tree import ShapeTree
from samba.silhouette.tracker import SilhouetteTracker, TrackerSettings
from samba.silhouette.view import SilhouetteView
from samba.synthetic.motions import generate


@pytest.fixture(scope="module")
def small_tree() -> ShapeTree:
    """The small tree of `silhouette_fixtures`."""
    return build_small_tree().tree


@pytest.fixture(scope="module")
def saved(small_tree: ShapeTree, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The small tree written once to a store folder; tests copy it before damaging it."""
    path = tree_path(tmp_path_factory.mktemp("store"), "cam-men-M")
    write_shape_tree(path, small_tree)
    return path


def _assert_same_tree(read: ShapeTree, written: ShapeTree) -> None:
    assert read.body == written.body
    a, b = read.view.camera, written.view.camera
    assert (a.name, a.size) == (b.name, b.size)
    for field in ("matrix", "rotation", "translation", "distortion"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field), err_msg=field)
    assert read.view.size == written.view.size
    np.testing.assert_array_equal(read.view.home, written.view.home)
    np.testing.assert_array_equal(read.view.home_pixel, written.view.home_pixel)
    assert len(read.levels) == len(written.levels)
    for level, (mine, theirs) in enumerate(zip(read.levels, written.levels, strict=True)):
        assert mine.silhouettes.size == theirs.silhouettes.size
        for name in ("offsets", "starts", "ends"):
            x, y = getattr(mine.silhouettes, name), getattr(theirs.silhouettes, name)
            assert x.dtype == y.dtype, f"level {level} {name}"
            np.testing.assert_array_equal(x, y, err_msg=f"level {level} {name}")
        for name in ("poses", "floor_offsets", "visibility", "parents"):
            x, y = getattr(mine, name), getattr(theirs, name)
            assert x.dtype == y.dtype, f"level {level} {name}"
            np.testing.assert_array_equal(x, y, err_msg=f"level {level} {name}")


def test_trees_live_in_the_store_shape_trees_folder() -> None:
    assert tree_path("db", "front-men-L") == Path("db") / "shape_trees" / "front-men-L.npz"


def test_a_written_tree_reads_back_identical(small_tree: ShapeTree, saved: Path) -> None:
    assert saved.is_file() and saved.parent.name == "shape_trees"  # folder was created
    _assert_same_tree(read_shape_tree(saved), small_tree)


def test_distortion_home_and_a_custom_body_survive(small_tree: ShapeTree, tmp_path: Path) -> None:
    camera = dataclasses.replace(CAMERA, name="wide", distortion=[-0.21, 0.05, 1e-3, -2e-3, 0.01])
    body = BodyModel.from_girths("tall-slim", "women", 1.83, 0.86, 0.66, 0.92)
    tree = ShapeTree(SilhouetteView(camera, np.array([0.4, 0.0, -0.3])), body, small_tree.levels)
    path = tree_path(tmp_path, "wide-tall-slim")
    write_shape_tree(path, tree)
    read = read_shape_tree(path)
    _assert_same_tree(read, tree)
    assert read.body.name == "tall-slim" and read.body.height == 1.83
    np.testing.assert_array_equal(read.view.home, [0.4, 0.0, -0.3])


@pytest.fixture(scope="module")
def wave_silhouettes(small_tree: ShapeTree) -> np.ndarray:
    """Noisy silhouettes (10, 240, 320) of 1 s of a held-out wave at 10 fps."""
    take = generate("wave", 1.0, 10.0, seed=77).poses.astype(np.float64)
    poses = staged(take, small_tree.view, BODY.height)
    return observed_silhouettes(poses, small_tree, 0.5, np.random.default_rng(3))


def test_a_tracker_on_the_read_tree_gives_the_same_estimates(
    small_tree: ShapeTree, saved: Path, wave_silhouettes: np.ndarray
) -> None:
    # The plain XOR distance: OpenCV's precise distance transform (of the other two)
    # rounds differently from call to call, so their trackers are not reproducible.
    settings = TrackerSettings(distance="xor")
    original = SilhouetteTracker(small_tree, settings).track(wave_silhouettes)
    read = SilhouetteTracker(read_shape_tree(saved), settings).track(wave_silhouettes)
    assert [e.leaf for e in read] == [e.leaf for e in original]
    for mine, theirs in zip(read, original, strict=True):
        np.testing.assert_array_equal(mine.pose, theirs.pose)
        assert (mine.distance, mine.evaluated) == (theirs.distance, theirs.evaluated)


def test_the_read_tree_scores_every_node_as_the_original(
    small_tree: ShapeTree, saved: Path, wave_silhouettes: np.ndarray
) -> None:
    read = read_shape_tree(saved)
    for mask in wave_silhouettes[::3]:
        normalised, _ = small_tree.view.normalise(mask)
        for mine, theirs in zip(read.levels, small_tree.levels, strict=True):
            image = downsampled(normalised, mine.silhouettes.size)
            sums = RowSums.from_weights(SilhouetteWeights.from_mask(image))
            np.testing.assert_array_equal(
                mine.silhouettes.distances(sums), theirs.silhouettes.distances(sums)
            )


def test_writing_over_a_tree_replaces_it(small_tree: ShapeTree, tmp_path: Path) -> None:
    path = tree_path(tmp_path, "cam-men-M")
    write_shape_tree(path, small_tree)
    moved = ShapeTree(SilhouetteView(CAMERA, np.array([0.5, 0.0, 0.2])), BODY, small_tree.levels)
    write_shape_tree(path, moved)
    np.testing.assert_array_equal(read_shape_tree(path).view.home, [0.5, 0.0, 0.2])
    assert [p.name for p in path.parent.iterdir()] == [path.name]


def test_a_write_that_fails_midway_leaves_the_old_tree(
    small_tree: ShapeTree, saved: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tree_path(tmp_path, "cam-men-M")
    path.parent.mkdir()
    path.write_bytes(saved.read_bytes())
    before = path.read_bytes()

    def disk_full(file: object, **arrays: np.ndarray) -> None:
        file.write(b"PK\x03\x04 half an archive")  # type: ignore[attr-defined]
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", disk_full)
    with pytest.raises(OSError, match="No space left"):
        write_shape_tree(path, small_tree)
    assert path.read_bytes() == before
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temporary left


def _truncated(good: bytes, path: Path) -> None:
    path.write_bytes(good[: len(good) // 2])


def _emptied(good: bytes, path: Path) -> None:
    path.write_bytes(b"")


def _flipped(good: bytes, path: Path) -> None:
    damaged = bytearray(good)
    damaged[len(damaged) // 2] ^= 0xFF
    path.write_bytes(bytes(damaged))


def _garbage(good: bytes, path: Path) -> None:
    path.write_bytes(np.random.default_rng(0).bytes(4096))


def _text(good: bytes, path: Path) -> None:
    path.write_text("shape tree: see the store\n")


def _npy(good: bytes, path: Path) -> None:
    with path.open("wb") as file:
        np.save(file, np.zeros((3, 13, 3)))


def _other_npz(good: bytes, path: Path) -> None:
    with path.open("wb") as file:
        np.savez(file, poses=np.zeros((3, 13, 3)))


def _other_format(good: bytes, path: Path) -> None:
    header = json.dumps({"format": "samba-shape-tree/0", "levels": []}).encode()
    with path.open("wb") as file:
        np.savez(file, header=np.frombuffer(header, dtype=np.uint8))


def _header_only(good: bytes, path: Path) -> None:
    header = json.dumps({"format": FORMAT}).encode()
    with path.open("wb") as file:
        np.savez(file, header=np.frombuffer(header, dtype=np.uint8))


def _changed(path: Path, good: bytes, key: str, change) -> None:
    """The tree `good` with the array `key` replaced by `change(array)`."""
    with np.load(io.BytesIO(good)) as archive:
        arrays = {k: archive[k] for k in archive.files}
    arrays[key] = change(arrays[key])
    with path.open("wb") as file:
        np.savez(file, **arrays)


def _nan_poses(good: bytes, path: Path) -> None:
    _changed(path, good, "level2_poses", lambda a: np.full_like(a, np.nan))


def _parent_out_of_range(good: bytes, path: Path) -> None:
    _changed(path, good, "level2_parents", lambda a: np.where(np.arange(len(a)) == 5, 10**6, a))


@pytest.mark.parametrize(
    ("damage", "problem"),
    [
        (_nan_poses, "level 2: poses hold NaN"),
        (_parent_out_of_range, "level 2: parents must name one of the"),
        (_garbage, "not an .npz archive"),
        (_truncated, "damaged"),
        (_emptied, "damaged"),
        (_flipped, "damaged"),
        (_garbage, "damaged"),
        (_text, "damaged"),
        (_npy, "damaged"),
        (_other_npz, "damaged"),
        (_other_format, "samba-shape-tree/0"),
        (_header_only, "damaged"),
    ],
    ids=lambda v: getattr(v, "__name__", v).strip("_"),
)
def test_a_file_that_is_not_a_good_tree_raises_naming_it(
    damage, problem: str, saved: Path, tmp_path: Path
) -> None:
    path = tmp_path / "front-men-L.npz"
    damage(saved.read_bytes(), path)
    with pytest.raises(StoreError, match=problem) as caught:
        read_shape_tree(path)
    assert str(path) in str(caught.value)


def test_a_missing_tree_raises_naming_it(tmp_path: Path) -> None:
    path = tree_path(tmp_path, "front-men-L")
    with pytest.raises(StoreError, match="no such shape tree") as caught:
        read_shape_tree(path)
    assert str(path) in str(caught.value) and "samba db tree" in str(caught.value)
