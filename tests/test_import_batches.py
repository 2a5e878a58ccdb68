"""Group commits of `samba db import` (`samba.ingest.import_paths` over
`PoseStore.add_many`): one commit per group of files, per-file results and duplicates
as file by file, and a crash between a group's data append and its catalog commit leaves
the store at its previous state, of whole files only."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from bvh_fixtures import humanoid_bvh

import samba.db.store as store_module
from samba.db.pose_files import POSE_BYTES
from samba.db.store import PoseStore
from samba.ingest import import_paths, load_bvh_take
from samba.ingest.batch import READERS, ImportInterrupted, read_file

ROOT = Path(__file__).resolve().parents[1]
TIMEOUT = 120.0
"""Seconds the import subprocess may take on a loaded machine; never a pass/fail time."""

DIE_AT_SECOND_COMMIT = """
import os, signal, sys
import samba.db.store as store_module
from samba.db import PoseStore
from samba.ingest import import_paths

appended = 0
append_rows = store_module.append_rows


def append_then_die(*args):
    global appended
    append_rows(*args)
    appended += 1
    if appended == 2:  # the second group's rows are written and fsynced, not committed
        os.kill(os.getpid(), signal.SIGKILL)


store_module.append_rows = append_then_die
store = PoseStore.open(sys.argv[1])
import_paths(store, sys.argv[2:], progress=False, commit_files=2, commit_seconds=3600.0)
"""
"""An import that SIGKILLs itself inside its second group commit."""


@pytest.fixture
def empty(tmp_path: Path) -> PoseStore:
    """A new, empty store."""
    return PoseStore.create(tmp_path / "store")


@pytest.fixture
def bvh_files(tmp_path: Path) -> list[Path]:
    """Five small BVH files of different content."""
    folder = tmp_path / "bvh"
    folder.mkdir()
    files = []
    for seed in range(5):
        path = folder / f"walk_{seed}.bvh"
        path.write_text(humanoid_bvh(frames=12, seed=seed))
        files.append(path)
    return files


def count_commits(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """A list that grows by the number of takes appended at each data append (one per
    commit that adds poses)."""
    commits: list[int] = []
    append_rows = store_module.append_rows

    def counted(store: Path, name: str, n: int, blocks: list) -> None:
        commits.append(len(blocks))
        append_rows(store, name, n, blocks)

    monkeypatch.setattr(store_module, "append_rows", counted)
    return commits


def assert_whole_files(store: PoseStore, files: list[Path]) -> None:
    """Every take of `store` holds exactly the poses of its file, and the store verifies."""
    by_name = {f.stem: f for f in files}
    for take in store.takes:
        want = load_bvh_take(by_name[take.name]).poses.astype(np.float32)
        np.testing.assert_array_equal(store.take_poses(take.id), want, err_msg=take.name)
    assert store.verify().ok


def test_files_are_committed_in_groups_of_commit_files(
    empty: PoseStore, bvh_files: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    commits = count_commits(monkeypatch)
    results = import_paths(empty, bvh_files, progress=False, commit_files=2)
    assert [r.status for r in results] == ["added"] * 5
    assert commits == [2, 2, 1]
    assert [t.name for t in empty.takes] == [f.stem for f in bvh_files]
    assert [r.take_ids for r in results] == [(t.id,) for t in empty.takes]
    assert_whole_files(empty, bvh_files)
    assert empty.index_is_fresh()


def test_a_group_waits_no_longer_than_commit_seconds(
    empty: PoseStore, bvh_files: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    commits = count_commits(monkeypatch)
    import_paths(empty, bvh_files, progress=False, commit_seconds=0.0)
    assert commits == [1] * 5


def test_a_duplicate_in_the_same_group_is_reported_as_one(
    empty: PoseStore, bvh_files: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    copy = tmp_path / "copy_of_walk_1.bvh"
    copy.write_bytes(bvh_files[1].read_bytes())
    commits = count_commits(monkeypatch)
    results = import_paths(empty, [*bvh_files[:3], copy], progress=False)
    assert commits == [3]  # one group; the copy adds nothing
    assert [r.status for r in results] == ["added", "added", "added", "duplicate"]
    assert results[3].take_ids == results[1].take_ids
    assert results[3].frames_in == results[1].frames_in
    assert len(empty.takes) == 3


def test_a_group_of_duplicates_only_commits_nothing(
    empty: PoseStore, bvh_files: list[Path]
) -> None:
    import_paths(empty, bvh_files[:2], progress=False)
    generation, takes = empty.generation, list(empty.takes)
    results = import_paths(empty, bvh_files[:2], progress=False)
    assert [r.status for r in results] == ["duplicate", "duplicate"]
    assert [r.take_ids for r in results] == [(t.id,) for t in takes]
    assert empty.generation == generation and empty.index_is_fresh()


def test_a_bad_file_fails_alone_within_its_group(
    empty: PoseStore, bvh_files: list[Path], tmp_path: Path
) -> None:
    bad = tmp_path / "bad.bvh"
    bad.write_text(humanoid_bvh(frames=12, seed=9).replace("MOTION", "MOTON"))
    results = import_paths(empty, [bvh_files[0], bad, bvh_files[1]], progress=False)
    assert [r.status for r in results] == ["added", "failed", "added"]
    assert "expected ROOT or MOTION" in results[1].error
    assert len(empty.takes) == 2


def test_a_crash_inside_a_group_commit_leaves_the_previous_groups_whole(
    path: Path, bvh_files: list[Path]
) -> None:
    PoseStore.create(path)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    proc = subprocess.run(
        [sys.executable, "-c", DIE_AT_SECOND_COMMIT, str(path), *map(str, bvh_files)],
        capture_output=True,
        text=True,
        env=env,
        timeout=TIMEOUT,
    )
    assert proc.returncode == -signal.SIGKILL, proc.stderr

    store = PoseStore.open(path)
    assert [t.name for t in store.takes] == [f.stem for f in bvh_files[:2]]  # the first group
    assert_whole_files(store, bvh_files)
    written = (path / f"poses-{store.data_name}.f32").stat().st_size
    assert written > len(store) * POSE_BYTES  # the second group's rows, never committed

    results = import_paths(store, bvh_files, progress=False, commit_files=2)
    assert [r.status for r in results] == ["duplicate"] * 2 + ["added"] * 3
    assert [t.name for t in store.takes] == [f.stem for f in bvh_files]
    assert_whole_files(store, bvh_files)
    assert (path / f"poses-{store.data_name}.f32").stat().st_size == len(store) * POSE_BYTES


def test_files_read_ahead_in_threads_are_committed_in_file_order(
    empty: PoseStore, bvh_files: list[Path]
) -> None:
    second_read = threading.Event()

    def first_waits_for_second(path: Path, options: object) -> object:
        if path == bvh_files[0]:  # finishes only after a later file was read
            assert second_read.wait(60.0), "the second file was not read beside the first"
        take = read_file(path, None)
        if path == bvh_files[1]:
            second_read.set()
        return take

    results = import_paths(
        empty, bvh_files, progress=False, commit_files=2, read=first_waits_for_second
    )
    assert [r.status for r in results] == ["added"] * 5
    assert [t.name for t in empty.takes] == [f.stem for f in bvh_files]
    assert_whole_files(empty, bvh_files)


def test_ctrl_c_while_files_are_read_ahead_starts_no_more_files(
    empty: PoseStore, tmp_path: Path
) -> None:
    files = []
    for seed in range(40):
        path = tmp_path / f"take_{seed:02d}.bvh"
        path.write_text(humanoid_bvh(frames=6, seed=seed))
        files.append(path)
    started: list[Path] = []

    def interrupted_at_third(path: Path, options: object) -> object:
        started.append(path)
        if path == files[2]:
            raise KeyboardInterrupt
        return read_file(path, None)

    with pytest.raises(ImportInterrupted) as caught:
        import_paths(empty, files, progress=False, commit_files=1, read=interrupted_at_third)
    assert [r.status for r in caught.value.done] == ["added", "added"]
    assert len(started) <= 3 + 2 * READERS  # the files queued when Ctrl-C came are dropped
    count = len(started)
    time.sleep(0.2)
    assert len(started) == count  # and no reader goes on
    assert [t.name for t in empty.takes] == [f.stem for f in files[:2]]
