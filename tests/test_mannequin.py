"""The default avatar: a closed mannequin mesh that fits its rig and bends with it."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest
import trimesh

from samba.body.skeleton import Body
from samba.export.avatar_mesh import MAX_INFLUENCES, AvatarMesh
from samba.export.humanoid import BONE_INDEX, BONE_NAMES, N_BONES, TIP_BONES, HumanoidRig
from samba.export.mannequin import MIN_FACES, body_height, mannequin
from samba.export.motion import HumanoidMotion
from samba.export.retargeting import retarget

T_POSE = HumanoidRig.from_body()
A_POSE_SMALL = HumanoidRig.from_body(Body.from_height(1.5), arm_angle_deg=40)


class Case(NamedTuple):
    """A rig, its mannequin, and the body and arm angle (degrees) the rig was built from."""

    rig: HumanoidRig
    mesh: AvatarMesh
    body: Body
    arm_angle: float


BODIES = {
    "t-pose": (T_POSE, Body.from_height(), 90.0),
    "a-pose-small": (A_POSE_SMALL, Body.from_height(1.5), 40.0),
}


@pytest.fixture(scope="module", params=list(BODIES))
def case(request: pytest.FixtureRequest) -> Case:
    rig, body, arm_angle = BODIES[request.param]
    return Case(rig, mannequin(rig), body, arm_angle)


def dense_weights(mesh: AvatarMesh) -> np.ndarray:
    """Skin weights (V, 17) of every bone."""
    dense = np.zeros((len(mesh.vertices), N_BONES))
    rows = np.repeat(np.arange(len(mesh.vertices)), MAX_INFLUENCES)
    np.add.at(dense, (rows, mesh.joints.ravel().astype(int)), mesh.weights.ravel())
    return dense


def skinned(mesh: AvatarMesh, motion: HumanoidMotion, frame: int = 0) -> np.ndarray:
    """Vertices (V, 3) of `mesh` posed by linear blend skinning at a frame of `motion`."""
    world = motion.world_matrices()[frame]
    joints = motion.world_positions()[frame]
    rest = motion.rig.rest
    v = mesh.vertices.astype(np.float64)
    out = np.zeros_like(v)
    for k in range(MAX_INFLUENCES):
        j = mesh.joints[:, k].astype(int)
        moved = np.einsum("vij,vj->vi", world[j], v - rest[j]) + joints[j]
        out += mesh.weights[:, k, None] * moved
    return out


def segment_distance(
    points: np.ndarray, a: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Distance (n,) of points (n, 3) to segment a-b and where along it (0 at a, 1 at b)
    their projection falls (not clamped)."""
    axis = b - a
    t = (points - a) @ axis / (axis @ axis)
    closest = a + np.clip(t, 0.0, 1.0)[:, None] * axis
    return np.linalg.norm(points - closest, axis=1), t


def end_of(rig: HumanoidRig, bone: str) -> np.ndarray:
    """Where a limb bone ends: its child's joint, or its tip for hands and feet."""
    index = BONE_INDEX[bone]
    if index in TIP_BONES:
        return rig.rest[index] + rig.tips[TIP_BONES.index(index)]
    return rig.rest[index + 1]


def region(
    rig: HumanoidRig, mesh: AvatarMesh, bone: str, t_range: tuple[float, float], reach: float
) -> np.ndarray:
    """Vertices within `reach` (a fraction of body height) of a limb bone whose position
    along the bone (0 at its joint, 1 at its end) is within `t_range`."""
    distance, t = segment_distance(
        mesh.vertices.astype(np.float64), rig.rest[BONE_INDEX[bone]], end_of(rig, bone)
    )
    selected = (t >= t_range[0]) & (t <= t_range[1]) & (distance < reach * body_height(rig))
    assert selected.sum() >= 8, f"too few vertices found on {bone}"
    return selected


def test_the_mannequin_is_one_closed_outward_facing_surface(case: Case) -> None:
    rig, mesh, _, _ = case
    surface = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    assert surface.is_watertight
    assert surface.is_winding_consistent
    assert surface.body_count == 1
    assert surface.volume > 0.008 * body_height(rig) ** 3
    assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-5)
    corner_normals = mesh.normals[mesh.faces]
    agreement = np.einsum("fcj,fj->fc", corner_normals, surface.face_normals)
    assert np.mean(agreement > 0) > 0.99


@pytest.mark.parametrize("target", [2500, 6000])
def test_the_triangle_count_is_close_to_the_target(target: int) -> None:
    mesh = mannequin(A_POSE_SMALL, target_faces=target)
    assert abs(len(mesh.faces) - target) <= 0.1 * target
    assert trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).is_watertight


def test_too_few_triangles_are_refused() -> None:
    with pytest.raises(ValueError, match="at least"):
        mannequin(T_POSE, target_faces=MIN_FACES - 1)


def test_the_mannequin_stands_on_the_floor_and_fills_the_rigs_height_and_span(case: Case) -> None:
    rig, mesh, _, _ = case
    v = mesh.vertices
    tips = rig.rest[list(TIP_BONES)] + rig.tips
    assert v[:, 1].min() == pytest.approx(0.0, abs=0.005)
    assert v[:, 1].max() == pytest.approx(tips[0, 1], abs=0.01)
    assert v[:, 0].max() == pytest.approx(tips[1, 0], abs=0.02)
    assert v[:, 0].min() == pytest.approx(tips[2, 0], abs=0.02)
    assert v[:, 2].max() == pytest.approx(tips[3, 2], abs=0.01)


def test_skin_weights_are_four_sorted_non_negative_and_sum_to_one(case: Case) -> None:
    _, mesh, _, _ = case
    w, j = mesh.weights, mesh.joints
    assert w.shape == j.shape == (len(mesh.vertices), MAX_INFLUENCES)
    assert w.dtype == np.float32 and j.dtype == np.uint16
    assert (w >= 0).all() and (j < N_BONES).all()
    assert np.abs(w.sum(axis=1) - 1.0).max() < 1e-6
    assert (np.diff(w, axis=1) <= 0).all()
    assert (j[w == 0] == 0).all()
    used = np.where(w > 0, j.astype(int), -1 - np.arange(MAX_INFLUENCES))
    assert (np.sort(used, axis=1)[:, 1:] != np.sort(used, axis=1)[:, :-1]).all()


@pytest.mark.parametrize(
    ("bone", "t_range", "reach"),
    [
        ("LeftUpperArm", (0.4, 0.7), 0.035),
        ("LeftLowerArm", (0.3, 0.7), 0.03),
        ("RightLowerArm", (0.3, 0.7), 0.03),
        ("LeftHand", (0.3, 1.0), 0.045),
        ("RightUpperLeg", (0.3, 0.7), 0.05),
        ("LeftLowerLeg", (0.3, 0.7), 0.04),
        ("LeftFoot", (0.4, 1.0), 0.045),
        ("Head", (0.3, 1.0), 0.07),
    ],
)
def test_the_middle_of_a_body_part_moves_with_its_own_bone(
    case: Case, bone: str, t_range: tuple[float, float], reach: float
) -> None:
    rig, mesh, _, _ = case
    weights = dense_weights(mesh)[region(rig, mesh, bone, t_range, reach), BONE_INDEX[bone]]
    assert weights.min() > 0.75
    assert weights.mean() > 0.95


@pytest.mark.parametrize(
    ("parent", "child"),
    [
        ("LeftUpperArm", "LeftLowerArm"),
        ("RightUpperLeg", "RightLowerLeg"),
        ("Chest", "LeftUpperArm"),
    ],
)
def test_joints_blend_the_two_bones_they_join(case: Case, parent: str, child: str) -> None:
    rig, mesh, _, _ = case
    joint = rig.rest[BONE_INDEX[child]]
    near = np.linalg.norm(mesh.vertices - joint, axis=1) < 0.045 * body_height(rig)
    weights = dense_weights(mesh)[near]
    both = weights[:, BONE_INDEX[parent]] + weights[:, BONE_INDEX[child]]
    assert near.sum() >= 8
    assert np.median(weights[:, BONE_INDEX[parent]]) > 0.2
    assert np.median(weights[:, BONE_INDEX[child]]) > 0.2
    assert np.median(both) > 0.9


def test_bones_of_one_side_never_move_the_other_side(case: Case) -> None:
    rig, mesh, _, _ = case
    weights = dense_weights(mesh)
    side = {s: [i for i, n in enumerate(BONE_NAMES) if n.startswith(s)] for s in ("Left", "Right")}
    x = mesh.vertices[:, 0] / body_height(rig)
    assert weights[x > 0.05][:, side["Right"]].max() == 0.0
    assert weights[x < -0.05][:, side["Left"]].max() == 0.0


def test_an_arm_moves_only_with_its_own_bones_and_the_chest(case: Case) -> None:
    rig, mesh, _, _ = case
    arm = (
        region(rig, mesh, "LeftUpperArm", (0.4, 1.0), 0.035)
        | region(rig, mesh, "LeftLowerArm", (0.0, 1.0), 0.035)
        | region(rig, mesh, "LeftHand", (0.0, 1.0), 0.045)
    )
    allowed = [BONE_INDEX[n] for n in ("Chest", "LeftUpperArm", "LeftLowerArm", "LeftHand")]
    others = np.delete(dense_weights(mesh)[arm], allowed, axis=1)
    assert others.max() == 0.0


def test_a_rigid_motion_of_the_whole_skeleton_moves_the_mannequin_rigidly(case: Case) -> None:
    rig, mesh, _, _ = case
    turn = np.array([0.2, -0.4, 0.1, 0.9]) / np.linalg.norm([0.2, -0.4, 0.1, 0.9])
    rotations = np.tile([0.0, 0.0, 0.0, 1.0], (1, N_BONES, 1))
    rotations[0, 0] = turn
    root = rig.rest[0] + [0.3, -0.1, 1.2]
    motion = HumanoidMotion(rig, rotations, root[None], fps=30.0)
    world = motion.world_matrices()[0, 0]
    expected = (mesh.vertices - rig.rest[0]) @ world.T + root
    assert np.abs(skinned(mesh, motion) - expected).max() < 1e-5


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def bent_left_elbow(body: Body, arm_angle: float) -> np.ndarray:
    """The standard pose (13, 3) with the left forearm turned to point straight forward."""
    pose = body.standard_pose(arm_angle)
    pose[5] = pose[3] + body.forearm * np.array([0.0, 0.0, 1.0])
    return pose


def test_a_bent_elbow_carries_the_hand_and_forearm_with_their_joints(case: Case) -> None:
    rig, mesh, body, arm_angle = case
    motion = retarget(bent_left_elbow(body, arm_angle)[None], rig, fps=30.0)
    joints = motion.world_positions()[0]
    elbow, wrist = joints[BONE_INDEX["LeftLowerArm"]], joints[BONE_INDEX["LeftHand"]]
    hand_tip = motion.tip_positions()[0, TIP_BONES.index(BONE_INDEX["LeftHand"])]
    assert _unit(wrist - elbow) == pytest.approx([0.0, 0.0, 1.0], abs=1e-6)
    rest, posed = mesh.vertices.astype(np.float64), skinned(mesh, motion)
    for bone, t_range, (a, b) in (
        ("LeftLowerArm", (0.3, 0.7), (elbow, wrist)),
        ("LeftHand", (0.3, 1.0), (wrist, hand_tip)),
    ):
        part = region(rig, mesh, bone, t_range, 0.045)
        distance_rest, t_rest = segment_distance(
            rest[part], rig.rest[BONE_INDEX[bone]], end_of(rig, bone)
        )
        distance_posed, t_posed = segment_distance(posed[part], a, b)
        assert np.abs(distance_posed - distance_rest).max() < 0.005
        assert np.abs(t_posed - t_rest).max() < 0.05


def test_bending_the_elbow_keeps_the_body_volume(case: Case) -> None:
    rig, mesh, body, arm_angle = case
    motion = retarget(bent_left_elbow(body, arm_angle)[None], rig, fps=30.0)
    rest_volume = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).volume
    posed_volume = trimesh.Trimesh(skinned(mesh, motion), mesh.faces, process=False).volume
    assert posed_volume == pytest.approx(rest_volume, rel=0.01)


def test_the_mannequin_is_built_the_same_every_time() -> None:
    first = mannequin(T_POSE)
    second = mannequin(T_POSE)
    for field in ("vertices", "normals", "faces", "joints", "weights"):
        assert np.array_equal(getattr(first, field), getattr(second, field))
