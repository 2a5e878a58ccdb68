"""The pose store: create/open, import, duplicates, mirroring, near-duplicate dropping,
labels, removal with compaction, the saved k-d tree index, queries and older snapshots
(damage and failed writes: test_store_damage.py)."""

from __future__ import annotations

import hashlib
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest
from store_fixtures import data_files, make_poses, make_take, snapshot_files

from samba.body.skeleton import markers_of, mirror_poses
from samba.body.take import Take
from samba.db.errors import StoreError
from samba.db.index import PoseIndex
from samba.db.pose_files import POSE_BYTES, ROW_BYTES
from samba.db.store import CATALOG, INDEX, PoseStore, drop_near_duplicates

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
    assert store.take("#2").name == "b"
    assert store.take("c").id == 3
    assert store.take(store.take_ids[-1]).name == "c"  # an np.int32 from the row arrays
    with pytest.raises(StoreError, match="no take named 'nope'"):
        store.take("nope")
    with pytest.raises(StoreError, match="no take with id #99"):
        store.take(99)
    store.add(make_take("a", 10, seed=9))  # a second take named "a"
    with pytest.raises(StoreError, match=r"2 takes are named 'a' \(#1, #4\): name one by its id"):
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
