"""Joint-specific retrieval: unobserved joints re-estimated from the poses nearest in the
markers that matter for them.

The main reconstruction finds neighbours by all 8 markers, so a wrist's neighbours are
chosen as much by the legs as by the arm; the elbow between them comes out 7-9 cm off.
Here each `Part` queries the pose index again with only its own markers (an elbow: both
shoulders and its wrist; the hips: all but the wrists; the head: shoulders and knees),
aligns the neighbours by those markers, and takes their kernel-weighted mean of the
part's joints. The estimate is blended into the main one with the part's weight.
Measured with `samba eval` (docs/reconstruction.md): elbows 7-8 cm -> 5.5 cm, hips
4.2 -> 3.5 cm, head 2.3 -> 2.1 cm.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from samba.base import kernels_enabled
from samba.body import N_JOINTS, N_MARKERS, Alignment, has_heading, markers_of
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


def refine_with_parts(
    source: NeighbourSource,
    markers: np.ndarray,
    poses: np.ndarray,
    k: int,
    eps: float = 0.0,
    parts: Sequence[Part] = PARTS,
) -> np.ndarray:
    """Poses (b, 13, 3) with each part's joints blended towards its own estimate.

    `markers` (b, 8, 3) world meters (NaN = missing); `k` neighbours per part, `eps` the
    index query's approximation. A frame whose part markers lack a complete left/right
    pair keeps the main estimate for that part.
    """
    out = np.array(poses, dtype=np.float64)
    for part in parts:
        keep = np.zeros(N_MARKERS, dtype=bool)
        keep[list(part.markers)] = True
        masked = np.where(keep[:, None], markers, np.nan)
        present = ~np.isnan(masked).any(axis=-1)
        ok = has_heading(present) & (present.sum(axis=1) >= 3)
        if not ok.any():
            continue
        estimate = part_estimate(source, masked[ok], k, eps)
        joints = list(part.joints)
        blended = (1.0 - part.weight) * out[ok][:, joints] + part.weight * estimate[:, joints]
        rows = np.flatnonzero(ok)
        out[rows[:, None], joints] = blended
    return out


def part_estimate(
    source: NeighbourSource, markers: np.ndarray, k: int, eps: float = 0.0
) -> np.ndarray:
    """Kernel-weighted mean pose (b, 13, 3), world meters, of the k poses nearest to
    markers (b, 8, 3) over the markers present, each aligned by those markers.

    The weight of a neighbour at feature distance d is exp(-(d / d1)^2), d1 the nearest
    one's distance (at least 1 mm): close matches count, far ones fade. After the query,
    by the compiled kernel (`samba.reconstruct.kernels.part_estimates_kernel`) unless
    `kernels_enabled()` says numpy.
    """
    scale = source.scale_by_tibia
    distances, rows = source.query(markers, k=k, eps=eps)
    poses = np.asarray(source.poses[rows.reshape(-1)], dtype=np.float64)
    if kernels_enabled():
        import samba.reconstruct.kernels as kernels  # numba only when a kernel runs

        neighbours = poses.reshape(len(markers), k, N_JOINTS, 3)
        return kernels.part_estimates_kernel(
            np.ascontiguousarray(markers), neighbours, distances, bool(scale)
        )
    seen = markers_of(poses.reshape(len(markers), k, N_JOINTS, 3))
    seen = np.where(np.isnan(markers)[:, None], np.nan, seen).reshape(-1, N_MARKERS, 3)
    aligned = Alignment.from_markers(seen, scale_by_tibia=scale).apply(poses)
    aligned = aligned.reshape(len(markers), k, N_JOINTS, 3)
    nearest = np.maximum(distances[:, :1], 1e-3)
    weights = np.exp(-((distances / nearest) ** 2))
    mean = np.einsum("bk,bkjc->bjc", weights / weights.sum(axis=1, keepdims=True), aligned)
    return Alignment.from_markers(markers, scale_by_tibia=scale).invert(mean)
