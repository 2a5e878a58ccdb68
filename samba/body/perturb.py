"""Small random joint-angle perturbations of 13-joint poses that keep bone lengths exact.

Each limb is perturbed at its root joint (shoulder, hip: a swing about a random axis
perpendicular to the bone, no twist) and at its hinge (elbow, knee: a rotation about the
normal of the limb plane); a rotation moves every joint below it. The head swings about
the shoulder midpoint. Used to grow pose databases for benchmarks and tests.
"""

from __future__ import annotations

import numpy as np

_LIMBS = ((1, 3, 5), (2, 4, 6), (7, 9, 11), (8, 10, 12))


def _unit(v: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(norm, 1e-12)


def _rotate(
    points: np.ndarray, center: np.ndarray, axis: np.ndarray, angle: np.ndarray
) -> np.ndarray:
    """Rodrigues rotation of points (n, m, 3) about unit axes (n, 3) through centers (n, 3)."""
    p = points - center[:, None]
    k = axis[:, None]
    c, s = np.cos(angle)[:, None, None], np.sin(angle)[:, None, None]
    kxp = np.cross(k, p)
    kdp = np.sum(k * p, axis=-1, keepdims=True)
    return center[:, None] + p * c + kxp * s + k * kdp * (1 - c)


def _perpendicular(bone: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to `bone`, from `reference` where that is not parallel."""
    axis = np.cross(bone, reference)
    weak = np.linalg.norm(axis, axis=-1) < 1e-6
    axis[weak] = np.cross(bone[weak], [0.0, 0.0, 1.0])
    return _unit(axis)


def perturb_joint_angles(
    poses: np.ndarray, sigma_deg: float, rng: np.random.Generator
) -> np.ndarray:
    """Poses (n, 13, 3) with every joint angle jittered by N(0, sigma_deg) degrees.

    Returns a new float64 (n, 13, 3) array; bone lengths equal the input's.
    """
    out = np.array(poses, dtype=np.float64)
    n = len(out)
    sigma = np.radians(sigma_deg)
    for root, mid, end in _LIMBS:
        bone = out[:, mid] - out[:, root]
        random_dir = rng.normal(size=(n, 3))
        swing_axis = _unit(np.cross(bone, random_dir))
        out[:, [mid, end]] = _rotate(
            out[:, [mid, end]], out[:, root], swing_axis, rng.normal(0, sigma, n)
        )
        upper = out[:, mid] - out[:, root]
        hinge = _perpendicular(upper, out[:, end] - out[:, mid])
        out[:, [end]] = _rotate(out[:, [end]], out[:, mid], hinge, rng.normal(0, sigma, n))
    neck = 0.5 * (out[:, 1] + out[:, 2])
    head_axis = _unit(np.cross(out[:, 0] - neck, rng.normal(size=(n, 3))))
    out[:, [0]] = _rotate(out[:, [0]], neck, head_axis, rng.normal(0, sigma, n))
    return out
