"""Start-up costs of the compiled kernels: the compile a first run pays, the cache load of
every later run, `samba --help`, and the time to a first reconstructed frame.

Run from the project root:  python bench/bench_startup.py [--compile] [--repeats 3]

Every number is a fresh process. `--compile` first deletes numba's cache of Samba's
kernels, so the first row is what the first run after an install pays (the cache is
rebuilt by that run). The baseline, in the same run, is the numpy path
(`SAMBA_KERNELS=numpy`): the same start-up without kernels.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from text_table import print_table  # noqa: E402

KERNEL_MODULES = (ROOT / "samba" / "reconstruct", ROOT / "db")
"""Folders whose `kernels` module numba caches in `__pycache__`."""
WARM = """
import time
start = time.perf_counter()
from samba.db.kernels import KERNELS as INDEX
from samba.reconstruct.kernels import KERNELS as RECONSTRUCTION
imported = time.perf_counter() - start
print(imported, RECONSTRUCTION.warm_up(), INDEX.warm_up())
"""
FIRST_FRAME = """
import time
start = time.perf_counter()
import numpy as np
from samba.body import markers_of
from samba.db import PoseIndex
from samba.reconstruct import METHODS
from samba.synthetic.motions import library
poses = np.concatenate([take.poses for take in library(1, 2.0)])
index = PoseIndex.build(poses)
reconstructor = METHODS["samba"].build(index)
reconstructor.step(markers_of(poses[5]).astype(np.float64))
print(time.perf_counter() - start)
"""


def run(code: str, kernels: bool) -> list[float]:
    """The numbers a fresh `python -c code` prints, with the kernels on or off."""
    env = dict(os.environ, SAMBA_KERNELS="numba" if kernels else "numpy")
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    return [float(x) for x in out.stdout.split()]


def seconds(command: list[str], kernels: bool) -> float:
    """Wall time of a fresh process running `command`, the kernels on or off."""
    env = dict(os.environ, SAMBA_KERNELS="numba" if kernels else "numpy")
    start = time.perf_counter()
    subprocess.run(command, env=env, capture_output=True, check=True)
    return time.perf_counter() - start


def runs(times: list[float]) -> str:
    """Seconds of each run, "a / b / c"."""
    return " / ".join(f"{t:.2f}" for t in times)


def clear_cache() -> int:
    """Delete numba's cached kernels of Samba; returns the files removed."""
    removed = 0
    for folder in KERNEL_MODULES:
        for cached in (folder / "__pycache__").glob("kernels.*.nb[ic]"):
            cached.unlink()
            removed += 1
    return removed


def main() -> None:
    """Command line entry."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--compile", action="store_true", help="clear the kernel cache first")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each row (default 3)")
    args = parser.parse_args()
    bench(args.compile, args.repeats)


def bench(compile_first: bool, repeats: int) -> list[list[str]]:
    """Measure every row (`compile_first`: clear the cache first); prints and returns them."""
    rows = []
    if compile_first:
        clear_cache()
        _, reconstruction, index = run(WARM, kernels=True)
        rows.append(["first run: compile the kernels", f"{reconstruction + index:.1f}", "-"])
    loads = [sum(run(WARM, kernels=True)) for _ in range(repeats)]
    rows.append(["later runs: import numba + load the cached kernels", runs(loads), "-"])
    samba = str(Path(sys.executable).with_name("samba"))
    helps = [seconds([samba, "--help"], kernels=True) for _ in range(repeats)]
    plain = [seconds([samba, "--help"], kernels=False) for _ in range(repeats)]
    rows.append(["samba --help", runs(helps), runs(plain)])
    frames = [run(FIRST_FRAME, kernels=True)[0] for _ in range(repeats)]
    numpy_frames = [run(FIRST_FRAME, kernels=False)[0] for _ in range(repeats)]
    label = "import, index 2,400 poses, samba reconstructor, one frame"
    rows.append([label, runs(frames), runs(numpy_frames)])
    print("Start-up, fresh processes, seconds (each run)")
    print_table(None, ["", "kernels", "baseline: numpy path"], rows)
    return rows


if __name__ == "__main__":
    main()
