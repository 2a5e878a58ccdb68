"""Retargeting: 13 joint positions per frame -> local bone rotations of a humanoid rig.

Bone directions come from the captured joints and are reproduced exactly (up to float
rounding) for every bone whose both ends are captured: upper arms, forearms, thighs,
shins, the neck (shoulder middle to head), the spine as a whole (hip middle to shoulder
middle), and the shoulder and hip lines. The avatar keeps its own bone lengths.

Twist comes from the body lines and the limb planes:

* Hips turn so the hip line points along the captured one, Chest likewise with the
  shoulder line; Spine takes whatever rotation puts the Neck joint on the captured spine
  line (the chain bends between pelvis and shoulders).
* Upper and lower limb share one bend axis: the normal of the limb plane (shoulder,
  elbow, wrist or hip, knee, ankle). Where the limb is nearly straight the plane is
  undefined; the axis then blends smoothly (2° .. 25° of bend) into a reference axis
  carried along with the torso by the shortest swing from a reference limb direction.
  That swing is singular only for an arm pointing up, back and across the body or a
  leg pointing straight up, so straight limbs do not flip.
* Hands follow the forearms and the head the neck (the 13 joints say nothing of
  them); feet stay level, turned about the vertical to the knee axis, and follow the
  shin instead where the knee axis is far from horizontal.

The root (Hips) follows the captured hip middle scaled by the ratio of the rig's leg
length to the subject's, so the avatar's feet stay on the floor and its steps match.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from export.humanoid import CAPTURE_JOINT, N_BONES, PARENTS, HumanoidRig
from export.motion import HumanoidMotion
from samba.skeleton import N_JOINTS

MEASURED_BONES: tuple[tuple[str, int, int], ...] = (
    ("spine", 0, 3),
    ("neck", 3, 4),
    ("shoulder line", 8, 5),
    ("hip line", 14, 11),
    ("left upper arm", 5, 6),
    ("left forearm", 6, 7),
    ("right upper arm", 8, 9),
    ("right forearm", 9, 10),
    ("left thigh", 11, 12),
    ("left shin", 12, 13),
    ("right thigh", 14, 15),
    ("right shin", 15, 16),
)
"""Directions the retargeting reproduces: (name, from bone, to bone); each is the
direction between the two bones' joints, compared with the same points of the capture."""

_LIMBS: tuple[
    tuple[int, int, int, int, tuple[float, float, float], tuple[float, float, float]], ...
] = (
    # (upper bone, lower bone, end bone, parent of the limb, reference direction, bend direction)
    (5, 6, 7, 2, (0.5, -0.6, 0.6), (0.0, 0.0, 1.0)),
    (8, 9, 10, 2, (-0.5, -0.6, 0.6), (0.0, 0.0, 1.0)),
    (11, 12, 13, 0, (0.0, -1.0, 0.1), (0.0, 0.0, -1.0)),
    (14, 15, 16, 0, (0.0, -1.0, 0.1), (0.0, 0.0, -1.0)),
)
_STRAIGHT = (np.sin(np.radians(2.0)), np.sin(np.radians(25.0)))
"""Bend (as sine of the angle) below which a limb counts as straight, above which its
plane alone gives the bend axis."""
_LEVEL_FOOT = (0.5, 0.8)
"""Horizontal share of the knee axis below which a foot follows its shin, above which it
stays level."""


def capture_points(poses: np.ndarray) -> np.ndarray:
    """Where each humanoid bone's joint is on captured poses (n, 13, 3): returns (n, 17, 3)
    with Hips at the hip middle, Neck at the shoulder middle, Spine and Chest at 1/4 and
    3/5 of the way between them, the others at their 13-joint joint."""
    poses = np.asarray(poses, dtype=np.float64)
    out = np.empty((*poses.shape[:-2], N_BONES, 3))
    pelvis = (poses[..., 7, :] + poses[..., 8, :]) / 2
    neck = (poses[..., 1, :] + poses[..., 2, :]) / 2
    out[..., 0, :] = pelvis
    out[..., 1, :] = pelvis + 0.25 * (neck - pelvis)
    out[..., 2, :] = pelvis + 0.6 * (neck - pelvis)
    out[..., 3, :] = neck
    for bone, joint in CAPTURE_JOINT.items():
        out[..., bone, :] = poses[..., joint, :]
    return out


def bone_direction_errors(avatar: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Angles (n, 12) in degrees between the `MEASURED_BONES` directions of avatar joint
    positions (n, 17, 3) and of captured poses (n, 13, 3)."""
    capture = capture_points(poses)
    avatar = np.asarray(avatar, dtype=np.float64)
    a = np.stack([avatar[:, j] - avatar[:, i] for _, i, j in MEASURED_BONES], axis=1)
    c = np.stack([capture[:, j] - capture[:, i] for _, i, j in MEASURED_BONES], axis=1)
    cos = np.sum(_unit(a) * _unit(c), axis=-1)
    sin = np.linalg.norm(np.cross(_unit(a), _unit(c)), axis=-1)
    return np.degrees(np.arctan2(sin, cos))


def leg_length(poses: np.ndarray) -> float:
    """The subject's leg length (hip-knee-ankle, median over frames and sides) in the
    units of poses (n, 13, 3)."""
    poses = np.asarray(poses, dtype=np.float64)
    thigh = np.linalg.norm(poses[:, [9, 10]] - poses[:, [7, 8]], axis=-1)
    shin = np.linalg.norm(poses[:, [11, 12]] - poses[:, [9, 10]], axis=-1)
    return float(np.median(thigh + shin))


def retarget(poses: np.ndarray, rig: HumanoidRig, fps: float) -> HumanoidMotion:
    """Local bone rotations of `rig` that follow captured poses (n, 13, 3) in meters
    (+Y up, subject facing +Z at rest, floor at the ankles' height) at `fps` frames/s."""
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (N_JOINTS, 3) or len(poses) == 0:
        raise ValueError(f"retarget needs poses of shape (n, 13, 3), got {poses.shape}")
    if not np.isfinite(poses).all():
        raise ValueError("retarget needs finite poses (fill or drop frames with NaN first)")
    world = _world_rotations(capture_points(poses), rig.rest)
    parents = np.array(PARENTS)
    local = world.copy()
    local[:, 1:] = np.swapaxes(world[:, parents[1:]], -1, -2) @ world[:, 1:]
    n = len(poses)
    rotations = Rotation.from_matrix(local.reshape(-1, 3, 3)).as_quat().reshape(n, N_BONES, 4)
    scale = rig.leg_length / leg_length(poses)
    root = capture_points(poses)[:, 0] * scale + [0.0, rig.ankle_height, 0.0]
    return HumanoidMotion(rig=rig, rotations=rotations, root=root, fps=fps)


def _world_rotations(capture: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """World rotations (n, 17, 3, 3) taking the rig's rest bones to the captured ones."""
    n = len(capture)
    world = np.empty((n, N_BONES, 3, 3))
    spine = capture[:, 3] - capture[:, 0]
    spine_rest = rest[3] - rest[0]
    hip_line = capture[:, 11] - capture[:, 14]
    shoulder_line = capture[:, 5] - capture[:, 8]
    world[:, 0] = _frame(hip_line, spine) @ _frame(rest[11] - rest[14], spine_rest).T
    world[:, 2] = _frame(shoulder_line, spine) @ _frame(rest[5] - rest[8], spine_rest).T
    world[:, 1] = _spine_rotation(world[:, 0], world[:, 2], spine, rest)
    world[:, 3] = (
        _frame(capture[:, 4] - capture[:, 3], shoulder_line)
        @ _frame(rest[4] - rest[3], rest[5] - rest[8]).T
    )
    world[:, 4] = world[:, 3]
    for upper, lower, end, parent, reference, bend in _LIMBS:
        reference = _unit(np.array(reference))
        bend_ref = _unit(np.cross(reference, bend))
        rest_axis = _bend_axis(
            rest[None, lower] - rest[upper],
            rest[None, end] - rest[lower],
            np.eye(3)[None],
            reference,
            bend_ref,
        )[0]
        axis = _bend_axis(
            capture[:, lower] - capture[:, upper],
            capture[:, end] - capture[:, lower],
            world[:, parent],
            reference,
            bend_ref,
        )
        for bone, child in ((upper, lower), (lower, end)):
            world[:, bone] = (
                _frame(capture[:, child] - capture[:, bone], axis)
                @ _frame(rest[child] - rest[bone], rest_axis).T
            )
        world[:, end] = world[:, lower]
        if parent == 0:
            world[:, end] = _level_foot(world[:, lower], axis)
    return world


def _spine_rotation(
    hips: np.ndarray, chest: np.ndarray, spine: np.ndarray, rest: np.ndarray
) -> np.ndarray:
    """Spine's world rotations (n, 3, 3) that put the Neck joint on the captured spine line
    given the Hips and Chest rotations (the Hips-Spine and Chest-Neck offsets are rigid)."""
    o1, o2, o3 = rest[1] - rest[0], rest[2] - rest[1], rest[3] - rest[2]
    u = hips @ o1 + chest @ o3
    d = _unit(spine)
    t = np.sum(d * u, axis=-1)
    reach = np.sqrt(np.maximum(t**2 - np.sum(u * u, axis=-1) + o2 @ o2, 0.0))
    target = (t + reach)[:, None] * d - u
    lateral = hips[..., 0] + chest[..., 0]
    lateral_rest = rest[11] - rest[14]
    return _frame(target, lateral) @ _frame(o2, lateral_rest).T


def _bend_axis(
    upper: np.ndarray,
    lower: np.ndarray,
    parent: np.ndarray,
    reference: np.ndarray,
    bend_ref: np.ndarray,
) -> np.ndarray:
    """Unit bend axes (n, 3) of limbs with segments `upper`, `lower` (n, 3) over a take.

    Where the limb is bent, the limb plane's normal. Where it is nearly straight, the
    axis of the last bent frame, carried along with the parent (`parent` (n, 3, 3) world
    rotations) and swung with the limb, or before any bent frame the reference axis
    swung from the reference direction; in between the two turn into each other about
    the limb. Only earlier frames are used, so a live stream gets the same axes.
    """
    u = _unit(upper)
    plane = np.cross(u, _unit(lower))
    sine = np.linalg.norm(plane, axis=-1)
    plane = plane / np.maximum(sine, 1e-12)[..., None]
    w = np.clip((sine - _STRAIGHT[0]) / (_STRAIGHT[1] - _STRAIGHT[0]), 0.0, 1.0)
    w = w * w * (3 - 2 * w)
    fallback = _swing(parent @ reference, u, parent @ bend_ref)
    frames = np.arange(len(u))
    last_bent = np.maximum.accumulate(np.where(w == 1.0, frames, -1))
    carried = last_bent >= 0
    if carried.any():
        k = last_bent[carried]
        to_now = parent[carried] @ np.swapaxes(parent[k], -1, -2)
        fallback[carried] = _swing(
            _unit(np.einsum("nij,nj->ni", to_now, u[k])),
            u[carried],
            np.einsum("nij,nj->ni", to_now, plane[k]),
        )
    fallback = _unit(fallback - np.sum(fallback * u, axis=-1, keepdims=True) * u)
    angle = np.arctan2(
        np.sum(u * np.cross(fallback, plane), axis=-1), np.sum(fallback * plane, axis=-1)
    )
    turn = (w * angle)[:, None]
    return fallback * np.cos(turn) + np.cross(u, fallback) * np.sin(turn)


def _swing(a: np.ndarray, b: np.ndarray, v: np.ndarray) -> np.ndarray:
    """`v` (n, 3) turned by the shortest rotation taking unit `a` to unit `b` (n, 3)."""
    axis = np.cross(a, b)
    c = np.sum(a * b, axis=-1, keepdims=True)
    k = 1.0 / np.maximum(1.0 + c, 1e-9)
    return v * c + np.cross(axis, v) + axis * np.sum(axis * v, axis=-1, keepdims=True) * k


def _level_foot(shin: np.ndarray, knee_axis: np.ndarray) -> np.ndarray:
    """Foot world rotations (n, 3, 3): level and turned to the knee axis where that axis is
    near horizontal, otherwise the shin's rotation (blended in between)."""
    lateral = knee_axis * [1.0, 0.0, 1.0]
    share = np.linalg.norm(lateral, axis=-1)
    up = np.broadcast_to([0.0, 1.0, 0.0], lateral.shape)
    level = _frame(up, np.where(share[:, None] > 1e-6, lateral, [1.0, 0.0, 0.0]))
    level = level @ _frame(np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])).T
    w = np.clip((share - _LEVEL_FOOT[0]) / (_LEVEL_FOOT[1] - _LEVEL_FOOT[0]), 0.0, 1.0)
    if np.all(w == 1.0):
        return level
    q_level = Rotation.from_matrix(level).as_quat()
    q_shin = Rotation.from_matrix(shin).as_quat()
    q_shin *= np.where(np.sum(q_level * q_shin, axis=-1) < 0, -1.0, 1.0)[:, None]
    q = w[:, None] * q_level + (1 - w[:, None]) * q_shin
    return Rotation.from_quat(q).as_matrix()


def _frame(primary: np.ndarray, secondary: np.ndarray) -> np.ndarray:
    """Orthonormal frames (..., 3, 3) whose columns are `primary`, the part of `secondary`
    orthogonal to it, and their cross product (all normalised)."""
    e1 = _unit(primary)
    e2 = _unit(secondary - np.sum(secondary * e1, axis=-1, keepdims=True) * e1)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=-1)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)
