"""The local pose space's kernels: the samples' principal components (in the 35 coordinates
shoulder-placed samples leave free) and the energy's minimiser in the kept subspace."""

from __future__ import annotations

import numpy as np

from samba.base import compiled
from samba.body import N_JOINTS

_DIMS = 3 * N_JOINTS


@compiled
def affine_of(
    samples: np.ndarray,
    shoulder_placed: bool,
    weights: np.ndarray,
    variance_kept: float,
    variance_floor: float,
    truncated: float,
    rounding: float,
    mask: np.ndarray,
    observed: np.ndarray,
    betas: np.ndarray,
    alpha: float,
    target: np.ndarray,
    offset: np.ndarray,
    gain: np.ndarray,
) -> None:
    """`LocalPoseSpace.from_samples` of samples (M, 39) with weights (M,) summing to 1,
    then `affine_solution` with the marker `mask`, `observed` markers and smoothness
    `betas` (39,) each: fills `offset` (39,) and `gain` (39, 39), canonical frame. With a
    smoothness `target` (39,) (canonical; empty for none) `offset` gets the pose for it,
    offset + gain @ target, and `gain` is left alone.

    Samples placed by their shoulder midpoint and turned by their shoulders
    (`shoulder_placed`) have the shoulders opposite (joint 2 = -joint 1) on the x axis's
    plane (z = 0): four of the 39 coordinates are zero variance by construction, so the
    principal components are taken in the other 35 (`_SHOULDER_FREE`), the same
    components at 0.7 times the eigendecomposition's cost."""
    d = samples.shape[1]
    mean = weights @ samples
    weight = alpha * mask + betas
    if variance_kept >= 1.0:
        cov = _covariance(samples, weights, mean)
        for i in range(d):
            cov[i, i] += variance_floor
        system = cov * weight
        for i in range(d):
            system[i, i] += 1.0
        if len(target):
            toward = mean + alpha * (cov @ (mask * observed)) + cov @ (betas * target)
            offset[:] = np.linalg.solve(system, toward)
            return
        rhs = np.empty((d, d + 1))
        rhs[:, 0] = mean + alpha * (cov @ (mask * observed))
        rhs[:, 1:] = cov * betas
        solution = np.linalg.solve(system, rhs)
        offset[:] = solution[:, 0]
        gain[:] = solution[:, 1:]
        return
    variances, vectors = _principal_axes(samples, weights, mean, shoulder_placed)
    _truncated_solution(
        mean,
        variances,
        vectors,
        variance_floor,
        variance_kept,
        rounding,
        mask,
        observed,
        betas,
        alpha,
        weight,
        target,
        offset,
        gain,
    )


@compiled
def _principal_axes(
    samples: np.ndarray, weights: np.ndarray, mean: np.ndarray, shoulder_placed: bool
) -> tuple[np.ndarray, np.ndarray]:
    """The weighted covariance's eigenvalues (c,) ascending and eigenvectors (39, c) of
    samples (M, 39) about their `mean` (39,): in the 35 free coordinates when the samples
    are `shoulder_placed` (see `affine_of`), else in all 39."""
    if shoulder_placed:
        free = _shoulder_free(samples)
        free_mean = weights @ free
        variances, free_vectors = np.linalg.eigh(_covariance(free, weights, free_mean))
        return variances, _from_shoulder_free(free_vectors)
    variances, vectors = np.linalg.eigh(_covariance(samples, weights, mean))
    return variances, np.ascontiguousarray(vectors)


@compiled
def _covariance(samples: np.ndarray, weights: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """The covariance (D, D) of samples (M, D) with weights (M,) summing to 1 about their
    weighted `mean` (D,), in the samples' unit squared."""
    return (samples.T * weights) @ samples - np.outer(mean, mean)


@compiled
def _truncated_solution(
    mean: np.ndarray,
    variances: np.ndarray,
    vectors: np.ndarray,
    variance_floor: float,
    variance_kept: float,
    rounding: float,
    mask: np.ndarray,
    observed: np.ndarray,
    betas: np.ndarray,
    alpha: float,
    weight: np.ndarray,
    target: np.ndarray,
    offset: np.ndarray,
    gain: np.ndarray,
) -> None:
    """The energy's minimiser in the principal subspace that keeps `variance_kept` of the
    variance: `variances` (c,) ascending and their `vectors` (39, c) of the samples about
    `mean` (39,), as `_affine_of` takes the rest; fills `offset` (39,), `gain` (39, 39),
    or with a `target` the pose for it."""
    d = len(variances)
    total = 0.0
    for i in range(d):
        total += variances[i] if variances[i] > rounding else 0.0
    total = max(total, 1e-30)
    larger = total
    first = d  # eigh sorts ascending: components first..d-1 are kept
    for i in range(d):
        larger -= variances[i] if variances[i] > rounding else 0.0
        if larger < variance_kept * total:
            first = i
            break
    # In the kept subspace U (the dropped components' variance, variance_floor *
    # TRUNCATED, holds the pose out of them to far below 1e-9 m): q = p + U w with
    # (diag(1 / lambda) + U^T W U) w = U^T (alpha D (x - p) + B (t - p)), W = alpha D + B.
    kept = d - first
    if kept == 0:  # identical samples: the pose is their mean
        offset[:] = mean
        if not len(target):
            gain[:] = 0.0
        return
    u = np.ascontiguousarray(vectors[:, first:])
    system = (u.T * weight) @ u
    for i in range(kept):
        system[i, i] += 1.0 / max(variances[first + i], variance_floor)
    if len(target):
        toward = u.T @ (alpha * mask * (observed - mean) + betas * (target - mean))
        offset[:] = mean + u @ np.linalg.solve(system, toward)
        return
    rhs = np.empty((kept, vectors.shape[0] + 1))
    rhs[:, 0] = u.T @ (alpha * mask * (observed - mean) - betas * mean)
    rhs[:, 1:] = u.T * betas
    solution = np.linalg.solve(system, rhs)
    offset[:] = mean + u @ np.ascontiguousarray(solution[:, 0])
    gain[:] = u @ np.ascontiguousarray(solution[:, 1:])


_SHOULDERS = (3, 6)
"""Where joints 1 and 2 (the shoulders) start among the 39 pose coordinates."""
_SHOULDER_FREE = np.array([i for i in range(_DIMS) if not 3 <= i < 9])
"""The 33 pose coordinates outside the shoulders; the shoulders' x and y follow them."""


@compiled
def _shoulder_free(samples: np.ndarray) -> np.ndarray:
    """Samples (M, 39) in the 35 coordinates their shoulders leave free: the 33 others,
    then (joint 1 - joint 2) / sqrt(2) in x and in y (an orthonormal basis)."""
    m = samples.shape[0]
    free = np.empty((m, len(_SHOULDER_FREE) + 2))
    half = np.sqrt(0.5)
    for s in range(m):
        for i in range(len(_SHOULDER_FREE)):
            free[s, i] = samples[s, _SHOULDER_FREE[i]]
        for axis in range(2):
            left, right = _SHOULDERS[0] + axis, _SHOULDERS[1] + axis
            free[s, len(_SHOULDER_FREE) + axis] = (samples[s, left] - samples[s, right]) * half
    return free


@compiled
def _from_shoulder_free(vectors: np.ndarray) -> np.ndarray:
    """Directions (35, c) in the coordinates of `_shoulder_free` as pose directions (39, c)."""
    out = np.zeros((_DIMS, vectors.shape[1]))
    half = np.sqrt(0.5)
    for i in range(len(_SHOULDER_FREE)):
        out[_SHOULDER_FREE[i]] = vectors[i]
    for axis in range(2):
        row = vectors[len(_SHOULDER_FREE) + axis]
        out[_SHOULDERS[0] + axis] = row * half
        out[_SHOULDERS[1] + axis] = -row * half
    return out
