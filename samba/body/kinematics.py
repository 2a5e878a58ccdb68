"""Forward kinematics and rotation interpolation for joint hierarchies, batched over frames.

Rotations are unit quaternions in scalar-last order (x, y, z, w), as in
`scipy.spatial.transform.Rotation`. A hierarchy is given by `parents`, the parent index
of each joint (-1 for a root), with every parent listed before its children.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def forward_kinematics(
    parents: np.ndarray, rotations: np.ndarray, translations: np.ndarray
) -> np.ndarray:
    """Global joint positions from local transforms.

    `rotations` (n, J, 4) are local joint rotations (quaternions), `translations`
    (n, J, 3) local joint positions in the parent's frame (for a root: in the world), in
    any length unit. Returns (n, J, 3) world positions in that unit.
    """
    n, n_joints = rotations.shape[:2]
    local = Rotation.from_quat(rotations.reshape(-1, 4)).as_matrix().reshape(n, n_joints, 3, 3)
    world_rot = np.empty_like(local)
    world_pos = np.empty((n, n_joints, 3))
    for j, p in enumerate(parents):
        if p < 0:
            world_rot[:, j] = local[:, j]
            world_pos[:, j] = translations[:, j]
        else:
            world_rot[:, j] = world_rot[:, p] @ local[:, j]
            world_pos[:, j] = world_pos[:, p] + np.einsum(
                "nij,nj->ni", world_rot[:, p], translations[:, j]
            )
    return world_pos


def euler_to_quaternions(axes: str, degrees: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) of intrinsic rotations about `axes` (e.g. 'ZXY': Rz @ Rx @ Ry).

    `degrees` (..., len(axes)) holds the angles in the order of `axes`.
    """
    half = np.radians(degrees) / 2
    out = np.zeros((*degrees.shape[:-1], 4))
    out[..., 3] = 1.0
    for k, axis in enumerate(axes.upper()):
        q = np.zeros_like(out)
        q[..., "XYZ".index(axis)] = np.sin(half[..., k])
        q[..., 3] = np.cos(half[..., k])
        out = quaternion_product(out, q)
    return out


def quaternion_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products a * b of quaternions (..., 4), scalar last (rotation a after b)."""
    xa, ya, za, wa = np.moveaxis(a, -1, 0)
    xb, yb, zb, wb = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            wa * xb + xa * wb + ya * zb - za * yb,
            wa * yb - xa * zb + ya * wb + za * xb,
            wa * zb + xa * yb - ya * xb + za * wb,
            wa * wb - xa * xb - ya * yb - za * zb,
        ],
        axis=-1,
    )


WHOLE_FPS_TOLERANCE = 1e-4
"""A frame rate within this fraction (0.01%) of a whole number is that number."""


def whole_fps(fps: float) -> float:
    """`fps` (frames per second), or the whole number it lies within 0.01% of: a BVH frame
    time of 0.0166670 s means 60 fps, not 59.9988."""
    whole = round(fps)
    if whole >= 1 and abs(fps - whole) <= WHOLE_FPS_TOLERANCE * fps:
        return float(whole)
    return fps


def resample_times(n_frames: int, source_fps: float, target_fps: float) -> np.ndarray:
    """Fractional source frame indices (m,) of the frames of a clip resampled to `target_fps`.

    The clip spans (n_frames - 1) / source_fps seconds; the result starts at 0 and keeps
    every target frame that falls inside it. A rate ratio within 0.05% of an integer (120
    fps files written with a frame time of .0083333) is taken as that integer, so frames
    are picked rather than interpolated.
    """
    ratio = source_fps / target_fps
    if round(ratio) >= 1 and abs(ratio - round(ratio)) < 5e-4 * ratio:
        ratio = float(round(ratio))
    m = int(np.floor((n_frames - 1) / ratio + 1e-9)) + 1
    return np.arange(m) * ratio


def sample_rotations(rotations: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Quaternions (n, J, 4) sampled at fractional frame indices `times` (m,) -> (m, J, 4).

    Integer times pick frames exactly; others use normalised linear interpolation on the
    shorter arc, which is accurate for the small angles between neighbouring frames.
    """
    lo, frac = _split_times(times, len(rotations))
    q0 = rotations[lo]
    q1 = rotations[np.minimum(lo + 1, len(rotations) - 1)]
    q1 = np.where((np.sum(q0 * q1, axis=-1) < 0)[..., None], -q1, q1)
    q = q0 + frac[:, None, None] * (q1 - q0)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def sample_linear(values: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Arrays (n, ...) linearly interpolated at fractional frame indices `times` (m,)."""
    lo, frac = _split_times(times, len(values))
    v0 = values[lo]
    v1 = values[np.minimum(lo + 1, len(values) - 1)]
    shape = (-1,) + (1,) * (values.ndim - 1)
    return v0 + frac.reshape(shape) * (v1 - v0)


def _split_times(times: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    times = np.clip(np.asarray(times, dtype=np.float64), 0.0, n - 1)
    lo = np.floor(times + 1e-9).astype(np.int64)
    lo = np.minimum(lo, n - 1)
    frac = np.clip(times - lo, 0.0, 1.0)
    return lo, frac


def continuous_quaternions(quaternions: np.ndarray) -> np.ndarray:
    """Quaternions (n, ..., 4) with signs flipped so that each frame's quaternion has a
    non-negative dot product with the previous frame's (same rotations, no sign jumps)."""
    q = np.array(quaternions, dtype=np.float64)
    if len(q) < 2:
        return q
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    flips = np.cumprod(np.where(dots < 0, -1.0, 1.0), axis=0)
    q[1:] *= flips[..., None]
    return q


def unit_vectors(vectors: np.ndarray) -> np.ndarray:
    """Unit vectors (..., 3) along `vectors` (..., 3); zero where a vector has (almost)
    no length (below 1e-9)."""
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    return np.divide(vectors, length, out=np.zeros_like(vectors), where=length > 1e-9)
