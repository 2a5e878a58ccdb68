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

The root is placed by the avatar's upper-leg joints, not its Hips joint: their middle
follows the captured hip middle scaled by the ratio of the rig's leg length to the
subject's, so the avatar's feet stay on the floor and its steps match, wherever the
avatar's Hips joint sits (above, level with or below its legs).
"""

from __future__ import annotations

import numpy as np

from samba.body import N_JOINTS
from samba.export.humanoid import CAPTURE_JOINT, N_BONES, PARENTS, HumanoidRig
from samba.export.motion import HumanoidMotion

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
_TORSO: tuple[tuple[int, tuple[int, int], tuple[int, int]], ...] = (
    # (bone, primary line, secondary line), a line running (from bone, to bone) between joints
    (0, (14, 11), (0, 3)),  # Hips: hip line, then spine
    (2, (8, 5), (0, 3)),  # Chest: shoulder line, then spine
    (3, (3, 4), (8, 5)),  # Neck: neck, then shoulder line
)
"""Torso bones whose frames come from two lines of their joints, captured or at rest."""
_STRAIGHT = (np.sin(np.radians(2.0)), np.sin(np.radians(25.0)))
"""Bend (as sine of the angle) below which a limb counts as straight, above which its
plane alone gives the bend axis."""
_LEVEL_FOOT = (0.5, 0.8)
"""Horizontal share of the knee axis below which a foot follows its shin, above which it
stays level."""

_PARENTS = np.array(PARENTS)
_CAPTURED_BONES = np.array(list(CAPTURE_JOINT))
_CAPTURED_JOINTS = np.array(list(CAPTURE_JOINT.values()))
_TORSO_BONES = np.array([bone for bone, _, _ in _TORSO])
_TORSO_PRIMARY = np.array([line for _, line, _ in _TORSO]).T
_TORSO_SECONDARY = np.array([line for _, _, line in _TORSO]).T
LIMBS = len(_LIMBS)
"""Limbs whose bend axes retargeting carries from frame to frame (arms, legs)."""
_UPPER, _LOWER, _END, _LIMB_PARENT = np.array([limb[:4] for limb in _LIMBS]).T
_SEGMENTS = np.concatenate([_UPPER, _LOWER])
"""Limb bones framed by their segment and the limb's bend axis; `_SEGMENT_ENDS` end them."""
_SEGMENT_ENDS = np.concatenate([_LOWER, _END])
_LEGS = np.flatnonzero(_LIMB_PARENT == 0)
"""The limbs hanging from the Hips, whose end bones (Feet) stand level."""
_FEET, _SHINS = _END[_LEGS], _LOWER[_LEGS]
_AFTER_TORSO = np.concatenate([[1], _SEGMENTS, _FEET])
"""Bones framed once the torso's rotations are known: Spine, limb segments, level Feet."""
_FOLLOWERS = np.array([4, 7, 10])
"""Head and Hands: they turn with their parents."""
_NEXT = np.array([1, 2, 0])
"""Each vector component's successor, cyclically (for `_cross`)."""


def capture_points(poses: np.ndarray) -> np.ndarray:
    """Where each humanoid bone's joint is on captured poses (n, 13, 3): returns (n, 17, 3)
    with Hips at the hip middle, Neck at the shoulder middle, Spine and Chest at 1/4 and
    3/5 of the way between them, the others at their 13-joint joint."""
    poses = np.asarray(poses, dtype=np.float64)
    out = np.empty((*poses.shape[:-2], N_BONES, 3))
    pelvis = _hip_middle(poses)
    neck = (poses[..., 1, :] + poses[..., 2, :]) / 2
    out[..., 0, :] = pelvis
    out[..., 1, :] = pelvis + 0.25 * (neck - pelvis)
    out[..., 2, :] = pelvis + 0.6 * (neck - pelvis)
    out[..., 3, :] = neck
    out[..., _CAPTURED_BONES, :] = poses[..., _CAPTURED_JOINTS, :]
    return out


def bone_direction_errors(avatar: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Angles (n, 12) in degrees between the `MEASURED_BONES` directions of avatar joint
    positions (n, 17, 3) and of captured poses (n, 13, 3)."""
    capture = capture_points(poses)
    avatar = np.asarray(avatar, dtype=np.float64)
    a = np.stack([avatar[:, j] - avatar[:, i] for _, i, j in MEASURED_BONES], axis=1)
    c = np.stack([capture[:, j] - capture[:, i] for _, i, j in MEASURED_BONES], axis=1)
    cos = np.sum(_unit(a) * _unit(c), axis=-1)
    sin = np.linalg.norm(_cross(_unit(a), _unit(c)), axis=-1)
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
    rotations, _, _ = local_rotations(poses, rig)
    root = root_positions(poses, rig, leg_length(poses), rotations[:, 0])
    return HumanoidMotion(rig=rig, rotations=rotations, root=root, fps=fps)


def rest_frames(rig: HumanoidRig) -> np.ndarray:
    """The frames (17, 3, 3) of `rig`'s rest bones that retargeting turns onto the captured
    ones, transposed (inverted): a bone's world rotation is its captured frame times this.

    They depend on the rig alone, so a caller retargeting many takes of one rig (the live
    service) computes them once for `local_rotations`. Head and Hands, which turn with
    their parents, get the identity; the Feet the level foot's frame (up, then +X).
    """
    rest = rig.rest
    frames = np.tile(np.eye(3), (N_BONES, 1, 1))
    frames[_TORSO_BONES] = _frame(_lines(rest, _TORSO_PRIMARY), _lines(rest, _TORSO_SECONDARY))
    frames[1] = _frame(rest[2] - rest[1], rest[11] - rest[14])
    axes, _, _ = _bend_axis(
        (rest[_LOWER] - rest[_UPPER])[None],
        (rest[_END] - rest[_LOWER])[None],
        np.broadcast_to(np.eye(3), (1, len(_LIMBS), 3, 3)),
    )
    frames[_SEGMENTS] = _frame(
        rest[_SEGMENT_ENDS] - rest[_SEGMENTS], np.concatenate([axes[0], axes[0]])
    )
    frames[_FEET] = _frame(_UP, _X)
    return np.ascontiguousarray(frames.swapaxes(-1, -2))


def local_rotations(
    poses: np.ndarray,
    rig: HumanoidRig,
    frames: np.ndarray | None = None,
    carried: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local bone rotations of `rig` for finite captured poses (n, 13, 3) in meters, and
    which frames the limbs are bent in; `frames` are the rig's `rest_frames`, computed
    here if not given. `carried` continues a take retargeted in earlier calls: the limb
    axes the last call returned (None: the take starts here).

    Returns `rotations` (n, 17, 4), quaternions (x, y, z, w) with each frame's sign as
    scipy's `Rotation.from_matrix` gives it (`HumanoidMotion` makes them
    hemisphere-continuous); `bent` (n, 4) bool, one column per limb (left arm, right
    arm, left leg, right leg): the frames whose limb plane alone gives the bend axis,
    which nearly straight later frames of that limb carry along; and the limb axes to
    carry on (4, 3, 2): each limb's direction and bend axis in its parent's frame at its
    last bent frame so far (NaN for a limb not bent yet).
    """
    if frames is None:
        frames = rest_frames(rig)
    world, bent, carried = _world_rotations(capture_points(poses), rig.rest, frames, carried)
    return _local_quaternions(world), bent, carried


def stream_rotations(
    poses: np.ndarray, rig: HumanoidRig, frames: np.ndarray, carried: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """`local_rotations` of one frame each of several takes: poses (s, 13, 3) in meters,
    row i the next frame of take i, whose limb axes so far are carried[i] (s, 4, 3, 2),
    NaN where a limb has not been bent yet (a take starting here: all NaN). `frames` are
    the rig's `rest_frames`. Returns the rotations (s, 17, 4) `local_rotations` gives
    each take's frame, and the limb axes (s, 4, 3, 2) each take carries on. The live
    service retargets the sessions whose frames arrive together so, in one batch."""
    world, _, carried = _world_rotations(
        capture_points(poses), rig.rest, frames, carried, streams=True
    )
    return _local_quaternions(world), carried


def _local_quaternions(world: np.ndarray) -> np.ndarray:
    """Local rotations (n, 17, 4) of the bones' world rotations (n, 17, 3, 3)."""
    local = world.copy()
    local[:, 1:] = world[:, _PARENTS[1:]].swapaxes(-1, -2) @ world[:, 1:]
    return _quaternions(local)


def root_positions(
    poses: np.ndarray, rig: HumanoidRig, subject_leg_length: float, hips: np.ndarray
) -> np.ndarray:
    """Hips positions (n, 3) in meters for captured poses (n, 13, 3) in meters and the
    Hips' rotations `hips` (n, 4), quaternions (x, y, z, w): placed so that the middle of
    the rig's upper-leg joints lands on the captured hip middle, scaled by the ratio of
    the rig's leg length to `subject_leg_length` (meters) and lifted by the rig's ankle
    height. The rig's Hips joint may sit anywhere relative to its legs."""
    scale = rig.leg_length / subject_leg_length
    legs = _hip_middle(np.asarray(poses, dtype=np.float64)) * scale + [0.0, rig.ankle_height, 0.0]
    return legs - _rotation_matrices(np.asarray(hips, dtype=np.float64)) @ rig.hips_to_legs


def _world_rotations(
    capture: np.ndarray,
    rest: np.ndarray,
    frames: np.ndarray,
    carried: np.ndarray | None,
    streams: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World rotations (n, 17, 3, 3) taking the rig's rest bones (`rest` (17, 3), its
    `rest_frames` `frames`) to the captured ones (n, 17, 3), whether each of `_LIMBS` is
    fully bent (n, 4) bool, and the limb axes carried on (`_bend_axis`): (4, 3, 2) for
    the n frames of one take, or with `streams` (n, 4, 3, 2) for one frame each of n takes
    (`carried` (n, 4, 3, 2) then)."""
    n = len(capture)
    world = np.empty((n, N_BONES, 3, 3))
    world[:, _TORSO_BONES] = (
        _frame(_lines(capture, _TORSO_PRIMARY), _lines(capture, _TORSO_SECONDARY))
        @ frames[_TORSO_BONES]
    )
    segments = capture[:, _SEGMENT_ENDS] - capture[:, _SEGMENTS]  # upper ones, lower ones
    limbs = len(_LIMBS)
    upper, lower, parent = segments[:, :limbs], segments[:, limbs:], world[:, _LIMB_PARENT]
    if streams:  # one frame of n takes: as one frame with every take's limbs side by side
        axes, bent, carried = _bend_axis(
            upper.reshape(1, -1, 3),
            lower.reshape(1, -1, 3),
            parent.reshape(1, -1, 3, 3),
            None if carried is None else carried.reshape(-1, 3, 2),
        )
        axes, bent = axes.reshape(n, limbs, 3), bent.reshape(n, limbs)
        carried = carried.reshape(n, limbs, 3, 2)
    else:
        axes, bent, carried = _bend_axis(upper, lower, parent, carried)
    spine, lateral = _spine_directions(
        world[:, 0], world[:, 2], capture[:, 3] - capture[:, 0], rest
    )
    knee = axes[:, _LEGS] * [1.0, 0.0, 1.0]
    horizontal = _norm(knee)
    # The `_AFTER_TORSO` bones in one batch, the Feet level and turned to the knee axis.
    primary = np.concatenate([spine[:, None], segments, np.full_like(knee, _UP)], axis=1)
    secondary = np.concatenate(
        [lateral[:, None], axes, axes, np.where(horizontal > 1e-6, knee, _X)], axis=1
    )
    world[:, _AFTER_TORSO] = _frame(primary, secondary) @ frames[_AFTER_TORSO]
    world[:, _FOLLOWERS] = world[:, _PARENTS[_FOLLOWERS]]
    world[:, _FEET] = _feet(world[:, _FEET], world[:, _SHINS], horizontal)
    return world, bent, carried


def _spine_directions(
    hips: np.ndarray, chest: np.ndarray, spine: np.ndarray, rest: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The Spine bone's direction (n, 3), Spine to Chest joint, that puts the Neck joint on
    the captured `spine` line (n, 3) given the Hips and Chest world rotations (n, 3, 3)
    (the Hips-Spine and Chest-Neck offsets are rigid), and the direction (n, 3) its frame
    takes second: the sum of the Hips' and the Chest's x axes (their hip lines)."""
    o1, o2, o3 = rest[1] - rest[0], rest[2] - rest[1], rest[3] - rest[2]
    u = hips @ o1 + chest @ o3
    d = _unit(spine)
    t = _dot(d, u)
    reach = np.sqrt(np.maximum(t**2 - _dot(u, u) + o2 @ o2, 0.0))
    return (t + reach) * d - u, hips[..., 0] + chest[..., 0]


def _bend_axis(
    upper: np.ndarray, lower: np.ndarray, parent: np.ndarray, carried: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit bend axes (n, L, 3) of the `_LIMBS` with segments `upper`, `lower` (n, L, 3)
    over a take, which frames are fully bent (n, L) bool (their plane alone gives the
    axis), and the axes to carry on (L, 3, 2): each limb's direction and bend axis
    (columns) in its parent's frame at its last bent frame, NaN where none yet. L is the
    4 limbs, or a multiple of them: the limbs of several takes side by side.

    Where a limb is bent, the limb plane's normal. Where it is nearly straight, the axis
    of its last bent frame, carried along with its parent (`parent` (n, 4, 3, 3) world
    rotations) and swung with the limb, or before any bent frame (of this call, or the
    `carried` axes of earlier calls of the take) the reference axis swung from the
    reference direction; in between the two turn into each other about the limb. Only
    earlier frames are used, so a live stream gets the same axes.
    """
    u = _unit(upper)
    plane = _cross(u, _unit(lower))
    sine = _norm(plane)
    plane = plane / np.maximum(sine, 1e-12)
    w = np.minimum(np.maximum((sine - _STRAIGHT[0]) / (_STRAIGHT[1] - _STRAIGHT[0]), 0.0), 1.0)
    w = w * w * (3 - 2 * w)
    bent = w[..., 0] == 1.0
    last_bent = np.maximum.accumulate(np.where(bent, np.arange(len(u))[:, None], -1), axis=0)
    # The limb direction and bend axis (columns) in the parent's frame, of the last bent
    # frame or else the reference ones, turned with the parent and swung onto the limb.
    in_parent = parent.swapaxes(-1, -2) @ np.stack([u, plane], axis=-1)
    limbs = np.arange(u.shape[1])
    kept = in_parent[np.maximum(last_bent, 0), limbs]
    if carried is None:
        carried = np.full((len(limbs), 3, 2), np.nan)
    reference = np.tile(_REFERENCE_AXES, (len(limbs) // len(_LIMBS), 1, 1))
    before = np.where(np.isnan(carried), reference, carried)
    moved = parent @ np.where((last_bent >= 0)[..., None, None], kept, before)
    fallback = _swing(_unit(moved[..., 0]), u, moved[..., 1])
    fallback = _unit(fallback - _dot(fallback, u) * u)
    angle = np.arctan2(_dot(u, _cross(fallback, plane)), _dot(fallback, plane))
    turn = w * angle
    carry = np.where((last_bent[-1] >= 0)[:, None, None], kept[-1], carried)
    return fallback * np.cos(turn) + _cross(u, fallback) * np.sin(turn), bent, carry


def _swing(a: np.ndarray, b: np.ndarray, v: np.ndarray) -> np.ndarray:
    """`v` (..., 3) turned by the shortest rotation taking unit `a` to unit `b` (..., 3)."""
    axis = _cross(a, b)
    c = _dot(a, b)
    k = 1.0 / np.maximum(1.0 + c, 1e-9)
    return v * c + _cross(axis, v) + axis * _dot(axis, v) * k


def _feet(level: np.ndarray, shin: np.ndarray, horizontal: np.ndarray) -> np.ndarray:
    """Foot world rotations (..., 3, 3): the `level` ones where the knee axis is near
    horizontal (`horizontal` (..., 1), the length of its horizontal part), otherwise the
    `shin`'s (blended in between)."""
    w = (horizontal - _LEVEL_FOOT[0]) / (_LEVEL_FOOT[1] - _LEVEL_FOOT[0])
    w = np.minimum(np.maximum(w, 0.0), 1.0)
    if np.all(w == 1.0):
        return level
    q_level = _quaternions(level)
    q_shin = _quaternions(shin)
    q_shin *= np.where(_dot(q_level, q_shin) < 0, -1.0, 1.0)
    return _rotation_matrices(w * q_level + (1 - w) * q_shin)


def _frame(primary: np.ndarray, secondary: np.ndarray) -> np.ndarray:
    """Orthonormal frames (..., 3, 3) whose columns are `primary`, the part of `secondary`
    orthogonal to it, and their cross product (all normalised)."""
    e1 = _unit(primary)
    e2 = _unit(secondary - _dot(secondary, e1) * e1)
    frames = np.empty((*e1.shape, 3))
    frames[..., 0], frames[..., 1], frames[..., 2] = e1, e2, _cross(e1, e2)
    return frames


def _quaternions(matrices: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4), (x, y, z, w), of rotation matrices (..., 3, 3), with the
    signs scipy's `Rotation.from_matrix` gives them.

    As scipy does, picks the largest of the diagonal and the trace, and takes the
    quaternion whose matching component is built from it (so positive): a row of the
    symmetric matrix K with upper left block M + M^T + (1 - trace) I, last row and column
    the skew part of M and corner 1 + trace.
    """
    shape = matrices.shape[:-2]
    diagonal = matrices.diagonal(axis1=-2, axis2=-1)
    trace = diagonal.sum(axis=-1)
    k = np.empty((*shape, 4, 4))
    np.add(matrices, matrices.swapaxes(-1, -2), out=k[..., :3, :3])
    k.reshape(*shape, 16)[..., 0:15:5] += (1 - trace)[..., None]  # the diagonal
    skew = matrices - matrices.swapaxes(-1, -2)  # entries (2, 1), (0, 2), (1, 0) of it
    k[..., 3, :3] = k[..., :3, 3] = skew.reshape(*shape, 9).take([7, 2, 3], axis=-1)
    k[..., 3, 3] = 1 + trace
    choice = np.argmax(np.concatenate([diagonal, trace[..., None]], axis=-1), axis=-1)
    rows = k.reshape(-1, 4, 4)[np.arange(choice.size), choice.ravel()]
    return _unit(rows).reshape(*shape, 4)


def _rotation_matrices(quaternions: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4), (x, y, z, w), normalised
    first: (w^2 - v.v) I + 2 v v^T + 2 w [v]x for the unit quaternion (v, w)."""
    q = _unit(quaternions)
    v, w = q[..., :3], q[..., 3:]
    skew = _cross(v[..., None, :], np.eye(3)).swapaxes(-1, -2)
    return (
        (w * w - _dot(v, v))[..., None] * np.eye(3)
        + 2 * v[..., :, None] * v[..., None, :]
        + 2 * w[..., None] * skew
    )


def _hip_middle(poses: np.ndarray) -> np.ndarray:
    """The middle (..., 3) of the hip joints of poses (..., 13, 3)."""
    return (poses[..., 7, :] + poses[..., 8, :]) / 2


def _lines(points: np.ndarray, lines: np.ndarray) -> np.ndarray:
    """Vectors (..., k, 3) between points (..., 17, 3) along `lines` (2, k): from, to."""
    return points[..., lines[1], :] - points[..., lines[0], :]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products (..., 3) of vectors `a`, `b` (..., 3), broadcast: np.cross's formula
    and results, without its overhead on small arrays."""
    return (a * b.take(_NEXT, axis=-1) - a.take(_NEXT, axis=-1) * b).take(_NEXT, axis=-1)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products (..., 1) of vectors `a`, `b` (..., 3)."""
    return (a * b).sum(axis=-1, keepdims=True)


def _norm(v: np.ndarray) -> np.ndarray:
    """Lengths (..., 1) of vectors (..., 3)."""
    return np.sqrt(_dot(v, v))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(_norm(v), 1e-12)


# Constants made with the helpers above.
_REFERENCE = _unit(np.array([limb[4] for limb in _LIMBS]))
_REFERENCE_AXES = np.stack(
    [_REFERENCE, _unit(_cross(_REFERENCE, np.array([limb[5] for limb in _LIMBS])))], axis=-1
)
"""Each limb's reference direction and the bend axis that goes with it: columns (4, 3, 2)."""
_UP = np.array([0.0, 1.0, 0.0])
_X = np.array([1.0, 0.0, 0.0])
