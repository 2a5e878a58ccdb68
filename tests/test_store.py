"""The pose store: create/open, import, duplicates, mirroring, near-duplicate dropping,
labels, removal with compaction, verification of damage, and the saved k-d tree index."""

from __future__ import annotations

import hashlib
import os
import sqlite3
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
from bvh_fixtures import humanoid_bvh

from samba.body.perturb import perturb_joint_angles
from samba.body.skeleton import Body, markers_of, mirror_poses
from samba.body.take import Take
from samba.db.errors import StoreCorruptedError, StoreError
from samba.db.index import PoseIndex
from samba.db.store import CATALOG, INDEX, POSE_BYTES, ROW_BYTES, PoseStore, drop_near_duplicates
from samba.ingest.batch import import_paths


def make_poses(n: int, seed: int) -> np.ndarray:
    """n distinct float32 poses (meters): perturbed A-poses of one body drifting on the floor."""
    rng = np.random.default_rng(seed)
    body = Body.from_height(float(rng.uniform(1.5, 1.9)))
    base = np.broadcast_to(body.standard_pose(float(rng.uniform(20, 70))), (n, 13, 3))
    poses = perturb_joint_angles(base, 15.0, rng)
    poses += np.cumsum(rng.normal(0, 0.01, (n, 1, 3)), axis=0) * [1.0, 0.0, 1.0]
    return poses.astype(np.float32)


def make_take(name: str, n: int = 30, seed: int = 0, **fields: object) -> Take:
    """A take of n poses whose content (and content hash) is set by `seed`."""
    defaults: dict[str, object] = {
        "fps": 30.0,
        "source": f"test://{name}",
        "content_hash": f"hash-{seed}",
        "rig": "test",
    }
    defaults.update(fields)
    return Take(name=name, poses=make_poses(n, seed), **defaults)  # type: ignore[arg-type]


def snapshot_files(path: Path) -> dict[str, bytes]:
    """Every file of a store directory (but the lock file) with its bytes."""
    return {p.name: p.read_bytes() for p in sorted(path.iterdir()) if p.name != "lock"}


def data_files(path: Path) -> set[str]:
    """Names of the pose and row data files in a store directory."""
    return {p.name for p in path.iterdir() if p.name.startswith(("poses-", "rows-"))}


@pytest.fixture
def path(tmp_path: Path) -> Path:
    """Where the test's store lives (not created yet)."""
    return tmp_path / "store"


@pytest.fixture
def store(path: Path) -> PoseStore:
    """A store with three takes: a (30 poses), b (20), c (25)."""
    s = PoseStore.create(path)
    s.add(make_take("a", 30, seed=1))
    s.add(make_take("b", 20, seed=2))
    s.add(make_take("c", 25, seed=3))
    return s


# -- create and open ---------------------------------------------------------------------


def test_create_makes_an_empty_store(path: Path) -> None:
    s = PoseStore.create(path)
    assert len(s) == 0 and s.takes == []
    assert s.poses.shape == (0, 13, 3) and s.poses.dtype == np.float32
    assert s.take_ids.shape == (0,) and s.frames.shape == (0,)
    assert {CATALOG, "poses-0.f32", "rows-0.i32"} <= {p.name for p in path.iterdir()}
    assert s.verify().ok and not s.index_is_fresh()
    reopened = PoseStore.open(path)
    assert len(reopened) == 0 and reopened.generation == s.generation


def test_create_accepts_an_existing_empty_directory(path: Path) -> None:
    path.mkdir()
    assert len(PoseStore.create(path)) == 0


def test_create_refuses_an_existing_store(store: PoseStore, path: Path) -> None:
    before = snapshot_files(path)
    with pytest.raises(StoreError, match="already exists"):
        PoseStore.create(path)
    assert snapshot_files(path) == before


def test_create_refuses_a_non_empty_directory_or_a_file(tmp_path: Path) -> None:
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "notes.txt").write_text("mine")
    with pytest.raises(StoreError, match="not an empty directory"):
        PoseStore.create(tmp_path / "full")
    assert [p.name for p in (tmp_path / "full").iterdir()] == ["notes.txt"]
    (tmp_path / "file").write_text("x")
    with pytest.raises(StoreError, match="not an empty directory"):
        PoseStore.create(tmp_path / "file")


def test_open_without_a_store_names_the_path(tmp_path: Path) -> None:
    for missing in (tmp_path / "nowhere", tmp_path):
        with pytest.raises(StoreError, match="no pose store") as err:
            PoseStore.open(missing)
        assert str(missing) in str(err.value)


# -- adding and reading back ---------------------------------------------------------------


def test_added_poses_read_back_exactly(path: Path) -> None:
    s = PoseStore.create(path)
    takes = [make_take("a", 30, seed=1), make_take("b", 20, seed=2)]
    results = [s.add(t) for t in takes]
    assert [r.take_ids for r in results] == [(1,), (2,)]
    assert [(r.frames_in, r.frames_kept, r.duplicate_of) for r in results] == [
        (30, 30, None),
        (20, 20, None),
    ]
    for s_ in (s, PoseStore.open(path)):
        assert s_.poses.shape == (50, 13, 3) and s_.poses.dtype == np.float32
        np.testing.assert_array_equal(s_.poses, np.concatenate([t.poses for t in takes]))
        np.testing.assert_array_equal(s_.take_ids, [1] * 30 + [2] * 20)
        np.testing.assert_array_equal(s_.frames, list(range(30)) + list(range(20)))
        assert s_.take_ids.dtype == np.int32 and s_.frames.dtype == np.int32
        assert s_.verify().ok


def test_catalog_row_records_the_take(path: Path) -> None:
    s = PoseStore.create(path)
    take = make_take(
        "walk",
        40,
        seed=5,
        fps=120.0,
        rig="cmu",
        subject="s07",
        action="walk",
        source_frames=80,
        meta={"units": "cm"},
        warnings=["odd"],
    )
    s.add(take)
    info = PoseStore.open(path).take("walk")
    assert (info.id, info.name, info.source, info.content_hash) == (
        1,
        "walk",
        "test://walk",
        "hash-5",
    )
    assert (info.rig, info.subject, info.action, info.tags) == ("cmu", "s07", "walk", ())
    assert (info.fps, info.frame_count, info.source_frames, info.first_row) == (120.0, 40, 80, 0)
    assert (info.mirrored, info.mirror_of) == (False, None)
    assert info.meta == {"units": "cm"} and info.warnings == ("odd",)
    assert info.checksum == hashlib.sha256(take.poses.tobytes()).hexdigest()
    assert datetime.fromisoformat(info.added_at).tzinfo is not None
    assert info.rows == range(0, 40)
    assert info.to_dict()["frames"] == 40


def test_each_add_changes_the_generation(path: Path) -> None:
    s = PoseStore.create(path)
    seen = {s.generation}
    for i in range(3):
        s.add(make_take(f"t{i}", 10, seed=i))
        seen.add(s.generation)
    assert len(seen) == 4


def test_same_content_is_a_no_op(store: PoseStore, path: Path) -> None:
    before_files = snapshot_files(path)
    generation, takes = store.generation, list(store.takes)
    again = make_take("renamed copy", 30, seed=1)  # same content hash as "a"
    for mirror in (False, True):
        result = store.add(again, mirror=mirror)
        assert result.duplicate_of == 1 and result.take_ids == () and result.frames_in == 30
    assert store.generation == generation and store.takes == takes
    assert snapshot_files(path) == before_files
    assert PoseStore.open(path).takes == takes


def test_take_by_id_name_and_numpy_integer(store: PoseStore) -> None:
    assert store.take(2).name == "b"
    assert store.take("2").name == "b"
    assert store.take("c").id == 3
    assert store.take(store.take_ids[-1]).name == "c"  # an np.int32 from the row arrays
    with pytest.raises(StoreError, match="no take"):
        store.take("nope")
    with pytest.raises(StoreError, match="no take"):
        store.take(99)
    store.add(make_take("a", 10, seed=9))  # a second take named "a"
    with pytest.raises(StoreError, match="2 takes"):
        store.take("a")


def test_take_poses_are_the_take_rows(store: PoseStore) -> None:
    np.testing.assert_array_equal(store.take_poses("b"), make_poses(20, 2))
    np.testing.assert_array_equal(store.take_poses(3), make_poses(25, 3))
    assert store.take_poses("a").dtype == np.float32


# -- options: mirror and min_change -----------------------------------------------------------


def test_mirror_stores_a_second_take(path: Path) -> None:
    s = PoseStore.create(path)
    take = make_take("jump", 24, seed=4)
    result = s.add(take, mirror=True)
    assert result.take_ids == (1, 2) and result.frames_kept == 24
    original, mirrored = s.take(1), s.take(2)
    assert (original.mirrored, mirrored.mirrored) == (False, True)
    assert mirrored.mirror_of == 1 and mirrored.name == "jump (mirrored)"
    assert mirrored.content_hash == original.content_hash and mirrored.first_row == 24
    np.testing.assert_array_equal(s.take_poses(1), take.poses)
    np.testing.assert_array_equal(s.take_poses(2), mirror_poses(take.poses))
    np.testing.assert_array_equal(s.frames, np.tile(np.arange(24), 2))
    assert s.stats()["mirrored_takes"] == 1
    assert s.add(take, mirror=True).duplicate_of == 1
    assert s.verify().ok


def test_removing_the_original_removes_its_mirror(path: Path) -> None:
    s = PoseStore.create(path)
    s.add(make_take("a", 10, seed=1), mirror=True)
    s.add(make_take("b", 12, seed=2), mirror=True)
    assert s.remove(["a"]) == [1, 2]
    assert [t.name for t in s.takes] == ["b", "b (mirrored)"]
    np.testing.assert_array_equal(s.take_poses("b (mirrored)"), mirror_poses(make_poses(12, 2)))
    assert s.verify().ok


def test_removing_only_the_mirror_keeps_the_original(path: Path) -> None:
    s = PoseStore.create(path)
    s.add(make_take("a", 10, seed=1), mirror=True)
    assert s.remove([2]) == [2]
    assert [t.name for t in s.takes] == ["a"]
    np.testing.assert_array_equal(s.poses, make_poses(10, 1))


def test_min_change_drops_near_duplicate_poses(path: Path) -> None:
    distinct = make_poses(10, seed=6)
    rng = np.random.default_rng(0)
    repeated = np.repeat(distinct, 3, axis=0) + rng.uniform(-1e-4, 1e-4, (30, 13, 3))
    take = Take(name="still", poses=repeated, fps=30, source="x", content_hash="h", rig="test")
    s = PoseStore.create(path)
    result = s.add(take, mirror=True, min_change=0.005)
    assert (result.frames_in, result.frames_kept) == (30, 10)
    np.testing.assert_array_equal(s.take_poses(1), take.poses[::3])
    np.testing.assert_array_equal(s.take_poses(2), mirror_poses(take.poses[::3]))
    np.testing.assert_array_equal(s.frames, np.tile(np.arange(0, 30, 3), 2))
    assert s.take(1).frame_count == 10 and s.take(1).source_frames == 30
    assert s.verify().ok


def test_drop_near_duplicates_keeps_the_first_and_moving_poses() -> None:
    poses = np.zeros((5, 13, 3), dtype=np.float32)
    poses[2:, 0, 0] = 0.1  # the head jumps 10 cm at frame 2
    poses[4, 5, 1] = 0.002  # a 2 mm twitch at frame 4
    np.testing.assert_array_equal(drop_near_duplicates(poses, 0.01), [0, 2])
    np.testing.assert_array_equal(drop_near_duplicates(poses, 0.001), [0, 2, 4])
    np.testing.assert_array_equal(drop_near_duplicates(poses, 0.0), np.arange(5))
    assert len(drop_near_duplicates(poses[:0], 0.01)) == 0


# -- labels ----------------------------------------------------------------------------------


def test_label_persists_without_changing_the_generation(store: PoseStore, path: Path) -> None:
    generation = store.generation
    assert store.index_is_fresh()
    info = store.label("b", subject="s01", action="dance", tags=["salsa", "fast", "salsa"])
    assert (info.subject, info.action, info.tags) == ("s01", "dance", ("fast", "salsa"))
    store.label(2, action="spin")  # only the action changes
    for s in (store, PoseStore.open(path)):
        info = s.take("b")
        assert (info.subject, info.action, info.tags) == ("s01", "spin", ("fast", "salsa"))
        assert s.take("a").subject == "" and s.take("a").tags == ()
        assert s.generation == generation and s.index_is_fresh()
        assert s.verify().ok


# -- removal -----------------------------------------------------------------------------------


def test_remove_compacts_the_data_files(store: PoseStore, path: Path) -> None:
    a, c = store.take_poses("a").copy(), store.take_poses("c").copy()
    generation = store.generation
    assert data_files(path) == {"poses-0.f32", "rows-0.i32"}
    assert store.remove(["b"]) == [2]
    for s in (store, PoseStore.open(path)):
        assert [(t.name, t.first_row, t.frame_count) for t in s.takes] == [
            ("a", 0, 30),
            ("c", 30, 25),
        ]
        np.testing.assert_array_equal(s.poses, np.concatenate([a, c]))
        np.testing.assert_array_equal(s.take_ids, [1] * 30 + [3] * 25)
        np.testing.assert_array_equal(s.frames, list(range(30)) + list(range(25)))
        assert s.data_name == "1" and s.generation != generation
        assert s.verify().ok and s.index_is_fresh()
    assert data_files(path) == {"poses-1.f32", "rows-1.i32"}
    assert (path / "poses-1.f32").stat().st_size == 55 * POSE_BYTES
    assert (path / "rows-1.i32").stat().st_size == 55 * ROW_BYTES
    store.add(make_take("d", 5, seed=8))  # appends to the compacted files
    np.testing.assert_array_equal(store.take_poses("d"), make_poses(5, 8))
    assert store.verify().ok


def test_remove_several_by_id_and_name(store: PoseStore) -> None:
    assert store.remove([1, "c"]) == [1, 3]
    assert [t.name for t in store.takes] == ["b"] and store.take("b").first_row == 0
    np.testing.assert_array_equal(store.poses, make_poses(20, 2))


def test_remove_everything_leaves_an_empty_store(store: PoseStore, path: Path) -> None:
    store.remove(["a", "b", "c"])
    assert len(store) == 0 and store.takes == []
    assert not (path / INDEX).exists()
    with pytest.raises(StoreError, match="no poses"):
        store.query(np.zeros((8, 3)))
    s = PoseStore.open(path)
    assert len(s) == 0 and s.verify().ok
    s.add(make_take("again", 7, seed=1))  # same content as the removed "a": no longer a duplicate
    np.testing.assert_array_equal(s.poses, make_poses(7, 1))


def test_remove_of_an_unknown_take_changes_nothing(store: PoseStore, path: Path) -> None:
    before = snapshot_files(path)
    with pytest.raises(StoreError, match="no take"):
        store.remove(["b", "nope"])
    assert snapshot_files(path) == before and len(store.takes) == 3


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


# -- stats -------------------------------------------------------------------------------------


def test_stats_counts(path: Path) -> None:
    s = PoseStore.create(path)
    s.add(make_take("a", 30, seed=1, fps=30.0), mirror=True)
    s.add(make_take("b", 24, seed=2, fps=120.0, rig="cmu"))
    stats = s.stats()
    assert stats["takes"] == 3 and stats["mirrored_takes"] == 1 and stats["poses"] == 84
    assert stats["poses_by_rig"] == {"test": 60, "cmu": 24}
    assert stats["seconds"] == round(1.0 + 1.0 + 0.2, 1)
    assert stats["bytes_on_disk"] == sum(p.stat().st_size for p in path.iterdir())
    assert stats["index_fresh"] is True and stats["generation"] == s.generation
    assert stats["path"] == str(path)


# -- the index -----------------------------------------------------------------------------------


def test_index_is_saved_on_add(path: Path) -> None:
    s = PoseStore.create(path)
    s.add(make_take("a", 30, seed=1))
    assert (path / INDEX).is_file() and s.index_is_fresh()
    loaded = PoseIndex.load(path / INDEX, s.poses)
    assert loaded is not None and loaded.generation == s.generation and len(loaded) == 30
    assert not any(p.name.startswith(".index-") for p in path.iterdir())


def test_add_without_index_leaves_it_stale_until_queried(store: PoseStore, path: Path) -> None:
    store.add(make_take("d", 10, seed=4), build_index=False)
    assert not store.index_is_fresh()
    reopened = PoseStore.open(path)
    assert reopened.verify().ok
    assert any("stale" in note for note in reopened.verify().notes)
    dist, idx = reopened.query(markers_of(reopened.take_poses("d")[3]), k=1)
    assert dist[0] < 1e-6 and idx[0] == reopened.take("d").first_row + 3
    assert reopened.index_is_fresh()  # the rebuilt index was saved


def test_reopen_loads_the_saved_index_without_rebuilding(
    store: PoseStore, path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_build(*args: object, **kwargs: object) -> PoseIndex:
        raise AssertionError("the index was rebuilt")

    monkeypatch.setattr(PoseIndex, "build", no_build)
    reopened = PoseStore.open(path)
    assert reopened.index_is_fresh()
    dist, idx = reopened.query(markers_of(reopened.poses[40]), k=2)
    assert dist[0] < 1e-6 and idx[0] == 40
    assert reopened.index.generation == reopened.generation


def _count_builds(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Patch `PoseIndex.build` to record the pose count of every build."""
    calls: list[int] = []
    original = PoseIndex.build

    def counting(poses: np.ndarray, *args: object, **kwargs: object) -> PoseIndex:
        calls.append(len(poses))
        return original(poses, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(PoseIndex, "build", counting)
    return calls


@pytest.mark.parametrize("damage", ["delete", "truncate", "garbage", "flip"])
def test_missing_or_damaged_index_is_rebuilt(
    store: PoseStore, path: Path, monkeypatch: pytest.MonkeyPatch, damage: str
) -> None:
    index = path / INDEX
    data = bytearray(index.read_bytes())
    if damage == "delete":
        index.unlink()
    elif damage == "truncate":
        index.write_bytes(data[: len(data) // 2])
    elif damage == "garbage":
        index.write_bytes(np.random.default_rng(5).bytes(len(data)))
    else:
        middle = len(data) // 2
        data[middle : middle + 16] = bytes(b ^ 0xFF for b in data[middle : middle + 16])
        index.write_bytes(bytes(data))
    calls = _count_builds(monkeypatch)
    reopened = PoseStore.open(path)
    assert not reopened.index_is_fresh()
    assert any("stale" in note for note in reopened.verify().notes)
    dist, idx = reopened.query(markers_of(reopened.poses[[5, 33, 60]]), k=1)
    np.testing.assert_array_equal(idx[:, 0], [5, 33, 60])
    assert (dist[:, 0] < 1e-6).all()
    assert calls == [75] and reopened.index_is_fresh()
    PoseStore.open(path).query(markers_of(reopened.poses[0]), k=1)
    assert calls == [75]  # the saved rebuild is used from now on


def test_index_of_another_state_with_as_many_poses_is_rebuilt(
    path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    s = PoseStore.create(path)
    s.add(make_take("a", 20, seed=1))
    old_index = (path / INDEX).read_bytes()
    s.remove(["a"])
    s.add(make_take("b", 20, seed=2))  # same pose count, other poses
    (path / INDEX).write_bytes(old_index)
    calls = _count_builds(monkeypatch)
    reopened = PoseStore.open(path)
    assert not reopened.index_is_fresh()
    dist, idx = reopened.query(markers_of(make_poses(20, 2)[7]), k=1)
    assert dist[0] < 1e-6 and idx[0] == 7 and calls == [20]


def test_a_commit_by_another_store_object_makes_the_index_stale(
    store: PoseStore, path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    other = PoseStore.open(path)
    other.add(make_take("d", 10, seed=4), build_index=False)
    store.refresh()
    assert not store.index_is_fresh() and len(store) == 85
    calls = _count_builds(monkeypatch)
    dist, idx = store.query(markers_of(store.take_poses("d")), k=1)
    np.testing.assert_array_equal(idx[:, 0], np.arange(75, 85))
    assert (dist[:, 0] < 1e-6).all() and calls == [85]
    assert store.index_is_fresh()


def test_a_stale_snapshot_keeps_its_own_index(
    store: PoseStore, path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    markers = markers_of(store.poses[[0, 74]])
    before = store.query(markers, k=3)
    other = PoseStore.open(path)
    other.add(make_take("d", 10, seed=4))  # builds and saves the index of the new state
    calls = _count_builds(monkeypatch)
    for got, want in zip(store.query(markers, k=3), before, strict=True):
        np.testing.assert_array_equal(got, want)
    store.refresh()
    assert store.index_is_fresh()
    dist, idx = store.query(markers_of(store.take_poses("d")[2]), k=1)
    assert dist[0] < 1e-6 and idx[0] == 77 and calls == []  # loaded, not rebuilt


# -- queries -------------------------------------------------------------------------------------


def test_query_finds_stored_poses_at_distance_zero(store: PoseStore) -> None:
    rows = np.arange(len(store))
    dist, idx = store.query(markers_of(store.poses), k=3)
    np.testing.assert_array_equal(idx[:, 0], rows)
    assert dist.shape == (75, 3) and (dist[:, 0] < 1e-6).all() and (dist[:, 1] > 1e-3).all()
    np.testing.assert_array_equal(store.take_ids[idx[:, 0]], [1] * 30 + [2] * 20 + [3] * 25)
    single_dist, single_idx = store.query(markers_of(store.take_poses("b")[4]), k=1)
    assert single_idx.shape == (1,) and store.take(store.take_ids[single_idx[0]]).name == "b"
    assert store.frames[single_idx[0]] == 4 and single_dist[0] < 1e-6


def test_query_on_an_empty_store_raises(path: Path) -> None:
    with pytest.raises(StoreError, match="no poses"):
        PoseStore.create(path).query(np.zeros((8, 3)))


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
    original = PoseStore._append_rows

    def append_then_fail(self: PoseStore, *args: object, **kwargs: object) -> None:
        original(self, *args, **kwargs)  # type: ignore[arg-type]
        raise OSError(28, "No space left on device (simulated)")

    monkeypatch.setattr(PoseStore, "_append_rows", append_then_fail)
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
    original = PoseStore._write_compacted

    def compact_then_fail(self: PoseStore, *args: object, **kwargs: object) -> int:
        original(self, *args, **kwargs)  # type: ignore[arg-type]
        raise OSError(5, "Input/output error (simulated)")

    monkeypatch.setattr(PoseStore, "_write_compacted", compact_then_fail)
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


# -- store objects with an older snapshot --------------------------------------------------------


def test_an_older_store_object_adds_after_another_removed(store: PoseStore, path: Path) -> None:
    other = PoseStore.open(path)
    other.remove(["a"])  # switches the data files; store's snapshot still names the old ones
    store.add(make_take("d", 10, seed=4))
    for s in (store, PoseStore.open(path)):
        assert [t.name for t in s.takes] == ["b", "c", "d"] and s.verify().ok
        np.testing.assert_array_equal(s.take_poses("d"), make_poses(10, 4))
        np.testing.assert_array_equal(s.take_poses("c"), make_poses(25, 3))


def test_an_older_store_object_removes_after_another_added(store: PoseStore, path: Path) -> None:
    other = PoseStore.open(path)
    other.add(make_take("d", 10, seed=4), mirror=True)
    store.remove(["b"])  # the takes added meanwhile must survive the compaction
    for s in (store, PoseStore.open(path)):
        assert [t.name for t in s.takes] == ["a", "c", "d", "d (mirrored)"] and s.verify().ok
        np.testing.assert_array_equal(s.take_poses("d"), make_poses(10, 4))
        np.testing.assert_array_equal(s.take_poses("d (mirrored)"), mirror_poses(make_poses(10, 4)))


def test_an_older_store_object_removes_after_another_removed(store: PoseStore, path: Path) -> None:
    other = PoseStore.open(path)
    other.remove(["a"])
    store.remove(["c"])  # rows of "b" moved meanwhile
    for s in (store, PoseStore.open(path)):
        assert [t.name for t in s.takes] == ["b"] and s.verify().ok
        np.testing.assert_array_equal(s.poses, make_poses(20, 2))
    assert data_files(path) == {"poses-2.f32", "rows-2.i32"}
    with pytest.raises(StoreError, match="removed meanwhile"):
        other.remove(["c"])


def test_imports_read_only_their_own_catalog_rows(
    path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Re-reading the whole catalog after each import made importing a folder of 2,000
    # files quadratic (109 ms per file at the end, against 8.5 ms now).
    import samba.db.store

    rows_read = []
    read_takes = samba.db.store.read_takes

    def counting(*args: object, **kwargs: object) -> list:
        takes = read_takes(*args, **kwargs)
        rows_read.append(len(takes))
        return takes

    monkeypatch.setattr(samba.db.store, "read_takes", counting)
    store = PoseStore.create(path)
    for i in range(40):
        store.add(make_take(f"t{i}", 5, seed=i), mirror=i % 2 == 0, build_index=False)
    assert sum(rows_read) == 60  # each row once: 40 takes and 20 mirrors
    assert [t.name for t in store.takes] == [t.name for t in PoseStore.open(path).takes]


def test_a_snapshot_sees_what_another_store_object_committed(store: PoseStore, path: Path) -> None:
    other = PoseStore.open(path)
    other.label("b", subject="s07")
    other.add(make_take("d", 10, seed=4))
    store.refresh()
    assert store.take("b").subject == "s07" and [t.name for t in store.takes] == list("abcd")
    store.label("d", action="jump")  # its own commit builds on the other object's
    other.refresh()
    assert other.take("d").action == "jump" and other.take("b").subject == "s07"


def test_a_tibia_scaled_store_keeps_its_setting_and_rebuilds_a_mismatched_index(
    tmp_path: Path,
) -> None:
    path = tmp_path / "scaled"
    store = PoseStore.create(path, scale_by_tibia=True)
    store.add(make_take("a", 40, seed=3))
    reopened = PoseStore.open(path)
    assert reopened.scale_by_tibia and reopened.index_is_fresh()
    assert reopened.index.scale_by_tibia and reopened.stats()["scale_by_tibia"] is True
    small = reopened.poses[7][[1, 2, 5, 6, 9, 10, 11, 12]].astype(np.float64) * 0.9
    _, rows = reopened.query(small, k=1)
    assert rows[0] == 7
    # an index saved without scaling is not taken for this store's
    PoseIndex.build(reopened.poses, generation=reopened.generation).save(path / INDEX)
    again = PoseStore.open(path)
    assert not again.index_is_fresh()
    assert again.index.scale_by_tibia
