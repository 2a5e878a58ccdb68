"""The default avatar: a mannequin body generated from a humanoid rig and skinned to it.

The body is a union of convex hulls of spheres and ellipsoids placed on the rig's rest
pose (manifold3d keeps it one watertight, manifold solid): a torso hull from the pelvis
to the shoulders, a neck, a head reaching the head tip, tapered capsules for upper arms,
forearms, thighs and shins, mitten hands reaching the finger tips and feet whose soles
lie at the toe tips' height (the floor, for `HumanoidRig.from_body`). Every size is a
fraction of the body's height, so small and tall rigs get the same build. Quadric edge
collapse (pymeshlab) then brings it down to a game-friendly triangle count, keeping
topology and face orientation, and a few edge-swap and smoothing rounds remove sliver
triangles. Skin weights come from `samba.export.skin_weights`, measured in the same body
thickness (`BONE_RADIUS`) the limbs are built with.
"""

from __future__ import annotations

import manifold3d
import numpy as np
import pymeshlab

from samba.export.avatar_mesh import AvatarMesh
from samba.export.humanoid import BONE_INDEX, TIP_BONES, HumanoidRig
from samba.export.skin_weights import skin_weights

SPHERE_SEGMENTS = 40
"""Segments around the primitive spheres before decimation."""
REFINED_EDGE = 2.3
"""Before decimation, edges are split to at most this many times the final vertex
spacing (the side of a square of the mean face area), so that decimation leaves vertices
along the limbs (the hulls' long faces would otherwise stay whole: they are flat)."""
RELAXATION_STEPS = 3
"""Edge-swap and tangential smoothing rounds after decimation."""
MIN_FACES = 1000
"""Fewest triangles a mannequin may be asked for: with fewer, hands and feet lose their
shape."""

BONE_RADIUS = np.array(
    [[0.065, 0.05], [0.065, 0.075], [0.075, 0.03], [0.031, 0.031], [0.05, 0.05]]
    + [[0.028, 0.021], [0.021, 0.016], [0.016, 0.009]] * 2
    + [[0.042, 0.03], [0.03, 0.02], [0.02, 0.012]] * 2
)
"""Body thickness about each bone (bone order) at its joint and at its far end, as a
fraction of body height: limbs and the neck taper between these radii, and skinning
measures distances in them."""

_HIPS, _SPINE, _CHEST, _NECK, _HEAD = (
    BONE_INDEX[n] for n in ("Hips", "Spine", "Chest", "Neck", "Head")
)
_SIDES = ("Left", "Right")
_UNIT_SPHERE = manifold3d.Manifold.sphere(1.0, SPHERE_SEGMENTS).to_mesh().vert_properties[:, :3]


def mannequin(rig: HumanoidRig, target_faces: int = 6000) -> AvatarMesh:
    """The default avatar's body for `rig`: one closed, manifold triangle mesh of about
    `target_faces` triangles in the rig's rest pose (meters), with area-weighted vertex
    normals, skinned to the rig's 17 bones with at most 4 influences per vertex.
    Raises ValueError for fewer than `MIN_FACES` triangles."""
    if target_faces < MIN_FACES:
        raise ValueError(f"a mannequin needs at least {MIN_FACES} faces, got {target_faces}")
    height = body_height(rig)
    body = _body(rig, height)
    spacing = np.sqrt(body.surface_area() / target_faces)
    mesh = body.refine_to_length(REFINED_EDGE * spacing).to_mesh()
    vertices, faces = _decimated(mesh.vert_properties[:, :3], mesh.tri_verts, target_faces, spacing)
    joints, weights = skin_weights(vertices, faces, rig, BONE_RADIUS * height)
    return AvatarMesh(
        vertices=vertices,
        normals=vertex_normals(vertices, faces),
        faces=faces,
        joints=joints,
        weights=weights,
    )


def body_height(rig: HumanoidRig) -> float:
    """Height of `rig` in meters: from the lowest foot tip up to the head tip."""
    tips = rig.rest[list(TIP_BONES)] + rig.tips
    return float(tips[0, 1] - tips[3:, 1].min())


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit normals (V, 3) of a mesh's `vertices` (V, 3): the area-weighted mean of the
    normals of the faces (F, 3) around each vertex (counter-clockwise faces give outward
    normals)."""
    corners = np.asarray(vertices, dtype=np.float64)[faces]
    face_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    sums = np.zeros((len(vertices), 3))
    np.add.at(sums, faces.ravel(), np.repeat(face_normals, 3, axis=0))
    return sums / np.maximum(np.linalg.norm(sums, axis=1, keepdims=True), 1e-30)


def _body(rig: HumanoidRig, height: float) -> manifold3d.Manifold:
    """The union of all body parts of `rig` (a body `height` meters tall)."""
    rest, tips = rig.rest, rig.tips
    radius = BONE_RADIUS * height
    torso = _torso_frame(rest)
    parts = [_torso(rest, torso, height), _capsule(rest[_NECK], rest[_HEAD], *radius[_NECK])]
    parts.append(_head(rest[_HEAD], tips[0], torso[2], height))
    for side, tip in zip(_SIDES, (tips[1], tips[2]), strict=True):
        upper, lower, hand = (BONE_INDEX[side + n] for n in ("UpperArm", "LowerArm", "Hand"))
        parts.append(_capsule(rest[upper], rest[lower], *radius[upper]))
        parts.append(_capsule(rest[lower], rest[hand], *radius[lower]))
        parts.append(_hand(rest[hand], tip, torso[2], radius[hand, 0], height))
    for side, tip in zip(_SIDES, (tips[3], tips[4]), strict=True):
        upper, lower, foot = (BONE_INDEX[side + n] for n in ("UpperLeg", "LowerLeg", "Foot"))
        parts.append(_capsule(rest[upper], rest[lower], *radius[upper]))
        parts.append(_capsule(rest[lower], rest[foot], *radius[lower]))
        parts.append(_foot(rest[foot], tip, torso[2], radius[foot, 0], height))
    return manifold3d.Manifold.batch_boolean(parts, manifold3d.OpType.Add)


def _torso_frame(rest: np.ndarray) -> np.ndarray:
    """Rows: the body's left, up and forward unit vectors in the rest pose (3, 3)."""
    up = _unit(rest[_NECK] - rest[_HIPS])
    left = _orthogonal(rest[BONE_INDEX["LeftUpperLeg"]] - rest[BONE_INDEX["RightUpperLeg"]], up)
    return np.stack([left, up, np.cross(left, up)])


def _torso(rest: np.ndarray, frame: np.ndarray, height: float) -> manifold3d.Manifold:
    """Hull of the pelvis, waist and chest ellipsoids and of spheres at the hips, the
    shoulders and the base of the neck."""
    up = frame[1]
    shoulders = [rest[BONE_INDEX[s + "UpperArm"]] - 0.01 * height * up for s in _SIDES]
    hips = [rest[BONE_INDEX[s + "UpperLeg"]] for s in _SIDES]
    centers = np.array([rest[_HIPS], rest[_SPINE], rest[_CHEST], rest[_NECK], *shoulders, *hips])
    semi_axes = np.array(
        [
            [0.085, 0.05, 0.065],
            [0.078, 0.05, 0.058],
            [0.092, 0.07, 0.065],
            [0.03, 0.03, 0.03],
            *[[0.036] * 3] * 2,
            *[[0.05] * 3] * 2,
        ]
    )
    return _hull(centers, semi_axes * height, frame)


def _head(
    joint: np.ndarray, tip: np.ndarray, forward: np.ndarray, height: float
) -> manifold3d.Manifold:
    """Hull of a cranium ellipsoid whose top is the head tip and a jaw sphere in front of
    the head joint."""
    up = _unit(tip)
    front = _orthogonal(forward, up)
    frame = np.stack([np.cross(up, front), up, front])
    crown = 0.52 * np.linalg.norm(tip)
    centers = np.array([joint + tip - crown * up, joint + 0.028 * height * front])
    semi_axes = np.array([[0.046 * height, crown, 0.056 * height], [0.03 * height] * 3])
    return _hull(centers, semi_axes, frame)


def _hand(
    wrist: np.ndarray, tip: np.ndarray, forward: np.ndarray, radius: float, height: float
) -> manifold3d.Manifold:
    """A mitten: hull of a wrist sphere, a palm and a finger ellipsoid reaching the tip,
    flat across the hand's width (the part of `forward` across the hand)."""
    length = np.linalg.norm(tip)
    along = tip / length
    across = _orthogonal(forward, along)
    frame = np.stack([along, across, np.cross(along, across)])
    centers = np.array([wrist, wrist + 0.32 * tip, wrist + 0.75 * tip])
    semi_axes = np.array(
        [
            [radius] * 3,
            [0.2 * length, 0.028 * height, 0.012 * height],
            [0.25 * length, 0.024 * height, 0.009 * height],
        ]
    )
    return _hull(centers, semi_axes, frame)


def _foot(
    ankle: np.ndarray, tip: np.ndarray, forward: np.ndarray, radius: float, height: float
) -> manifold3d.Manifold:
    """Hull of an ankle sphere and of heel, ball and toe spheres standing on the sole,
    the horizontal plane through the toe tip, the toes reaching the tip."""
    up = np.array([0.0, 1.0, 0.0])
    ahead = tip - up * tip[1]
    length = np.linalg.norm(ahead)
    ahead = ahead / length if length > 1e-9 else _orthogonal(forward, up)
    side = np.cross(up, ahead)
    sole = ankle + up * tip[1]
    r_heel, r_ball, r_toe = 0.022 * height, 0.013 * height, 0.01 * height
    ball = sole + 0.68 * length * ahead + r_ball * up
    centers = np.array(
        [
            ankle,
            sole - 0.12 * length * ahead + r_heel * up,
            ball + 0.016 * height * side,
            ball - 0.016 * height * side,
            sole + (length - r_toe) * ahead + r_toe * up,
        ]
    )
    radii = np.array([radius, r_heel, r_ball, r_ball, r_toe])
    return _hull(centers, radii[:, None] * np.ones(3), np.eye(3))


def _capsule(
    start: np.ndarray, end: np.ndarray, r_start: float, r_end: float
) -> manifold3d.Manifold:
    """A tapered capsule: hull of spheres of radius `r_start` at `start` and `r_end` at
    `end`, meters."""
    radii = np.array([r_start, r_end])
    return _hull(np.array([start, end]), radii[:, None] * np.ones(3), np.eye(3))


def _hull(centers: np.ndarray, semi_axes: np.ndarray, frame: np.ndarray) -> manifold3d.Manifold:
    """Convex hull of ellipsoids at `centers` (k, 3) with `semi_axes` (k, 3) along the
    rows of `frame` (3, 3), meters."""
    points = centers[:, None, :] + (_UNIT_SPHERE[None] * semi_axes[:, None, :]) @ frame
    return manifold3d.Manifold.hull_points(points.reshape(-1, 3))


def _decimated(
    vertices: np.ndarray, faces: np.ndarray, target_faces: int, spacing: float
) -> tuple[np.ndarray, np.ndarray]:
    """The mesh (V, 3) meters, (F, 3) indices reduced to `target_faces` triangles by
    quadric edge collapse that keeps its topology and face orientation, then relaxed
    (edge swaps and tangential smoothing, no vertex added or removed, staying within a
    tenth of the mean vertex `spacing` of the surface, meters) to remove slivers."""
    meshes = pymeshlab.MeshSet()
    meshes.add_mesh(
        pymeshlab.Mesh(
            vertex_matrix=vertices.astype(np.float64), face_matrix=faces.astype(np.int32)
        )
    )
    meshes.meshing_decimation_quadric_edge_collapse(
        targetfacenum=target_faces,
        qualitythr=0.5,
        preservetopology=True,
        preservenormal=True,
        optimalplacement=True,
        planarquadric=True,
    )
    meshes.meshing_isotropic_explicit_remeshing(
        iterations=RELAXATION_STEPS,
        targetlen=pymeshlab.PureValue(spacing),
        splitflag=False,
        collapseflag=False,
        maxsurfdist=pymeshlab.PureValue(0.1 * spacing),
    )
    meshes.meshing_remove_unreferenced_vertices()
    result = meshes.current_mesh()
    return result.vertex_matrix(), result.face_matrix()


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _orthogonal(v: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The unit part of `v` orthogonal to the unit `axis`."""
    return _unit(v - np.dot(v, axis) * axis)
