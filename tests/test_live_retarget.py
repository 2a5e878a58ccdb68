"""Live retargeting: frame by frame, the same rotations as retargeting the whole take."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from samba.body.skeleton import Body
from samba.export.humanoid import HumanoidRig
from samba.export.live_retarget import LiveRetarget, retarget_together
from samba.export.retargeting import leg_length, local_rotations, rest_frames, retarget
from samba.synthetic.motions import generate

T_POSE = HumanoidRig.from_body()
A_POSE_SMALL = HumanoidRig.from_body(
    Body.from_height(1.52).scaled({"forearm": 1.1, "thigh": 0.92}), arm_angle_deg=40
)


def stream(live: LiveRetarget, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every pose of (n, 13, 3) through `live.step`: rotations (n, 17, 4), roots (n, 3)."""
    steps = [live.step(pose) for pose in poses]
    return np.stack([q for q, _ in steps]), np.stack([root for _, root in steps])


def expected_root(poses: np.ndarray, rig: HumanoidRig, subject_leg: float) -> np.ndarray:
    """Hip middle (n, 3) of poses (n, 13, 3) scaled to the rig, lifted by its ankle height."""
    hips = (np.asarray(poses, dtype=np.float64)[:, 7] + poses[:, 8]) / 2
    return hips * (rig.leg_length / subject_leg) + [0.0, rig.ankle_height, 0.0]


@pytest.mark.parametrize("rig", [T_POSE, A_POSE_SMALL], ids=["t-pose", "a-pose-small"])
@pytest.mark.parametrize(
    ("kind", "seed"),
    [
        ("walk", 1),
        ("walk", 3),
        ("jumping_jacks", 1),
        ("arm_swing", 3),
        ("kick", 1),
        ("squat", 3),
        ("turn", 1),
        ("run", 3),
    ],
)
def test_streamed_rotations_and_roots_equal_the_whole_take(
    rig: HumanoidRig, kind: str, seed: int
) -> None:
    take = generate(kind, seed=seed, seconds=4.0)
    _, bent, _ = local_rotations(take.poses, rig)
    carried = np.maximum.accumulate(bent, axis=0) & ~bent
    assert carried.any(), "the take should have straight limbs carrying a bent frame's axis"
    offline = retarget(take.poses, rig, take.fps)
    rotations, roots = stream(LiveRetarget(rig, leg_length=leg_length(take.poses)), take.poses)
    np.testing.assert_allclose(rotations, offline.rotations, rtol=0, atol=1e-9)
    np.testing.assert_allclose(roots, offline.root, rtol=0, atol=1e-9)


@pytest.mark.parametrize("rig", [T_POSE, A_POSE_SMALL], ids=["t-pose", "a-pose-small"])
def test_local_rotations_take_given_rest_frames_and_scipys_signs(rig: HumanoidRig) -> None:
    take = generate("kick", seed=2, seconds=3.0)
    rotations, bent, _ = local_rotations(take.poses, rig)
    given, given_bent, _ = local_rotations(take.poses, rig, rest_frames(rig))
    np.testing.assert_array_equal(given, rotations)
    np.testing.assert_array_equal(given_bent, bent)
    matrices = Rotation.from_quat(rotations.reshape(-1, 4)).as_matrix()
    scipy_quaternions = Rotation.from_matrix(matrices).as_quat().reshape(rotations.shape)
    np.testing.assert_allclose(rotations, scipy_quaternions, rtol=0, atol=1e-12)


def test_a_take_retargeted_in_pieces_carries_the_limb_axes_across() -> None:
    # The arm swing keeps straight arms for stretches after bent frames: a piece that
    # starts straight must take its axes from the bent frames of the piece before.
    take = generate("arm_swing", seed=3, seconds=4.0)
    whole, bent, carried = local_rotations(take.poses, T_POSE)
    pieces, carry = [], None
    for piece in np.array_split(take.poses, 7):
        rotations, _, carry = local_rotations(piece, T_POSE, carried=carry)
        pieces.append(rotations)
    np.testing.assert_allclose(np.concatenate(pieces), whole, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(carry, carried)
    assert bent[:, :2].any(axis=0).all()  # both arms bend at times
    np.testing.assert_array_equal(np.isnan(carried).all(axis=(1, 2)), ~bent.any(axis=0))


def test_the_root_scale_settles_on_the_first_frames() -> None:
    take = generate("walk", seed=2, seconds=3.0)
    live = LiveRetarget(T_POSE, settle_frames=10)
    assert live.leg_length is None
    for i, pose in enumerate(take.poses):
        _, root = live.step(pose)
        settled = leg_length(take.poses[: min(i + 1, 10)])
        assert live.leg_length == settled
        np.testing.assert_allclose(root, expected_root(take.poses[i : i + 1], T_POSE, settled)[0])
    assert live.leg_length != leg_length(take.poses[:11])


def test_a_given_leg_length_is_used_from_the_first_frame() -> None:
    take = generate("run", seed=4, seconds=1.0)
    live = LiveRetarget(A_POSE_SMALL, leg_length=0.8)
    _, roots = stream(live, take.poses)
    assert live.leg_length == 0.8
    np.testing.assert_allclose(roots, expected_root(take.poses, A_POSE_SMALL, 0.8))


def test_reset_starts_a_new_stream() -> None:
    first = generate("arm_swing", seed=1, seconds=2.0)
    second = generate("kick", seed=2, seconds=3.0)
    live = LiveRetarget(T_POSE, settle_frames=5)
    stream(live, first.poses)
    live.reset()
    assert live.leg_length is None
    rotations, _ = stream(live, second.poses)
    np.testing.assert_allclose(
        rotations, retarget(second.poses, T_POSE, second.fps).rotations, rtol=0, atol=1e-9
    )
    assert live.leg_length == leg_length(second.poses[:5])

    given = LiveRetarget(T_POSE, leg_length=0.9)
    stream(given, first.poses[:3])
    given.reset()
    assert given.leg_length == 0.9


def test_bad_poses_are_rejected_without_disturbing_the_stream() -> None:
    take = generate("walk", seed=5, seconds=2.0)
    live = LiveRetarget(T_POSE, leg_length=leg_length(take.poses))
    steps = []
    for i, pose in enumerate(take.poses):
        if i == 20:
            broken = pose.copy()
            broken[3, 1] = np.nan
            with pytest.raises(ValueError, match="finite"):
                live.step(broken)
            with pytest.raises(ValueError, match=r"\(13, 3\)"):
                live.step(pose[:12])
        steps.append(live.step(pose))
    offline = retarget(take.poses, T_POSE, take.fps)
    np.testing.assert_allclose(np.stack([q for q, _ in steps]), offline.rotations, atol=1e-9)


@pytest.mark.parametrize(
    ("arguments", "problem"),
    [
        ({"leg_length": 0.0}, "leg_length"),
        ({"leg_length": np.nan}, "leg_length"),
        ({"settle_frames": 0}, "settle_frames"),
    ],
)
def test_bad_settings_are_rejected(arguments: dict[str, float], problem: str) -> None:
    with pytest.raises(ValueError, match=problem):
        LiveRetarget(T_POSE, **arguments)


def test_streams_retargeted_together_get_what_each_gets_alone() -> None:
    """Four live sessions, two rigs, retargeted in one batch each frame (one starting
    late): every stream's rotations and roots are the ones it gets on its own."""
    takes = [
        generate(kind, seed=5, seconds=2.0).poses for kind in ("walk", "kick", "squat", "turn")
    ]
    rigs = [T_POSE, A_POSE_SMALL, HumanoidRig.from_body(), A_POSE_SMALL]
    alone = [stream(LiveRetarget(rig), take) for rig, take in zip(rigs, takes, strict=True)]
    streams = [LiveRetarget(rig) for rig in rigs]
    got: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in takes]
    for f in range(len(takes[0])):
        running = [i for i in range(len(takes)) if i != 3 or f >= 10]
        poses = np.stack([takes[i][f if i != 3 else f - 10] for i in running])
        rotations, roots = retarget_together([streams[i] for i in running], poses)
        for row, i in enumerate(running):
            got[i].append((rotations[row], roots[row]))
    for (rotations, roots), frames in zip(alone, got, strict=True):
        n = len(frames)
        np.testing.assert_allclose(np.stack([q for q, _ in frames]), rotations[:n], atol=1e-12)
        np.testing.assert_allclose(np.stack([r for _, r in frames]), roots[:n], atol=1e-12)


def test_a_stream_retargeted_twice_in_one_batch_is_refused() -> None:
    live = LiveRetarget(T_POSE)
    pose = generate("walk", seed=1, seconds=1.0).poses[0]
    with pytest.raises(ValueError, match="must be distinct"):
        retarget_together([live, live], np.stack([pose, pose]))
    with pytest.raises(ValueError, match="one pose"):
        retarget_together([live], np.stack([pose, pose]))
