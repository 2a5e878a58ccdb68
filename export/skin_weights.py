"""Skin weights of a body mesh to the humanoid skeleton, from distances to the bones.

Each bone is one or more segments: from its joint to each child's joint, and for the
leaf bones (Head, hands, feet) from the joint to its tip, so Hips covers the pelvis to
both hips and to Spine, and Chest the chest to the neck and to both shoulders. A
vertex's distance to a segment is divided by the body's thickness there (radii given
at each bone's joint and far end, tapering linearly), so a thick torso and a thin arm
count alike, and the part of it lying beyond the segment's far end counts double, so a
heel belongs to the foot rather than to the shin that ends at the ankle.

A vertex belongs to the bone nearest in that measure, and only that bone, its parent
and its children may move it: a Gaussian of the normalised distance weighs them. Weights
are then smoothed over the mesh (a few Laplacian steps between neighbouring vertices),
and the largest `MAX_INFLUENCES` kept.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from samba.export.avatar_mesh import MAX_INFLUENCES
from samba.export.humanoid import N_BONES, PARENTS, TIP_BONES, HumanoidRig

FALLOFF = 2.0
"""Gaussian falloff: a bone weighs exp(-FALLOFF * (q² - q_min²)) at normalised distance q
when the nearest bone is at q_min."""
OVERSHOOT = 2.0
"""Factor on the distance along a segment's axis beyond its far end."""
SMOOTHING_STEPS = 3
"""Laplacian smoothing steps over the mesh."""
SMOOTHING_RATE = 0.5
"""Each smoothing step moves a vertex's weights this share of the way to the mean of its
neighbours' weights."""
MIN_WEIGHT = 0.01
"""Influences below this share of a vertex are dropped (the rest renormalised)."""


def bone_segments(rig: HumanoidRig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The segments that make up the bones of `rig` in its rest pose: `starts` (S, 3) and
    `ends` (S, 3) in meters and `bones` (S,) the bone index of each, S = 21 (one per
    parent-child pair, then one per tip, in `TIP_BONES` order)."""
    children = np.arange(1, N_BONES)
    parents = np.array(PARENTS[1:])
    tips = np.array(TIP_BONES)
    starts = np.concatenate([rig.rest[parents], rig.rest[tips]])
    ends = np.concatenate([rig.rest[children], rig.rest[tips] + rig.tips])
    return starts, ends, np.concatenate([parents, tips])


def skin_weights(
    vertices: np.ndarray,
    faces: np.ndarray,
    rig: HumanoidRig,
    bone_radius: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Skin weights of a mesh, `vertices` (V, 3) meters in the rest pose of `rig` and
    `faces` (F, 3) vertex indices, given the body's thickness about each bone
    `bone_radius` (17, 2): at its joint and at its far end (children's joints or tip),
    meters.

    Returns `joints` (V, 4) uint16 bone indices and `weights` (V, 4) float32, largest
    first, non-negative, summing to 1 per vertex, unused slots with bone 0 and weight 0.
    """
    q = _normalised_distances(np.asarray(vertices, dtype=np.float64), rig, bone_radius)
    owner = np.argmin(q, axis=1)
    q_min = q[np.arange(len(q)), owner]
    weights = np.exp(-FALLOFF * (q**2 - q_min[:, None] ** 2)) * _family()[owner]
    weights = _smoothed(weights, np.asarray(faces, dtype=np.int64), len(q))
    return _strongest(weights)


def _normalised_distances(
    vertices: np.ndarray, rig: HumanoidRig, bone_radius: np.ndarray
) -> np.ndarray:
    """Each vertex's distance (V, 17) to each bone (its nearest segment) in units of the
    body's thickness there, the overshoot beyond a segment's far end counted `OVERSHOOT`
    times."""
    starts, ends, bones = bone_segments(rig)
    r_start, r_end = np.asarray(bone_radius, dtype=np.float64)[bones].T
    axis = ends - starts
    length = np.linalg.norm(axis, axis=1)
    axis = axis / np.maximum(length, 1e-12)[:, None]
    offset = vertices[:, None, :] - starts[None]
    along = np.einsum("vsi,si->vs", offset, axis)
    clamped = np.clip(along, 0.0, length)
    radial = np.linalg.norm(offset - clamped[..., None] * axis, axis=-1)
    overshoot = OVERSHOOT * np.maximum(along - length, 0.0) + np.maximum(-along, 0.0)
    t = clamped / np.maximum(length, 1e-12)
    thickness = r_start + t * (r_end - r_start)
    q_segment = np.hypot(radial, overshoot) / thickness
    q = np.full((len(vertices), N_BONES), np.inf)
    np.minimum.at(q, (slice(None), bones), q_segment)
    return q


def _family() -> np.ndarray:
    """(17, 17) mask: bone j may move a vertex owned by bone i (j is i, its parent or a
    child of it)."""
    family = np.eye(N_BONES, dtype=bool)
    children = np.arange(1, N_BONES)
    parents = np.array(PARENTS[1:])
    family[children, parents] = True
    family[parents, children] = True
    return family


def _smoothed(weights: np.ndarray, faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Weights (V, 17) after `SMOOTHING_STEPS` Laplacian steps over the mesh's edges."""
    edges = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    adjacency = sparse.coo_matrix(
        (np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n_vertices, n_vertices)
    ).tocsr()
    adjacency = ((adjacency + adjacency.T) > 0).astype(np.float64)
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    mean = sparse.diags(1.0 / np.maximum(degree, 1.0)) @ adjacency
    weights = weights / weights.sum(axis=1, keepdims=True)
    for _ in range(SMOOTHING_STEPS):
        weights = weights + SMOOTHING_RATE * (mean @ weights - weights)
    return weights


def _strongest(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The `MAX_INFLUENCES` largest of weights (V, 17) above `MIN_WEIGHT` of the total,
    largest first and renormalised: joints (V, 4) uint16 and weights (V, 4) float32."""
    order = np.argsort(-weights, axis=1, kind="stable")[:, :MAX_INFLUENCES]
    top = np.take_along_axis(weights, order, axis=1)
    top = top / top.sum(axis=1, keepdims=True)
    keep = top >= MIN_WEIGHT
    top = np.where(keep, top, 0.0)
    top = (top / top.sum(axis=1, keepdims=True)).astype(np.float32)
    joints = np.where(keep, order, 0).astype(np.uint16)
    return joints, top
