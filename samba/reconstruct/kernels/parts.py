"""The part retrieval's kernels: `best`'s part estimates (the neighbours' kernel-weighted
mean) and `lwr`'s (their locally weighted linear regression)."""

from __future__ import annotations

import numpy as np

from samba.base import compiled
from samba.body import MARKER_JOINTS, N_JOINTS, N_MARKERS
from samba.body.kernels import alignment_of, apply_alignment, invert_alignment

_MARKER_JOINTS = np.array(MARKER_JOINTS)


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
