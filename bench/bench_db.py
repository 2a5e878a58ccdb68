"""Pose database benchmark: import throughput, index build and query latency, store size.

Run from the project root:  python bench/bench_db.py [--sizes 10000,100000,1000000]
(import throughput alone: python bench/bench_db.py --sections import --repeats 5)

Needs the shared CMU data (../shared/data or $SAMBA_DATA). Every table carries a
baseline measured in the same run:

* import: `np.loadtxt` of the files' motion sections alone (the cost of reading the
  numbers, before any mapping, kinematics or normalisation), beside the BVH reader's
  compiled kernel on the same sections, whole-file parsing (every frame, and only the
  frames a 30 fps take samples), conversion to takes and `samba db import` itself; the
  stages alternate round by round;
* queries: a plain scipy k-d tree over the raw 24-D aligned marker features.

Exact queries are timed through the tree and, up to 200,000 poses, by the scan that
small tables use (`samba.db.index.SCAN_LIMIT`), so the crossover shows.

Databases beyond the real poses are grown with small random joint-angle perturbations
(5 degrees per joint, bone lengths kept). Queries are observations the database does not
hold: 'novel' ones are real poses perturbed by 8 degrees per joint plus 1 cm marker noise
(nearest pose about 10 cm away at 10^6 poses), 'covered' ones 2 degrees plus 5 mm (motion
the database covers, as with a user's own recorded takes).
"""

from __future__ import annotations

import argparse
import io
import os
import re
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from text_table import print_table  # noqa: E402

from samba.body import resample_times  # noqa: E402
from samba.body.alignment import align_markers  # noqa: E402
from samba.body.perturb import perturb_joint_angles  # noqa: E402
from samba.body.skeleton import N_MARKERS, markers_of  # noqa: E402
from samba.body.take import Take  # noqa: E402
from samba.db.index import APPROXIMATE_EPS, SCAN_LIMIT, PoseIndex, marker_features  # noqa: E402
from samba.db.store import PoseStore  # noqa: E402
from samba.ingest import reader_kernels  # noqa: E402
from samba.ingest.batch import READERS, import_paths  # noqa: E402
from samba.ingest.bvh import parse_bvh  # noqa: E402
from samba.ingest.bvh_take import load_bvh_take  # noqa: E402
from samba.ingest.motion_table import read_table as read_motion_table  # noqa: E402

K = 10
SCANNED_UP_TO = 200_000
CELLS_EPS = 1.0
"""An eps at which the compiled cells still find recall@10 >= 0.99 at 10^6 poses (0.9955
on novel observations, 2026-12-05; 1.5 gave 0.988)."""
"""Largest table the benchmark also times the scan on (the tree's crossover is below)."""


def data_dir() -> Path:
    """The shared CMU folder, or exit with the reason."""
    env = os.environ.get("SAMBA_DATA")
    for base in ([Path(env)] if env else []) + [ROOT.parent / "shared" / "data"]:
        if any((base / "cmu").glob("*.bvh")):
            return base / "cmu"
    sys.exit(
        "bench_db: CMU data not found (set SAMBA_DATA or put ../shared/data beside the project)"
    )


def rss_mb() -> float:
    """Resident memory of this process in MiB."""
    with open("/proc/self/status") as fh:
        kb = int(re.search(r"VmRSS:\s+(\d+)", fh.read()).group(1))
    return kb / 1024


def motion_section(data: bytes) -> np.ndarray:
    """The frame lines of a BVH file's bytes, everything after its 'Frame Time:' line, as
    a uint8 array (a view, no copy)."""
    start = data.index(b"\n", data.index(b"Frame Time")) + 1
    return np.frombuffer(data, dtype=np.uint8, offset=start)


def best_of_rounds(repeats: int, stages: dict[str, Callable[[], object]]) -> dict[str, float]:
    """The shortest wall time (seconds) of each stage over `repeats` rounds, every round
    running each stage once in turn: a noisy machine slows all stages alike."""
    best = dict.fromkeys(stages, float("inf"))
    for _ in range(repeats):
        for name, stage in stages.items():
            t0 = time.perf_counter()
            stage()
            best[name] = min(best[name], time.perf_counter() - t0)
    return best


def at_30_fps(frames: int, fps: float) -> np.ndarray:
    """The frames a take read at 30 fps samples of a file of `frames` at `fps`."""
    return resample_times(frames, fps, 30.0)


def bench_import(files: list[Path], repeats: int = 3) -> np.ndarray:
    """Import throughput, each stage the best of `repeats` alternating rounds, against
    `np.loadtxt` of the same files' numbers in the same run; returns the real poses."""
    shapes = [parse_bvh(f.read_bytes()).motion.shape for f in files]
    reader_kernels().warm_up()  # compiled once per install, loaded once per process

    def loadtxt_numbers() -> None:
        for f in files:
            text = f.read_text()
            np.loadtxt(io.StringIO(text[text.index("Frame Time") :].split("\n", 1)[1]), ndmin=2)

    def reader_numbers() -> None:
        for f, (frames, channels) in zip(files, shapes, strict=True):
            body = motion_section(f.read_bytes())
            assert read_motion_table(body, frames, channels) is not None

    def parse_files() -> None:
        for f in files:
            parse_bvh(f.read_bytes(), source=str(f))

    def parse_sampled() -> None:
        for f in files:
            parse_bvh(f.read_bytes(), source=str(f), sample=at_30_fps)

    def import_all() -> None:
        results = import_paths(next(empty_stores), files, progress=False)
        assert all(r.status == "added" for r in results)

    takes = [load_bvh_take(f) for f in files]
    poses = np.concatenate([t.poses for t in takes])
    source_frames = sum(t.source_frames for t in takes)
    stages = {
        "baseline: np.loadtxt of the motion sections": loadtxt_numbers,
        "motion reader (compiled kernel) of the same": reader_numbers,
        "parse_bvh: whole files (hierarchy + motion)": parse_files,
        "parse_bvh: the frames a 30 fps take samples": parse_sampled,
        "read + map + FK + resample + normalise": lambda: [load_bvh_take(f) for f in files],
        "samba db import (group commits + index)": import_all,
    }
    with tempfile.TemporaryDirectory() as tmp:  # `samba db init` is no part of an import
        empty_stores = iter([PoseStore.create(Path(tmp) / f"s{k}") for k in range(repeats)])
        seconds = best_of_rounds(repeats, stages)
    base = seconds["baseline: np.loadtxt of the motion sections"]
    rows = [
        [
            stage,
            t,
            source_frames / t,
            len(poses) / t if stage.startswith(("read", "samba")) else "",
            base / t,
        ]
        for stage, t in seconds.items()
    ]
    print_table(
        f"Import: {len(files)} CMU files, {source_frames} source frames -> {len(poses)} poses"
        f" at 30 fps (one thread, but samba db import's {READERS} reading threads; best of"
        f" {repeats} alternating rounds)",
        ["stage", "seconds", "source frames/s", "poses/s", "rate vs np.loadtxt"],
        rows,
    )
    return poses


def grow(poses: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """n poses: the real ones, then 5-degree joint-angle perturbations of them."""
    parts = [poses]
    while sum(len(p) for p in parts) < n:
        parts.append(perturb_joint_angles(poses, 5.0, rng))
    return np.concatenate(parts)[:n].astype(np.float32)


def latencies(
    fn: Callable[[np.ndarray], object], queries: np.ndarray
) -> tuple[float, float, float]:
    """Median, 99th and 99.9th percentile (microseconds) of fn(query) over single queries."""
    times = []
    for q in queries:
        t0 = time.perf_counter()
        fn(q)
        times.append(time.perf_counter() - t0)
    us = np.array(times) * 1e6
    return float(np.median(us)), float(np.percentile(us, 99)), float(np.percentile(us, 99.9))


def throughput(fn: Callable[[np.ndarray], object], queries: np.ndarray) -> float:
    """Queries per second of fn(batch)."""
    t0 = time.perf_counter()
    fn(queries)
    return len(queries) / (time.perf_counter() - t0)


def recall(found: np.ndarray, truth: np.ndarray) -> float:
    """Mean fraction of the true k nearest that were found."""
    return float(
        np.mean([len(set(a) & set(b)) / len(b) for a, b in zip(found, truth, strict=True)])
    )


def bench_index(real: np.ndarray, sizes: list[int], rng: np.random.Generator) -> None:
    """Build time, latency, throughput and recall per database size and query set."""
    query_sets = {}
    for label, degrees, noise in (("novel", 8.0, 0.01), ("covered", 2.0, 0.005)):
        picked = real[rng.choice(len(real), 2000)].astype(np.float64)
        markers = markers_of(perturb_joint_angles(picked, degrees, rng))
        query_sets[label] = markers + rng.normal(0, noise, markers.shape)
    rows, missing_rows = [], []
    for n in sizes:
        size_rows, missing = bench_size(grow(real, n, rng), query_sets)
        rows += size_rows
        missing_rows += missing
        print(f"  ... {n} poses done", flush=True)
    print_table(
        f"k={K} nearest poses, single queries (p50/p99 over 300) and a batch of 2000; "
        f"recall@{K} against brute force on 200 queries. Queries: 'novel' = real poses "
        "+ 8 deg per joint + 1 cm noise, 'covered' = + 2 deg + 5 mm",
        [
            "poses",
            "queries",
            "method",
            "build s",
            "p50 us",
            "p99 us",
            "batch q/s",
            "recall@10",
            "p50 speed vs baseline",
        ],
        rows,
    )
    print_table(
        "Novel queries with markers missing (left wrist; and right knee), exact, compiled "
        "kernels: the first query of a mask is answered from the full table's cells and "
        "queues its masked table, made in the background (large indexes; small ones scan "
        "it); then 1000 single queries",
        [
            "poses",
            "missing",
            "first query ms",
            "table ready after s",
            "p50 us",
            "p99 us",
            "p99.9 us",
            "batch q/s",
        ],
        missing_rows,
    )


def bench_size(poses: np.ndarray, query_sets: dict[str, np.ndarray]) -> tuple[list[list], list]:
    """Table rows for one database: baseline, exact and approximate index per query set,
    and the missing-marker row for the first set."""
    n = len(poses)
    features = marker_features(poses, np.ones(N_MARKERS, dtype=bool)).astype(np.float64)
    t0 = time.perf_counter()
    plain = cKDTree(features)
    plain_build = time.perf_counter() - t0
    t0 = time.perf_counter()
    index = PoseIndex.build(poses)
    build = time.perf_counter() - t0

    def plain_query(q: np.ndarray) -> object:
        batch = q.reshape(-1, N_MARKERS, 3)
        return plain.query(align_markers(batch)[0].reshape(len(batch), -1), k=K, workers=-1)

    rows = []
    for label, observations in query_sets.items():
        single = observations[:300]
        aligned = align_markers(observations[:200])[0].reshape(200, -1)
        truth = np.array([np.argsort(np.linalg.norm(features - a, axis=1))[:K] for a in aligned])
        b50, b99, _ = latencies(plain_query, single)
        b_batch = throughput(plain_query, observations)
        rows.append(
            [n, label, "baseline: cKDTree raw 24-D", plain_build, b50, b99, b_batch, 1.0, 1.0]
        )
        for path in ("kernels", "numpy"):
            os.environ["SAMBA_KERNELS"] = "numpy" if path == "numpy" else "numba"
            index_name = "cells" if path == "kernels" else "tree"
            searches = [(f"index, exact, {index_name}", 0.0, 0)]
            if n <= SCANNED_UP_TO and path == "numpy":
                searches.append(("index, exact, scan", 0.0, n))
            searches.append((f"index, eps={APPROXIMATE_EPS}, {index_name}", APPROXIMATE_EPS, 0))
            if path == "kernels":  # the cells keep recall@10 >= 0.99 at a larger eps
                searches.append((f"index, eps={CELLS_EPS}, cells", CELLS_EPS, 0))
            for method, eps, scan_limit in searches:
                index.scan_limit = scan_limit
                p50, p99, _ = latencies(lambda q, e=eps: index.query(q, K, eps=e), single)
                batch = throughput(lambda q, e=eps: index.query(q, K, eps=e), observations)
                found = index.query(observations[:200], K, eps=eps)[1]
                hits, speed = recall(found, truth), b50 / p50
                rows.append([n, label, f"{method} ({path})", build, p50, p99, batch, hits, speed])
    os.environ.pop("SAMBA_KERNELS", None)
    index.scan_limit = SCAN_LIMIT
    missing = []
    for lost in ([2], [2, 5]):
        dropped = next(iter(query_sets.values())).copy()
        dropped[:, lost] = np.nan  # left wrist (and right knee) lost
        t0 = time.perf_counter()
        index.query(dropped[0], K)
        first = time.perf_counter() - t0
        t0 = time.perf_counter()
        index.wait_for_masked_tables()
        made = time.perf_counter() - t0
        m50, m99, m999 = latencies(lambda q: index.query(q, K), dropped[1:1001])
        batch = throughput(lambda q: index.query(q, K), dropped)
        missing.append([n, len(lost), first * 1e3, made, m50, m99, m999, batch])
    return rows, missing


def bench_store(real: np.ndarray, n: int, rng: np.random.Generator) -> None:
    """Bytes on disk, open time, index load time and memory of a store of n poses."""
    poses = grow(real, n, rng)
    with tempfile.TemporaryDirectory() as tmp:
        store = PoseStore.create(Path(tmp) / "s")
        t0 = time.perf_counter()
        store.add(Take(name="grown", poses=poses, fps=30.0, content_hash="grown", rig="bench"))
        add = time.perf_counter() - t0
        del store
        size = sum(p.stat().st_size for p in (Path(tmp) / "s").iterdir())
        before = rss_mb()
        t0 = time.perf_counter()
        store = PoseStore.open(Path(tmp) / "s")
        opened = time.perf_counter() - t0
        t0 = time.perf_counter()
        _ = store.index
        loaded = time.perf_counter() - t0
        store.query(markers_of(real[:100].astype(np.float64)), K)
        after = rss_mb()
    print_table(
        f"Store of {n} poses",
        [
            "add + index s",
            "on disk MiB",
            "open ms",
            "index load ms",
            "RSS after open+load+query MiB",
        ],
        [[add, size / 2**20, opened * 1e3, loaded * 1e3, after - before]],
    )


def main() -> None:
    """Run the chosen sections and print their tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--sizes", default="10000,100000,1000000", help="database sizes for the index benchmark"
    )
    parser.add_argument(
        "--sections",
        default="import,index,store",
        help="comma-separated sections: import, index, store (default all; import always "
        "runs, its poses feed the others)",
    )
    parser.add_argument(
        "--repeats", type=int, default=3, help="rounds of the import section (best of)"
    )
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    sections = set(args.sections.split(","))
    rng = np.random.default_rng(0)
    real = bench_import(sorted(data_dir().glob("*.bvh")), repeats=args.repeats)
    if "index" in sections:
        bench_index(real, sizes, rng)
    if "store" in sections:
        bench_store(real, max(sizes), rng)


if __name__ == "__main__":
    main()
