"""The pose store under damage and failure: verification of damaged data and catalogs,
bad takes refused before anything is written, and failed writes that leave the previous
state."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from bvh_fixtures import humanoid_bvh
from store_fixtures import data_files, make_poses, make_take, snapshot_files

from samba.body.take import Take
from samba.db import store as store_module
from samba.db.errors import StoreCorruptedError, StoreError
from samba.db.pose_files import POSE_BYTES, ROW_BYTES
from samba.db.store import CATALOG, INDEX, PoseStore
from samba.ingest.batch import import_paths

# -- verification of damage --------------------------------------------------------------------


def test_verify_detects_flipped_pose_bytes(store: PoseStore, path: Path) -> None:
    with open(path / "poses-0.f32", "r+b") as fh:
        fh.seek(35 * POSE_BYTES + 8)  # a pose of take "b" (rows 30..49)
        byte = fh.read(1)
        fh.seek(-1, os.SEEK_CUR)
        fh.write(bytes([byte[0] ^ 0x01]))
    report = PoseStore.open(path).verify()
    assert not report.ok
    assert len(report.problems) == 1 and "take 2 (b)" in report.problems[0]
    assert "checksum mismatch" in report.problems[0]
    with pytest.raises(StoreCorruptedError, match="checksum mismatch"):
        PoseStore.open(path).verify_or_raise()


@pytest.mark.parametrize("value", [np.nan, 3e38])
def test_damaged_pose_values_are_refused_by_search_import_and_export(
    store: PoseStore, path: Path, value: float
) -> None:
    # A NaN or an absurd coordinate in take "b" (rows 30..49): the index's PCA would fail
    # (LinAlgError) or search garbage, so every user of the data names the file instead.
    with open(path / "poses-0.f32", "r+b") as fh:
        fh.seek(35 * POSE_BYTES + 8)
        fh.write(np.full(3, value, dtype=np.float32).tobytes())
    (path / INDEX).unlink()
    damaged = PoseStore.open(path)
    for use in (damaged.check_poses, damaged.build_index, lambda: damaged.index):
        with pytest.raises(StoreError, match="pose data damaged: 3 values") as err:
            use()
        assert "poses-0.f32" in str(err.value) and "samba db verify" in str(err.value)
    with pytest.raises(StoreError, match=r"take 2 \('b'\) damaged"):
        damaged.take_poses("b")
    assert damaged.take_poses("a").shape == (30, 13, 3)  # sound takes still read
    before = snapshot_files(path)
    with pytest.raises(StoreError, match="pose data damaged"):
        bvh = path.parent / "x.bvh"
        bvh.write_text(humanoid_bvh())
        import_paths(damaged, [bvh], progress=False)
    assert snapshot_files(path) == before  # nothing written into the damaged store


def test_verify_detects_rows_that_name_another_take(store: PoseStore, path: Path) -> None:
    with open(path / "rows-0.i32", "r+b") as fh:
        fh.seek(3 * ROW_BYTES)  # take id of row 3 (take "a")
        fh.write(np.int32(3).tobytes())
    report = PoseStore.open(path).verify()
    assert any("take 1 (a): pose rows name another take" in p for p in report.problems)


@pytest.mark.parametrize("name", ["poses-0.f32", "rows-0.i32"])
def test_truncated_data_file_is_reported_on_open(store: PoseStore, path: Path, name: str) -> None:
    file = path / name
    os.truncate(file, file.stat().st_size - 1)
    with pytest.raises(StoreError, match="shorter than the 75 committed poses") as err:
        PoseStore.open(path)
    assert name in str(err.value)


@pytest.mark.parametrize("name", ["poses-0.f32", "rows-0.i32"])
def test_a_missing_data_file_is_named(store: PoseStore, path: Path, name: str) -> None:
    (path / name).unlink()
    with pytest.raises(StoreError, match="missing: the store's data file is gone") as err:
        PoseStore.open(path)
    assert str(path / name) in str(err.value)


def test_damaged_catalog_raises_store_error(store: PoseStore, path: Path) -> None:
    catalog = path / CATALOG
    good = catalog.read_bytes()
    garbage = np.random.default_rng(3).bytes(len(good))
    for damaged in (b"", garbage, good[: len(good) // 2], b"\xff" * 4096 + good[4096:]):
        catalog.write_bytes(damaged)
        with pytest.raises(StoreError, match="catalog") as err:
            PoseStore.open(path)
        assert CATALOG in str(err.value)


def test_damaged_catalog_rows_are_reported_by_verify(store: PoseStore, path: Path) -> None:
    with sqlite3.connect(path / CATALOG) as conn:
        conn.execute("UPDATE takes SET checksum = 'x' WHERE id = 1")
        conn.execute("UPDATE takes SET first_row = 31 WHERE id = 2")
    conn.close()
    problems = PoseStore.open(path).verify().problems
    assert any("take 1 (a): pose data checksum mismatch" in p for p in problems)
    assert any("take 2 starts at row 31, expected 30" in p for p in problems)


def test_nothing_is_imported_into_a_damaged_catalog(store: PoseStore, path: Path) -> None:
    # The index of take names/hashes overwritten: the store opens, verify reports it, and
    # an import refuses before writing anything.
    with sqlite3.connect(path / CATALOG) as conn:
        (root,) = conn.execute(
            "SELECT rootpage FROM sqlite_master WHERE name = 'sqlite_autoindex_takes_1'"
        ).fetchone()
        (page_size,) = conn.execute("PRAGMA page_size").fetchone()
    conn.close()
    with open(path / CATALOG, "r+b") as fh:
        fh.seek(root * page_size - 200)  # cells fill a b-tree page from its end
        fh.write(b"\xff" * 200)
    damaged = PoseStore.open(path)
    assert not damaged.verify().ok
    bvh = path.parent / "x.bvh"
    bvh.write_text(humanoid_bvh())
    before = snapshot_files(path)
    with pytest.raises(StoreError, match=r"catalog\.sqlite: damaged") as err:
        import_paths(damaged, [bvh], progress=False)
    assert "samba db verify" in str(err.value)
    assert snapshot_files(path) == before


def test_random_catalog_damage_gives_only_typed_errors(store: PoseStore, path: Path) -> None:
    """Bytes of the catalog overwritten anywhere: open raises `StoreError` or verify reports;
    no raw sqlite3 or decoding error escapes."""
    catalog = path / CATALOG
    good = catalog.read_bytes()
    rng = np.random.default_rng(7)
    outcomes = {"error": 0, "problem": 0, "ok": 0}
    for _ in range(150):
        damaged = bytearray(good)
        start, length = int(rng.integers(0, len(good))), int(rng.integers(1, 64))
        damaged[start : start + length] = rng.bytes(len(damaged[start : start + length]))
        catalog.write_bytes(bytes(damaged))
        try:
            report = PoseStore.open(path).verify()
        except StoreError:
            outcomes["error"] += 1
        else:
            outcomes["ok" if report.ok else "problem"] += 1
    damaged = bytearray(good)
    damaged[4060:4080] = b"\xff" * 20  # the end of page 1 holds the schema text
    catalog.write_bytes(bytes(damaged))
    with pytest.raises(StoreError):
        PoseStore.open(path)
    assert outcomes["error"] > 0


# -- bad input and failed writes ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("poses", "fps", "match"),
    [
        (np.full((5, 13, 3), np.nan), 30.0, "NaN"),
        (np.full((5, 13, 3), np.inf), 30.0, "NaN or infinity"),
        (np.zeros((5, 12, 3)), 30.0, "must be"),
        (np.zeros((13, 3)), 30.0, "must be"),
        (np.zeros((5, 13, 3)), 0.0, "fps"),
    ],
)
def test_bad_takes_raise_before_anything_is_written(
    store: PoseStore, path: Path, poses: np.ndarray, fps: float, match: str
) -> None:
    before = snapshot_files(path)
    with pytest.raises(ValueError, match=match):
        store.add(Take(name="bad", poses=poses, fps=fps, source="bad", content_hash="bad"))
    with pytest.raises(ValueError, match="frames"):
        Take(name="bad", poses=np.zeros((5, 13, 3)), fps=30, frames=np.arange(4))
    assert snapshot_files(path) == before


def test_an_empty_take_is_refused_before_anything_is_written(store: PoseStore, path: Path) -> None:
    before = snapshot_files(path)
    empty = Take(name="empty", poses=np.zeros((0, 13, 3)), fps=30, source="e.bvh", content_hash="e")
    with pytest.raises(StoreError, match=r"e\.bvh: the take holds no poses"):
        store.add(empty)
    assert snapshot_files(path) == before


def test_a_failed_append_leaves_the_previous_state(
    store: PoseStore, path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    before = snapshot_files(path)
    poses, takes, generation = np.array(store.poses), list(store.takes), store.generation
    original = store_module.append_rows

    def append_then_fail(*args: object, **kwargs: object) -> None:
        original(*args, **kwargs)  # type: ignore[arg-type]
        raise OSError(28, "No space left on device (simulated)")

    monkeypatch.setattr(store_module, "append_rows", append_then_fail)
    with pytest.raises(OSError, match="simulated"):
        store.add(make_take("d", 40, seed=4), mirror=True)
    monkeypatch.undo()
    for s in (store, PoseStore.open(path)):
        assert s.takes == takes and s.generation == generation and s.verify().ok
        np.testing.assert_array_equal(s.poses, poses)
        assert s.index_is_fresh()
    after = snapshot_files(path)
    assert after[CATALOG] == before[CATALOG] and after[INDEX] == before[INDEX]
    for name, size in (("poses-0.f32", POSE_BYTES), ("rows-0.i32", ROW_BYTES)):
        assert len(after[name]) == (75 + 80) * size  # garbage rows past the committed ones
        assert after[name][: 75 * size] == before[name]
    result = store.add(make_take("e", 6, seed=5))
    assert result.take_ids == (4,)
    assert (path / "poses-0.f32").stat().st_size == 81 * POSE_BYTES  # the garbage is cut off
    assert (path / "rows-0.i32").stat().st_size == 81 * ROW_BYTES
    np.testing.assert_array_equal(store.poses[:75], poses)
    np.testing.assert_array_equal(store.take_poses("e"), make_poses(6, 5))
    np.testing.assert_array_equal(store.take_ids[75:], [4] * 6)
    assert store.verify().ok and PoseStore.open(path).verify().ok
    assert store.add(make_take("d", 40, seed=4)).take_ids == (5,)  # the failed take goes in now


def test_a_failed_compaction_leaves_the_previous_state(
    store: PoseStore, path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    poses, takes, generation = np.array(store.poses), list(store.takes), store.generation
    original = store_module.write_compacted

    def compact_then_fail(*args: object, **kwargs: object) -> int:
        original(*args, **kwargs)  # type: ignore[arg-type]
        raise OSError(5, "Input/output error (simulated)")

    monkeypatch.setattr(store_module, "write_compacted", compact_then_fail)
    with pytest.raises(OSError, match="simulated"):
        store.remove(["b"])
    monkeypatch.undo()
    assert "poses-1.f32" in data_files(path)  # written but never committed
    for s in (store, PoseStore.open(path)):
        assert s.takes == takes and s.generation == generation and s.data_name == "0"
        np.testing.assert_array_equal(s.poses, poses)
        assert s.verify().ok
    store.label("a", subject="x")  # the next writer clears the uncommitted files
    assert data_files(path) == {"poses-0.f32", "rows-0.i32"}
    store.remove(["b"])
    assert [t.name for t in store.takes] == ["a", "c"] and store.verify().ok
