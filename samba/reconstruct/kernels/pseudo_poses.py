"""The pseudo-poses' kernel: a neighbour's N pseudo-poses from its chains' local frames."""

from __future__ import annotations

import numpy as np

from samba.base import compiled

_CHAIN_ROOTS = np.array([-1, 1, 2, 7, 8])
"""Root joint of each of the five chains (-1: the shoulder midpoint, for the neck)."""
_CHAIN_MIDS = np.array([0, 3, 4, 9, 10])
"""The joint each chain's swing moves directly: head, elbows, knees."""
_CHAIN_ENDS = np.array([0, 5, 6, 11, 12])
"""The end of each chain (the head for the neck, whose lower part is empty)."""
_FIXED = np.array([1, 2, 7, 8])
"""Joints no pseudo-pose rotation moves."""


@compiled
def pseudo_poses_of(pose: np.ndarray, coefficients: np.ndarray, out: np.ndarray) -> None:
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
