"""Export speed and the round trip of every CMU file through every format.

Run from the project root:  python bench/bench_export.py [--frames 10000] [--roundtrip]

Speed: a synthetic walk of `--frames` frames at 30 fps (default 10,000), retargeted to
the default mannequin and written as .usda, .usdc, .glb (with the skinned mannequin) and
.bvh. Baseline, measured in the same run: the take's raw 13-joint positions written as
text with `np.savetxt`. Targets (issue 5): retargeting >= 20,000 frames/s, every writer
<= 5 s for 10,000 frames. Single-threaded BLAS (threadpoolctl).

Round trip (`--roundtrip`): every BVH file under the data folder (../shared/data or
$SAMBA_DATA) -> 13 joints -> retarget -> each format -> joint positions read back by a
reader we did not write where one exists (UsdSkel for USD, our FK of the glTF nodes and
samplers, our BVH reader) -> the largest distance to the retargeted joints (mm) and the
largest bone-direction error against the capture (degrees).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from text_table import print_table  # noqa: E402

from samba.export.avatar_mesh import AvatarMesh  # noqa: E402
from samba.export.bvh_writer import write_bvh  # noqa: E402
from samba.export.gltf_reader import read_glb_joint_positions  # noqa: E402
from samba.export.gltf_writer import write_glb  # noqa: E402
from samba.export.humanoid import BONE_NAMES, HumanoidRig  # noqa: E402
from samba.export.mannequin import mannequin  # noqa: E402
from samba.export.motion import HumanoidMotion  # noqa: E402
from samba.export.retargeting import bone_direction_errors, retarget  # noqa: E402
from samba.export.usd_reader import read_usd_joint_positions  # noqa: E402
from samba.export.usd_writer import write_usd  # noqa: E402
from samba.ingest.bvh import read_bvh  # noqa: E402
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take  # noqa: E402
from samba.synthetic.motions import generate  # noqa: E402

TARGET_RETARGET_FPS = 20_000
TARGET_WRITE_SECONDS = 5.0
FORMATS = (".usda", ".usdc", ".glb", ".bvh")


def write(path: Path, motion: HumanoidMotion, mesh: AvatarMesh) -> None:
    """Write `motion` to `path` in the format its suffix names (mesh for USD / glTF)."""
    if path.suffix == ".bvh":
        write_bvh(path, motion)
    elif path.suffix == ".glb":
        write_glb(path, motion, mesh)
    else:
        write_usd(path, motion, mesh)


def read_back(path: Path) -> np.ndarray:
    """Joint world positions (n, 17, 3) in meters, in bone order, read from an export."""
    if path.suffix == ".bvh":
        bvh = read_bvh(path)
        return bvh.positions([bvh.names.index(name) for name in BONE_NAMES])
    reader: Callable[[Path], tuple[tuple[str, ...], np.ndarray]] = (
        read_glb_joint_positions if path.suffix == ".glb" else read_usd_joint_positions
    )
    names, positions = reader(path)
    return positions[:, [names.index(name) for name in BONE_NAMES]]


def _best_seconds(run: Callable[[], object], repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - start)
    return best


def bench_speed(frames: int, repeats: int = 3) -> None:
    """Print the speed table for a synthetic take of `frames` frames."""
    take = generate("walk", seconds=frames / 30.0, fps=30.0, seed=1)
    rig = HumanoidRig.from_body()
    mesh = mannequin(rig)
    motion = retarget(take.poses, rig, take.fps)
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder)
        flat = take.poses.reshape(len(take), -1)
        baseline = _best_seconds(lambda: np.savetxt(out / "raw.txt", flat, fmt="%.6f"), repeats)
        rows = [
            [
                "baseline: np.savetxt of 13 joints",
                f"{baseline:.3f}",
                len(take) / baseline,
                "1.0",
                "",
            ]
        ]
        seconds = _best_seconds(lambda: retarget(take.poses, rig, take.fps), repeats)
        rows.append(
            [
                "retarget",
                f"{seconds:.3f}",
                len(take) / seconds,
                f"{seconds / baseline:.2f}",
                "met" if len(take) / seconds >= TARGET_RETARGET_FPS else "NOT met",
            ]
        )
        for suffix in FORMATS:
            path = out / f"take{suffix}"
            seconds = _best_seconds(lambda p=path: write(p, motion, mesh), repeats)
            size = path.stat().st_size / 2**20
            rows.append(
                [
                    f"write {suffix} ({size:.1f} MiB)",
                    f"{seconds:.3f}",
                    len(take) / seconds,
                    f"{seconds / baseline:.2f}",
                    "met" if seconds <= TARGET_WRITE_SECONDS else "NOT met",
                ]
            )
    print_table(
        f"Export of a {len(take)}-frame take (best of {repeats}; mannequin of "
        f"{len(mesh.faces)} triangles); targets: retarget >= {TARGET_RETARGET_FPS} frames/s, "
        f"each writer <= {TARGET_WRITE_SECONDS:g} s",
        ["step", "seconds", "frames/s", "x baseline", "target"],
        rows,
    )


def bench_roundtrip(files: list[Path]) -> None:
    """Print the round-trip table over BVH `files`."""
    rig = HumanoidRig.from_body()
    mesh = mannequin(rig)
    rows = []
    worst_mm = dict.fromkeys(FORMATS, 0.0)
    worst_deg = dict.fromkeys(FORMATS, 0.0)
    with tempfile.TemporaryDirectory() as folder:
        for file in files:
            take = load_bvh_take(file, BvhImportOptions(fps=None))
            motion = retarget(take.poses, rig, take.fps)
            expected = motion.world_positions()
            row: list[object] = [file.stem, len(take)]
            for suffix in FORMATS:
                path = Path(folder) / f"take{suffix}"
                write(path, motion, mesh)
                got = read_back(path)
                mm = 1000 * float(np.linalg.norm(got - expected, axis=-1).max())
                deg = float(bone_direction_errors(got, take.poses).max())
                worst_mm[suffix] = max(worst_mm[suffix], mm)
                worst_deg[suffix] = max(worst_deg[suffix], deg)
                row += [f"{mm:.4f}", f"{deg:.4f}"]
            rows.append(row)
    rows.append(
        ["worst", ""] + [c for s in FORMATS for c in (f"{worst_mm[s]:.4f}", f"{worst_deg[s]:.4f}")]
    )
    header = ["take", "frames"] + [f"{s} {m}" for s in FORMATS for m in ("mm", "deg")]
    print_table(
        f"Round trip of {len(files)} BVH files: BVH -> 13 joints -> retarget -> file -> joints "
        "(mm: largest distance to the retargeted joints; deg: largest bone-direction error "
        "against the capture)",
        header,
        rows,
    )


def data_files() -> list[Path]:
    """Every .bvh under $SAMBA_DATA or ../shared/data (empty when neither exists)."""
    root = Path(os.environ.get("SAMBA_DATA", ROOT.parent / "shared" / "data"))
    return sorted(root.rglob("*.bvh")) if root.is_dir() else []


def main() -> None:
    """Run the benchmark from the command line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--roundtrip",
        action="store_true",
        help="also run every BVH file of the data folder through every format",
    )
    args = parser.parse_args()
    with threadpool_limits(1):
        bench_speed(args.frames, args.repeats)
        if args.roundtrip:
            files = data_files()
            if not files:
                print("\nRound trip skipped: no BVH files in $SAMBA_DATA or ../shared/data")
            else:
                bench_roundtrip(files)


if __name__ == "__main__":
    main()
