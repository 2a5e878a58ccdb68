"""Camera-node speed: marker detection + 8-label tracking per frame, and triangulation.

Run from the project root:  python bench/bench_cameras.py [--frames 300]

Single-threaded by construction: the process pins itself to one core where the OS allows
it, BLAS is limited to one thread (threadpoolctl) and OpenCV to one (cv2.setNumThreads).
Frames are the synthetic rig's renders of a jumping-jacks take through one camera placed
as in EVALUATION.md, at 160x120 .. 1920x1080; rendering is not timed. Each frame is
timed through `detect_markers` (automatic threshold, static-spot mask) and
`MarkerTracker.step`, beside the paper's camera-node times (Table 1: 64 / 131 / 423 ms
at 160x120 / 320x240 / 640x480 on a 720 MHz ARM) and a baseline measured on the same
frames in the same run: a fixed `cv2.threshold` and `cv2.connectedComponentsWithStats`
alone. Triangulation: the DLT of 8 markers seen by 4 cameras, batched over frames.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from threadpoolctl import threadpool_limits

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from text_table import print_table  # noqa: E402

from samba.body.skeleton import markers_of  # noqa: E402
from samba.cameras.synthetic_cameras import with_size  # noqa: E402
from samba.cameras.triangulation import triangulate  # noqa: E402
from samba.markers.detection import detect_markers  # noqa: E402
from samba.markers.observation import (  # noqa: E402
    evaluation_cameras,
    spread_cameras,
)
from samba.markers.render import RenderOptions, render  # noqa: E402
from samba.markers.tracking import MarkerTracker, TrackerSettings  # noqa: E402
from samba.synthetic.motions import generate  # noqa: E402

RESOLUTIONS = ((160, 120), (320, 240), (640, 480), (1280, 720), (1920, 1080))
PAPER_MS = {(160, 120): 64.0, (320, 240): 131.0, (640, 480): 423.0}
"""The paper's average camera-node time per frame (Table 1)."""
TARGET_MS = {(160, 120): 0.5, (640, 480): 5.0}
"""The issue's targets for detection + tracking per frame."""
TARGET_TRIANGULATION_FPS = 20_000
RENDER_CHUNK = 50
"""Frames rendered at a time (a 1080p take does not fit in memory at once)."""


def time_camera(size: tuple[int, int], poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Seconds per frame (F,) of detection + tracking and of the baseline, at `size`."""
    camera = with_size(evaluation_cameras(poses)[0], size)
    options = RenderOptions()
    mask = np.zeros((size[1], size[0]), dtype=bool)
    first = render(poses[:1], [camera], options, seed=0)[0]
    start = np.where(first.visible[0][:, None], first.pixels[0], np.nan)
    tracker = MarkerTracker(start, TrackerSettings.for_camera(camera))
    chain, baseline = [], []
    for offset in range(0, len(poses), RENDER_CHUNK):
        frames = render(poses[offset : offset + RENDER_CHUNK], [camera], options, offset)[0].frames
        for frame in frames:
            begin = time.perf_counter()
            blobs = detect_markers(frame, mask=mask)
            tracker.step(blobs.centroids, blobs.merged())
            middle = time.perf_counter()
            _, binary = cv2.threshold(frame, 40, 255, cv2.THRESH_BINARY)
            cv2.connectedComponentsWithStats(binary, connectivity=8)
            end = time.perf_counter()
            chain.append(middle - begin)
            baseline.append(end - middle)
    return np.array(chain[5:]), np.array(baseline[5:])  # the first frames warm caches up


def time_triangulation(frames: int, repeats: int = 3) -> float:
    """Frames per second of the batched DLT of 8 markers x 4 cameras (best of `repeats`)."""
    poses = generate("jumping_jacks", seconds=frames / 30, fps=30, seed=1).poses
    cameras = spread_cameras(poses, 4)
    projections = np.stack([c.projection for c in cameras])
    pixels = np.stack([c.project(markers_of(poses)) for c in cameras])  # (4, F, 8, 2)
    best = np.inf
    for _ in range(repeats):
        begin = time.perf_counter()
        triangulate(projections, pixels)
        best = min(best, time.perf_counter() - begin)
    return len(poses) / best


def bench(
    frames: int,
    resolutions: tuple[tuple[int, int], ...] = RESOLUTIONS,
    triangulation_frames: int = 10_000,
) -> tuple[list[list[str]], float]:
    """Measure and print both tables; returns (camera rows, triangulation frames/s)."""
    poses = generate("jumping_jacks", seconds=frames / 30, fps=30, seed=1).poses
    rows = []
    for size in resolutions:
        chain, baseline = time_camera(size, poses)
        p50, p99 = np.median(chain) * 1e3, np.percentile(chain, 99) * 1e3
        paper = PAPER_MS.get(size)
        target = TARGET_MS.get(size)
        rows.append(
            [
                f"{size[0]}x{size[1]}",
                f"{paper:.0f}" if paper else "-",
                f"{p50:.3f}",
                f"{p99:.3f}",
                f"{np.median(baseline) * 1e3:.3f}",
                f"{paper / p50:.0f}x" if paper else "-",
                f"< {target}" if target else "-",
            ]
        )
    header = ["image", "paper ms", "p50 ms", "p99 ms", "baseline p50", "paper / p50", "target"]
    print(f"Detection + tracking per frame, one core, {len(poses) - 5} frames per resolution")
    print("baseline: fixed cv2.threshold + cv2.connectedComponentsWithStats on the same frames")
    print_table(None, header, rows)
    fps = time_triangulation(triangulation_frames)
    print(
        f"Triangulation, 8 markers x 4 cameras, batched DLT: {fps:,.0f} frames/s "
        f"(target >= {TARGET_TRIANGULATION_FPS:,})"
    )
    return rows, fps


def main() -> None:
    """Command line entry."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300, help="frames per resolution")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    cv2.setNumThreads(1)
    with threadpool_limits(limits=1):
        bench(args.frames)


if __name__ == "__main__":
    main()
