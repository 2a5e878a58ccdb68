"""Joint-specific retrieval: unobserved joints re-estimated from the poses nearest in the
markers that matter for them.

The main reconstruction finds neighbours by all 8 markers, so a wrist's neighbours are
chosen as much by the legs as by the arm; the elbow between them comes out 7-9 cm off.
Here each `Part` queries the pose index again with only its own markers (an elbow: both
shoulders and its wrist; the hips: all but the wrists; the head: shoulders and knees),
aligns the neighbours by those markers, and takes their kernel-weighted mean of the
part's joints. The estimate is blended into the main one with the part's weight.
Measured with `samba eval` (docs/reconstruction.md): elbows 7-8 cm -> 5.5 cm, hips
4.2 -> 3.5 cm, head 2.3 -> 2.1 cm. With a ridge the part's estimate is instead a locally
weighted linear regression on its markers over the same neighbours
(`samba.reconstruct.local_regression`), blended with `REGRESSION_PARTS`' weights.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from samba.base import kernels_enabled
from samba.body import N_JOINTS, N_MARKERS, Alignment, has_heading, markers_of
from samba.reconstruct.local_regression import local_regression
from samba.reconstruct.neighbours import NeighbourSource


@dataclass(frozen=True)
class Part:
    """Joints (indices) re-estimated from the markers (marker indices) that locate them;
    `weight` in [0, 1] of the part estimate against the main reconstruction."""

    joints: tuple[int, ...]
    markers: tuple[int, ...]
    weight: float


PARTS: tuple[Part, ...] = (
    Part((3,), (0, 1, 2), 0.7),  # left elbow: shoulders, left wrist
    Part((4,), (0, 1, 3), 0.7),  # right elbow: shoulders, right wrist
    Part((7, 8), (0, 1, 4, 5, 6, 7), 0.5),  # hips: shoulders, knees, feet
    Part((0,), (0, 1, 4, 5), 0.4),  # head: shoulders, knees
)
"""The parts `best` uses; masks and weights chosen on a validation third of the CMU takes."""
REGRESSION_PARTS: tuple[Part, ...] = (
    *(replace(part, weight=0.7) for part in PARTS[:2]),
    Part((0, 7, 8), (0, 1, 4, 5, 6, 7), 0.7),  # head and hips: shoulders, knees, feet
)
"""The parts of the regression (`lwr`), each blended at 0.7 (0.6-0.9 tried): `PARTS`' elbows
and hips, the head with the hips (1.86 cm against 1.89 by shoulders and knees, and one
query less); regressions on both wrists for the elbows (5.40 against 5.22 cm), on every
marker for the hips (3.31 against 2.96 cm) or on shoulders and knees (3.24) came out
worse. Chosen leave-one-take-out over the takes outside the validation split (issue 44)."""


def _part_markers(parts: tuple[Part, ...]) -> np.ndarray:
    """Each part's markers as a row of a (parts, 8) bool table."""
    table = np.zeros((len(parts), N_MARKERS), dtype=bool)
    for row, part in enumerate(parts):
        table[row, list(part.markers)] = True
    return table


_PART_MARKERS = {parts: _part_markers(parts) for parts in (PARTS, REGRESSION_PARTS)}


def refine_with_parts(
    source: NeighbourSource,
    markers: np.ndarray,
    poses: np.ndarray,
    k: int,
    eps: float = 0.0,
    ridge: float = 0.0,
) -> np.ndarray:
    """Poses (b, 13, 3) with each part's joints blended towards its own estimate.

    `markers` (b, 8, 3) world meters (NaN = missing); `k` neighbours per part, `eps` the
    index query's approximation (every part in one query). `ridge` 0 takes the
    neighbours' kernel-weighted mean (`PARTS`), > 0 (m^2) their local linear regression
    with that ridge (`REGRESSION_PARTS`). A frame whose part markers lack a complete
    left/right pair keeps the main estimate for that part.
    """
    parts = REGRESSION_PARTS if ridge else PARTS
    out = np.array(poses, dtype=np.float64)
    keep = _PART_MARKERS[parts]  # (parts, 8)
    masked = np.where(keep[:, None, :, None], markers[None], np.nan)  # (parts, b, 8, 3)
    present = keep[:, None] & ~np.isnan(markers).any(axis=-1)[None]
    ok = has_heading(present.reshape(-1, N_MARKERS)).reshape(len(parts), -1)
    ok &= present.sum(axis=-1) >= 3
    if not ok.any():
        return out
    queried = masked[ok]
    distances, rows = source.query(queried, k=k, eps=eps)
    neighbours = np.asarray(source.poses[rows.reshape(-1)], dtype=np.float64)
    neighbours = neighbours.reshape(len(queried), k, N_JOINTS, 3)
    scale = bool(source.scale_by_tibia)
    counts = ok.sum(axis=1)
    ends = np.cumsum(counts)
    if ridge:
        joints = np.full((len(queried), max(len(part.joints) for part in parts)), -1)
        for part, count, end in zip(parts, counts, ends, strict=True):
            joints[end - count : end, : len(part.joints)] = part.joints
        estimates = local_regression(queried, neighbours, distances, joints, scale, ridge)
    else:
        estimates = neighbour_mean(queried, neighbours, distances, scale)
    for part, chosen, count, end in zip(parts, ok, counts, ends, strict=True):
        joints = list(part.joints)
        estimate = estimates[end - count : end]
        estimate = estimate[:, : len(joints)] if ridge else estimate[:, joints]
        rows = np.flatnonzero(chosen)
        blended = (1.0 - part.weight) * out[rows][:, joints] + part.weight * estimate
        out[rows[:, None], joints] = blended
    return out


def neighbour_mean(
    markers: np.ndarray, neighbours: np.ndarray, distances: np.ndarray, scale_by_tibia: bool
) -> np.ndarray:
    """Kernel-weighted mean pose (b, 13, 3), world meters, of the neighbours
    (b, K, 13, 3) world meters of markers (b, 8, 3) (world meters, NaN = missing) at
    feature distances (b, K) meters, each aligned by the markers present.

    The weight of a neighbour at feature distance d is exp(-(d / d1)^2), d1 the nearest
    one's distance (at least 1 mm): close matches count, far ones fade. By the compiled
    kernel (`samba.reconstruct.kernels.part_estimates_kernel`) unless `kernels_enabled()`
    says numpy.
    """
    if kernels_enabled():
        import samba.reconstruct.kernels as kernels  # numba only when a kernel runs

        return kernels.part_estimates_kernel(
            np.ascontiguousarray(markers),
            np.ascontiguousarray(neighbours),
            np.ascontiguousarray(distances),
            scale_by_tibia,
        )
    b, k = distances.shape
    seen = np.where(np.isnan(markers)[:, None], np.nan, markers_of(neighbours))
    aligned = Alignment.from_markers(seen.reshape(-1, N_MARKERS, 3), scale_by_tibia).apply(
        neighbours.reshape(-1, N_JOINTS, 3)
    )
    aligned = aligned.reshape(b, k, N_JOINTS, 3)
    nearest = np.maximum(distances[:, :1], 1e-3)
    weights = np.exp(-((distances / nearest) ** 2))
    mean = np.einsum("bk,bkjc->bjc", weights / weights.sum(axis=1, keepdims=True), aligned)
    return Alignment.from_markers(markers, scale_by_tibia=scale_by_tibia).invert(mean)
