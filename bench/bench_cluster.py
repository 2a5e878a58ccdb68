"""Dask cluster benchmark (issue 43): `samba db import` of the shared CMU files and a
leave-one-take-out evaluation over them, in this process and on local clusters of 1 and
2 worker processes; then the costs that would stop a 100-worker cluster scaling.

Run from the project root:  python bench/bench_cluster.py [--repeats 3] [--eval-takes 16]
(`--files 4 --eval-takes 2 --eval-frames 30 --empty-tasks 20 --repeats 1`: a quick run
that only shows the benchmark works, as its test does)

Needs the shared CMU data (../shared/data or $SAMBA_DATA) and the cluster extra. The
baseline of both tables is the same job in this process, in the same run; the speed-up
that matters is 2 workers over 1 (the 2-core target is 1.6x). Every job is timed
`--repeats` times, the configurations alternating round by round, and the best time
kept (the first round also loads each process's compiled kernels). An import opens an
empty store made beforehand, as `samba db import` opens the store `samba db init` made
(until 2026-12-05 the timed import also created its store: 65-130 ms on this machine,
serial work on top of every configuration). Starting a cluster is timed apart: a
long-lived cluster pays it once. The load average is printed before and
after, since other work on the machine slows the workers and not the baseline alone.

The limits, each measured alone: the single writer's commit rate (`PoseStore.add_many`
of takes already read), the transfer of the training takes to every worker, and the
scheduler's cost per task (empty tasks on 2 workers).
"""

from __future__ import annotations

import argparse
import os
import pickle
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from text_table import print_table  # noqa: E402

from samba.base import cluster_client  # noqa: E402
from samba.db import PoseIndex, PoseStore  # noqa: E402
from samba.evaluation import evaluate  # noqa: E402
from samba.ingest import import_paths, read_file  # noqa: E402
from samba.reconstruct import method  # noqa: E402


def data_dir() -> Path:
    """The shared CMU folder; exits with a clear line when it is absent."""
    root = Path(os.environ.get("SAMBA_DATA", ROOT.parent / "shared" / "data"))
    if not any((root / "cmu").glob("*.bvh")):
        sys.exit(f"no CMU data in {root / 'cmu'}: set SAMBA_DATA or put ../shared/data there")
    return root / "cmu"


def best_times(jobs: dict[str, Callable[[], None]], repeats: int) -> dict[str, float]:
    """The best wall time (s) of every job over `repeats` rounds, the jobs alternating."""
    best = dict.fromkeys(jobs, float("inf"))
    for _ in range(repeats):
        for label, job in jobs.items():
            start = time.perf_counter()
            job()
            best[label] = min(best[label], time.perf_counter() - start)
    return best


def speed_table(title: str, unit: str, count: int, seconds: dict[str, float]) -> None:
    """Print the table of one job: time, rate and speed-ups over in-process and 1 worker."""
    rows = []
    for label, s in seconds.items():
        rows.append(
            [
                label,
                s,
                count / s,
                seconds["in-process"] / s,
                seconds["1 worker"] / s if label != "in-process" else "",
            ]
        )
    header = ["run", "seconds", f"{unit}/s", "x in-process", "x 1 worker"]
    print_table(title, header, rows)


def commit_rate(files: list[Path], folder: Path) -> tuple[float, float, int]:
    """(seconds to commit the files' takes, already read, in one `add_many`; seconds to
    build the index after it; poses stored)."""
    takes = [read_file(f, None) for f in files]
    store = PoseStore.create(folder / "commit-alone")
    start = time.perf_counter()
    store.add_many(takes, build_index=False)
    commit = time.perf_counter() - start
    start = time.perf_counter()
    store.build_index()
    return commit, time.perf_counter() - start, len(store)


def main(argv: list[str] | None = None) -> None:
    """Run the benchmark with the command-line arguments `argv` (None: the process's) and
    print its tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="rounds per job (default 3)")
    parser.add_argument(
        "--eval-takes", type=int, default=16, help="test takes of the evaluation (default 16)"
    )
    parser.add_argument(
        "--eval-frames", type=int, default=150, help="frames per test take (default 150)"
    )
    parser.add_argument(
        "--files", type=int, default=None, help="the first FILES CMU files only (default all)"
    )
    parser.add_argument(
        "--empty-tasks",
        type=int,
        default=2000,
        help="empty tasks timed for the scheduler's cost per task (default 2000)",
    )
    args = parser.parse_args(argv)
    files = sorted(data_dir().glob("*.bvh"))[: args.files]
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    takes = [read_file(f, None) for f in files]
    train = [(t.name, t.poses) for t in takes]
    test = [(name, poses[: args.eval_frames]) for name, poses in train[: args.eval_takes]]
    runs = {"samba": method("samba")}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        made = [PoseStore.create(folder / f"store-{i}").path for i in range(3 * args.repeats)]
        stores = iter(made)  # made beforehand, as `samba db init` does: not timed

        def importer(client: object) -> Callable[[], None]:
            def job() -> None:
                store = PoseStore.open(next(stores))  # what `samba db import` opens
                import_paths(store, files, progress=False, client=client)

            return job

        def evaluator(client: object) -> Callable[[], None]:
            return lambda: evaluate(train, test, runs, PoseIndex.build, client=client)

        started = {}
        start = time.perf_counter()
        with cluster_client(1) as one:
            started["1 worker"] = time.perf_counter() - start
            start = time.perf_counter()
            with cluster_client(2) as two:
                started["2 workers"] = time.perf_counter() - start
                clients = {"in-process": None, "1 worker": one, "2 workers": two}
                imports = best_times({k: importer(c) for k, c in clients.items()}, args.repeats)
                evals = best_times({k: evaluator(c) for k, c in clients.items()}, args.repeats)
                start = time.perf_counter()
                two.gather(two.map(abs, range(args.empty_tasks), pure=False))
                per_task = (time.perf_counter() - start) / args.empty_tasks
                start = time.perf_counter()
                two.scatter(train, broadcast=True)
                transfer = time.perf_counter() - start
        commit, index, poses = commit_rate(files, folder)
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    frames = sum(len(t.poses) for t in takes)
    speed_table(
        f"import of the {len(files)} shared CMU files ({frames} poses at 30 fps)",
        "files",
        len(files),
        imports,
    )
    speed_table(
        f"evaluation: samba, leave-one-take-out, {len(test)} test takes of {args.eval_frames} "
        f"frames against the {len(train)} takes",
        "takes",
        len(test),
        evals,
    )
    print_table(
        "starting a local cluster (not in the times above)",
        ["cluster", "seconds"],
        [[label, s] for label, s in started.items()],
    )
    read_per_file = imports["in-process"] / len(files)
    eval_per_take = evals["in-process"] / len(test)
    size = len(pickle.dumps(train, protocol=5)) / 1e6
    sent_back = len(pickle.dumps(takes, protocol=5)) / len(files) / 1e3
    print_table(
        "limits, each measured alone (what a 100-worker cluster meets first)",
        ["cost", "measured", "unit", "limit it sets"],
        [
            [
                "single writer: commit",
                commit / len(files) * 1e3,
                "ms per file",
                f"{read_per_file / (commit / len(files)):.0f} readers' worth of files",
            ],
            ["single writer: index rebuild", index, f"s for {poses} poses", "once per import"],
            [
                "a file's take, worker to client",
                sent_back,
                "kB",
                f"{sent_back / read_per_file / 1e3:.1f} MB/s per busy worker",
            ],
            [
                "training takes to 2 workers",
                transfer,
                f"s for {size:.1f} MB",
                f"{size / transfer:.0f} MB/s",
            ],
            [
                "scheduler per empty task",
                per_task * 1e3,
                "ms",
                f"{eval_per_take / per_task:.0f} eval tasks in flight, "
                f"{read_per_file * 8 / per_task:.0f} import tasks",
            ],
        ],
    )


if __name__ == "__main__":
    main()
