"""Pseudo-poses (Samba paper, Section 4.2): database poses with small joint-angle noise.

Each neighbour pose gets N variations. A variation rotates, root first:

* the neck chain (2-DOF): the head about the shoulder midpoint;
* the shoulders and hips (2-DOF): the whole limb below, first by theta1 about
  R1 = Z x X, then by theta2 about Z, where Z is the unit bone (shoulder -> elbow,
  hip -> knee) and X the right-to-left shoulder line made perpendicular to Z (Eq. 9-11);
  twist about the bone is ignored;
* the elbows and knees (1-DOF): the wrist / foot about R = J1 x J2, the normal of the
  limb plane (Eq. 7-8), which changes the joint angle by exactly the drawn amount.

A rotation moves every joint below it, so bone lengths are kept exactly. Where an axis is
undefined (a straight limb, a bone along the shoulder line) a perpendicular fallback
built from the shoulder line or the bone is used.

Implementation: a rotation of the whole limb about its root commutes with the hinge
rotation inside it, so the hinge is applied first, in the plane of the unperturbed limb,
and the swing last, in the limb's local frame (X, R1, Z) where Eq. 10-11 are plain
formulas. For fixed angles those formulas are linear in seven numbers per limb (the
lower limb and its 90-degree turn in the limb plane, in local coordinates, and the upper
limb's length), so `AngleNoise` turns its angles into coefficients once and a frame costs
one small batched matrix product on top of building each neighbour's limb frames.

The angles come from an `AngleNoise` table drawn once per reconstructor: the same
(K, N) table perturbs every frame's neighbours, which makes a frame's result independent
of the frames processed before it and costs no random draws per frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from samba.body import N_JOINTS

LIMB_ROOTS = [1, 2, 7, 8]
"""Ball joints at the top of each limb: l/r shoulder, l/r hip."""
LIMB_HINGES = [3, 4, 9, 10]
"""Hinge joints in each limb: l/r elbow, l/r knee."""
LIMB_ENDS = [5, 6, 11, 12]
"""End joints of each limb: l/r wrist, l/r foot."""
CHAIN_MIDS = [0, *LIMB_HINGES]
"""The joint each chain's swing moves directly: head, elbows, knees."""
THETA1 = [0, 2, 4, 6, 8]
"""Columns of the first swing angle of the neck, l/r shoulder, l/r hip."""
THETA2 = [1, 3, 5, 7, 9]
"""Columns of the second swing angle (about the bone) of the same chains."""
FIXED_JOINTS = [1, 2, 7, 8]
"""Joints no pseudo-pose rotation moves: the shoulders and hips."""
CHAIN_ENDS = [0, *LIMB_ENDS]
"""The end of each chain (the head for the neck chain, whose lower part is empty)."""
N_LIMB_NUMBERS = 7
"""Numbers per chain the pseudo-pose offsets are linear in (see `_local_offsets`)."""
N_ANGLES = 2 + 4 * 2 + 4
"""Angles drawn per pseudo-pose: neck (2), shoulders and hips (2 each), elbows and knees."""


@dataclass(frozen=True)
class AngleNoise:
    """Joint-angle noise for pseudo-poses: `angles` (K, N, N_ANGLES) radians.

    Column order: neck theta1, theta2; for each of l_shoulder, r_shoulder, l_hip, r_hip
    theta1, theta2; then l_elbow, r_elbow, l_knee, r_knee. Row n = 0 of every neighbour
    is all zeros, so the neighbour itself is among its pseudo-poses and N = 1 means no
    pseudo-poses (the local pose space of the K neighbours alone).
    """

    angles: np.ndarray
    coefficients: np.ndarray = field(init=False, repr=False)
    """(K, 5 chains, N * 2 points, 7 * 3): world offsets of the swung joint and the limb
    end as linear maps of (limb numbers x local axes), see `pseudo_poses`."""

    def __post_init__(self) -> None:
        k, n, _ = self.angles.shape
        basis = np.eye(N_LIMB_NUMBERS)[:, :, None, None, None]  # (7 numbers, 7, 1, 1, 1)
        a = self.angles[None]
        theta1, theta2 = a[..., THETA1], a[..., THETA2]
        delta = np.concatenate([np.zeros_like(a[..., :1]), a[..., 10:14]], axis=-1)
        mid, end = _local_offsets(*basis, theta1, theta2, delta)  # 3 x (7, K, N, 5)
        local = np.stack([np.stack(mid), np.stack(end)])  # (2 points, 3 axes, 7, K, N, 5)
        coefficients = local.transpose(3, 5, 4, 0, 2, 1).reshape(k, 5, n * 2, -1)
        object.__setattr__(self, "coefficients", np.ascontiguousarray(coefficients))

    @classmethod
    def draw(cls, k: int, n: int, sigma_deg: float, seed: int = 0) -> AngleNoise:
        """Gaussian angles with standard deviation `sigma_deg` degrees, deterministic in seed."""
        if k < 1 or n < 1:
            raise ValueError(f"pseudo-pose noise needs K >= 1 and N >= 1, got K={k}, N={n}")
        rng = np.random.default_rng(seed)
        angles = rng.normal(0.0, np.radians(sigma_deg), size=(k, n, N_ANGLES))
        angles[:, 0] = 0.0
        return cls(angles)

    @property
    def shape(self) -> tuple[int, int]:
        """(K, N)."""
        return self.angles.shape[0], self.angles.shape[1]


def _local_offsets(
    lx: np.ndarray,
    ly: np.ndarray,
    lz: np.ndarray,
    side_x: np.ndarray,
    side_y: np.ndarray,
    side_z: np.ndarray,
    length: np.ndarray,
    theta1: np.ndarray,
    theta2: np.ndarray,
    delta: np.ndarray,
) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """Local-frame offsets from the chain root of the swung joint and of the limb end.

    (lx, ly, lz) is the lower limb, side its 90-degree turn in the limb plane, length the
    upper limb's; the hinge turns the lower limb by delta in its plane, then the swing
    turns everything by theta1 about local y (Eq. 10) and theta2 about local z (Eq. 11).
    """
    cd, sd = np.cos(delta), np.sin(delta)
    end_x = lx * cd + side_x * sd
    end_y = ly * cd + side_y * sd
    end_z = length + lz * cd + side_z * sd
    c1, s1, c2, s2 = np.cos(theta1), np.sin(theta1), np.cos(theta2), np.sin(theta2)
    mid = (c2 * s1 * length, s2 * s1 * length, c1 * length)
    end_x1 = c1 * end_x + s1 * end_z
    end = (c2 * end_x1 - s2 * end_y, s2 * end_x1 + c2 * end_y, c1 * end_z - s1 * end_x)
    return mid, end


def pseudo_poses(poses: np.ndarray, noise: AngleNoise) -> np.ndarray:
    """N pseudo-poses of each of K neighbour poses, for a batch of frames.

    `poses` (..., K, 13, 3) meters, any frame; returns (..., K, N, 13, 3) float64 whose
    bone lengths equal the input's. The angles of `noise` (K, N) apply to every leading
    batch entry alike.
    """
    poses = np.asarray(poses, dtype=np.float64)
    k, n = noise.shape
    if poses.shape[-3:] != (k, N_JOINTS, 3):
        raise ValueError(f"poses must be (..., {k}, 13, 3) for K={k}, got {poses.shape}")
    # Five chains: the neck (shoulder midpoint -> head, no hinge) and the four limbs.
    neck = 0.5 * (poses[..., 1:2, :] + poses[..., 2:3, :])
    roots = np.concatenate([neck, poses[..., LIMB_ROOTS, :]], axis=-2)  # (..., K, 5, 3)
    upper = poses[..., CHAIN_MIDS, :] - roots
    lower = poses[..., CHAIN_ENDS, :] - poses[..., CHAIN_MIDS, :]  # zero for the neck
    length = np.sqrt(_dot(upper, upper))
    z = upper / np.maximum(length, 1e-12)[..., None]
    x = _perpendicular(z, poses[..., 1:2, :] - poses[..., 2:3, :])
    y = _cross(z, x)

    # The lower limb in the local frame (x, y, z): the limb plane contains z, so its
    # normal is (ly, -lx, 0) / r and the lower limb turned 90 degrees in that plane is
    # (-lx lz, -ly lz, r^2) / r; a straight limb bends about x instead.
    lx, ly, lz = _dot(x, lower), _dot(y, lower), _dot(z, lower)
    r = np.hypot(lx, ly)
    straight = r < 1e-9
    safe_r = np.where(straight, 1.0, r)
    # One matrix product per (neighbour, chain) over the whole batch, whose coefficients
    # (K, 5, 2N, 21) every frame shares: lift the numbers against the local axes into
    # (K, 5, 21, B * 3) and multiply. Both factors are filled in place, slice by slice
    # (np.stack and np.moveaxis cost more than the arithmetic at live-path sizes).
    batch = poses.shape[:-3]
    size = math.prod(batch)
    numbers = np.empty((k, 5, N_LIMB_NUMBERS, size))  # (K, 5, 7, B)
    for column, value in enumerate(
        (
            lx,
            ly,
            lz,
            np.where(straight, 0.0, -lx * lz / safe_r),
            np.where(straight, -lz, -ly * lz / safe_r),
            np.where(straight, ly, r),
            length,
        )
    ):
        numbers[:, :, column] = value.reshape(size, k, 5).transpose(1, 2, 0)
    axes = np.empty((k, 5, 3, size, 3))  # (K, 5, axis, B, 3)
    for row, axis in enumerate((x, y, z)):
        axes[:, :, row] = axis.reshape(size, k, 5, 3).transpose(1, 2, 0, 3)
    lifted = numbers[:, :, :, None, :, None] * axes[:, :, None]  # (K, 5, 7, 3, B, 3)
    offsets = np.matmul(noise.coefficients, lifted.reshape(k, 5, -1, size * 3))
    offsets = offsets.reshape(k, 5, n, 2, size, 3)
    flat_poses = poses.reshape(size, k, N_JOINTS, 3)
    flat_roots = roots.reshape(size, k, 5, 3)
    out = np.empty((size, k, n, N_JOINTS, 3))
    # Joint by joint: 13 strided copies over the whole batch beat one fancy-indexed copy.
    for joint in FIXED_JOINTS:
        out[:, :, :, joint] = flat_poses[:, :, None, joint]
    for chain, joint in enumerate(CHAIN_MIDS):
        moved = offsets[:, chain, :, 0].transpose(2, 0, 1, 3)  # (B, K, N, 3)
        np.add(flat_roots[:, :, None, chain], moved, out=out[:, :, :, joint])
    for chain, joint in enumerate(LIMB_ENDS, start=1):
        moved = offsets[:, chain, :, 1].transpose(2, 0, 1, 3)
        np.add(flat_roots[:, :, None, chain], moved, out=out[:, :, :, joint])
    return out.reshape(*batch, k, n, N_JOINTS, 3)


def _perpendicular(z: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unit part of v (..., 3) perpendicular to unit z (Eq. 9); a fixed perpendicular
    where v is parallel to z."""
    x = v - _dot(v, z)[..., None] * z
    norm = np.sqrt(_dot(x, x))
    parallel = norm < 1e-9
    if parallel.any():
        helper = np.where(np.abs(z[..., 1:2]) < 0.9, [0.0, 1.0, 0.0], [0.0, 0.0, 1.0])
        x = np.where(parallel[..., None], _cross(helper, z), x)
        norm = np.sqrt(_dot(x, x))
    return x / norm[..., None]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("...i,...i->...", a, b)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of (..., 3) vectors (faster than np.cross for small batches)."""
    return a[..., [1, 2, 0]] * b[..., [2, 0, 1]] - a[..., [2, 0, 1]] * b[..., [1, 2, 0]]
