"""`samba db import --workers N | --cluster ADDRESS` (Dask distributed): files read on the
workers of a `LocalCluster(n_workers=2, processes=True)`, committed by the client in file
order. The store ends as a serial import leaves it, bit for bit; a worker killed
mid-import leaves a sound store and the file reported; wrong cluster flags are one line."""

from __future__ import annotations

from collections.abc import Iterator
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cluster_fixtures import read_or_die
from distributed import LocalCluster

import samba.base.cluster as cluster_module
from samba.base import InputError, cluster_client
from samba.cli import main
from samba.db import PoseStore
from samba.ingest import import_paths

SMALL_TAKES = ("iclone_002_01", "iclone_002_02", "iclone_002_03", "iclone_002_04", "cgspeed_131_01")
"""Five small real CMU takes of two rigs (a few seconds each to read)."""


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    """A Dask client of a local cluster of two worker processes, shared by the module."""
    with cluster_client(workers=2) as dask_client:
        yield dask_client


@pytest.fixture(scope="module")
def small_files(cmu_dir: Path) -> list[Path]:
    """The real files of `SMALL_TAKES`, in that order."""
    return [cmu_dir / f"{name}.bvh" for name in SMALL_TAKES]


def stored(path: Path) -> tuple[list[tuple[object, ...]], np.ndarray, np.ndarray, np.ndarray]:
    """What a store holds, to compare stores: each take's catalog row but its import
    time, and the pose, take-id and frame arrays."""
    store = PoseStore.open(path)
    rows = [
        (t.id, t.name, t.content_hash, t.first_row, t.frame_count, t.checksum, t.mirror_of)
        for t in store.takes
    ]
    return rows, np.asarray(store.poses), np.asarray(store.take_ids), np.asarray(store.frames)


def test_cluster_import_stores_what_a_serial_import_stores(
    client: Any, small_files: list[Path], tmp_path: Path
) -> None:
    files = [*small_files, small_files[1], tmp_path / "missing.bvh"]  # a duplicate, a bad path
    serial = PoseStore.create(tmp_path / "serial")
    on_cluster = PoseStore.create(tmp_path / "cluster")
    expected = import_paths(serial, files, mirror=True, progress=False)
    results = import_paths(on_cluster, files, mirror=True, progress=False, client=client)
    assert [(r.path, r.status, r.take_ids, r.frames_kept) for r in results] == [
        (r.path, r.status, r.take_ids, r.frames_kept) for r in expected
    ]
    assert [r.status for r in results[-2:]] == ["duplicate", "failed"]
    rows, poses, take_ids, frames = stored(tmp_path / "cluster")
    serial_rows, serial_poses, serial_ids, serial_frames = stored(tmp_path / "serial")
    assert rows == serial_rows
    assert poses.tobytes() == serial_poses.tobytes()
    assert np.array_equal(take_ids, serial_ids) and np.array_equal(frames, serial_frames)
    assert PoseStore.open(tmp_path / "cluster").verify().ok


@pytest.mark.slow
@pytest.mark.timeout(300)  # a cluster that lost its workers waits for them: fail instead
def test_a_worker_killed_mid_import_leaves_a_sound_store_and_the_file_reported(
    client: Any, small_files: list[Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(cluster_module, "TASKS_PER_WORKER", 1)  # 2 tasks: files 1-3, 0 and 4
    always, once = small_files[1].name, small_files[3].name  # in one task, with file 2
    read = partial(read_or_die, always=always, once=once, marks=tmp_path)
    store = PoseStore.create(tmp_path / "store")
    results = import_paths(store, small_files, progress=False, client=client, read=read)
    status = {Path(r.path).name: r for r in results}
    assert status[always].status == "failed"
    assert "died each time it was tried" in status[always].error
    assert status[once].status == "added"  # retried on another worker
    assert status[small_files[2].name].status == "added"  # in the killers' task, read alone
    assert (tmp_path / once).exists()  # it did die once
    assert [r.status for r in results].count("added") == len(small_files) - 1
    reopened = PoseStore.open(tmp_path / "store")
    assert reopened.verify().ok
    assert sorted(t.name for t in reopened.takes) == sorted(
        f.stem for f in small_files if f.name != always
    )


def test_items_go_in_groups_of_similar_cost_window_by_window_the_costliest_first() -> None:
    costs = [5.0, 1.0, 1.0, 1.0, 4.0, 2.0, 2.0, 3.0, 1.0, 9.0]  # windows of 2 groups of 3
    groups = cluster_module._groups(costs, most=3, per_window=2)
    assert groups == [[0, 1, 2], [3, 4, 5], [9], [6, 7, 8]]  # sums 7, 7 | 9, 6
    assert cluster_module._groups([1.0] * 3, most=1, per_window=4) == [[0], [1], [2]]


def test_samba_db_import_with_workers_adds_the_files(
    small_files: list[Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = tmp_path / "store"
    PoseStore.create(store)
    paths = [str(f) for f in small_files[:2]]
    code = main(["db", "import", str(store), *paths, "--workers", "2", "--no-progress"])
    assert code == 0
    assert "2 added, 0 already stored, 0 failed" in capsys.readouterr().out
    assert [t.name for t in PoseStore.open(store).takes] == list(SMALL_TAKES[:2])


@pytest.mark.parametrize(
    ("flags", "code", "says"),
    [
        (["--workers", "0"], 2, "argument --workers: must be >= 1, got 0"),
        (["--workers", "2", "--cluster", "tcp://127.0.0.1:9"], 2, "not allowed with argument"),
        (["--cluster", "tcp://127.0.0.1:9"], 1, "--cluster tcp://127.0.0.1:9: no Dask scheduler"),
        (["--cluster", "no-port"], 1, "--cluster no-port: no Dask scheduler answers there"),
    ],
)
def test_wrong_cluster_flags_are_one_line_and_the_store_keeps_its_takes(
    flags: list[str],
    code: int,
    says: str,
    small_files: list[Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(cluster_module, "CONNECT_SECONDS", 1.0)
    store = tmp_path / "store"
    import_paths(PoseStore.create(store), small_files[:1], progress=False)
    before = stored(store)
    try:
        returned = main(["db", "import", str(store), str(small_files[2]), *flags])
    except SystemExit as exit_:
        returned = exit_.code
    err = capsys.readouterr().err
    assert returned == code
    last = err.strip().splitlines()[-1]
    assert says in last and "Traceback" not in err
    assert stored(store)[0] == before[0]


def test_a_scheduler_without_workers_is_one_line(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(cluster_module, "CONNECT_SECONDS", 1.0)
    with LocalCluster(n_workers=0, processes=False, dashboard_address=":0") as empty:
        address = empty.scheduler_address
        with pytest.raises(InputError) as caught, cluster_client(address=address):
            pass
    assert str(caught.value) == (
        f"--cluster {address}: the scheduler has no worker; start some: dask worker {address}"
    )
