"""Retargeting 13 joint positions to a humanoid rig: directions, proportions, stability."""

from __future__ import annotations

import numpy as np
import pytest

from samba.body.skeleton import Body
from samba.export.humanoid import BONE_INDEX, BONE_NAMES, PARENTS, HumanoidRig
from samba.export.live_retarget import LiveRetarget
from samba.export.motion import HumanoidMotion
from samba.export.retargeting import MEASURED_BONES, bone_direction_errors, leg_length, retarget
from samba.synthetic.motions import generate

T_POSE = HumanoidRig.from_body()
A_POSE_SMALL = HumanoidRig.from_body(
    Body.from_height(1.52).scaled({"forearm": 1.1, "thigh": 0.92}), arm_angle_deg=40
)
RIGS = pytest.mark.parametrize("rig", [T_POSE, A_POSE_SMALL], ids=["t-pose", "a-pose-small"])


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def posed(
    body: Body,
    left_arm: tuple[tuple[float, float, float], tuple[float, float, float]],
    right_arm: tuple[tuple[float, float, float], tuple[float, float, float]],
    left_leg: tuple[tuple[float, float, float], tuple[float, float, float]] = ((0, -1, 0),) * 2,
    right_leg: tuple[tuple[float, float, float], tuple[float, float, float]] = ((0, -1, 0),) * 2,
    pelvis_drop: float = 0.0,
) -> np.ndarray:
    """A (13, 3) pose of `body` with upper/lower segment directions for each limb."""
    pose = body.standard_pose()
    pose[[0, 1, 2, 7, 8], 1] -= pelvis_drop
    limbs = (
        (1, 3, 5, left_arm, body.upper_arm, body.forearm),
        (2, 4, 6, right_arm, body.upper_arm, body.forearm),
        (7, 9, 11, left_leg, body.thigh, body.shin),
        (8, 10, 12, right_leg, body.thigh, body.shin),
    )
    for root, mid, end, (upper, lower), l1, l2 in limbs:
        pose[mid] = pose[root] + l1 * _unit(upper)
        pose[end] = pose[mid] + l2 * _unit(lower)
    return pose


def blend(a: np.ndarray, b: np.ndarray, frames: int) -> np.ndarray:
    """`frames` poses moving from pose a to pose b, each joint direction turning evenly
    (limb segments keep their lengths)."""
    t = np.linspace(0.0, 1.0, frames)[:, None, None]
    poses = (1 - t) * a + t * b
    for parent, child in ((1, 3), (3, 5), (2, 4), (4, 6), (7, 9), (9, 11), (8, 10), (10, 12)):
        length = np.linalg.norm(a[child] - a[parent])
        d = _unit(
            (1 - t[:, 0]) * _unit(a[child] - a[parent]) + t[:, 0] * _unit(b[child] - b[parent])
        )
        poses[:, child] = poses[:, parent] + length * d
    return poses


BODY = Body.from_height(1.75)
STAND = posed(BODY, ((0.7, -0.7, 0), (0.7, -0.7, 0)), ((-0.7, -0.7, 0), (-0.7, -0.7, 0)))
STRAIGHT_DOWN = posed(BODY, ((0.05, -1, 0),) * 2, ((-0.05, -1, 0),) * 2)
ARMS_OVER_HEAD = posed(BODY, ((0.1, 1, 0.05),) * 2, ((-0.1, 1, 0.05),) * 2)
CROSSED_ARMS = posed(
    BODY, ((0.2, -0.5, 0.8), (-1, 0.15, 0.1)), ((-0.2, -0.5, 0.8), (1, 0.25, 0.05))
)
DEEP_SQUAT = posed(
    BODY,
    ((0.3, -0.2, 1), (0.1, 0.1, 1)),
    ((-0.3, -0.2, 1), (-0.1, 0.1, 1)),
    left_leg=((0.35, -0.25, 1), (0.05, -1, -0.45)),
    right_leg=((-0.35, -0.25, 1), (-0.05, -1, -0.45)),
    pelvis_drop=0.55,
)
T_POSE_CAPTURE = posed(BODY, ((1, 0, 0),) * 2, ((-1, 0, 0),) * 2)


def world_step_degrees(motion: HumanoidMotion) -> np.ndarray:
    """Rotation angle (n - 1, 17) of every bone's world rotation between frames."""
    w = motion.world_matrices()
    rel = np.einsum("nbji,nbjk->nbik", w[:-1], w[1:])
    cos = (np.trace(rel, axis1=2, axis2=3) - 1) / 2
    return np.degrees(np.arccos(np.clip(cos, -1, 1)))


def test_a_capture_in_the_rigs_rest_pose_gives_identity_rotations() -> None:
    motion = retarget(T_POSE_CAPTURE[None], T_POSE, fps=30)
    angles = np.degrees(2 * np.arccos(np.clip(np.abs(motion.rotations[..., 3]), 0, 1)))
    assert angles.max() < 0.01
    assert np.abs(motion.world_positions()[0] - T_POSE.rest).max() < 0.03


@RIGS
@pytest.mark.parametrize("kind", ["walk", "jumping_jacks", "squat", "kick", "turn", "wave"])
def test_every_captured_bone_direction_is_reproduced_within_a_degree(
    rig: HumanoidRig, kind: str
) -> None:
    take = generate(kind, seed=3, seconds=3.0)
    motion = retarget(take.poses, rig, take.fps)
    errors = bone_direction_errors(motion.world_positions(), take.poses)
    assert errors.shape == (len(take), len(MEASURED_BONES))
    assert errors.max() < 1.0


@RIGS
def test_the_avatar_keeps_its_own_bone_lengths(rig: HumanoidRig) -> None:
    take = generate("run", seed=1, seconds=2.0)
    positions = retarget(take.poses, rig, take.fps).world_positions()
    parents = np.array(PARENTS)
    lengths = np.linalg.norm(positions[:, 1:] - positions[:, parents[1:]], axis=-1)
    rest = np.linalg.norm(rig.offsets[1:], axis=-1)
    assert np.abs(lengths - rest).max() < 1e-9


@RIGS
def test_root_height_scales_with_leg_length_so_feet_stay_on_the_floor(rig: HumanoidRig) -> None:
    take = generate("walk", seed=2, seconds=4.0)
    motion = retarget(take.poses, rig, take.fps)
    feet = motion.world_positions()[:, [BONE_INDEX["LeftFoot"], BONE_INDEX["RightFoot"]], 1]
    lower_foot = feet.min(axis=1)
    assert np.median(lower_foot) == pytest.approx(rig.ankle_height, abs=0.01)
    travelled = np.linalg.norm(take.poses[-1, 7] - take.poses[0, 7])
    avatar_travelled = np.linalg.norm(motion.root[-1] - motion.root[0])
    scale = rig.leg_length / leg_length(take.poses)
    assert avatar_travelled == pytest.approx(travelled * scale, rel=0.02)


@RIGS
@pytest.mark.parametrize(
    "target",
    [STRAIGHT_DOWN, ARMS_OVER_HEAD, CROSSED_ARMS, DEEP_SQUAT, T_POSE_CAPTURE],
    ids=["straight-arms", "arms-over-head", "crossed-arms", "deep-squat", "t-pose"],
)
def test_no_flips_moving_into_hard_poses(rig: HumanoidRig, target: np.ndarray) -> None:
    poses = np.concatenate([blend(STAND, target, 60), blend(target, STAND, 60)])
    motion = retarget(poses, rig, fps=30)
    assert bone_direction_errors(motion.world_positions(), poses).max() < 1.0
    # joint directions turn ~2-3 degrees per frame here, a twist settling as a straight
    # limb bends spreads over 2..25 degrees of bend; a flip would turn 90+ in one frame
    assert world_step_degrees(motion).max() < 20.0
    dots = np.sum(motion.rotations[1:] * motion.rotations[:-1], axis=-1)
    assert dots.min() > 0.95


@pytest.mark.parametrize("side", ["left", "right"])
def test_a_straight_arm_starting_to_bend_does_not_twist_suddenly(side: str) -> None:
    sign = 1.0 if side == "left" else -1.0
    bent = (sign * 0.7, -0.7, 0.0)
    straight = posed(BODY, ((0.7, -0.7, 0),) * 2, ((-0.7, -0.7, 0),) * 2)
    # bend forward, straighten, then bend upwards: the twist must move gradually
    frames = []
    for forearm in [(sign * 0.6, -0.3, 0.75), (sign * 0.7, -0.7, 0.0), (sign * 0.3, 0.9, 0.0)]:
        arms = {side: (bent, forearm)}
        target = posed(
            BODY,
            arms.get("left", ((0.7, -0.7, 0),) * 2),
            arms.get("right", ((-0.7, -0.7, 0),) * 2),
        )
        frames.append(blend(straight if not frames else frames[-1][-1], target, 40))
    poses = np.concatenate(frames)
    motion = retarget(poses, T_POSE, fps=30)
    lower = BONE_INDEX[f"{side.capitalize()}LowerArm"]
    assert world_step_degrees(motion)[:, lower].max() < 20.0


def test_rotations_of_a_prefix_match_the_whole_take_live_use() -> None:
    take = generate("arm_swing", seed=5, seconds=3.0)
    whole = retarget(take.poses, T_POSE, take.fps)
    prefix = retarget(take.poses[:40], T_POSE, take.fps)
    np.testing.assert_allclose(prefix.rotations, whole.rotations[:40], atol=1e-9)


def test_quaternions_are_unit_and_continuous_over_time() -> None:
    take = generate("turn", seed=4, seconds=4.0)
    q = retarget(take.poses, T_POSE, take.fps).rotations
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-9)
    assert (np.sum(q[1:] * q[:-1], axis=-1) >= 0).all()


def test_hands_follow_forearms_and_feet_stay_level_on_a_standing_subject() -> None:
    take = generate("wave", seed=6, seconds=2.0)
    motion = retarget(take.poses, T_POSE, take.fps)
    q = motion.rotations
    for hand in ("LeftHand", "RightHand", "Head"):
        angle = np.degrees(2 * np.arccos(np.clip(np.abs(q[:, BONE_INDEX[hand], 3]), 0, 1)))
        assert angle.max() < 1e-6, hand
    world = motion.world_matrices()
    for foot in ("LeftFoot", "RightFoot"):
        up = world[:, BONE_INDEX[foot]] @ [0.0, 1.0, 0.0]
        assert np.degrees(np.arccos(np.clip(up[:, 1], -1, 1))).max() < 1.0, foot


def test_bad_input_is_rejected_with_the_problem_named() -> None:
    with pytest.raises(ValueError, match=r"\(n, 13, 3\)"):
        retarget(np.zeros((5, 12, 3)), T_POSE, 30)
    poses = np.repeat(STAND[None], 3, axis=0)
    poses[1, 4] = np.nan
    with pytest.raises(ValueError, match="finite"):
        retarget(poses, T_POSE, 30)


def test_bone_names_are_unity_humanoid_names() -> None:
    assert BONE_NAMES[0] == "Hips"
    assert {"LeftUpperArm", "RightLowerLeg", "Neck", "Chest", "Spine"} <= set(BONE_NAMES)
    assert all(PARENTS[j] < j for j in range(1, len(PARENTS)))


def _hips_moved(rig: HumanoidRig, dy: float) -> HumanoidRig:
    """`rig` with its Hips joint `dy` meters above (below, if negative) its leg joints'
    middle, as avatars have it; every other joint stays."""
    rest = rig.rest.copy()
    legs = rest[[BONE_INDEX["LeftUpperLeg"], BONE_INDEX["RightUpperLeg"]]]
    rest[BONE_INDEX["Hips"]] = legs.mean(axis=0)
    rest[BONE_INDEX["Hips"], 1] += dy
    return HumanoidRig(rest=rest, tips=rig.tips, name=f"hips{dy:+.2f}")


@pytest.mark.parametrize(
    "dy", [-0.07, 0.0, 0.08, 0.25], ids=["7cm-below", "level", "8cm-above", "25cm-above"]
)
def test_a_planted_foot_stays_on_the_floor_wherever_the_avatars_hips_joint_sits(dy: float) -> None:
    """At the source walk's foot contacts each avatar's ankle is at its own rest ankle
    height within 1 cm, offline and live, whatever the height of its Hips joint."""
    rig = _hips_moved(HumanoidRig.from_body(), dy)
    take = generate("walk", seed=2, seconds=4.0)
    ankles = take.poses[:, [11, 12], 1]
    planted = ankles < 0.001  # (n, 2): the source's foot contacts (the walk plants at y = 0)
    offline = retarget(take.poses, rig, take.fps)
    live = LiveRetarget(rig, leg_length=leg_length(take.poses))
    live_roots = np.stack([live.step(pose)[1] for pose in take.poses])
    for root in (offline.root, live_roots):
        motion = HumanoidMotion(rig, offline.rotations, root, take.fps)
        feet = motion.world_positions()[:, [BONE_INDEX["LeftFoot"], BONE_INDEX["RightFoot"]], 1]
        assert planted.sum() > 20
        assert np.abs(feet[planted] - rig.ankle_height).max() < 0.01
