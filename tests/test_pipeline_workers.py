"""Frames computed in worker processes: the same poses as in the event loop, the order
kept, refused files named, and a worker that dies replaced without stopping the server."""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from live_fixtures import config

from samba.base.errors import InputError
from samba.db.store import PoseStore
from samba.db.synthetic_store import build_synthetic_store
from samba.service.errors import ServiceError
from samba.service.frame_pipeline import CameraMarkers
from samba.service.pipeline_workers import FrameDone, InlinePipelines, WorkerPipelines
from samba.service.session_indexes import SessionIndexes
from samba.service.synthetic_capture import SyntheticCapture
from samba.synthetic.motions import generate


class Collected:
    """A `deliver` callable collecting `FrameDone`s from any thread."""

    def __init__(self) -> None:
        self.done: list[FrameDone] = []
        self._changed = threading.Condition()

    def __call__(self, done: FrameDone) -> None:
        with self._changed:
            self.done.append(done)
            self._changed.notify_all()

    def wait_for(self, count: int, timeout: float = 60.0) -> list[FrameDone]:
        """The first `count` deliveries; fails after `timeout` seconds."""
        with self._changed:
            assert self._changed.wait_for(lambda: len(self.done) >= count, timeout), self.done
            return self.done[:count]


def submit_all(pipelines: InlinePipelines | WorkerPipelines, capture: SyntheticCapture) -> None:
    for frame in range(capture.frames):
        pixels = CameraMarkers.from_labels(capture.pixels[:, frame])
        pipelines.submit("stage", frame, pixels, frame / 60.0, time.time())


def test_workers_give_the_poses_of_the_event_loop_in_order(
    live_store: Path, live_calibration: Path, live_capture: SyntheticCapture
) -> None:
    inline, workers = Collected(), Collected()
    local = InlinePipelines(inline)
    pool = WorkerPipelines(2, workers)
    try:
        assert pool.open(config(live_calibration, live_store), 0.0) == local.open(
            config(live_calibration, live_store), 0.0
        )
        submit_all(local, live_capture)
        submit_all(pool, live_capture)
        remote = workers.wait_for(live_capture.frames)
        assert len(pool.worker_pids()) == 1  # one session: one process started
    finally:
        pool.shutdown()
        local.shutdown()
    assert [d.sequence for d in remote] == list(range(live_capture.frames))
    here = np.array([d.output.estimate.pose for d in inline.done])
    there = np.array([d.output.estimate.pose for d in remote])
    np.testing.assert_array_equal(there, here)  # the same code, the same numbers


@pytest.mark.parametrize("workers", [0, 1], ids=["in the event loop", "in a worker process"])
def test_sessions_computed_together_get_the_poses_they_get_alone(
    live_store: Path, live_calibration: Path, live_capture: SyntheticCapture, workers: int
) -> None:
    """Three sessions on one database whose frames arrive together (one starting 10
    frames late), and a session that is not open: each open session gets, frame by frame
    and in order, the poses it gets alone; the unknown one's frames fail, named."""
    alone = Collected()
    single = InlinePipelines(alone)
    single.open(config(live_calibration, live_store), 0.0)
    submit_all(single, live_capture)
    single.shutdown()
    expected = np.array([d.output.estimate.pose for d in alone.done])

    collected = Collected()
    pool = InlinePipelines(collected) if workers == 0 else WorkerPipelines(workers, collected)
    starts = {"a": 0, "b": 0, "c": 10}
    try:
        for name in starts:
            pool.open(config(live_calibration, live_store, name=name), 0.0)
        for instant in range(live_capture.frames):
            with pool.together():
                for name, start in {**starts, "gone": 0}.items():
                    if instant >= start:
                        pixels = CameraMarkers.from_labels(live_capture.pixels[:, instant - start])
                        pool.submit(name, instant - start, pixels, instant / 60.0, time.time())
        total = 4 * live_capture.frames - 10
        done = collected.wait_for(total)
    finally:
        pool.shutdown()
    assert {d.error for d in done if d.session == "gone"} == {"the session is not open"}
    for name, start in starts.items():
        mine = [d for d in done if d.session == name]
        assert [d.sequence for d in mine] == list(range(live_capture.frames - start))
        poses = np.array([d.output.estimate.pose for d in mine])
        np.testing.assert_allclose(poses, expected[: len(poses)], rtol=0, atol=1e-9)


def test_a_frame_that_fails_alone_does_not_fail_the_frames_computed_with_it(
    live_store: Path, live_calibration: Path, live_capture: SyntheticCapture
) -> None:
    """Session a's second frame has three cameras' labels for its two cameras: that frame
    fails with the reason, b's frame computed with it and a's next frame come out."""
    collected = Collected()
    pool = InlinePipelines(collected)
    try:
        for name in "ab":
            pool.open(config(live_calibration, live_store, name=name), 0.0)
        for frame in range(3):
            pixels = live_capture.pixels[:, frame]
            broken = CameraMarkers.from_labels(np.concatenate([pixels, pixels[:1]]))
            with pool.together():
                for name in "ab":
                    bad = name == "a" and frame == 1
                    values = broken if bad else CameraMarkers.from_labels(pixels)
                    pool.submit(name, frame, values, frame / 60.0, time.time())
        done = collected.wait_for(6)
    finally:
        pool.shutdown()
    failed = [(d.session, d.sequence) for d in done if d.error is not None]
    assert failed == [("a", 1)]
    assert "ValueError" in next(d.error for d in done if d.error is not None)
    assert sum(d.output is not None for d in done) == 5


def test_sessions_share_the_index_of_one_database_snapshot(tmp_path: Path) -> None:
    """One loaded index per store snapshot and kind: a second session on the same store
    gets the same one, the mirrored kind another, and a store changed since a new one."""
    path = tmp_path / "db"
    build_synthetic_store(path, takes_per_motion=1, seconds=1.0, seed=3)
    indexes = SessionIndexes()
    first = indexes.index(path, mirrored=False)
    assert indexes.index(path, mirrored=False) is first
    mirrored = indexes.index(path, mirrored=True)
    assert mirrored is not first and len(mirrored.poses) == 2 * len(first.poses)
    PoseStore.open(path).add(generate("wave", seconds=1.0, seed=77))
    changed = indexes.index(path, mirrored=False)
    assert changed is not first and len(changed.poses) > len(first.poses)


def test_sessions_spread_over_the_workers_and_a_bad_file_is_named(
    live_store: Path, live_calibration: Path, tmp_path: Path
) -> None:
    pool = WorkerPipelines(2, Collected())
    try:
        for name in ("a", "b", "c"):
            pool.open(config(live_calibration, live_store, name=name), 0.0)
        assert len(pool.worker_pids()) == 2
        broken = tmp_path / "broken.toml"
        broken.write_text("[cam_0]\nname = ")
        with pytest.raises(ServiceError) as raised:
            pool.open(config(broken, live_store, name="d"), 0.0)
        assert str(broken) in str(raised.value)
        with pytest.raises(InputError, match="no-such-store"):
            pool.open(config(live_calibration, tmp_path / "no-such-store", name="e"), 0.0)
    finally:
        pids = pool.worker_pids()
        pool.shutdown()
    assert not any(Path(f"/proc/{pid}").exists() for pid in pids)


@pytest.mark.slow
def test_a_worker_that_dies_is_replaced_and_its_session_goes_on(
    live_store: Path, live_calibration: Path, live_capture: SyntheticCapture
) -> None:
    collected = Collected()
    pool = WorkerPipelines(1, collected)
    try:
        pool.open(config(live_calibration, live_store), 0.0)
        first = pool.worker_pids()
        pool.submit(
            "stage", 0, CameraMarkers.from_labels(live_capture.pixels[:, 0]), 0.0, time.time()
        )
        os.kill(first[0], signal.SIGKILL)
        deadline = time.time() + 60
        while pool.restarts == 0:
            assert time.time() < deadline, "no new worker"
            time.sleep(0.05)
        assert pool.worker_pids() != first
        submit_all(pool, live_capture)
        done = collected.wait_for(1 + live_capture.frames)
    finally:
        pool.shutdown()
    # frame 0 was computed before the kill, or reported lost with the reason
    assert done[0].output is not None or "exited with code -9" in (done[0].error or "")
    after = done[1:]
    assert all(d.output is not None for d in after), [d.error for d in after if d.error][:3]
