"""Numba kernels compiled once per install, never on a live clock.

A subpackage with compiled kernels (its `kernels` module) lists them as `KernelSet`s: each
kernel with a small example call that compiles it. `KernelSet.warm_up` runs those calls
once per process; numba then loads the machine code it cached on disk (`cache=True`,
a fraction of a second) or, on the first run after an install, compiles it, and says so
first on stderr: `samba: compiling reconstruction kernels, once: ~20 s`. `samba warmup`
warms every set ahead of a live session; constructors of the objects that use kernels
(e.g. `Reconstructor`) warm theirs, so the first frame does not pay it.

`NUMBA_AVAILABLE` is False where numba cannot be imported; `SAMBA_KERNELS=numpy` in the
environment turns every kernel off (`kernels_enabled`), and the numpy references run.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TextIO

NUMBA_AVAILABLE = importlib.util.find_spec("numba") is not None
"""Whether numba is installed (it is imported only by the `kernels` modules, which are
imported on first use: its 0.2 s import stays off commands that run no kernel)."""


def kernels_enabled() -> bool:
    """Whether compiled kernels run: numba is available and `SAMBA_KERNELS` is not "numpy"."""
    return NUMBA_AVAILABLE and os.environ.get("SAMBA_KERNELS", "numba") != "numpy"


def usable_cores() -> int:
    """The CPU cores this process may run on (its affinity where the OS has one), at most
    `OMP_NUM_THREADS` when that is set (Dask sets it to 1 in its workers, one per core):
    how many threads a batch of compiled-kernel work is split over."""
    if hasattr(os, "sched_getaffinity"):
        cores = len(os.sched_getaffinity(0))
    else:
        cores = os.cpu_count() or 1
    limit = os.environ.get("OMP_NUM_THREADS", "")
    if limit.isdigit() and int(limit) > 0:
        return min(cores, int(limit))
    return cores


def compiled(function: Callable | None = None, *, reassociate: bool = False) -> Callable:
    """`function` as a numba kernel (`@njit(cache=True, nogil=True)`, numpy's error model:
    a division by zero gives inf or NaN as in its numpy reference, not an exception);
    unchanged (plain Python, never called by the reconstruction) when numba is not
    available. `@compiled(reassociate=True)` lets sums be reordered (and vectorised):
    results then differ from the reference's in the last bits only; infinities and NaN
    keep their meaning (no other fast-math flag)."""
    if function is None:
        return lambda f: compiled(f, reassociate=reassociate)
    if not NUMBA_AVAILABLE:
        return function
    from numba import njit

    fastmath = {"reassoc", "contract"} if reassociate else False
    return njit(cache=True, nogil=True, error_model="numpy", fastmath=fastmath)(function)


@dataclass
class KernelSet:
    """The kernels of one subpackage: `name` (for the message), `kernels` (the numba
    dispatchers) and `examples` (calls that compile them, run in order), `estimate_s` the
    compile time measured on a quiet 2-core machine (seconds)."""

    name: str
    kernels: Sequence[Callable]
    examples: Sequence[Callable[[], object]]
    estimate_s: float
    warmed: bool = field(default=False, init=False)
    _warming: threading.Lock = field(default_factory=threading.Lock, init=False, repr=False)

    def is_cached(self) -> bool:
        """Whether numba's disk cache holds every kernel of the set (so warming loads it
        rather than compiling)."""
        for kernel in self.kernels:
            cache = getattr(kernel, "_cache", None)
            index = getattr(getattr(cache, "_cache_file", None), "_index_path", None)
            if index is not None and not os.path.exists(index):
                return False
        return True

    def warm_up(self, stream: TextIO | None = None) -> float:
        """Compile or load the kernels, once per process; returns the seconds it took
        (0 when already warm or kernels are off). Prints one line to `stream` (default
        stderr) before a compile. Thread-safe: a second caller waits for the first."""
        if self.warmed or not kernels_enabled():
            return 0.0
        with self._warming:
            if self.warmed:
                return 0.0
            if not self.is_cached():
                print(
                    f"samba: compiling {self.name} kernels, once: ~{self.estimate_s:.0f} s",
                    file=stream or sys.stderr,
                    flush=True,
                )
            start = time.perf_counter()
            for example in self.examples:
                example()
            self.warmed = True
            return time.perf_counter() - start
