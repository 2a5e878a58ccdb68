"""Compiled kernels of the reconstruction's per-frame path (numba, `@njit(cache=True)`).

`local_solutions_kernel` computes, frame by frame in one compiled loop, what
`Reconstructor._solve_batch` computes with numpy (its reference, kept and selected by
`SAMBA_KERNELS=numpy`): from the observed markers and their K neighbour poses, the
alignment of both into the canonical frame (`samba.body.Alignment`), the pseudo-poses
(`pseudo_poses`), the samples' kernel weights (`Reconstructor.sample_weights`), the local
pose space (`LocalPoseSpace.from_samples`), the energy's affine minimiser
(`affine_solution`) and its turn back to the world frame. `part_estimates_kernel` does
the same for `part_retrieval.neighbour_mean` after its index query (the neighbours aligned
by the part's markers, their kernel-weighted mean, turned back), and
`part_regressions_kernel` for `local_regression.local_regression_numpy` (the same neighbours'
locally weighted linear regression, read at the observation). The numpy functions stay
the references; `tests/test_reconstruct_kernels.py` checks that both paths give the same
poses (1e-9 m).

The reconstruction takes the kernel unless `samba.base.kernels_enabled()` says no
(`SAMBA_KERNELS=numpy`, for debugging, or no numba on the platform). Numba compiles it on
its first call and caches the machine code beside this module (`__pycache__`), so only the
first run after an install pays the compile: `KERNELS.warm_up()` (called by every
`Reconstructor`, and by `samba warmup`) says so on that run.
"""

from __future__ import annotations

import numpy as np

from samba.base import KernelSet, compiled
from samba.body import MARKER_JOINTS, N_JOINTS, N_MARKERS, standard_pose
from samba.body.kernels import alignment_of, apply_alignment, invert_alignment, shoulder_origin

_CHAIN_ROOTS = np.array([-1, 1, 2, 7, 8])
"""Root joint of each of the five chains (-1: the shoulder midpoint, for the neck)."""
_CHAIN_MIDS = np.array([0, 3, 4, 9, 10])
"""The joint each chain's swing moves directly: head, elbows, knees."""
_CHAIN_ENDS = np.array([0, 5, 6, 11, 12])
"""The end of each chain (the head for the neck, whose lower part is empty)."""
_FIXED = np.array([1, 2, 7, 8])
"""Joints no pseudo-pose rotation moves."""
_MARKER_JOINTS = np.array(MARKER_JOINTS)
_DIMS = 3 * N_JOINTS


@compiled
def local_solutions_kernel(
    markers: np.ndarray,
    neighbours: np.ndarray,
    has_target: np.ndarray,
    coefficients: np.ndarray,
    scale_by_tibia: bool,
    settings: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame, the energy's minimiser as an affine map of the smoothness target t
    (world meters): pose = offset + gain @ (t - anchor); the same values as
    `Reconstructor._solve_batch`.

    `markers` (b, 8, 3) the observations, world meters, NaN = missing (every frame with a
    left/right pair); `neighbours` (b, K, 13, 3) their K nearest database poses, world
    meters; `has_target` (b,) bool; `coefficients` (K, 5, 2N, 21) of the `AngleNoise`;
    `scale_by_tibia` as the pose index's; `settings` (10,): variance_kept, variance_floor
    (m^2), TRUNCATED, ROUNDING_VARIANCE (m^2), alpha, beta, beta_missing (1/m^2),
    bandwidth, min_bandwidth (m) of the configuration (`local_space`), and 1.0 to place
    by the shoulder midpoint (`shoulder_origin`), 0.0 by the centroid. Returns offset
    (b, 39), gain (b, 39, 39) and anchor (b, 39), world frame.
    """
    b, k = neighbours.shape[0], neighbours.shape[1]
    n = coefficients.shape[2] // 2
    m = k * n
    variance_kept, variance_floor, truncated, rounding = settings[:4]
    alpha, beta, beta_missing, bandwidth, min_bandwidth = settings[4:9]
    by_shoulders = settings[9] > 0.5
    offset = np.empty((b, _DIMS))
    gain = np.empty((b, _DIMS, _DIMS))
    anchor = np.empty((b, _DIMS))
    present = np.empty(N_MARKERS, dtype=np.bool_)
    aligned = np.empty((N_MARKERS, 3))
    turn = np.empty(4)  # origin-free transform: cos * scale, sin * scale, scale, and 1/scale
    origin = np.empty(3)
    pose = np.empty((N_JOINTS, 3))
    samples = np.empty((m, N_JOINTS, 3))
    weights = np.empty(m)
    mask = np.zeros(_DIMS)
    observed = np.zeros(_DIMS)
    betas = np.empty(_DIMS)
    canonical_offset = np.empty(_DIMS)
    for f in range(b):
        for i in range(N_MARKERS):
            present[i] = not np.isnan(markers[f, i, 0] + markers[f, i, 1] + markers[f, i, 2])
        alignment_of(markers[f], present, scale_by_tibia, origin, turn)
        if by_shoulders:
            shoulder_origin(markers[f], present, origin)
        apply_alignment(markers[f], origin, turn, aligned)
        observation_origin = origin.copy()
        observation_turn = turn.copy()
        for j in range(k):
            seen = neighbours[f, j][_MARKER_JOINTS]
            alignment_of(seen, present, scale_by_tibia, origin, turn)
            if by_shoulders:
                shoulder_origin(seen, present, origin)
            apply_alignment(neighbours[f, j], origin, turn, pose)
            _pseudo_poses_of(pose, coefficients[j], samples[j * n : (j + 1) * n])
        _sample_weights(samples, aligned, present, bandwidth, min_bandwidth, weights)
        for i in range(N_MARKERS):
            for c in range(3):
                at = 3 * _MARKER_JOINTS[i] + c
                mask[at] = 1.0 if present[i] else 0.0
                observed[at] = aligned[i, c] if present[i] else 0.0
        for at in range(_DIMS):
            betas[at] = beta if has_target[f] else 0.0
        if has_target[f]:
            for i in range(N_MARKERS):
                if not present[i]:
                    for c in range(3):
                        betas[3 * _MARKER_JOINTS[i] + c] += beta_missing
        _affine_of(
            samples.reshape(m, _DIMS),
            by_shoulders and present[0] and present[1],
            weights,
            variance_kept,
            variance_floor,
            truncated,
            rounding,
            mask,
            observed,
            betas,
            alpha,
            canonical_offset,
            gain[f],
        )
        _to_world(
            observation_origin, observation_turn, canonical_offset, gain[f], offset[f], anchor[f]
        )
    return offset, gain, anchor


@compiled
def part_estimates_kernel(
    markers: np.ndarray, neighbours: np.ndarray, distances: np.ndarray, scale_by_tibia: bool
) -> np.ndarray:
    """`part_retrieval.neighbour_mean`: poses (b, 13, 3) world meters, the
    kernel-weighted mean of the neighbours (b, K, 13, 3) world meters at feature distances
    (b, K), each aligned by the markers (b, 8, 3) present (NaN = missing), turned back by
    the observation's alignment."""
    b, k = neighbours.shape[0], neighbours.shape[1]
    out = np.empty((b, N_JOINTS, 3))
    present = np.empty(N_MARKERS, dtype=np.bool_)
    origin = np.empty(3)
    turn = np.empty(4)
    aligned = np.empty((N_JOINTS, 3))
    mean = np.empty((N_JOINTS, 3))
    for f in range(b):
        for i in range(N_MARKERS):
            present[i] = not np.isnan(markers[f, i, 0] + markers[f, i, 1] + markers[f, i, 2])
        nearest = max(distances[f, 0], 1e-3)
        total = 0.0
        mean[:] = 0.0
        for j in range(k):
            weight = np.exp(-((distances[f, j] / nearest) ** 2))
            total += weight
            alignment_of(neighbours[f, j][_MARKER_JOINTS], present, scale_by_tibia, origin, turn)
            apply_alignment(neighbours[f, j], origin, turn, aligned)
            mean += weight * aligned
        mean /= total
        alignment_of(markers[f], present, scale_by_tibia, origin, turn)
        invert_alignment(mean, origin, turn, out[f])
    return out


@compiled
def part_regressions_kernel(
    markers: np.ndarray,
    neighbours: np.ndarray,
    distances: np.ndarray,
    joints: np.ndarray,
    scale_by_tibia: bool,
    ridge: float,
    width: float,
) -> np.ndarray:
    """`local_regression.local_regression_numpy`: each observation's `joints` (b, J) (-1:
    none, NaN back) of markers (b, 8, 3) world meters (NaN = missing) by a locally
    weighted linear regression over their neighbours (b, K, 13, 3) world meters at
    feature distances (b, K), kernel `width` times the nearest distance, `ridge` (m^2) on
    the slopes; returns (b, J, 3) world meters. Only the markers present enter the
    design, which gives the numpy reference's solution."""
    b, k = neighbours.shape[0], neighbours.shape[1]
    outputs = 3 * joints.shape[1]
    out = np.empty((b, joints.shape[1], 3))
    present = np.empty(N_MARKERS, dtype=np.bool_)
    origin = np.empty(3)
    turn = np.empty(4)
    neighbour_origin = np.empty(3)
    neighbour_turn = np.empty(4)
    observed = np.empty((N_MARKERS, 3))
    seen = np.empty((N_MARKERS, 3))
    aligned = np.empty((N_JOINTS, 3))
    weights = np.empty(k)
    row = np.empty(1 + 3 * N_MARKERS)
    estimate = np.empty((joints.shape[1], 3))
    for f in range(b):
        dims = 1
        for i in range(N_MARKERS):
            present[i] = not np.isnan(markers[f, i, 0] + markers[f, i, 1] + markers[f, i, 2])
            dims += 3 if present[i] else 0
        alignment_of(markers[f], present, scale_by_tibia, origin, turn)
        apply_alignment(markers[f], origin, turn, observed)
        normal = np.zeros((dims, dims))
        rhs = np.zeros((dims, outputs))
        nearest = width * max(distances[f, 0], 1e-3)
        for j in range(k):
            weights[j] = np.exp(-((distances[f, j] / nearest) ** 2))
        weights /= np.sum(weights)
        for j in range(k):
            for i in range(N_MARKERS):
                for c in range(3):
                    seen[i, c] = neighbours[f, j, _MARKER_JOINTS[i], c]
            alignment_of(seen, present, scale_by_tibia, neighbour_origin, neighbour_turn)
            apply_alignment(neighbours[f, j], neighbour_origin, neighbour_turn, aligned)
            row[0] = 1.0
            d = 1
            for i in range(N_MARKERS):
                if present[i]:
                    for c in range(3):
                        row[d] = aligned[_MARKER_JOINTS[i], c] - observed[i, c]
                        d += 1
            for p in range(dims):
                weighted = weights[j] * row[p]
                for q in range(p, dims):
                    normal[p, q] += weighted * row[q]
                for o in range(joints.shape[1]):
                    joint = max(joints[f, o], 0)
                    for c in range(3):
                        rhs[p, 3 * o + c] += weighted * aligned[joint, c]
        for p in range(dims):
            for q in range(p):
                normal[p, q] = normal[q, p]
            if p > 0:
                normal[p, p] += ridge
        solution = np.linalg.solve(normal, rhs)
        for o in range(joints.shape[1]):
            for c in range(3):
                estimate[o, c] = solution[0, 3 * o + c]
        invert_alignment(estimate, origin, turn, out[f])
        for o in range(joints.shape[1]):
            if joints[f, o] < 0:
                out[f, o] = np.nan
    return out


@compiled
def _to_world(
    origin: np.ndarray,
    turn: np.ndarray,
    offset: np.ndarray,
    gain: np.ndarray,
    world_offset: np.ndarray,
    anchor: np.ndarray,
) -> None:
    """The canonical minimiser offset (39,) and gain (39, 39, in place) in the world frame
    of the alignment (`origin`, `turn`): world_offset = `Alignment.invert(offset)` and
    gain R^T gain R per joint block, anchor (39,) the origin per joint."""
    c, s = turn[0] * turn[3], turn[1] * turn[3]
    invert_alignment(offset.reshape(N_JOINTS, 3), origin, turn, world_offset.reshape(N_JOINTS, 3))
    for j in range(N_JOINTS):
        anchor[3 * j : 3 * j + 3] = origin
    # R = [[c, 0, s], [0, 1, 0], [-s, 0, c]] takes world to canonical directions.
    for row in range(_DIMS):  # columns: gain R
        for j in range(N_JOINTS):
            x, z = gain[row, 3 * j], gain[row, 3 * j + 2]
            gain[row, 3 * j] = x * c - z * s
            gain[row, 3 * j + 2] = x * s + z * c
    for j in range(N_JOINTS):  # rows: R^T gain
        for col in range(_DIMS):
            x, z = gain[3 * j, col], gain[3 * j + 2, col]
            gain[3 * j, col] = c * x - s * z
            gain[3 * j + 2, col] = s * x + c * z


@compiled
def _pseudo_poses_of(pose: np.ndarray, coefficients: np.ndarray, out: np.ndarray) -> None:
    """`pseudo_poses` of one neighbour pose (13, 3) with its coefficients (5, 2N, 21)
    into `out` (N, 13, 3): per chain (neck, two arms, two legs) the local frame of the
    upper bone, the lower limb's coordinates in it and their 90-degree turn in the limb
    plane make the seven numbers every pseudo-pose's offsets are linear in."""
    n = coefficients.shape[1] // 2
    numbers = np.empty(7)
    frame = np.empty((3, 3))  # rows: the chain's local axes x, y, z
    lifted = np.empty((21, 3))
    root = np.empty(3)
    for i in range(n):
        for joint in _FIXED:
            out[i, joint] = pose[joint]
    for chain in range(5):
        mid, end = _CHAIN_MIDS[chain], _CHAIN_ENDS[chain]
        for c in range(3):
            if chain == 0:
                root[c] = 0.5 * (pose[1, c] + pose[2, c])
            else:
                root[c] = pose[_CHAIN_ROOTS[chain], c]
        _chain_frame(pose, root, mid, end, frame, numbers)
        for q in range(7):
            for a in range(3):
                for c in range(3):
                    lifted[3 * q + a, c] = numbers[q] * frame[a, c]
        for i in range(n):
            for point in range(2 if chain > 0 else 1):
                joint = mid if point == 0 else end
                row = coefficients[chain, 2 * i + point]
                for c in range(3):
                    total = root[c]
                    for q in range(21):
                        total += row[q] * lifted[q, c]
                    out[i, joint, c] = total


@compiled
def _chain_frame(
    pose: np.ndarray,
    root: np.ndarray,
    mid: int,
    end: int,
    frame: np.ndarray,
    numbers: np.ndarray,
) -> None:
    """Fill `frame` (3, 3) with a chain's local axes x, y, z (rows; z along the upper
    bone root -> mid, x the shoulder line made perpendicular to it, or a fixed
    perpendicular) and `numbers` (7,) with the lower limb mid -> end in that frame, its
    90-degree turn in the limb plane and the upper bone's length (meters)."""
    length = 0.0
    for c in range(3):
        frame[2, c] = pose[mid, c] - root[c]
        length += frame[2, c] ** 2
    length = np.sqrt(length)
    scale = 1.0 / max(length, 1e-12)
    along = 0.0
    for c in range(3):
        frame[2, c] *= scale
        along += (pose[1, c] - pose[2, c]) * frame[2, c]
    norm = 0.0
    for c in range(3):
        frame[0, c] = pose[1, c] - pose[2, c] - along * frame[2, c]
        norm += frame[0, c] ** 2
    norm = np.sqrt(norm)
    if norm < 1e-9:
        zx, zy, zz = frame[2, 0], frame[2, 1], frame[2, 2]
        if abs(zy) < 0.9:  # helper (0, 1, 0) x z
            frame[0, 0], frame[0, 1], frame[0, 2] = zz, 0.0, -zx
        else:  # helper (0, 0, 1) x z
            frame[0, 0], frame[0, 1], frame[0, 2] = -zy, zx, 0.0
        norm = np.sqrt(frame[0, 0] ** 2 + frame[0, 1] ** 2 + frame[0, 2] ** 2)
    for c in range(3):
        frame[0, c] /= norm
    frame[1, 0] = frame[2, 1] * frame[0, 2] - frame[2, 2] * frame[0, 1]
    frame[1, 1] = frame[2, 2] * frame[0, 0] - frame[2, 0] * frame[0, 2]
    frame[1, 2] = frame[2, 0] * frame[0, 1] - frame[2, 1] * frame[0, 0]
    lx = ly = lz = 0.0
    for c in range(3):
        lower = pose[end, c] - pose[mid, c]
        lx += frame[0, c] * lower
        ly += frame[1, c] * lower
        lz += frame[2, c] * lower
    r = np.hypot(lx, ly)
    numbers[0], numbers[1], numbers[2], numbers[6] = lx, ly, lz, length
    if r < 1e-9:
        numbers[3], numbers[4], numbers[5] = 0.0, -lz, ly
    else:
        numbers[3], numbers[4], numbers[5] = -lx * lz / r, -ly * lz / r, r


@compiled
def _sample_weights(
    samples: np.ndarray,
    aligned: np.ndarray,
    present: np.ndarray,
    bandwidth: float,
    min_bandwidth: float,
    weights: np.ndarray,
) -> None:
    """`Reconstructor.sample_weights` of samples (M, 13, 3) against the aligned
    observation (8, 3), normalised to sum 1, into `weights` (M,); all alike when
    `bandwidth` is 0."""
    m = samples.shape[0]
    if bandwidth == 0.0:
        weights[:] = 1.0 / m
        return
    nearest = np.inf
    for s in range(m):
        total = 0.0
        for i in range(N_MARKERS):
            if present[i]:
                for c in range(3):
                    diff = samples[s, _MARKER_JOINTS[i], c] - aligned[i, c]
                    total += diff * diff
        weights[s] = total
        nearest = min(nearest, total)
    h2 = max(nearest * bandwidth**2, min_bandwidth**2)
    for s in range(m):
        weights[s] = np.exp(-weights[s] / h2)
    weights /= np.sum(weights)


@compiled
def _affine_of(
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
    offset: np.ndarray,
    gain: np.ndarray,
) -> None:
    """`LocalPoseSpace.from_samples` of samples (M, 39) with weights (M,) summing to 1,
    then `affine_solution` with the marker `mask`, `observed` markers and smoothness
    `betas` (39,) each: fills `offset` (39,) and `gain` (39, 39), canonical frame.

    Samples placed by their shoulder midpoint and turned by their shoulders
    (`shoulder_placed`) have the shoulders opposite (joint 2 = -joint 1) on the x axis's
    plane (z = 0): four of the 39 coordinates are zero variance by construction, so the
    principal components are taken in the other 35 (`_SHOULDER_FREE`), the same
    components at 0.7 times the eigendecomposition's cost."""
    d = samples.shape[1]
    mean = weights @ samples
    weight = alpha * mask + betas
    if variance_kept < 1.0 and shoulder_placed:
        free = _shoulder_free(samples)
        free_mean = weights @ free
        free_cov = (free.T * weights) @ free - np.outer(free_mean, free_mean)
        variances, free_vectors = np.linalg.eigh(free_cov)
        _truncated_solution(
            mean,
            variances,
            _from_shoulder_free(free_vectors),
            variance_floor,
            variance_kept,
            rounding,
            mask,
            observed,
            betas,
            alpha,
            weight,
            offset,
            gain,
        )
        return
    cov = (samples.T * weights) @ samples - np.outer(mean, mean)
    if variance_kept >= 1.0:
        for i in range(d):
            cov[i, i] += variance_floor
        system = cov * weight
        for i in range(d):
            system[i, i] += 1.0
        rhs = np.empty((d, d + 1))
        rhs[:, 0] = mean + alpha * (cov @ (mask * observed))
        rhs[:, 1:] = cov * betas
        solution = np.linalg.solve(system, rhs)
        offset[:] = solution[:, 0]
        gain[:] = solution[:, 1:]
        return
    variances, vectors = np.linalg.eigh(cov)
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
        offset,
        gain,
    )


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
    offset: np.ndarray,
    gain: np.ndarray,
) -> None:
    """The energy's minimiser in the principal subspace that keeps `variance_kept` of the
    variance: `variances` (c,) ascending and their `vectors` (39, c) of the samples about
    `mean` (39,), as `_affine_of` takes the rest; fills `offset` (39,), `gain` (39, 39)."""
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
        gain[:] = 0.0
        return
    u = np.ascontiguousarray(vectors[:, first:])
    system = (u.T * weight) @ u
    for i in range(kept):
        system[i, i] += 1.0 / max(variances[first + i], variance_floor)
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


def _example() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Compile `local_solutions_kernel` for the reconstruction's argument types."""
    pose = standard_pose()
    markers = np.ascontiguousarray(pose[list(MARKER_JOINTS)][None])
    neighbours = np.ascontiguousarray(np.repeat(pose[None, None], 2, axis=1))
    settings = np.array([0.9, 1e-6, 1e-12, 1e-12, 1.0, 1.0, 0.0, 0.0, 0.0])
    return local_solutions_kernel(
        markers, neighbours, np.ones(1, dtype=np.bool_), np.zeros((2, 5, 2, 21)), False, settings
    )


def _example_parts() -> np.ndarray:
    """Compile `part_estimates_kernel` for the reconstruction's argument types."""
    pose = standard_pose()
    markers = np.ascontiguousarray(pose[list(MARKER_JOINTS)][None])
    neighbours = np.ascontiguousarray(np.repeat(pose[None, None], 2, axis=1))
    return part_estimates_kernel(markers, neighbours, np.zeros((1, 2)), False)


def _example_regressions() -> np.ndarray:
    """Compile `part_regressions_kernel` for the reconstruction's argument types."""
    pose = standard_pose()
    markers = np.ascontiguousarray(pose[list(MARKER_JOINTS)][None])
    neighbours = np.ascontiguousarray(np.repeat(pose[None, None], 2, axis=1))
    joints = np.zeros((1, 1), dtype=np.int64)
    return part_regressions_kernel(markers, neighbours, np.zeros((1, 2)), joints, False, 1.0, 2.0)


KERNELS = KernelSet(
    "reconstruction",
    (local_solutions_kernel, part_estimates_kernel, part_regressions_kernel),
    (_example, _example_parts, _example_regressions),
    estimate_s=20.0,
)
"""The reconstruction's kernels, warmed by every `Reconstructor` (`KernelSet.warm_up`)."""
