"""Compiled kernels of the pose index (numba, `@njit(cache=True)`).

| kernel | numpy reference |
|---|---|
| `scan_kernel` | `_Tree._scan` (`samba.db.index`): a float32 ranking, re-ranked exactly |

A live frame queries one observation at a time; numpy's scan of it is a matrix product,
an `argpartition` of every pose and a re-ranking (about 0.23 ms at 16,000 poses), the
kernel one pass that keeps the k nearest as it goes (about 0.05 ms). Both give the exact
float64 distances of the k nearest (`tests/test_index_kernels.py`). `KERNELS` warms it
(`samba.base.KernelSet`).
"""

from __future__ import annotations

import numpy as np

from samba.base import KernelSet, compiled


@compiled(reassociate=True)
def scan_kernel(features: np.ndarray, queries: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The exact k nearest rows of `features` (n, D) float32 to each of `queries` (b, D),
    by Euclidean distance as the tree search re-ranks them (the query rounded to float32,
    differences in float32, their squares summed in float64): (distances (b, k) meters,
    row indices (b, k) int64), nearest first; of equally distant rows the first."""
    b = queries.shape[0]
    n, d = features.shape
    distances = np.empty((b, k))
    indices = np.empty((b, k), dtype=np.int64)
    best = np.empty(k)
    rows = np.empty(k, dtype=np.int64)
    for q in range(b):
        query = queries[q].astype(np.float32)
        best[:] = np.inf
        rows[:] = -1
        worst = np.inf
        for i in range(n):
            total = 0.0
            for j in range(d):
                diff = np.float64(features[i, j] - query[j])  # as the tree's re-ranking
                total += diff * diff
            if total < worst:
                p = k - 1
                while p > 0 and best[p - 1] > total:
                    best[p] = best[p - 1]
                    rows[p] = rows[p - 1]
                    p -= 1
                best[p] = total
                rows[p] = i
                worst = best[k - 1]
        distances[q] = np.sqrt(best)
        indices[q] = rows
    return distances, indices


def _example_scan() -> tuple[np.ndarray, np.ndarray]:
    """Compile `scan_kernel` for the index's argument types."""
    return scan_kernel(np.zeros((4, 24), dtype=np.float32), np.zeros((1, 24)), 2)


KERNELS = KernelSet("pose index", (scan_kernel,), (_example_scan,), estimate_s=2.0)
"""The index's kernels, warmed with every `PoseIndex` that scans."""
