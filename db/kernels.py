"""Compiled kernels of the pose index (numba, `@njit(cache=True)`).

| kernel | numpy reference |
|---|---|
| `scan_kernel` | `_Tree._scan` (`samba.db.index`): a float32 ranking, re-ranked exactly |
| `cells_kernel` | brute force (`scan_kernel`), over k-means cells (`samba.db.cells`) |
| `nearest_poses_kernel` | `PoseIndex.query` of complete observations by `cells_kernel` |
| `projected_kernel` | brute force over a masked table, read from the full table's cells |
| `turned_centers_kernel` | the cells' means and radii of features turned to another heading |
| `marker_features_kernel` | `marker_features` (`samba.db.index`) |
| `aligned_markers_kernel` | `align_markers` (`samba.body.alignment`) |

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
                _keep(best, rows, total, i)
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
    order: np.ndarray,
    queries: np.ndarray,
    k: int,
    eps: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The k nearest of `features` (n, D) float32, stored cell by cell (cell c holds rows
    starts[c]:starts[c + 1]) with their dimensions in `order` (D,), to each of `queries`
    (b, D) in the table's dimensions, distances as `scan_kernel` computes them: (distances
    (b, k) meters, rows (b, k) int64 in the stored order).

    The search reads the query's nearest cell, then the cells whose lower bound of the
    distance of any of their rows is below the k-th distance found, in order of that bound,
    and stops when the next bound times (1 + `eps`) is no less than the k-th distance:
    exact with eps = 0; otherwise each distance returned is at most (1 + eps) times the
    true one (the k-d tree's meaning of eps). The bound of cell c is the larger of
    |q - centroid_c| - radii[c] (every row lies within radii[c] of its centroid) and the
    distance from q to the bisector of c and q's nearest centroid, (|q - c|^2 -
    |q - nearest|^2) / (2 between[nearest, c]) less 1 um for the float32 assignment,
    `between` (cells, cells) the centroids' distances (every row lies in its nearest
    centroid's cell). A row whose distance over the first half of the dimensions (the
    centroids' widest) already reaches the k-th is not read further.
    """
    b = queries.shape[0]
    d = centroids.shape[1]
    distances = np.empty((b, k))
    indices = np.empty((b, k), dtype=np.int64)
    best = np.empty(k)
    rows = np.empty(k, dtype=np.int64)
    scratch = np.empty((2, centroids.shape[0]))
    query = np.empty(d, dtype=np.float32)
    for q in range(b):
        for j in range(d):
            query[j] = np.float32(queries[q, order[j]])
        _search_cells(features, starts, centroids, between, radii, query, eps, best, rows, scratch)
        distances[q] = np.sqrt(best)
        indices[q] = rows
    return distances, indices


@compiled(reassociate=True)
def nearest_poses_kernel(
    markers: np.ndarray,
    scale_by_tibia: bool,
    features: np.ndarray,
    starts: np.ndarray,
    centroids: np.ndarray,
    between: np.ndarray,
    radii: np.ndarray,
    order: np.ndarray,
    stored: np.ndarray,
    k: int,
    eps: float,
) -> tuple[np.ndarray, np.ndarray]:
    """`cells_kernel` of observations that share one set of markers present: markers
    (b, 8, 3) world meters (NaN = missing), aligned here by the markers present
    (`alignment_of`, `apply_alignment`); the cells of the table of those markers
    (`features` ... `order` as `cells_kernel` takes them) and `stored` (n,) the table row
    of each stored one. Returns (distances (b, k) meters, table rows (b, k)), what
    `PoseIndex.query` returns, in one call (a live frame's query)."""
    b = markers.shape[0]
    queries = np.empty((b, centroids.shape[1]))
    present = np.empty(N_MARKERS, dtype=np.bool_)
    origin = np.empty(3)
    turn = np.empty(4)
    aligned = np.empty((N_MARKERS, 3))
    for q in range(b):
        for i in range(N_MARKERS):
            present[i] = not np.isnan(markers[q, i, 0] + markers[q, i, 1] + markers[q, i, 2])
        alignment_of(markers[q], present, scale_by_tibia, origin, turn)
        apply_alignment(markers[q], origin, turn, aligned)
        slot = 0
        for i in range(N_MARKERS):
            if present[i]:
                for a in range(3):
                    queries[q, slot] = aligned[i, a]
                    slot += 1
    distances, rows = cells_kernel(
        features, starts, centroids, between, radii, order, queries, k, eps
    )
    indices = np.empty((b, k), dtype=np.int64)
    for q in range(b):
        for j in range(k):
            indices[q, j] = stored[rows[q, j]]
    return distances, indices


@compiled(reassociate=True)
def _search_cells(
    features: np.ndarray,
    starts: np.ndarray,
    centroids: np.ndarray,
    between: np.ndarray,
    radii: np.ndarray,
    query: np.ndarray,
    eps: float,
    best: np.ndarray,
    rows: np.ndarray,
    scratch: np.ndarray,
) -> None:
    """One query (D,) float32 in the stored dimensions: fills `best` (k,) with the squared
    distances of its k nearest and `rows` (k,) with their stored rows (`cells_kernel`);
    `scratch` (2, cells) holds the cells' bounds and the cells pending."""
    n_cells, d = centroids.shape
    bound = scratch[0]
    pending = scratch[1]
    slack = (1.0 + eps) ** 2
    nearest = 0
    for c in range(n_cells):
        total = 0.0
        for j in range(d):
            diff = centroids[c, j] - query[j]
            total += diff * diff
        bound[c] = total
        if total < bound[nearest]:
            nearest = c
    closest = bound[nearest]
    for c in range(n_cells):
        squared = bound[c]
        bound[c] = max(np.sqrt(squared) - radii[c], 0.0)
        if c != nearest and between[nearest, c] > 0.0:
            gap = (squared - closest) / (2.0 * between[nearest, c]) - 1e-6
            bound[c] = max(bound[c], gap)
    best[:] = np.inf
    rows[:] = -1
    half = d // 2
    worst = _read_cell(features, starts[nearest], starts[nearest + 1], query, half, best, rows)
    count = 0
    for c in range(n_cells):
        if c != nearest and bound[c] * bound[c] * slack < worst:
            pending[count] = c
            count += 1
    for visit in np.argsort(bound[pending[:count].astype(np.int64)]):
        c = int(pending[visit])
        if bound[c] * bound[c] * slack >= worst:
            break
        worst = _read_cell(features, starts[c], starts[c + 1], query, half, best, rows)


@compiled(reassociate=True)
def _read_cell(
    features: np.ndarray,
    first: int,
    end: int,
    query: np.ndarray,
    half: int,
    best: np.ndarray,
    rows: np.ndarray,
) -> float:
    """Rows first:end of `features` (n, D) float32 against `query` (D,) float32, kept in
    the k nearest so far (`best` (k,) squared distances, `rows` (k,), nearest first); a
    row is dropped once its distance over the first `half` dimensions reaches the k-th.
    Returns the k-th squared distance."""
    k = len(best)
    d = features.shape[1]
    worst = best[k - 1]
    for i in range(first, end):
        total = 0.0
        for j in range(half):
            diff = np.float64(features[i, j] - query[j])
            total += diff * diff
        if total >= worst:
            continue
        for j in range(half, d):
            diff = np.float64(features[i, j] - query[j])
            total += diff * diff
        if total < worst:
            _keep(best, rows, total, i)
            worst = best[k - 1]
    return worst


@compiled
def _keep(best: np.ndarray, rows: np.ndarray, total: float, row: int) -> None:
    """Insert `row` at squared distance `total` into the k nearest so far (`best` (k,)
    ascending, `rows` (k,)), dropping the k-th."""
    p = len(best) - 1
    while p > 0 and best[p - 1] > total:
        best[p] = best[p - 1]
        rows[p] = rows[p - 1]
        p -= 1
    best[p] = total
    rows[p] = row


@compiled(reassociate=True)
def projected_kernel(
    features: np.ndarray,
    starts: np.ndarray,
    order: np.ndarray,
    centers: np.ndarray,
    radii: np.ndarray,
    pair: np.ndarray,
    keep: np.ndarray,
    queries: np.ndarray,
    k: int,
) -> tuple[np.ndarray, np.ndarray]:
    """The exact k nearest poses to observations with markers missing, read from the full
    table's cells (`features` (n, 24) float32 in cell order with dimensions in `order`,
    `starts`) without a masked table: (distances (b, k) meters, rows (b, k) in the stored
    order).

    A pose's masked features follow from its full ones (aligned by all 8 markers, heading
    from the shoulders): turned about +Y so that the markers of heading `pair` (2,) lie
    along +X (`pair` = (-1, -1) when the shoulders give the heading, no turn), then the
    markers in `keep` (8,) bool taken and centred on their mean. `queries` (b, 3 m) are
    the observations' features over the m markers kept (`align_markers` with the others
    masked). Cells are read in order of the bound |q - P center_c| - radii[c], `centers`
    (cells, 24) the cells' means of the turned features (table dimensions), `radii` (cells,)
    the largest distance of a turned feature from them, P the masking and centring (it
    shortens no distance): exact, up to the features' float32 rounding (about 1e-7 m).
    """
    b = queries.shape[0]
    n_cells = centers.shape[0]
    kept = np.flatnonzero(keep)
    position = np.argsort(order)
    column = np.empty((N_MARKERS, 3), dtype=np.int64)
    for i in range(N_MARKERS):
        for a in range(3):
            column[i, a] = position[3 * i + a]
    distances = np.empty((b, k))
    indices = np.empty((b, k), dtype=np.int64)
    best = np.empty(k)
    rows = np.empty(k, dtype=np.int64)
    bound = np.empty(n_cells)
    turned = np.empty((N_MARKERS, 3))
    mean = np.empty(3)
    for q in range(b):
        query = queries[q]
        for c in range(n_cells):
            for i in range(N_MARKERS):
                for a in range(3):
                    turned[i, a] = centers[c, 3 * i + a]
            bound[c] = max(np.sqrt(_masked_distance(turned, kept, query, mean)) - radii[c], 0.0)
        best[:] = np.inf
        rows[:] = -1
        worst = np.inf
        for c in np.argsort(bound):
            if bound[c] * bound[c] >= worst:
                break
            for r in range(starts[c], starts[c + 1]):
                if pair[0] < 0:  # shoulders kept: no turn, the kept columns read in place
                    total = _centred_distance(features, r, column, kept, query)
                else:
                    _turned_row(features, r, column, pair, turned)
                    total = _masked_distance(turned, kept, query, mean)
                if total < worst:
                    _keep(best, rows, total, r)
                    worst = best[k - 1]
        distances[q] = np.sqrt(best)
        indices[q] = rows
    return distances, indices


@compiled(reassociate=True)
def _centred_distance(
    features: np.ndarray, r: int, column: np.ndarray, kept: np.ndarray, query: np.ndarray
) -> float:
    """`_masked_distance` of row r of `features` unturned, read in place: with the query
    centred, |x - mean - q|^2 = |x - q|^2 - |sum x|^2 / m over the m `kept` markers;
    `column` (8, 3) the stored column of each marker coordinate."""
    total = 0.0
    sx = sy = sz = 0.0
    for s in range(len(kept)):
        i = kept[s]
        x = np.float64(features[r, column[i, 0]])
        y = np.float64(features[r, column[i, 1]])
        z = np.float64(features[r, column[i, 2]])
        sx += x
        sy += y
        sz += z
        dx, dy, dz = x - query[3 * s], y - query[3 * s + 1], z - query[3 * s + 2]
        total += dx * dx + dy * dy + dz * dz
    return total - (sx * sx + sy * sy + sz * sz) / len(kept)


@compiled
def _turned_row(
    features: np.ndarray, r: int, column: np.ndarray, pair: np.ndarray, out: np.ndarray
) -> None:
    """Row r of `features` as markers (8, 3) into `out`, turned about +Y so that the line
    between the markers of `pair` (2,) points along +X (unturned for pair (-1, -1));
    `column` (8, 3) the stored column of each marker coordinate."""
    for i in range(N_MARKERS):
        for a in range(3):
            out[i, a] = features[r, column[i, a]]
    if pair[0] < 0:
        return
    line_x = out[pair[0], 0] - out[pair[1], 0]
    line_z = out[pair[0], 2] - out[pair[1], 2]
    length = np.sqrt(line_x * line_x + line_z * line_z)
    cos, sin = (line_x / length, line_z / length) if length > 0.0 else (1.0, 0.0)
    for i in range(N_MARKERS):
        x, z = out[i, 0], out[i, 2]
        out[i, 0] = cos * x + sin * z
        out[i, 2] = cos * z - sin * x


@compiled
def _masked_distance(
    markers: np.ndarray, kept: np.ndarray, query: np.ndarray, mean: np.ndarray
) -> float:
    """Squared distance between `markers` (8, 3) over the `kept` ones, centred on their
    mean, and `query` (3 len(kept),); `mean` (3,) is scratch."""
    mean[:] = 0.0
    for i in kept:
        for a in range(3):
            mean[a] += markers[i, a]
    mean /= len(kept)
    total = 0.0
    for s in range(len(kept)):
        for a in range(3):
            diff = markers[kept[s], a] - mean[a] - query[3 * s + a]
            total += diff * diff
    return total


@compiled
def turned_centers_kernel(
    features: np.ndarray, starts: np.ndarray, order: np.ndarray, pair: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each cell's mean (cells, 24) of its rows turned as `projected_kernel` turns them for
    heading `pair` (2,), in the table's dimensions, and the largest distance (cells,) of a
    turned row from it, with a margin for float32 rounding (meters)."""
    n_cells = len(starts) - 1
    position = np.argsort(order)
    column = np.empty((N_MARKERS, 3), dtype=np.int64)
    for i in range(N_MARKERS):
        for a in range(3):
            column[i, a] = position[3 * i + a]
    centers = np.zeros((n_cells, 3 * N_MARKERS))
    radii = np.zeros(n_cells)
    turned = np.empty((N_MARKERS, 3))
    for c in range(n_cells):
        for r in range(starts[c], starts[c + 1]):
            _turned_row(features, r, column, pair, turned)
            for i in range(N_MARKERS):
                for a in range(3):
                    centers[c, 3 * i + a] += turned[i, a]
        centers[c] /= max(starts[c + 1] - starts[c], 1)
        for r in range(starts[c], starts[c + 1]):
            _turned_row(features, r, column, pair, turned)
            total = 0.0
            for i in range(N_MARKERS):
                for a in range(3):
                    diff = turned[i, a] - centers[c, 3 * i + a]
                    total += diff * diff
            radii[c] = max(radii[c], np.sqrt(total))
    return centers, radii * (1.0 + 1e-6) + 1e-6


@compiled
def aligned_markers_kernel(markers: np.ndarray, scale_by_tibia: bool) -> np.ndarray:
    """`align_markers`: observations (b, 8, 3) world meters, NaN = missing, in the
    canonical frame of their own markers present (b, 8, 3); missing stay NaN."""
    out = np.empty_like(markers)
    present = np.empty(N_MARKERS, dtype=np.bool_)
    origin = np.empty(3)
    turn = np.empty(4)
    for q in range(markers.shape[0]):
        for i in range(N_MARKERS):
            present[i] = not np.isnan(markers[q, i, 0] + markers[q, i, 1] + markers[q, i, 2])
        alignment_of(markers[q], present, scale_by_tibia, origin, turn)
        apply_alignment(markers[q], origin, turn, out[q])
    return out


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
    """Compile `cells_kernel`, `projected_kernel` and `turned_centers_kernel` for the
    index's argument types."""
    features = np.zeros((4, 24), dtype=np.float32)
    starts = np.array([0, 2, 4])
    centroids = np.zeros((2, 24))
    order = np.arange(24)
    pair = np.array([4, 5])
    keep = np.ones(N_MARKERS, dtype=np.bool_)
    keep[0] = False
    centers, radii = turned_centers_kernel(features, starts, order, pair)
    projected_kernel(features, starts, order, centers, radii, pair, keep, np.zeros((1, 21)), 2)
    arguments = (features, starts, centroids, np.ones((2, 2)), np.zeros(2), order)
    nearest_poses_kernel(np.ones((1, N_MARKERS, 3)), False, *arguments, np.arange(4), 2, 0.0)
    return cells_kernel(*arguments, np.zeros((1, 24)), 2, 0.0)


def _example_features() -> np.ndarray:
    """Compile `marker_features_kernel` for the index's argument types (float32 and
    float64 poses: a store's memory map and arrays) and `aligned_markers_kernel`."""
    aligned_markers_kernel(np.ones((1, N_MARKERS, 3)), False)
    keep = np.ones(N_MARKERS, dtype=np.bool_)
    marker_features_kernel(np.ones((1, 13, 3), dtype=np.float32), keep, False)
    return marker_features_kernel(np.ones((1, 13, 3)), keep, False)


KERNELS = KernelSet(
    "pose index",
    (
        scan_kernel,
        cells_kernel,
        nearest_poses_kernel,
        projected_kernel,
        turned_centers_kernel,
        aligned_markers_kernel,
        marker_features_kernel,
    ),
    (_example_scan, _example_cells, _example_features),
    estimate_s=8.0,
)
"""The index's kernels, warmed with every `PoseIndex`."""
