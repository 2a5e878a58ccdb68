"""Compiled kernels of the canonical alignment (`samba.body.alignment`), called from the
kernels of other packages (`samba.reconstruct.kernels`, `samba.db.kernels`): numba needs
them as compiled functions those kernels call, so kernel modules import them from here,
lazily with themselves (`pyproject.toml` lets those imports past the face).

| kernel | numpy reference |
|---|---|
| `alignment_of` | `Alignment.from_markers` of one marker set |
| `shoulder_origin` | its `shoulder_origin` |
| `apply_alignment` | `Alignment.apply` |
| `invert_alignment` | `Alignment.invert` |

An alignment is held as `origin` (3,) and `turn` (4,): cos(yaw) * scale, sin(yaw) *
scale, scale and 1 / scale. Tested through the kernels that call them
(`tests/test_reconstruct_kernels.py`, `tests/test_index_kernels.py`).
"""

from __future__ import annotations

import numpy as np

from samba.base import compiled
from samba.body.alignment import HEADING_PAIRS, REFERENCE_TIBIA, TIBIA_PAIRS
from samba.body.skeleton import N_MARKERS

_HEADING = np.array(HEADING_PAIRS)
_TIBIA = np.array(TIBIA_PAIRS)


@compiled
def alignment_of(
    markers: np.ndarray,
    present: np.ndarray,
    scale_by_tibia: bool,
    origin: np.ndarray,
    turn: np.ndarray,
) -> None:
    """`Alignment.from_markers` of one marker set (8, 3) over its `present` markers: fills
    `origin` (3,) and `turn` (cos(yaw) * scale, sin(yaw) * scale, scale, 1 / scale)."""
    count = 0
    origin[:] = 0.0
    for i in range(N_MARKERS):
        if present[i]:
            count += 1
            origin += markers[i]
    origin /= max(count, 1)
    yaw = 0.0
    for pair in range(len(_HEADING)):
        left, right = _HEADING[pair, 0], _HEADING[pair, 1]
        if present[left] and present[right]:
            yaw = np.arctan2(
                markers[left, 2] - markers[right, 2], markers[left, 0] - markers[right, 0]
            )
            break
    scale = 1.0
    if scale_by_tibia:
        total = 0.0
        known = 0
        for pair in range(len(_TIBIA)):
            knee, foot = _TIBIA[pair, 0], _TIBIA[pair, 1]
            if present[knee] and present[foot]:
                total += np.sqrt(np.sum((markers[knee] - markers[foot]) ** 2))
                known += 1
        if known > 0 and total / known > 1e-6:
            scale = REFERENCE_TIBIA / (total / known)
    turn[0], turn[1], turn[2], turn[3] = np.cos(yaw) * scale, np.sin(yaw) * scale, scale, 1 / scale


@compiled
def shoulder_origin(markers: np.ndarray, present: np.ndarray, origin: np.ndarray) -> None:
    """`Alignment.from_markers` with `shoulder_origin`: after `alignment_of`, moves
    `origin` (3,) to the midpoint of the shoulder markers of `markers` (8, 3) when both
    are `present`."""
    if present[0] and present[1]:
        for c in range(3):
            origin[c] = 0.5 * (markers[0, c] + markers[1, c])


@compiled
def apply_alignment(
    points: np.ndarray, origin: np.ndarray, turn: np.ndarray, out: np.ndarray
) -> None:
    """`Alignment.apply`: points (p, 3) world to `out` (p, 3) canonical."""
    c, s, scale = turn[0], turn[1], turn[2]
    for i in range(points.shape[0]):
        x, y, z = points[i, 0] - origin[0], points[i, 1] - origin[1], points[i, 2] - origin[2]
        out[i, 0] = c * x + s * z
        out[i, 1] = scale * y
        out[i, 2] = c * z - s * x


@compiled
def invert_alignment(
    points: np.ndarray, origin: np.ndarray, turn: np.ndarray, out: np.ndarray
) -> None:
    """`Alignment.invert`: canonical points (p, 3) back to `out` (p, 3) in the world."""
    c, s, inverse = turn[0] * turn[3], turn[1] * turn[3], turn[3]
    for i in range(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        out[i, 0] = (c * x - s * z) * inverse + origin[0]
        out[i, 1] = y * inverse + origin[1]
        out[i, 2] = (s * x + c * z) * inverse + origin[2]
