"""Pseudo-poses (`samba.reconstruct.pseudo_poses`): joint-angle noise that keeps the skeleton rigid.

Every pseudo-pose must keep the neighbour's bone lengths and neck length, include the
neighbour itself, bend each elbow and knee by exactly the drawn angle, swing each upper
limb (and the head) by exactly the drawn first swing angle without moving the shoulders
and hips, and do so for real poses as well as for limbs whose rotation axes are
undefined (a straight limb, an arm along the shoulder line).
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from samba.body.skeleton import bone_lengths, standard_pose
from samba.reconstruct.pseudo_poses import AngleNoise, pseudo_poses
from samba.synthetic.motions import generate

N = 12
SIGMA_DEG = 8.0
HINGES = (  # (upper joint, hinge joint, end joint, column of the hinge angle)
    (1, 3, 5, 10),  # left elbow
    (2, 4, 6, 11),  # right elbow
    (7, 9, 11, 12),  # left knee
    (8, 10, 12, 13),  # right knee
)
SWINGS = ((1, 3, 2), (2, 4, 4), (7, 9, 6), (8, 10, 8))
"""(limb root, swung joint, column of theta1) for the shoulders and hips."""
ROOTS = [1, 2, 7, 8]
"""Shoulders and hips: the swings rotate about them."""


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (...) in radians between vectors a and b (..., 3), accurate near 0 and pi."""
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), (a * b).sum(axis=-1))


def _bone(poses: np.ndarray, parent: int, child: int) -> np.ndarray:
    """Parent to child joint vectors (..., 3) of poses (..., 13, 3)."""
    return poses[..., child, :] - poses[..., parent, :]


def _neck(poses: np.ndarray) -> np.ndarray:
    """Shoulder midpoint to head vectors (..., 3)."""
    return poses[..., 0, :] - 0.5 * (poses[..., 1, :] + poses[..., 2, :])


def _arms_along_shoulder_line() -> np.ndarray:
    """Two poses with both upper arms along the shoulder line: straight, and the forearms
    bent 90 degrees forward (+Z)."""
    straight = standard_pose(arm_angle_deg=90.0)
    bent = straight.copy()
    for elbow, wrist in ((3, 5), (4, 6)):
        forearm = np.linalg.norm(straight[wrist] - straight[elbow])
        bent[wrist] = straight[elbow] + [0.0, 0.0, forearm]
    return np.stack([straight, bent])


@cache
def _pose_sets() -> dict[str, np.ndarray]:
    """Neighbour sets (K, 13, 3) float64: real-looking poses of several motions, and
    degenerate ones (straight limbs; upper arms along the shoulder line)."""
    real = [
        generate(motion, seconds=1.0, seed=seed).poses[::10]
        for seed, motion in enumerate(("run", "squat", "kick", "wave", "walk", "jumping_jacks"))
    ]
    return {
        "real": np.concatenate(real).astype(np.float64),
        "straight_limbs": np.stack([standard_pose(h, a) for h in (1.6, 1.9) for a in (10, 45)]),
        "arm_on_shoulder_line": _arms_along_shoulder_line(),
    }


POSE_SETS = ("real", "straight_limbs", "arm_on_shoulder_line")


def _perturbed(name: str, seed: int = 0) -> tuple[np.ndarray, AngleNoise, np.ndarray]:
    poses = _pose_sets()[name]
    noise = AngleNoise.draw(len(poses), N, SIGMA_DEG, seed)
    return poses, noise, pseudo_poses(poses, noise)


@pytest.mark.parametrize("name", POSE_SETS)
def test_bone_lengths_and_neck_are_kept(name: str) -> None:
    poses, _, out = _perturbed(name)
    assert out.shape == (len(poses), N, 13, 3)
    assert np.abs(bone_lengths(out) - bone_lengths(poses)[:, None]).max() < 1e-9
    neck = np.linalg.norm(_neck(out), axis=-1)
    assert np.abs(neck - np.linalg.norm(_neck(poses), axis=-1)[:, None]).max() < 1e-9


@pytest.mark.parametrize("name", POSE_SETS)
def test_first_pseudo_pose_is_the_neighbour(name: str) -> None:
    poses, _, out = _perturbed(name)
    assert np.abs(out[:, 0] - poses).max() < 1e-12
    assert np.abs(out[:, 1:] - poses[:, None]).max() > 1e-3  # the others do move


@pytest.mark.parametrize("name", POSE_SETS)
def test_hinge_angle_changes_by_the_drawn_angle(name: str) -> None:
    poses, noise, out = _perturbed(name)
    checked = 0
    for upper, hinge, end, column in HINGES:
        before = _angle(_bone(poses, upper, hinge), _bone(poses, hinge, end))
        after = _angle(_bone(out, upper, hinge), _bone(out, hinge, end))
        drawn = np.abs(noise.angles[..., column])
        before = np.broadcast_to(before[:, None], drawn.shape)
        # A bend must not cross zero (straight) or pi; a straight limb bends by |angle|.
        ok = ((before > drawn) | (before < 1e-9)) & (before + drawn < np.pi)
        assert np.abs(np.abs(after - before) - drawn)[ok].max() < 1e-9
        checked += ok.sum()
    assert checked > 0.7 * 4 * len(poses) * N


@pytest.mark.parametrize("name", POSE_SETS)
def test_swing_turns_the_upper_bone_by_theta1(name: str) -> None:
    poses, noise, out = _perturbed(name)
    for root, joint, column in SWINGS:
        turned = _angle(_bone(poses, root, joint)[:, None], _bone(out, root, joint))
        assert np.abs(turned - np.abs(noise.angles[..., column])).max() < 1e-9
    head_turn = _angle(_neck(poses)[:, None], _neck(out))
    assert np.abs(head_turn - np.abs(noise.angles[..., 0])).max() < 1e-9


@pytest.mark.parametrize("name", POSE_SETS)
def test_shoulders_and_hips_do_not_move(name: str) -> None:
    poses, _, out = _perturbed(name)
    assert np.abs(out[..., ROOTS, :] - poses[:, None, ROOTS]).max() < 1e-12


def test_batch_axes_give_the_per_frame_result() -> None:
    k = 5
    poses = generate("arm_swing", seconds=1.0, seed=7).poses[: 6 * k].reshape(2, 3, k, 13, 3)
    noise = AngleNoise.draw(k, N, SIGMA_DEG, seed=3)
    batched = pseudo_poses(poses, noise)
    assert batched.shape == (2, 3, k, N, 13, 3)
    for i in range(2):
        for j in range(3):
            assert np.abs(batched[i, j] - pseudo_poses(poses[i, j], noise)).max() < 1e-12


def test_noise_is_deterministic_per_seed() -> None:
    poses = _pose_sets()["real"]
    a, b, c = (AngleNoise.draw(len(poses), N, SIGMA_DEG, seed) for seed in (5, 5, 6))
    assert np.array_equal(a.angles, b.angles)
    assert np.array_equal(pseudo_poses(poses, a), pseudo_poses(poses, b))
    assert not np.allclose(a.angles, c.angles)


def test_noise_has_the_requested_spread() -> None:
    noise = AngleNoise.draw(40, 50, SIGMA_DEG, seed=1)
    assert noise.shape == (40, 50)
    assert np.all(noise.angles[:, 0] == 0.0)
    spread = np.degrees(noise.angles[:, 1:].std())
    assert abs(spread - SIGMA_DEG) < 0.05 * SIGMA_DEG


@pytest.mark.parametrize("shape", [(4, 13, 3), (6, 12, 3), (6, 13, 2), (13, 3)])
def test_wrong_pose_shape_raises(shape: tuple[int, ...]) -> None:
    noise = AngleNoise.draw(6, N, SIGMA_DEG)
    with pytest.raises(ValueError, match="poses must be"):
        pseudo_poses(np.zeros(shape), noise)


@pytest.mark.parametrize(("k", "n"), [(0, 10), (10, 0)])
def test_empty_noise_table_raises(k: int, n: int) -> None:
    with pytest.raises(ValueError, match="K >= 1 and N >= 1"):
        AngleNoise.draw(k, n, SIGMA_DEG)
