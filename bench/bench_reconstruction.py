"""Reconstruction speed: time per frame of the live path and throughput of the batch path.

Run from the project root:  python bench/bench_reconstruction.py [--frames 2000]

Single-threaded by construction: BLAS is limited to one thread (threadpoolctl) and the
process pins itself to one core where the OS allows it; the last column alone runs the
batch path on every core the process started with. The database is the shared CMU
data (../shared/data or $SAMBA_DATA) without one take, which is observed through the
EVALUATION.md cameras; without the data, the built-in synthetic motions stand in (and
the table says so). Every method runs on the same frames in the same run, with the
compiled kernels and with their numpy references (the same-run baseline); the `nn`
baseline and the paper's 23.5 ms per frame are printed beside each.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from text_table import print_table  # noqa: E402

from samba.body.skeleton import mirror_poses  # noqa: E402
from samba.db.index import PoseIndex  # noqa: E402
from samba.evaluation.protocol import capture_take  # noqa: E402
from samba.ingest.bvh_take import load_bvh_take  # noqa: E402
from samba.reconstruct.methods import METHODS  # noqa: E402
from samba.reconstruct.reconstruction import Reconstructor  # noqa: E402
from samba.synthetic.motions import generate, library  # noqa: E402

PAPER_MS = 23.5
"""The paper's time per frame (K = 10, N = 10, Section 6.2)."""


def database_and_test(max_frames: int) -> tuple[str, np.ndarray, np.ndarray]:
    """(source label, database poses (n, 13, 3), test markers (F, 8, 3))."""
    env = os.environ.get("SAMBA_DATA")
    for base in ([Path(env)] if env else []) + [ROOT.parent / "shared" / "data"]:
        files = sorted((base / "cmu").glob("*.bvh"))
        if files:
            takes = [load_bvh_take(f) for f in files]
            test = np.concatenate([t.poses for t in takes[:3]])[:max_frames]
            database = np.concatenate([t.poses for t in takes[3:]])
            label = f"CMU: {len(takes) - 3} takes in the database, 3 takes observed"
            return label, database, capture_take("test", test, seed=0).markers
    database = np.concatenate([t.poses for t in library(takes_per_motion=6, seconds=10)])
    test = generate("kick", seconds=max_frames / 30, fps=30, seed=99).poses
    return "synthetic motions (no CMU data found)", database, capture_take("t", test, 0).markers


def time_live(reconstructor: Reconstructor, markers: np.ndarray) -> np.ndarray:
    """Seconds per frame (F,) of `step`, frame by frame, after a 20-frame warm-up."""
    for frame in markers[:20]:
        reconstructor.step(frame)
    reconstructor.reset()
    seconds = np.empty(len(markers))
    for i, frame in enumerate(markers):
        start = time.perf_counter()
        reconstructor.step(frame)
        seconds[i] = time.perf_counter() - start
    return seconds


def time_batch(reconstructor: Reconstructor, markers: np.ndarray, repeats: int = 3) -> float:
    """Frames per second of `reconstruct` on the whole sequence (best of `repeats`)."""
    best = np.inf
    for _ in range(repeats):
        reconstructor.reset()
        start = time.perf_counter()
        reconstructor.reconstruct(markers)
        best = min(best, time.perf_counter() - start)
    return len(markers) / best


ALL_CORES = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else set()
"""The cores the benchmark may use before it pins itself to one."""


@contextmanager
def every_core() -> Iterator[None]:
    """Run the block on every core (and BLAS threads) the benchmark started with."""
    if not ALL_CORES:
        yield
        return
    pinned = os.sched_getaffinity(0)
    os.sched_setaffinity(0, ALL_CORES)
    try:
        with threadpool_limits(limits=len(ALL_CORES)):
            yield
    finally:
        os.sched_setaffinity(0, pinned)


def bench(
    max_frames: int, methods: list[str], paths: tuple[str, ...] = ("kernels", "numpy")
) -> list[list[object]]:
    """Measure every method on every path ("kernels": the numba kernels; "numpy": their
    numpy references, `SAMBA_KERNELS=numpy`, the same-run baseline); prints and returns
    the table rows."""
    label, database, markers = database_and_test(max_frames)
    plain = PoseIndex.build(database)
    mirrored = PoseIndex.build(np.concatenate([database, mirror_poses(database)]))
    measured: dict[tuple[str, str], tuple[float, float, float, float]] = {}
    for name in methods:
        method = METHODS[name]
        index = mirrored if method.mirrored_database else plain
        for path in paths:
            os.environ["SAMBA_KERNELS"] = "numpy" if path == "numpy" else "numba"
            reconstructor = method.build(index)
            index.wait_for_masked_tables()  # a live session makes them while it starts
            live = time_live(reconstructor, markers) * 1e3
            batch = time_batch(reconstructor, markers)
            with every_core():
                batch_all = time_batch(reconstructor, markers)
            measured[name, path] = (np.median(live), np.percentile(live, 99), batch, batch_all)
    os.environ.pop("SAMBA_KERNELS", None)
    rows: list[list[object]] = []
    for (name, path), (p50, p99, batch, batch_all) in measured.items():
        numpy_p50 = measured.get((name, "numpy"), (None,))[0]
        speedup = f"{numpy_p50 / p50:.1f}x" if numpy_p50 else "-"
        nn_p50 = measured.get(("nn", path), (None,))[0]  # nn on the same path
        rows.append(
            [
                name,
                path,
                f"{len(mirrored if METHODS[name].mirrored_database else plain)}",
                f"{p50:.3f}",
                f"{p99:.3f}",
                speedup,
                f"{p50 / nn_p50:.1f}x" if nn_p50 else "-",
                f"{PAPER_MS / p50:.0f}x",
                f"{batch:.0f}",
                f"{batch_all:.0f}",
            ]
        )
    header = ["method", "path", "poses", "p50 ms", "p99 ms", "numpy / p50", "p50 / nn"]
    header += ["paper / p50", "batch f/s", f"batch f/s, {len(ALL_CORES)} cores"]
    print(f"Reconstruction, one core, {len(markers)} frames; {label}")
    print(f"paper: {PAPER_MS} ms per frame (K = 10, N = 10)")
    print_table(None, header, rows)
    return rows


def main() -> None:
    """Command line entry."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=2000, help="test frames (default 2000)")
    parser.add_argument("--methods", default=",".join(METHODS), help="comma-separated")
    parser.add_argument(
        "--paths",
        default="kernels,numpy",
        help="comma-separated: kernels (numba), numpy (their references; the baseline)",
    )
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    with threadpool_limits(limits=1):
        bench(args.frames, args.methods.split(","), tuple(args.paths.split(",")))


if __name__ == "__main__":
    main()
