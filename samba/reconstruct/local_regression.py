"""Locally weighted linear regression of a part's joints on its markers (issue 44).

`part_retrieval`'s kernel-weighted mean answers with the joints of the poses nearest to
the observation, wherever in their neighbourhood the observation lies: when the wrist
sits 3 cm beyond every neighbour's wrist, their mean elbow does not follow it. Here the
`k` neighbours, each aligned by the part's markers, fit a linear map from their aligned
markers to their aligned joints, weighted by exp(-(d / (REGRESSION_WIDTH * d1))^2) at
feature distance d (d1 the nearest one's, at least 1 mm) and with a ridge penalty on
the slopes; the map is read at the observation. Measured leave-one-take-out
(docs/reconstruction.md): elbows 5.5 -> 5.2 cm, hips 3.7 -> 3.0 cm, head 2.1 -> 1.9 cm
against the mean.
"""

from __future__ import annotations

import numpy as np

from samba.base import kernels_enabled
from samba.body import N_JOINTS, N_MARKERS, Alignment, markers_of

REGRESSION_WIDTH = 2.0
"""Kernel width in units of the nearest neighbour's feature distance (chosen
leave-one-take-out over the takes outside the validation split: 1, 2 and 4 tried)."""


def local_regression(
    markers: np.ndarray,
    neighbours: np.ndarray,
    distances: np.ndarray,
    joints: np.ndarray,
    scale_by_tibia: bool,
    ridge: float,
) -> np.ndarray:
    """Each observation's `joints` (b, J) (joint indices, -1 = none: NaN comes back) as
    (b, J, 3) world meters, from markers (b, 8, 3) (world meters, NaN = missing) by a
    locally weighted linear regression over their neighbours (b, K, 13, 3) world meters
    at index feature distances (b, K) meters.

    Each neighbour is aligned by the markers present (`samba.body.Alignment`, as the
    index compares them, scaled by the tibia when `scale_by_tibia`); the regression maps
    its aligned markers, relative to the aligned observation's, to its aligned `joints`,
    with `ridge` (m^2, > 0, against weights summing to 1) on the slopes; its intercept,
    turned back by the observation's alignment, is the estimate. By the compiled kernel
    (`samba.reconstruct.kernels.part_regressions_kernel`) unless `kernels_enabled()`
    says numpy."""
    if kernels_enabled():
        import samba.reconstruct.kernels as kernels  # numba only when a kernel runs

        return kernels.part_regressions_kernel(
            np.ascontiguousarray(markers),
            np.ascontiguousarray(neighbours),
            np.ascontiguousarray(distances),
            np.ascontiguousarray(joints, dtype=np.int64),
            scale_by_tibia,
            ridge,
            REGRESSION_WIDTH,
        )
    return local_regression_numpy(markers, neighbours, distances, joints, scale_by_tibia, ridge)


def local_regression_numpy(
    markers: np.ndarray,
    neighbours: np.ndarray,
    distances: np.ndarray,
    joints: np.ndarray,
    scale_by_tibia: bool,
    ridge: float,
) -> np.ndarray:
    """`local_regression` by numpy (the kernel's reference), same arguments and result."""
    b, k = distances.shape
    present = ~np.isnan(markers).any(axis=-1)
    seen = np.where(~present[:, None, :, None], np.nan, markers_of(neighbours))
    aligned = Alignment.from_markers(seen.reshape(-1, N_MARKERS, 3), scale_by_tibia).apply(
        neighbours.reshape(-1, N_JOINTS, 3)
    )
    aligned = aligned.reshape(b, k, N_JOINTS, 3)
    observation = Alignment.from_markers(markers, scale_by_tibia)
    at = np.nan_to_num(observation.apply(markers))
    features = markers_of(aligned) - at[:, None]
    features = np.where(present[:, None, :, None], features, 0.0).reshape(b, k, 3 * N_MARKERS)
    design = np.concatenate([np.ones((b, k, 1)), features], axis=2)
    nearest = np.maximum(distances[:, :1], 1e-3)
    weights = np.exp(-((distances / (REGRESSION_WIDTH * nearest)) ** 2))
    weights /= weights.sum(axis=1, keepdims=True)
    weighted = design.swapaxes(1, 2) * weights[:, None]
    penalty = np.full(design.shape[2], ridge)
    penalty[0] = 0.0
    joints = np.asarray(joints)
    chosen = np.maximum(joints, 0)[:, None, :, None]
    targets = np.take_along_axis(aligned, chosen, axis=2).reshape(b, k, -1)
    solution = np.linalg.solve(weighted @ design + np.diag(penalty), weighted @ targets)
    estimate = observation.invert(solution[:, 0].reshape(b, joints.shape[1], 3))
    return np.where(joints[..., None] >= 0, estimate, np.nan)
