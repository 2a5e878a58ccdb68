"""Single-camera silhouette tracking: accuracy, the paper's Figure 4, speed and tree size.

Run from the project root:  python bench/bench_silhouette.py [--takes 3] [--reps 6]
                            [--sequences 24] [--large-headings 15] [--tables 1 2 3]

One camera, 320x240 silhouettes, the men's M body model (1.75 m); held-out takes of the
built-in synthetic motions (seeds the trees never saw), staged in front of the camera
facing it at the start (walking on the spot), rendered as the body model's
silhouettes and spoilt like background subtraction spoils them (`noisy_silhouettes`
at level 0, 0.5 and 1, then `clean_silhouette`). MPJPE in cm with the tibia scaled to
45 cm (EVALUATION.md); a failure is a frame above 15 cm.

Tables:
1. accuracy per motion of the tracker (normalised distance, occlusion-aware motion
   model) on a tree of the synthetic library (`--takes` takes per motion), beside two
   baselines measured in the same run: the nearest leaf silhouette in every frame (no
   tree search, no motion model) and the tracker with the plain XOR distance; then
   (1b) the same takes, at noise 0.5, of a subject 4% shorter or taller than the body
   model (the catalogue's step), the tracker told the subject's stature or not;
2. the paper's Figure 4: `--sequences` arm swings seen from the side, three distances x
   the plain (m = 1) and the occlusion-aware (m = 5) motion model;
3. speed and size: the tree of a large database (the CMU takes of ../shared/data or
   $SAMBA_DATA plus the synthetic library, turned every `--large-headings` degrees;
   50,000 leaves or more), its build time and memory, and the time per frame (p50 / p99,
   one core) of the tracker on it, beside the paper's 127 ms (PC) and 86 ms (Cell) averages and the
   nearest-silhouette baseline's full leaf scan on the same tree.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from text_table import print_table  # noqa: E402

from samba.body.body_model import BodyModel  # noqa: E402
from samba.body.skeleton import mirror_poses  # noqa: E402
from samba.cameras.camera import Camera  # noqa: E402
from samba.ingest.bvh_take import load_bvh_take  # noqa: E402
from samba.silhouette.distance import SilhouetteWeights  # noqa: E402
from samba.silhouette.evaluation import (  # noqa: E402
    FAILURE_CM,
    arm_swing_experiment,
    observed_silhouettes,
    staged,
    track_take,
)
from samba.silhouette.runs import RowSums  # noqa: E402
from samba.silhouette.shape_tree import ShapeTree  # noqa: E402
from samba.silhouette.tracker import TrackerSettings  # noqa: E402
from samba.silhouette.view import SilhouetteView  # noqa: E402
from samba.synthetic.motions import generate, library  # noqa: E402

CAMERA = Camera.look_at("front", (0.0, 1.2, 3.6), (0.0, 0.9, 0.0), (320, 240), 55.0)
BODY = BodyModel.for_subject(1.75)
MOTIONS = ("walk", "turn", "golf_swing", "point", "wave", "arm_swing", "jumping_jacks")
NOISE = (0.0, 0.5, 1.0)
FPS = 15.0
PAPER_MS = {"PC": 127.0, "Cell": 86.0}


def synthetic_tree(takes: int) -> tuple[ShapeTree, float]:
    """The tree of `takes` takes per built-in motion (seed 1) and their left/right mirror
    images (as `samba db import --mirror` stores takes), and its build seconds."""
    poses = np.concatenate([t.poses for t in library(takes, 4.0, FPS, seed=1)])
    poses = np.concatenate([poses, mirror_poses(poses)])
    start = time.perf_counter()
    tree = ShapeTree.build(poses.astype(np.float64), SilhouetteView(CAMERA), BODY)
    return tree, time.perf_counter() - start


def held_out_takes(
    reps: int, view: SilhouetteView, motions: tuple[str, ...] = MOTIONS, height: float = BODY.height
) -> list[tuple[str, np.ndarray]]:
    """(motion, staged poses) of `reps` held-out takes per motion, of a subject `height`
    m tall."""
    takes = []
    for k, (motion, _) in enumerate((m, r) for m in motions for r in range(reps)):
        poses = generate(motion, 4.0, FPS, seed=900 + k).poses.astype(np.float64)
        takes.append((motion, staged(poses, view, height, in_place=motion == "walk")))
    return takes


def nearest_silhouette(poses: np.ndarray, tree: ShapeTree, noise: float, seed: int) -> np.ndarray:
    """Baseline: per frame the leaf with the nearest silhouette (normalised distance),
    placed like the tracker places its leaf; MPJPE per frame (n,) cm, tibia 45 cm."""
    masks = observed_silhouettes(poses, tree, noise, np.random.default_rng(seed))
    estimates = []
    for mask in masks:
        normalised, placement = tree.view.normalise(mask)
        sums = RowSums.from_weights(SilhouetteWeights.from_mask(normalised))
        leaf = np.argmin(tree.leaves.silhouettes.distances(sums))
        estimates.append(tree.placed(np.array([leaf]), placement)[0])
    tibia = np.linalg.norm(poses[:, [9, 10]] - poses[:, [11, 12]], axis=-1).mean()
    return np.linalg.norm(np.array(estimates) - poses, axis=-1).mean(axis=1) * 45.0 / tibia


def accuracy(
    tree: ShapeTree, reps: int, motions: tuple[str, ...], noises: tuple[float, ...]
) -> list[list[object]]:
    """Rows of table 1: per noise level and motion, tracker and baselines."""
    rows = []
    takes = held_out_takes(reps, tree.view, motions)
    xor = TrackerSettings(distance="xor")
    for noise in noises:
        for motion in motions:
            ours, plain, nearest = [], [], []
            for k, (name, poses) in enumerate(takes):
                if name != motion:
                    continue
                ours.append(track_take(name, poses, tree, None, noise, seed=k).errors.mean(1))
                plain.append(track_take(name, poses, tree, xor, noise, seed=k).errors.mean(1))
                nearest.append(nearest_silhouette(poses, tree, noise, seed=k))
            rows.append([noise, motion, *_means_and_failures(ours, plain, nearest)])
    return rows


def _means_and_failures(*runs: list[np.ndarray]) -> list[float]:
    """Per run (a list of per-frame MPJPE arrays, cm): the mean over its frames and the
    percentage of frames above `FAILURE_CM`."""
    scores = []
    for run in runs:
        errors = np.concatenate(run)
        scores += [float(errors.mean()), 100 * float(np.mean(errors > FAILURE_CM))]
    return scores


STATURES = (0.96, 1.04)
"""Table 1b: the subject's stature over the body model's."""


def stature(tree: ShapeTree, reps: int, motions: tuple[str, ...]) -> list[list[object]]:
    """Rows of table 1b: per stature factor and motion, the tracker told the subject's
    stature and not told it, at noise 0.5 (the body model scaled by the factor)."""
    rows = []
    for factor in STATURES:
        subject = tree.body.scaled(factor)
        takes = held_out_takes(reps, tree.view, motions, subject.height)
        for motion in motions:
            told, not_told = [], []
            for k, (name, poses) in enumerate(takes):
                if name != motion:
                    continue
                told.append(
                    track_take(
                        name, poses, tree, None, 0.5, k, subject, subject.height
                    ).errors.mean(axis=1)
                )
                not_told.append(
                    track_take(name, poses, tree, None, 0.5, k, subject).errors.mean(axis=1)
                )
            rows.append([factor, motion, *_means_and_failures(told, not_told)])
    return rows


def large_database() -> tuple[str, np.ndarray]:
    """(label, poses) of the large tree: CMU takes at 15 fps plus the synthetic library."""
    synthetic = np.concatenate([t.poses for t in library(6, 4.0, FPS, seed=3)])
    env = os.environ.get("SAMBA_DATA")
    for base in ([Path(env)] if env else []) + [ROOT.parent / "shared" / "data"]:
        files = sorted((base / "cmu").glob("*.bvh"))
        if files:
            cmu = []
            for path in files:
                take = load_bvh_take(path)
                cmu.append(take.poses[:: max(1, round(take.fps / FPS))])
            label = f"{len(files)} CMU takes at {FPS:g} fps + synthetic library"
            return label, np.concatenate([*cmu, synthetic]).astype(np.float64)
    return "synthetic library only (no CMU data found)", synthetic.astype(np.float64)


def speed(tree: ShapeTree, reps: int) -> tuple[np.ndarray, np.ndarray]:
    """Seconds per frame (tracker, full leaf scan) on held-out takes at noise 0.5."""
    tracked, scanned = [], []
    for k, (name, poses) in enumerate(held_out_takes(reps, tree.view)):
        tracked.append(track_take(name, poses, tree, None, 0.5, seed=k).seconds)
        masks = observed_silhouettes(poses[:10], tree, 0.5, np.random.default_rng(k))
        with threadpool_limits(1):
            for mask in masks:
                start = time.perf_counter()
                normalised, _ = tree.view.normalise(mask)
                sums = RowSums.from_weights(SilhouetteWeights.from_mask(normalised))
                tree.leaves.silhouettes.distances(sums)
                scanned.append(time.perf_counter() - start)
    return np.concatenate(tracked), np.array(scanned)


def bench(
    takes: int,
    reps: int,
    sequences: int,
    large: bool,
    motions: tuple[str, ...] = MOTIONS,
    noises: tuple[float, ...] = NOISE,
    large_headings: float = 15.0,
    small: bool = True,
) -> dict[str, list[list[object]]]:
    """Run the tables (1 and 2 when `small`, 3 when `large`; accuracy on `motions` at
    `noises` only); returns their rows by name."""
    tables: dict[str, list[list[object]]] = {}
    if small:
        tables.update(_small_tables(takes, reps, sequences, motions, noises))
    if large:
        tables["speed"] = _speed_table(large_headings)
    return tables


def _small_tables(
    takes: int,
    reps: int,
    sequences: int,
    motions: tuple[str, ...],
    noises: tuple[float, ...],
) -> dict[str, list[list[object]]]:
    tree, seconds = synthetic_tree(takes)
    counts = " / ".join(f"{len(level):,}" for level in tree.levels)
    print(f"Synthetic tree: {takes} takes per motion -> {counts} nodes, built in {seconds:.0f} s")
    tables: dict[str, list[list[object]]] = {"accuracy": accuracy(tree, reps, motions, noises)}
    print_table(
        f"1. Accuracy on held-out takes ({reps} per motion, {FPS:g} fps), MPJPE cm "
        f"(tibia 45 cm) and failures % (> {FAILURE_CM:g} cm)",
        ["noise", "motion", "tracker", "fail %", "xor tracker", "fail %", "nearest", "fail %"],
        tables["accuracy"],
    )
    tables["stature"] = stature(tree, reps, motions)
    print_table(
        "1b. A subject shorter or taller than the body model, noise 0.5: MPJPE cm and "
        "failures %, the tracker told the subject's stature (`--height`) or not",
        ["stature / model", "motion", "told", "fail %", "not told", "fail %"],
        tables["stature"],
    )
    tables["figure4"] = [
        [
            o.distance,
            o.occlusion_factor,
            o.velocity_gain,
            o.failed,
            o.error,
            o.succeeded,
            o.arm_error_cm,
        ]
        for o in arm_swing_experiment(tree, sequences)
    ]
    print_table(
        f"2. Figure 4: {sequences} arm swings seen from the side, noise 0.5 (velocity 0: "
        "the paper's first-order models; the last row: our default settings)",
        ["distance", "m", "velocity", "fail", "error", "success", "arm error cm"],
        tables["figure4"],
    )
    return tables


def _speed_table(headings: float) -> list[list[object]]:
    label, poses = large_database()
    start = time.perf_counter()
    big = ShapeTree.build(
        poses, SilhouetteView(CAMERA), BODY, headings=np.arange(-180.0, 180.0, headings)
    )
    build = time.perf_counter() - start
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    tracked, scanned = speed(big, 1)
    counts = " / ".join(f"{len(level):,}" for level in big.levels)
    rows = [
        [
            "tracker",
            counts,
            float(np.percentile(tracked, 50) * 1e3),
            float(np.percentile(tracked, 99) * 1e3),
            float(1.0 / np.percentile(tracked, 50)),
        ],
        [
            "nearest (all leaves)",
            counts,
            float(np.percentile(scanned, 50) * 1e3),
            float(np.percentile(scanned, 99) * 1e3),
            float(1.0 / np.percentile(scanned, 50)),
        ],
    ]
    rows += [[f"paper ({k}, average)", "57,136", v, "-", 1e3 / v] for k, v in PAPER_MS.items()]
    print_table(
        f"3. Speed per frame at 320x240, one core: {label}, {len(poses):,} poses; tree "
        f"built in {build:.0f} s, {big.nbytes / 2**20:.0f} MiB of arrays, peak process "
        f"memory {peak:.0f} MiB",
        ["search", "nodes top / middle / leaves", "p50 ms", "p99 ms", "frames/s"],
        rows,
    )
    return rows


def main() -> None:
    """Parse the flags and run the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--takes", type=int, default=3, help="tree: takes per motion")
    parser.add_argument("--reps", type=int, default=6, help="held-out takes per motion")
    parser.add_argument("--sequences", type=int, default=24, help="Figure 4 sequences")
    parser.add_argument(
        "--large-headings", type=float, default=15.0, help="large tree: heading step, degrees"
    )
    parser.add_argument("--tables", type=int, nargs="+", default=[1, 2, 3], choices=[1, 2, 3])
    args = parser.parse_args()
    small = bool({1, 2} & set(args.tables))
    bench(
        args.takes,
        args.reps,
        args.sequences,
        3 in args.tables,
        large_headings=args.large_headings,
        small=small,
    )


if __name__ == "__main__":
    main()
