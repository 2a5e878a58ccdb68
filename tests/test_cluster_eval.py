"""`samba eval --workers N | --cluster ADDRESS` (Dask distributed): one task per test
take on a `LocalCluster(n_workers=2, processes=True)` gives the errors of the serial
evaluation, take by take, bit for bit."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import samba.base.cluster as cluster_module
from samba.base import InputError, cluster_client
from samba.cli import main
from samba.db import PoseIndex
from samba.evaluation import evaluate
from samba.ingest import load_bvh_take
from samba.reconstruct import method

TAKES = ("iclone_002_01", "iclone_002_02", "iclone_002_03", "iclone_002_04")
"""Four short real CMU takes: leave-one-take-out over them."""
FRAMES = 40
"""Frames of each test take evaluated."""


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    """A Dask client of a local cluster of two worker processes, shared by the module."""
    with cluster_client(workers=2) as dask_client:
        yield dask_client


@pytest.fixture(scope="module")
def takes(cmu_dir: Path) -> list[tuple[str, np.ndarray]]:
    """The takes of `TAKES` in memory at 30 fps."""
    return [(name, load_bvh_take(cmu_dir / f"{name}.bvh").poses) for name in TAKES]


def test_cluster_evaluation_gives_the_serial_errors_take_by_take(
    client: Any, takes: list[tuple[str, np.ndarray]]
) -> None:
    runs = {name: method(name) for name in ("nn", "samba")}
    test = [(name, poses[:FRAMES]) for name, poses in takes]
    serial = evaluate(takes, test, runs, PoseIndex.build, seed=3, dropout=0.1)
    spread = evaluate(takes, test, runs, PoseIndex.build, seed=3, dropout=0.1, client=client)
    assert spread.left_out == serial.left_out == TAKES
    for label in runs:
        assert [r.name for r in spread.results[label]] == list(TAKES)
        for mine, theirs in zip(spread.results[label], serial.results[label], strict=True):
            assert np.array_equal(mine.errors, theirs.errors)
            assert np.array_equal(mine.poses, theirs.poses)
    per_take = {label: s["per_take_cm"] for label, s in spread.summaries.items()}
    assert per_take == {label: s["per_take_cm"] for label, s in serial.summaries.items()}


def test_a_task_error_on_a_worker_reaches_the_caller_as_raised(
    client: Any, takes: list[tuple[str, np.ndarray]]
) -> None:
    runs = {"samba": method("samba").with_sizes(10_000, None)}  # K beyond the database
    with pytest.raises(InputError, match="K = 10000 exceeds the"):
        evaluate(takes[:2], takes[:1], runs, PoseIndex.build, client=client)


def test_samba_eval_with_workers_prints_the_per_take_table(
    cmu_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    files = [str(cmu_dir / f"{name}.bvh") for name in TAKES[:2]]
    argv = ["eval", "--train", *files, "--test", *files, "--methods", "nn"]
    code = main([*argv, "--max-frames", "20", "--workers", "2"])
    out = capsys.readouterr().out
    assert code == 0
    assert "leave-one-take-out" in out and all(name in out for name in TAKES[:2])


def test_samba_eval_without_a_scheduler_is_one_line(
    cmu_dir: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(cluster_module, "CONNECT_SECONDS", 1.0)
    files = [str(cmu_dir / f"{name}.bvh") for name in TAKES[:2]]
    argv = ["eval", "--train", *files, "--test", *files, "--methods", "nn"]
    code = main([*argv, "--cluster", "tcp://127.0.0.1:9"])
    err = capsys.readouterr().err
    assert code == 1
    assert err.strip().splitlines() == [
        "samba: error: --cluster tcp://127.0.0.1:9: no Dask scheduler answers there "
        "(Timed out trying to connect to tcp://127.0.0.1:9 after 1 s)"
    ]
