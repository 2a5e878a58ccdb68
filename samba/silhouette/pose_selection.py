"""Thinning a pose set to poses that differ from each other by some angle in some bone.

Okada, Stenger and Kondoh keep "only poses that differ at least 5 degrees in any joint
angle from other poses" for their silhouette tree. Our poses are joint positions, so the
joint angles here are the world-frame directions of 12 bones (`DIRECTION_NAMES`): the 8
limb bones, the trunk, the neck, and the shoulder and hip lines, which carry the body's
heading (a single camera sees a turned body as a different pose). Two poses differ by
`min_degrees` when the directions of at least one bone differ by that much.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from samba.base import InputError
from samba.body import BONES, N_JOINTS, checked_poses

_LIMB_NAMES: tuple[str, ...] = (
    "left upper arm",
    "left forearm",
    "right upper arm",
    "right forearm",
    "left thigh",
    "left shin",
    "right thigh",
    "right shin",
)
_DIRECTION_ENDS: tuple[tuple[tuple[int, ...], tuple[int, ...]], ...] = (
    *(((parent,), (child,)) for parent, child in BONES),
    ((7, 8), (1, 2)),  # trunk: hip midpoint to shoulder midpoint
    ((1, 2), (0,)),  # neck: shoulder midpoint to head
    ((2,), (1,)),  # shoulder line: right to left shoulder
    ((8,), (7,)),  # hip line: right to left hip
)
"""Each bone direction as (joints averaged at its start, joints averaged at its end)."""

DIRECTION_NAMES: tuple[str, ...] = (*_LIMB_NAMES, "trunk", "neck", "shoulder line", "hip line")
"""The 12 bones of `bone_directions`, in its order: the 8 limb bones in `BONES` order,
the trunk (hip midpoint to shoulder midpoint), the neck (shoulder midpoint to head), the
shoulder line and the hip line (right joint to left joint, so they point to the body's
left, +X in the standard pose)."""
N_DIRECTIONS = len(DIRECTION_NAMES)

_MIN_LENGTH = 1e-6
"""Length (m) below which a bone has no direction."""
_LEAF = 64
"""Poses `distinct_poses` decides one by one from all their pairs (larger sets are halved)."""
_PAIR_CHUNK = 8192
"""Pose pairs whose bone angles are compared at a time (small enough to stay in cache)."""


def _direction_matrix() -> np.ndarray:
    """(12, 13) weights turning joint positions into the bone vectors (end minus start)."""
    weights = np.zeros((N_DIRECTIONS, N_JOINTS))
    for row, (start, end) in enumerate(_DIRECTION_ENDS):
        weights[row, list(end)] += 1.0 / len(end)
        weights[row, list(start)] -= 1.0 / len(start)
    return weights


_DIRECTION_MATRIX = _direction_matrix()


def bone_directions(poses: np.ndarray) -> np.ndarray:
    """Unit world-frame directions (n, 12, 3) of the bones of poses (n, 13, 3) in meters.

    The order is `DIRECTION_NAMES`. Raises `InputError` ("poses") for a wrong shape, NaN
    or infinity, or a bone shorter than 1 micrometer (naming the pose and the bone).
    """
    vectors = _DIRECTION_MATRIX @ checked_poses(poses)
    lengths = np.linalg.norm(vectors, axis=-1)
    if (lengths < _MIN_LENGTH).any():
        pose, bone = np.argwhere(lengths < _MIN_LENGTH)[0]
        raise InputError("poses", f"pose {pose}: the {DIRECTION_NAMES[bone]} has no length")
    return vectors / lengths[..., None]


def _all_within(directions: np.ndarray, a: np.ndarray, b: np.ndarray, cos_min: float) -> np.ndarray:
    """Whether poses a[k] and b[k] (m,) are closer than the angle of `cos_min` in every
    bone, for unit directions (n, 3 * 12) stored coordinate-major (all x, all y, all z);
    in chunks of `_PAIR_CHUNK` pairs."""
    within = np.empty(len(a), dtype=bool)
    for start in range(0, len(a), _PAIR_CHUNK):
        part = slice(start, start + _PAIR_CHUNK)
        products = directions[a[part]]
        products *= directions[b[part]]
        cosines = products[:, :N_DIRECTIONS] + products[:, N_DIRECTIONS : 2 * N_DIRECTIONS]
        cosines += products[:, 2 * N_DIRECTIONS :]
        within[part] = cosines.min(axis=1) > cos_min
    return within


def _covered(
    directions: np.ndarray, block: np.ndarray, kept: np.ndarray, radius: float, cos_min: float
) -> np.ndarray:
    """Which poses of `block` (b,) lie within the angle in every bone of a `kept` pose.

    A k-d tree of the kept poses gives each one its nearest kept pose, which settles most
    of them; the others are checked against every kept pose in the Euclidean `radius`.
    """
    covered = np.zeros(len(block), dtype=bool)
    if not (block.size and kept.size):
        return covered
    tree = cKDTree(directions[kept])
    distance, nearest = tree.query(directions[block], distance_upper_bound=radius)
    near = np.isfinite(distance)
    covered[near] = _all_within(directions, block[near], kept[nearest[near]], cos_min)
    open_rows = np.flatnonzero(near & ~covered)
    if open_rows.size:
        found = tree.query_ball_point(directions[block[open_rows]], radius)
        counts = np.fromiter(map(len, found), dtype=np.intp, count=len(found))
        rows = np.repeat(open_rows, counts)
        others = kept[np.concatenate(found).astype(np.intp)]
        hit = _all_within(directions, block[rows], others, cos_min)
        covered[rows[hit]] = True
    return covered


def _greedy(directions: np.ndarray, block: np.ndarray, radius: float, cos_min: float) -> np.ndarray:
    """The poses of `block` (ascending indices) kept by the greedy among themselves.

    Exact divide and conquer: the first half is thinned, the poses of the second half
    that a pose kept there covers are dropped, and the rest are thinned in turn. Blocks
    of `_LEAF` poses are decided pose by pose from all their pairs.
    """
    if len(block) <= _LEAF:
        first, second = np.triu_indices(len(block), 1)
        within = np.zeros((len(block), len(block)), dtype=bool)
        within[second, first] = _all_within(directions, block[first], block[second], cos_min)
        keep = np.ones(len(block), dtype=bool)
        for pose in range(1, len(block)):
            keep[pose] = not (within[pose, :pose] & keep[:pose]).any()
        return block[keep]
    half = len(block) // 2
    kept = _greedy(directions, block[:half], radius, cos_min)
    rest = block[half:]
    rest = rest[~_covered(directions, rest, kept, radius, cos_min)]
    return np.concatenate([kept, _greedy(directions, rest, radius, cos_min)])


def distinct_poses(poses: np.ndarray, min_degrees: float = 5.0) -> np.ndarray:
    """Indices (k,) int, ascending, of the poses (n, 13, 3) m kept by the paper's thinning.

    Greedy in input order: a pose is kept unless an already kept pose is within
    `min_degrees` degrees of it in every bone of `bone_directions`. So every dropped
    pose has a kept one closer than `min_degrees` in all bones, and any two kept poses
    differ by at least `min_degrees` in some bone.

    Exact and batched: halves of the input are thinned in turn, each against the poses
    kept before it (recursively, down to blocks of `_LEAF` poses). Candidate pairs come
    from k-d trees (scipy `cKDTree`) on the 36 concatenated direction coordinates: poses
    within the angle in all 12 bones are within the Euclidean radius
    sqrt(12) * 2 sin(angle / 2) there; the candidates are then checked bone by bone.
    Raises `InputError` for bad poses (see `bone_directions`) or `min_degrees` outside
    (0, 180].
    """
    if not 0.0 < min_degrees <= 180.0:
        raise InputError("min_degrees", f"must be in (0, 180] degrees, got {min_degrees}")
    directions = bone_directions(poses).transpose(0, 2, 1).reshape(-1, 3 * N_DIRECTIONS)
    cos_min = float(np.cos(np.radians(min_degrees)))
    radius = np.sqrt(N_DIRECTIONS * (2.0 - 2.0 * cos_min)) * (1.0 + 1e-9) + 1e-12
    return _greedy(directions, np.arange(len(directions)), radius, cos_min)


def turned(poses: np.ndarray, degrees: np.ndarray) -> np.ndarray:
    """Poses (n, 13, 3) m turned about the vertical (+Y) through each one's hip midpoint
    by each of `degrees` (k,), counterclockwise seen from above (+Z toward +X).

    Returns (n * k, 13, 3) float64, pose-major: row i * k + j is pose i turned by
    degrees[j]. Raises `InputError` for bad poses, or `degrees` not finite or not 1-D.
    """
    array = checked_poses(poses)
    angles = np.asarray(degrees, dtype=np.float64)
    if angles.ndim != 1 or not np.isfinite(angles).all():
        raise InputError("degrees", f"must be a 1-D array of finite angles, got {angles}")
    cos = np.cos(np.radians(angles))[None, :, None]
    sin = np.sin(np.radians(angles))[None, :, None]
    pivot = array[:, None, [7, 8]].mean(axis=2, keepdims=True) * np.array([1.0, 0.0, 1.0])
    x, y, z = np.moveaxis(array[:, None] - pivot, -1, 0)
    turned_x, turned_z = cos * x + sin * z, cos * z - sin * x
    out = np.stack([turned_x, np.broadcast_to(y, turned_x.shape), turned_z], axis=-1)
    return (out + pivot).reshape(-1, N_JOINTS, 3)
