"""Model-free volumetric capture: speed per frame, human takes, synthetic creatures.

Run from the project root:  python bench/bench_volume.py [--seeds 11 12 13] [--tables 1 2 3]

Tables:
1. speed: seconds per frame of model and motion capture (Isomap, spherical shells,
   frame model; one core) on human volumes of about 3,000 and 10,000 voxels, with the
   Isomap step's share, against the paper's 60-90 s per frame (Matlab, 350 MHz,
   about 90% in Isomap) and, measured in the same run on the same 3,000-voxel frames,
   full Isomap (geodesics between all voxel pairs, classical MDS), the paper's step;
2. human takes (held-out seeds, never used to tune): jumping jacks and waving of the
   men-M capsule body with the limbs held apart (`exaggerated`), then jumping jacks,
   waving, squats and arm swings as generated ("natural": the feet together for much
   of the take), four 320x240 cameras
   on three sides, visual hull of 30 mm voxels at the paper's 10 Hz: the share of
   frames whose model has human topology (all frames; frames with separated limbs),
   the common model, and the error of the 13 mapped joints in cm;
3. creatures: a quadruped (13 links, 6 ends) and a 6-link chain, scan-converted at
   25 mm: ends and links recovered, over-segmentation (extra links; model joints
   farther than 2 voxels from every true joint), and the share of true joints with a
   model joint within 2 voxels (median over frames).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.sparse.csgraph import dijkstra
from threadpoolctl import threadpool_limits

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.text_table import print_table  # noqa: E402
from samba.volume.articulated_figure import long_chain, quadruped  # noqa: E402
from samba.volume.evaluation import creature_take, human_take  # noqa: E402
from samba.volume.isomap import VoxelGraph  # noqa: E402

PAPER_SECONDS = (60.0, 90.0)
"""The paper's seconds per frame (Matlab on a 350 MHz Pentium)."""


def full_isomap_seconds(graph: VoxelGraph) -> float:
    """Seconds of the paper's Isomap step on a connected graph: all-pairs geodesics and
    classical MDS to 3-D."""
    start = time.perf_counter()
    squared = dijkstra(graph.edges, directed=False) ** 2
    n = len(squared)
    squared -= squared.mean(axis=0)
    squared -= squared.mean(axis=1, keepdims=True)
    gram = -0.5 * squared
    values, vectors = np.linalg.eigh(gram)
    embedding = vectors[:, -3:] * np.sqrt(np.maximum(values[-3:], 0))
    assert embedding.shape == (n, 3)
    return time.perf_counter() - start


def bench_speed(seconds: float) -> list[list[object]]:
    """Table 1 rows."""
    rows: list[list[object]] = []
    for voxel in (0.03, 0.02):
        report = human_take("jumping_jacks", 21, seconds=seconds, voxel=voxel)
        times = report.capture.times
        rows.append(
            [
                f"ours, {voxel * 1000:.0f} mm voxels",
                int(np.median(report.voxels)),
                float(np.median(times.total)),
                float(np.percentile(times.total, 99)),
                f"{np.sum(times.isomap) / np.sum(times.total):.0%}",
                f"{np.mean(PAPER_SECONDS) / np.median(times.total):,.0f}x",
            ]
        )
        if voxel == 0.03:
            graph_times = []
            for volume in report.volumes[:3]:
                graph = VoxelGraph.from_indices(np.argwhere(volume))
                graph_times.append(full_isomap_seconds(graph.subgraph(graph.largest())))
            baseline = float(np.median(graph_times))
            rows.append(
                [
                    "baseline: full Isomap step only, 30 mm",
                    int(np.median(report.voxels)),
                    baseline,
                    "-",
                    "100%",
                    f"{np.mean(PAPER_SECONDS) / baseline:,.0f}x",
                ]
            )
    rows.append(["paper (Matlab, 350 MHz)", "-", "60-90", "-", "~90%", "1x"])
    print_table(
        "Speed: seconds per frame, one core (p50, p99), Isomap share; ratio = paper / ours",
        ["method", "voxels", "s p50", "s p99", "Isomap", "vs paper"],
        rows,
    )
    return rows


def bench_humans(seeds: list[int], seconds: float) -> list[list[object]]:
    """Table 2 rows."""
    rows: list[list[object]] = []
    takes = [(motion, True) for motion in ("jumping_jacks", "wave")]
    takes += [(motion, False) for motion in ("jumping_jacks", "wave", "squat", "arm_swing")]
    for motion, exaggerate in takes:
        for seed in seeds:
            report = human_take(motion, seed, seconds=seconds, exaggerate=exaggerate)
            model = report.capture.fit.model
            rows.append(
                [
                    report.name + ("" if exaggerate else " natural"),
                    len(report.humanoid),
                    int(np.median(report.voxels)),
                    f"{report.humanoid.mean():.0%}",
                    (
                        f"{report.humanoid_rate_separated:.0%} of {report.separated.sum()}"
                        if report.separated.any()
                        else "no frame separated"
                    ),
                    f"{model.branch_count} ends, {model.link_count} links",
                    *(
                        (float(np.nanmean(report.errors)), float(np.nanmedian(report.errors)))
                        if np.isfinite(report.errors).any()
                        else ("not human", "-")
                    ),
                ]
            )
    print_table(
        "Human takes: human topology per frame (all; frames with separated limbs), "
        "13-joint error in cm",
        ["take", "frames", "voxels", "human", "human, separated", "model", "MPJPE", "median"],
        rows,
    )
    return rows


def bench_creatures(seeds: list[int], frames: int) -> list[list[object]]:
    """Table 3 rows."""
    rows: list[list[object]] = []
    for name, figure, high in (
        ("quadruped", quadruped(), 1.2),
        ("chain", long_chain(6), 0.8),
    ):
        for seed in seeds:
            report = creature_take(
                figure, name, seed, frames=frames, bounds=((-1.0, 0.0, -1.0), (1.0, high, 1.0))
            )
            rows.append(
                [
                    f"{name}-{seed}",
                    f"{report.model_ends} / {report.true_ends}",
                    f"{report.model_links} / {report.true_links}",
                    report.model_links - report.true_links,
                    report.spurious,
                    f"{report.joints_found:.0%}",
                    float(np.median(report.joint_voxels)),
                ]
            )
    print_table(
        "Creatures: recovered / true; over-segmentation; true joints within 2 voxels",
        [
            "take",
            "ends",
            "links",
            "extra links",
            "spurious joints",
            "joints <= 2 vox",
            "median vox",
        ],
        rows,
    )
    return rows


def main() -> None:
    """Parse the flags, print the chosen tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[11, 12, 13])
    parser.add_argument("--seconds", type=float, default=3.0, help="seconds per human take")
    parser.add_argument("--frames", type=int, default=30, help="frames per creature take")
    parser.add_argument("--tables", type=int, nargs="+", default=[1, 2, 3])
    args = parser.parse_args()
    with threadpool_limits(1):
        if 1 in args.tables:
            bench_speed(min(args.seconds, 1.0))
        if 2 in args.tables:
            bench_humans(args.seeds, args.seconds)
        if 3 in args.tables:
            bench_creatures(args.seeds, args.frames)


if __name__ == "__main__":
    main()
