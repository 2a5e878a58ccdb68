"""The frames' kernels: per frame the alignment, the samples and their weights, the local
pose space's solution as an affine map of the smoothness target (`local_solutions_kernel`,
the batch path) or as the pose for a known target (`local_poses_kernel`, a live frame)."""

from __future__ import annotations

import numpy as np

from samba.base import compiled
from samba.body import MARKER_JOINTS, N_JOINTS, N_MARKERS
from samba.body.kernels import alignment_of, apply_alignment, invert_alignment, shoulder_origin
from samba.reconstruct.kernels.pose_space import affine_of
from samba.reconstruct.kernels.pseudo_poses import pseudo_poses_of

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
    b = neighbours.shape[0]
    offset = np.empty((b, _DIMS))
    gain = np.empty((b, _DIMS, _DIMS))
    anchor = np.empty((b, _DIMS))
    _solve_frames(
        markers,
        neighbours,
        np.empty((b, 0)),
        has_target,
        coefficients,
        scale_by_tibia,
        settings,
        offset,
        gain,
        anchor,
    )
    return offset, gain, anchor


@compiled
def local_poses_kernel(
    markers: np.ndarray,
    neighbours: np.ndarray,
    targets: np.ndarray,
    has_target: np.ndarray,
    coefficients: np.ndarray,
    scale_by_tibia: bool,
    settings: np.ndarray,
) -> np.ndarray:
    """Per frame, the energy's minimiser (b, 39) world meters for the smoothness targets
    (b, 39) world meters (used where `has_target`): `local_solutions_kernel`'s offset +
    gain @ (target - anchor) without forming the gain (a live frame's target is known
    before its solve). The other arguments as `local_solutions_kernel` takes them."""
    b = neighbours.shape[0]
    poses = np.empty((b, _DIMS))
    unused = np.empty((b, 0, 0))
    _solve_frames(
        markers,
        neighbours,
        targets,
        has_target,
        coefficients,
        scale_by_tibia,
        settings,
        poses,
        unused,
        np.empty((b, 0)),
    )
    return poses


@compiled
def _solve_frames(
    markers: np.ndarray,
    neighbours: np.ndarray,
    targets: np.ndarray,
    has_target: np.ndarray,
    coefficients: np.ndarray,
    scale_by_tibia: bool,
    settings: np.ndarray,
    offset: np.ndarray,
    gain: np.ndarray,
    anchor: np.ndarray,
) -> None:
    """The body of `local_solutions_kernel` (`targets` (b, 0): fills offset, gain and
    anchor) and of `local_poses_kernel` (`targets` (b, 39): fills `offset` with the poses,
    world meters; gain and anchor unused)."""
    b, k = neighbours.shape[0], neighbours.shape[1]
    n = coefficients.shape[2] // 2
    m = k * n
    variance_kept, variance_floor, truncated, rounding = settings[:4]
    alpha, beta, beta_missing, bandwidth, min_bandwidth = settings[4:9]
    by_shoulders = settings[9] > 0.5
    direct = targets.shape[1] > 0
    target = np.empty((N_JOINTS, 3))
    scratch = np.empty((0, 0))
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
            pseudo_poses_of(pose, coefficients[j], samples[j * n : (j + 1) * n])
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
        if direct:
            apply_alignment(
                targets[f].reshape(N_JOINTS, 3), observation_origin, observation_turn, target
            )
        affine_of(
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
            target.reshape(_DIMS) if direct else target.reshape(_DIMS)[:0],
            canonical_offset,
            scratch if direct else gain[f],
        )
        if direct:
            invert_alignment(
                canonical_offset.reshape(N_JOINTS, 3),
                observation_origin,
                observation_turn,
                offset[f].reshape(N_JOINTS, 3),
            )
        else:
            _to_world(
                observation_origin,
                observation_turn,
                canonical_offset,
                gain[f],
                offset[f],
                anchor[f],
            )


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
