"""The camera chain end to end on held-out motion: accuracy, missing markers, label swaps.

Run from the project root:  python bench/camera_chain_report.py [BVH ...] [--seconds S]

Each take (default: ../shared/data/cmu/iclone_007_05.bvh, or $SAMBA_DATA; a synthetic
kick without the data) is filmed by the synthetic rig (`samba.camera_chain.run_chain`):
render -> detect -> track -> triangulate, after a standing lead-in in the standard pose.
Rows: two EVALUATION.md cameras at 160x120, 320x240 and 640x480; three and four cameras
spread around the subject (`spread_cameras`) at 160x120 and 640x480, all with lost labels
found again across the cameras (`samba.cross_view_labels`); and, as the baselines
measured on the same frames, each camera's guarded tracker alone and the paper's plain
nearest-neighbour filter (`guard_swaps=False`). Columns: RMS 3D error (cm) over the
markers reconstructed where at least two cameras see them; missing = (frame, marker)
without a 3D position; lost = of those at least two cameras see, the share left without
one (what detection and tracking lose beyond occlusion); label swaps and phantoms summed
over cameras and frames.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from text_table import print_table  # noqa: E402

from ingest.bvh_take import BvhImportOptions, load_bvh_take  # noqa: E402
from samba.camera_chain import ChainSettings, run_chain  # noqa: E402
from samba.observation import spread_cameras  # noqa: E402
from samba.synthetic import generate  # noqa: E402
from samba.synthetic_cameras import with_size  # noqa: E402

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
    return rows


def main() -> None:
    """Command line entry."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("takes", nargs="*", type=Path, help="BVH files (default: iclone_007_05)")
    parser.add_argument("--seconds", type=float, help="only the first S seconds of each take")
    args = parser.parse_args()
    report(args.takes or default_takes(), args.seconds)


if __name__ == "__main__":
    main()
