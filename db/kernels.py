"""Compiled kernels of the pose index (numba, `@njit(cache=True)`).

| kernel | numpy reference |
|---|---|
| `scan_kernel` | `_Tree._scan` (`samba.db.index`): a float32 ranking, re-ranked exactly |
| `cells_kernel` | brute force (`scan_kernel`), over k-means cells (`samba.db.cells`) |
| `marker_features_kernel` | `marker_features` (`samba.db.index`) |

A live frame queries one observation at a time; numpy's scan of it is a matrix product,
an `argpartition` of every pose and a re-ranking (about 0.23 ms at 16,000 poses), the
kernel one pass that keeps the k nearest as it goes (about 0.05 ms). Both give the exact
float64 distances of the k nearest (`tests/test_index_kernels.py`). `KERNELS` warms it
(`samba.base.KernelSet`).
"""

from __future__ import annotations

import numpy as np

from samba.base import KernelSet, compiled
from samba.body import MARKER_JOINTS, N_MARKERS
from samba.body.kernels import alignment_of, apply_alignment

_MARKER_JOINTS = np.array(MARKER_JOINTS)


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


@compiled(reassociate=True)
def cells_kernel(
    features: np.ndarray,
    starts: np.ndarray,
    centroids: np.ndarray,
    between: np.ndarray,
    radii: np.ndarray,
    queries: np.ndarray,
    k: int,
    eps: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The k nearest of `features` (n, D) float32, stored cell by cell (cell c holds rows
    starts[c]:starts[c + 1]), to each of `queries` (b, D), distances as `scan_kernel`
    computes them: (distances (b, k) meters, rows (b, k) int64 in the stored order).

    Cells are visited in order of a lower bound of the distance of any of their rows and
    the search stops when the next bound times (1 + `eps`) is no less than the k-th
    distance found: exact with eps = 0; otherwise each distance returned is at most
    (1 + eps) times the true one (the k-d tree's meaning of eps). The bound of cell c is
    the larger of |q - centroid_c| - radii[c] (every row lies within radii[c] of its
    centroid) and the distance from q to the bisector of c and q's nearest centroid,
    (|q - c|^2 - |q - nearest|^2) / (2 between[nearest, c]), `between` (cells, cells)
    the centroids' distances (every row lies in its nearest centroid's cell).
    """
    b = queries.shape[0]
    n_cells, d = centroids.shape
    distances = np.empty((b, k))
    indices = np.empty((b, k), dtype=np.int64)
    best = np.empty(k)
    rows = np.empty(k, dtype=np.int64)
    squared = np.empty(n_cells)
    bound = np.empty(n_cells)
    for q in range(b):
        query = queries[q].astype(np.float32)
        for c in range(n_cells):
            total = 0.0
            for j in range(d):
                diff = centroids[c, j] - query[j]
                total += diff * diff
            squared[c] = total
        nearest = np.argmin(squared)
        for c in range(n_cells):
            bound[c] = max(np.sqrt(squared[c]) - radii[c], 0.0)
            if c != nearest:
                gap = (squared[c] - squared[nearest]) / (2.0 * between[nearest, c])
                bound[c] = max(bound[c], gap)
        order = np.argsort(bound)
        best[:] = np.inf
        rows[:] = -1
        worst = np.inf
        slack = (1.0 + eps) ** 2
        for visit in range(n_cells):
            c = order[visit]
            if bound[c] * bound[c] * slack >= worst:
                break
            for i in range(starts[c], starts[c + 1]):
                total = 0.0
                for j in range(d):
                    diff = np.float64(features[i, j] - query[j])
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


@compiled
def marker_features_kernel(poses: np.ndarray, keep: np.ndarray, scale_by_tibia: bool) -> np.ndarray:
    """`marker_features`: the markers in `keep` (8,) bool of poses (n, 13, 3) meters,
    aligned with the other markers masked, as (n, 3 * keep.sum()) float32."""
    n = poses.shape[0]
    kept = np.flatnonzero(keep)
    out = np.empty((n, 3 * len(kept)), dtype=np.float32)
    markers = np.empty((N_MARKERS, 3))
    aligned = np.empty((N_MARKERS, 3))
    origin = np.empty(3)
    turn = np.empty(4)
    for i in range(n):
        for m in range(N_MARKERS):
            for c in range(3):
                markers[m, c] = poses[i, _MARKER_JOINTS[m], c]
        alignment_of(markers, keep, scale_by_tibia, origin, turn)
        apply_alignment(markers, origin, turn, aligned)
        for slot in range(len(kept)):
            for c in range(3):
                out[i, 3 * slot + c] = aligned[kept[slot], c]
    return out


def _example_scan() -> tuple[np.ndarray, np.ndarray]:
    """Compile `scan_kernel` for the index's argument types."""
    return scan_kernel(np.zeros((4, 24), dtype=np.float32), np.zeros((1, 24)), 2)


def _example_cells() -> tuple[np.ndarray, np.ndarray]:
    """Compile `cells_kernel` for the index's argument types."""
    features = np.zeros((4, 24), dtype=np.float32)
    starts = np.array([0, 2, 4])
    centroids = np.zeros((2, 24))
    return cells_kernel(
        features, starts, centroids, np.ones((2, 2)), np.zeros(2), np.zeros((1, 24)), 2, 0.0
    )


def _example_features() -> np.ndarray:
    """Compile `marker_features_kernel` for the index's argument types (float32 and
    float64 poses: a store's memory map and arrays)."""
    keep = np.ones(N_MARKERS, dtype=np.bool_)
    marker_features_kernel(np.ones((1, 13, 3), dtype=np.float32), keep, False)
    return marker_features_kernel(np.ones((1, 13, 3)), keep, False)


KERNELS = KernelSet(
    "pose index",
    (scan_kernel, cells_kernel, marker_features_kernel),
    (_example_scan, _example_cells, _example_features),
    estimate_s=8.0,
)
"""The index's kernels, warmed with every `PoseIndex`."""
