"""The camera chain end to end on held-out motion: accuracy, missing markers, label swaps.

Run from the project root:  python bench/camera_chain_report.py [BVH ...] [--seconds S]

Each take (default: ../shared/data/cmu/iclone_007_05.bvh, or $SAMBA_DATA; a synthetic
kick without the data) is filmed by the synthetic rig (`samba.markers.camera_chain.run_chain`):
render -> detect -> track -> triangulate, after a standing lead-in in the standard pose.
Rows: two EVALUATION.md cameras at 160x120, 320x240 and 640x480; three and four cameras
spread around the subject (`spread_cameras`) at 160x120 and 640x480, all with lost labels
found again across the cameras (`samba.markers.cross_view_labels`); and, as the baselines
measured on the same frames, each camera's guarded tracker alone and the paper's plain
nearest-neighbour filter (`guard_swaps=False`). Columns: RMS 3D error (cm) over the
markers reconstructed where at least two cameras see them; missing = (frame, marker)
without a 3D position; lost = of those at least two cameras see, the share left without
one (what detection and tracking lose beyond occlusion); label swaps and phantoms summed
over cameras and frames.

A second table films each take as the subject leaving and coming back
(`leave_and_return`): its first half, a second with nobody on the stage, then the
second half 1.3 m away, turned 25 degrees from where the take started, after a second
in the standard pose. The stage finds the subject again (`samba.markers.standard_pose_search`);
the baseline rows are the same stage without that search, on the same frames. "lost
after return" counts from the end of that second.

A third table places random subjects in the standard pose on the stage
(`samba.synthetic.motions.random_standing`: bodies 1.5-1.95 m with segments scaled 0.9-1.1,
arms 10-70 degrees, within 1 m of the centre, turned up to 50 degrees) before three
320x240 cameras, as an ideal detector sees them with pixel noise and stray bright spots
(`detected_blobs`), and counts how often the search finds them, the frames with a label
on a wrong blob, and the share of visible labels given; its time per frame beside the
baseline, one labelling step (`StageTracker.step`) on the same blobs.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from text_table import print_table  # noqa: E402

from samba.body.skeleton import markers_of  # noqa: E402
from samba.cameras.camera import CameraGroup  # noqa: E402
from samba.cameras.synthetic_cameras import detected_blobs, with_size  # noqa: E402
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take  # noqa: E402
from samba.markers.camera_chain import ChainSettings, run_chain  # noqa: E402
from samba.markers.cross_view_labels import CrossViewSettings  # noqa: E402
from samba.markers.lead_in import standing_lead_in  # noqa: E402
from samba.markers.observation import spread_cameras  # noqa: E402
from samba.markers.stage_tracking import StageTracker  # noqa: E402
from samba.markers.standard_pose_search import StandardPoseSearch  # noqa: E402
from samba.synthetic.motions import generate, random_standing  # noqa: E402

CONFIGURATIONS = (
    ("2 cameras", 2, (160, 120), "cross-view"),
    ("2 cameras", 2, (320, 240), "cross-view"),
    ("2 cameras", 2, (640, 480), "cross-view"),
    ("3 cameras", 3, (160, 120), "cross-view"),
    ("4 cameras", 4, (160, 120), "cross-view"),
    ("3 cameras", 3, (640, 480), "cross-view"),
    ("4 cameras", 4, (640, 480), "cross-view"),
    ("2 cameras, trackers alone", 2, (160, 120), "alone"),
    ("3 cameras, trackers alone", 3, (160, 120), "alone"),
    ("3 cameras, trackers alone", 3, (640, 480), "alone"),
    ("4 cameras, trackers alone", 4, (640, 480), "alone"),
    ("2 cameras, plain NN", 2, (160, 120), "plain"),
)
"""(row name, cameras, image size, labelling): "cross-view" the guarded trackers with
`CrossViewLabeller`, "alone" the guarded trackers by themselves, "plain" the paper's
nearest-neighbour filter."""


RETURN_CONFIGURATIONS = (
    ("2 cameras", 2, (320, 240), True),
    ("2 cameras, no search", 2, (320, 240), False),
    ("3 cameras", 3, (320, 240), True),
    ("3 cameras, no search", 3, (320, 240), False),
    ("3 cameras", 3, (640, 480), True),
    ("3 cameras, no search", 3, (640, 480), False),
    ("4 cameras", 4, (640, 480), True),
    ("4 cameras, no search", 4, (640, 480), False),
)
"""(row name, cameras, image size, search) of the leave-and-return table."""


def leave_and_return(poses: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray, int]:
    """A take (F, 13, 3) m filmed as the subject leaving and coming back (see the module
    docstring): the poses, those on the stage (for placing the cameras), and the frame
    where the second in the standard pose after the return ends."""
    half = len(poses) // 2
    first, second = poses[:half], poses[half:]
    turn = standing_lead_in(first, fps).heading_deg + 25.0
    turn -= standing_lead_in(second, fps).heading_deg
    hips = (second[0, 7] + second[0, 8]) / 2 * [1.0, 0.0, 1.0]
    turned = Rotation.from_euler("y", turn, degrees=True).apply((second - hips).reshape(-1, 3))
    start = (first[0, 7] + first[0, 8]) / 2 * [1.0, 0.0, 1.0]
    back = standing_lead_in(turned.reshape(second.shape) + start + [0.9, 0.0, -0.9], fps, 1.0)
    gone = np.repeat(first[-1:] + np.array([100.0, 0.0, 0.0]), round(fps), axis=0)  # away
    hold = half + len(gone) + round(fps)
    return np.concatenate([first, gone, back.poses]), np.concatenate([first, back.poses]), hold


def return_report(
    takes: list, seconds: float | None, configurations: tuple = RETURN_CONFIGURATIONS
) -> list[list[str]]:
    """The leave-and-return table of `configurations` (as `RETURN_CONFIGURATIONS`);
    prints and returns its rows."""
    rows = []
    for take in takes:
        poses = take.poses if seconds is None else take.poses[: round(seconds * take.fps)]
        filmed, on_stage, hold = leave_and_return(poses, take.fps)
        for name, count, size, search in configurations:
            cameras = [with_size(c, size) for c in spread_cameras(on_stage, count)]
            result = run_chain(filmed, cameras, take.fps, ChainSettings(search=search))
            seen = result.seen_by_two[hold:]
            lost = (seen & ~result.reconstructed[hold:]).sum() / max(int(seen.sum()), 1)
            rows.append(
                [
                    take.name,
                    name,
                    f"{size[0]}x{size[1]}",
                    f"{len(filmed)}",
                    f"{result.rms_error() * 100:.2f}",
                    f"{lost * 100:.1f}",
                    f"{result.lost_rate() * 100:.1f}",
                    f"{result.swaps()}",
                ]
            )
    header = ["take", "cameras", "image", "frames", "RMS cm", "lost after return %",
              "lost %", "swaps"]  # fmt: skip
    print("Leaving the stage and coming back elsewhere, in the standard pose")
    print_table(None, header, rows)
    return rows


PLACEMENT_SETTINGS = ((0.3, 3), (0.5, 10))
"""(pixel noise, stray spots per camera) of the placement table's rows."""


def placement_report(trials: int = 300, settings: tuple = PLACEMENT_SETTINGS) -> list[list[str]]:
    """The random-placement table (module docstring); prints and returns its rows."""
    cameras = CameraGroup(
        tuple(with_size(c, (320, 240)) for c in spread_cameras(generate("walk").poses, 3))
    )
    search = StandardPoseSearch(cameras)
    rows = []
    for noise, stray in settings:
        rng = np.random.default_rng(0)
        found = wrong = given = visible = 0
        search_s, step_s = [], []
        for _ in range(trials):
            markers = markers_of(random_standing(rng))
            pixels, blobs = detected_blobs(cameras, markers, rng, noise, stray)
            start = time.perf_counter()
            result = search.find(blobs)
            search_s.append(time.perf_counter() - start)
            stage = StageTracker.from_labels(cameras, pixels, cross_view=CrossViewSettings())
            start = time.perf_counter()
            stage.step(blobs)
            step_s.append(time.perf_counter() - start)
            visible += sum(c.in_image(uv).sum() for c, uv in zip(cameras, pixels, strict=True))
            if result is not None:
                labelled = ~np.isnan(result.labels[..., 0])
                off = np.linalg.norm(result.labels[labelled] - pixels[labelled], axis=-1)
                found += 1
                wrong += int((off > 1e-6).any())
                given += int(labelled.sum())
        search_ms, step_ms = np.median(search_s) * 1e3, np.median(step_s) * 1e3
        rows.append(
            [
                f"{noise:g}",
                f"{stray}",
                f"{trials}",
                f"{found / trials * 100:.1f}",
                f"{wrong}",
                f"{given / visible * 100:.1f}",
                f"{search_ms:.2f}",
                f"{search_ms / step_ms:.1f}x",
            ]
        )
    header = ["noise px", "stray spots", "frames", "found %", "wrong frames",
              "labels given %", "search ms p50", "vs labelling step"]  # fmt: skip
    print("Random subjects in the standard pose, three 320x240 cameras")
    print_table(None, header, rows)
    return rows


def chain_settings(labelling: str) -> ChainSettings:
    """The chain settings of a `CONFIGURATIONS` labelling."""
    if labelling == "cross-view":
        return ChainSettings()
    return ChainSettings(tracker={"guard_swaps": labelling == "alone"}, cross_view=None)


def default_takes() -> list[Path]:
    """iclone_007_05.bvh of the shared CMU data, if present."""
    env = os.environ.get("SAMBA_DATA")
    for base in ([Path(env)] if env else []) + [ROOT.parent / "shared" / "data"]:
        path = base / "cmu" / "iclone_007_05.bvh"
        if path.exists():
            return [path]
    return []


def report(paths: list[Path], seconds: float | None) -> list[list[str]]:
    """Run every configuration on every take; prints and returns the rows."""
    if paths:
        takes = [load_bvh_take(p, BvhImportOptions(skip_tpose=True)) for p in paths]
    else:
        takes = [generate("kick", seconds=seconds or 5.0, fps=30.0, seed=7)]
    rows = []
    for take in takes:
        poses = take.poses if seconds is None else take.poses[: round(seconds * take.fps)]
        for name, count, size, labelling in CONFIGURATIONS:
            cameras = [with_size(c, size) for c in spread_cameras(poses, count)]
            result = run_chain(poses, cameras, take.fps, chain_settings(labelling))
            rows.append(
                [
                    take.name,
                    name,
                    f"{size[0]}x{size[1]}",
                    f"{len(poses)}",
                    f"{result.rms_error() * 100:.2f}",
                    f"{result.missing_rate() * 100:.1f}",
                    f"{result.lost_rate() * 100:.1f}",
                    f"{result.seen_by_two.mean() * 100:.1f}",
                    f"{result.swaps()}",
                    f"{result.phantoms()}",
                ]
            )
    header = ["take", "cameras", "image", "frames", "RMS cm", "missing %", "lost %",
              "seen by 2 %", "swaps", "phantoms"]  # fmt: skip
    source = "held-out CMU" if paths else "synthetic kick (no CMU data found)"
    print(f"Camera chain: render -> detect -> track -> DLT; {source}")
    print_table(None, header, rows)
    return_report(takes, seconds)
    return rows


def main() -> None:
    """Command line entry."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("takes", nargs="*", type=Path, help="BVH files (default: iclone_007_05)")
    parser.add_argument("--seconds", type=float, help="only the first S seconds of each take")
    args = parser.parse_args()
    report(args.takes or default_takes(), args.seconds)
    placement_report()


if __name__ == "__main__":
    main()
