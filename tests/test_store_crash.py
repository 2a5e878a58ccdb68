"""Crash safety and snapshot isolation of the pose store, with real writer processes.

A writer subprocess (`tests/store_writer.py`) imports takes, or imports and removes them,
while the test SIGKILLs it at random moments, or it kills itself at chosen points of a
write. After every kill the store must open and verify at a state of the writer's plan,
never behind the state seen before, with every take holding exactly its own poses, and
the test process must be able to import into it. A reader that opened the store before
a writer ran keeps its snapshot until it refreshes.
"""

from __future__ import annotations

import functools
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from store_writer import (
    apply,
    is_mirrored,
    plan,
    plan_states,
    plan_step,
    probe_take,
    take_number,
    writer_take,
)

from samba.body.skeleton import markers_of, mirror_poses
from samba.db.index import PoseIndex
from samba.db.pose_files import POSE_BYTES, ROW_BYTES
from samba.db.store import INDEX, PoseStore

pytestmark = pytest.mark.slow  # benchmark-like or end to end: CI runs it

ROOT = Path(__file__).resolve().parents[1]
WRITER = Path(__file__).with_name("store_writer.py")
TIMEOUT = 120.0
"""Seconds a writer may take to start or finish on a loaded machine; never a pass/fail time."""


@functools.cache
def states_of(mode: str) -> list[frozenset[int]]:
    """The writer takes present after each prefix of the plan of `mode`."""
    return plan_states(plan(mode))


def start_writer(path: Path, mode: str, *options: str) -> subprocess.Popen[str]:
    """Start `store_writer.py` on the store at `path`."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return subprocess.Popen(
        [sys.executable, str(WRITER), str(path), mode, *options],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=ROOT,
    )


def read_line(proc: subprocess.Popen[str]) -> str:
    """The next line the writer prints; fails with its stderr if it prints none."""
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], TIMEOUT)
    line = proc.stdout.readline() if ready else ""
    if not line:
        proc.kill()
        _, err = proc.communicate(timeout=TIMEOUT)
        raise AssertionError(f"the writer printed nothing (exit {proc.returncode}):\n{err}")
    return line


def kill(proc: subprocess.Popen[str]) -> None:
    """SIGKILL the writer and reap it; it must not have ended any other way."""
    proc.send_signal(signal.SIGKILL)
    _, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == -signal.SIGKILL, f"writer ended with {proc.returncode}:\n{err}"


def finish(proc: subprocess.Popen[str]) -> str:
    """Wait for the writer to end by itself, successfully; returns what it printed."""
    out, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0, f"writer ended with {proc.returncode}:\n{err}"
    return out


def check_store(path: Path, mode: str, probes: int) -> tuple[PoseStore, int]:
    """Open and check the store after a writer ended; returns it and its step in the plan.

    The store must verify; its writer takes must be a state of the plan, with the mirrors
    the plan asks for; every take must hold exactly its own poses, rows and frame numbers;
    the `probes` takes imported by the test must all be there; stored poses must be found
    by a query of their markers.
    """
    store = PoseStore.open(path)
    report = store.verify()
    assert report.ok, report.problems
    step = plan_step(store, states_of(mode))
    held = states_of(mode)[step]
    ids = {t.name: t.id for t in store.takes}
    mirrors, probe_names = set(), set()
    for t in store.takes:
        if t.name.startswith("probe-"):
            expected = probe_take(int(t.name.removeprefix("probe-"))).poses
            probe_names.add(t.name)
        else:
            i = take_number(t.name)
            expected = writer_take(i).poses
            if t.mirrored:
                expected = mirror_poses(expected)
                mirrors.add(i)
                assert t.mirror_of == ids[writer_take(i).name]
        np.testing.assert_array_equal(store.take_poses(t.id), expected, err_msg=t.name)
        assert (store.take_ids[t.rows.start : t.rows.stop] == t.id).all(), t.name
        np.testing.assert_array_equal(
            store.frames[t.rows.start : t.rows.stop], np.arange(len(t.rows))
        )
    assert mirrors == {i for i in held if is_mirrored(i)}
    assert probe_names == {f"probe-{k}" for k in range(probes)}
    if len(store):
        rows = np.unique([0, len(store) // 2, len(store) - 1])
        dist, idx = store.query(markers_of(store.poses[rows]), k=1)
        np.testing.assert_array_equal(idx[:, 0], rows)
        assert (dist[:, 0] < 1e-6).all()
    return store, step


def import_probe(store: PoseStore, k: int) -> None:
    """Import probe take k in the test process and check it went in whole."""
    before = len(store)
    result = store.add(probe_take(k))
    assert len(result.take_ids) == 1
    np.testing.assert_array_equal(store.take_poses(f"probe-{k}"), probe_take(k).poses)
    assert len(store) == before + len(probe_take(k))
    assert store.verify().ok and store.index_is_fresh()


@pytest.mark.parametrize(("mode", "kills", "seed"), [("import", 8, 1), ("mixed", 7, 2)])
def test_a_writer_killed_at_random_moments_leaves_a_plan_state(
    tmp_path: Path, mode: str, kills: int, seed: int
) -> None:
    path = tmp_path / "store"
    PoseStore.create(path)
    rng = np.random.default_rng(seed)
    last = 0
    for k in range(kills):
        proc = start_writer(path, mode)
        if k % 4 == 0:  # very early: most likely before the writer has even opened the store
            time.sleep(rng.uniform(0.0, 0.3))
        else:
            assert read_line(proc).split() == ["ready", str(last)]
            time.sleep(rng.uniform(0.0, 0.3))
        kill(proc)
        store, step = check_store(path, mode, probes=k)
        assert step >= last, f"kill {k}: the store went back from step {last} to {step}"
        last = step
        import_probe(store, k)
    out = finish(start_writer(path, mode, "--max-ops", "4"))
    assert out.split() == ["ready", str(last), "done", str(last + 4)]
    assert check_store(path, mode, probes=kills)[1] == last + 4


@pytest.mark.parametrize(
    ("point", "prefix", "commits"),
    [
        ("append", 6, False),  # ops[6] adds take 4: rows written, then killed before commit
        ("compact", 5, False),  # ops[5] removes take 2: new files written, killed before commit
        ("index", 6, True),  # ops[6] adds take 4: committed, killed before the index build
        ("save", 5, True),  # ops[5] removes take 2: committed, killed while saving the index
    ],
)
def test_a_writer_killed_at_each_point_of_a_write(
    tmp_path: Path, point: str, prefix: int, commits: bool
) -> None:
    path = tmp_path / "store"
    store = PoseStore.create(path)
    for op in plan("mixed")[:prefix]:
        apply(store, op)
    poses, takes, generation = np.array(store.poses), list(store.takes), store.generation
    data_name = store.data_name

    proc = start_writer(path, "mixed", "--die-at", point)
    _, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == -signal.SIGKILL, f"writer ended with {proc.returncode}:\n{err}"

    names = {p.name for p in path.iterdir()}
    index_fresh = PoseStore.open(path).index_is_fresh()  # before a query rebuilds it
    store, step = check_store(path, "mixed", probes=0)
    assert step == prefix + commits
    if not commits:
        assert store.takes == takes and store.generation == generation
        np.testing.assert_array_equal(store.poses, poses)
    n = len(store)
    if point == "append":
        assert (path / f"poses-{data_name}.f32").stat().st_size > n * POSE_BYTES
        assert (path / f"rows-{data_name}.i32").stat().st_size > n * ROW_BYTES
    elif point == "compact":
        assert f"poses-{int(data_name) + 1}.f32" in names
    else:
        assert not index_fresh
        assert (point == "save") == any(name.startswith(".index-") for name in names)
    assert store.index_is_fresh()  # the query in check_store rebuilt and saved it

    import_probe(store, 0)  # the next writer cuts garbage off and removes orphans
    n = len(store)
    assert sorted(p.name for p in path.iterdir()) == sorted(
        [
            "catalog.sqlite",
            INDEX,
            "lock",
            f"poses-{store.data_name}.f32",
            f"rows-{store.data_name}.i32",
        ]
    )
    assert (path / f"poses-{store.data_name}.f32").stat().st_size == n * POSE_BYTES
    assert (path / f"rows-{store.data_name}.i32").stat().st_size == n * ROW_BYTES

    out = finish(start_writer(path, "mixed", "--max-ops", "3"))
    assert out.split() == ["ready", str(step), "done", str(step + 3)]
    assert check_store(path, "mixed", probes=1)[1] == step + 3


def test_a_reader_keeps_its_snapshot_while_a_writer_imports_and_removes(tmp_path: Path) -> None:
    path = tmp_path / "store"
    setup = PoseStore.create(path)
    ops = plan("mixed")
    for op in ops[:7]:
        apply(setup, op)
    start = 7

    reader = PoseStore.open(path)
    rng = np.random.default_rng(3)
    rows = rng.choice(len(reader), 20, replace=False)
    markers = markers_of(reader.poses[rows].astype(np.float64)) + rng.normal(0, 0.01, (20, 8, 3))
    dist0, idx0 = reader.query(markers, k=5)  # loads the saved index
    poses0, ids0, frames0 = (
        np.array(reader.poses),
        np.array(reader.take_ids),
        np.array(reader.frames),
    )
    takes0, generation0, data_name0 = list(reader.takes), reader.generation, reader.data_name
    take_4 = np.array(reader.take_poses("take-0004"))  # removed by the writer below
    unqueried = PoseStore.open(path)  # loads its index only after the writer is done

    def assert_snapshot(s: PoseStore) -> None:
        """`s` still shows exactly what was committed when the test opened it."""
        np.testing.assert_array_equal(s.poses, poses0)
        np.testing.assert_array_equal(s.take_ids, ids0)
        np.testing.assert_array_equal(s.frames, frames0)
        assert s.takes == takes0 and s.generation == generation0
        np.testing.assert_array_equal(s.take_poses("take-0004"), take_4)

    proc = start_writer(path, "mixed", "--max-ops", "30")
    seen = start
    while proc.poll() is None:
        assert_snapshot(reader)
        dist, idx = reader.query(markers, k=5)
        np.testing.assert_array_equal(idx, idx0)
        np.testing.assert_array_equal(dist, dist0)
        # a reader opened meanwhile sees a whole committed state, never an older one
        middle = PoseStore.open(path)
        step = plan_step(middle, states_of("mixed"))
        assert seen <= step <= start + 30
        seen = step
        assert middle.verify().ok
        pick = np.array([0, len(middle) - 1])
        _, found = middle.query(markers_of(middle.poses[pick]), k=1)
        np.testing.assert_array_equal(found[:, 0], pick)
        time.sleep(0.02)
    out = finish(proc)
    assert out.split() == ["ready", str(start), "done", str(start + 30)]

    fresh, step = check_store(path, "mixed", probes=0)
    assert step == start + 30
    assert fresh.data_name != data_name0 and not (path / f"poses-{data_name0}.f32").exists()
    assert_snapshot(reader)
    for got, want in zip(reader.query(markers, k=5), (dist0, idx0), strict=True):
        np.testing.assert_array_equal(got, want)

    assert_snapshot(unqueried)
    index_was_fresh = fresh.index_is_fresh()
    expected = PoseIndex.build(poses0).query(markers, k=5)
    dist, idx = unqueried.query(markers, k=5)  # the saved index is the writer's: rebuilt
    np.testing.assert_array_equal(idx, expected[1])
    np.testing.assert_allclose(dist, expected[0], rtol=0, atol=1e-12)
    assert unqueried.index.generation == generation0
    assert fresh.index_is_fresh() == index_was_fresh  # the old snapshot's index is not saved

    reader.refresh()
    assert reader.takes == fresh.takes and reader.generation == fresh.generation
    np.testing.assert_array_equal(reader.poses, fresh.poses)
    np.testing.assert_array_equal(reader.take_ids, fresh.take_ids)
    newest = reader.takes[-1]
    dist, idx = reader.query(markers_of(reader.take_poses(newest.id)[0]), k=1)
    assert idx[0] == newest.first_row and dist[0] < 1e-6
