"""Tests of the procedural motion generator `samba.synthetic.motions`."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from samba.body.skeleton import Body, bone_lengths
from samba.body.take import Take
from samba.synthetic.motions import MOTIONS, generate, library, random_body

CONTACT_MOTIONS = ("walk", "squat", "wave", "arm_swing", "turn", "kick", "golf_swing", "point")
FLIGHT_MOTIONS = ("run", "jumping_jacks")
SEEDS = (0, 1, 2)
N_FRAMES = 120  # 4 s at 30 fps, the defaults


@cache
def _take(motion: str, seed: int) -> Take:
    return generate(motion, seed=seed)


def _hinge_deg(poses: np.ndarray, a: int, b: int, c: int) -> np.ndarray:
    """Flexion (n,) in degrees at joint b: the angle between bones a->b and b->c."""
    upper, lower = poses[:, b] - poses[:, a], poses[:, c] - poses[:, b]
    cos = (upper * lower).sum(-1) / np.linalg.norm(upper, axis=-1) / np.linalg.norm(lower, axis=-1)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _pelvis(poses: np.ndarray) -> np.ndarray:
    return poses[:, [7, 8]].astype(np.float64).mean(axis=1)


def test_motion_names() -> None:
    assert MOTIONS == (
        "walk",
        "run",
        "jumping_jacks",
        "arm_swing",
        "squat",
        "kick",
        "wave",
        "turn",
        "golf_swing",
        "point",
    )
    assert set(CONTACT_MOTIONS) | set(FLIGHT_MOTIONS) == set(MOTIONS)


@pytest.mark.parametrize("motion", MOTIONS)
def test_take_shape_and_metadata(motion: str) -> None:
    take = _take(motion, 0)
    assert take.poses.shape == (N_FRAMES, 13, 3)
    assert take.poses.dtype == np.float32
    assert np.isfinite(take.poses).all()
    assert take.name == f"synthetic-{motion}-0"
    assert take.rig == "synthetic"
    assert take.action == motion
    assert take.subject == "synthetic-0"
    assert take.fps == 30.0
    assert take.source == f"synthetic:{motion}?seed=0&seconds=4.0&fps=30.0"
    assert len(take.content_hash) == 64
    assert generate(motion, seconds=1.0, fps=50.0).poses.shape == (50, 13, 3)


@pytest.mark.parametrize("motion", MOTIONS)
def test_bone_lengths_are_the_bodys_segments(motion: str) -> None:
    body = random_body(np.random.default_rng(123))
    take = generate(motion, seed=5, body=body)
    expected = [body.upper_arm, body.forearm] * 2 + [body.thigh, body.shin] * 2
    lengths = bone_lengths(take.poses.astype(np.float64))
    assert np.abs(lengths - expected).max() < 1e-5


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("motion", MOTIONS)
def test_bone_lengths_are_constant(motion: str, seed: int) -> None:
    lengths = bone_lengths(_take(motion, seed).poses.astype(np.float64))
    assert np.ptp(lengths, axis=0).max() < 1e-5


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("motion", MOTIONS)
def test_head_is_above_the_feet(motion: str, seed: int) -> None:
    poses = _take(motion, seed).poses
    assert (poses[:, 0, 1] > poses[:, [11, 12], 1].max(axis=1)).all()


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("motion", MOTIONS)
def test_feet_never_go_through_the_floor(motion: str, seed: int) -> None:
    lowest = _take(motion, seed).poses[:, [11, 12], 1].min(axis=1)
    assert lowest.min() >= -1e-5
    if motion in CONTACT_MOTIONS:
        assert lowest.max() <= 0.01


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("motion", MOTIONS)
def test_elbows_and_knees_bend_within_limits(motion: str, seed: int) -> None:
    poses = _take(motion, seed).poses.astype(np.float64)
    for a, b, c in ((1, 3, 5), (2, 4, 6), (7, 9, 11), (8, 10, 12)):
        angles = _hinge_deg(poses, a, b, c)
        assert angles.min() >= 0.0
        assert angles.max() <= 160.0


@pytest.mark.parametrize("motion", MOTIONS)
def test_same_seed_same_take(motion: str) -> None:
    a, b = generate(motion, seed=3), generate(motion, seed=3)
    assert np.array_equal(a.poses, b.poses)
    assert a.content_hash == b.content_hash
    c = generate(motion, seed=4)
    assert not np.array_equal(a.poses, c.poses)
    assert a.content_hash != c.content_hash


def test_hash_depends_on_every_parameter() -> None:
    base = generate("walk", seed=1)
    variants = [
        generate("walk", seed=1, speed=1.0),
        generate("walk", seed=1, body=Body.from_height(1.70)),
        generate("walk", seed=1, seconds=3.0),
        generate("walk", seed=1, fps=60.0),
        generate("run", seed=1),
    ]
    hashes = {base.content_hash, *(take.content_hash for take in variants)}
    assert len(hashes) == len(variants) + 1


def test_random_body_ranges() -> None:
    rng = np.random.default_rng(0)
    for _ in range(50):
        body = random_body(rng)
        assert 1.50 <= body.height <= 1.95
        average = Body.from_height(body.height)
        for name in ("shoulder_width", "hip_width", "upper_arm", "forearm", "thigh", "shin"):
            assert 0.9 - 1e-9 <= getattr(body, name) / getattr(average, name) <= 1.1 + 1e-9
        assert 0.9 - 1e-9 <= body.torso / average.torso <= 1.1 + 1e-9
        assert 0.9 - 1e-9 <= body.neck / average.neck <= 1.1 + 1e-9


@pytest.mark.parametrize("seed", SEEDS)
def test_walk_and_run_travel(seed: int) -> None:
    travel = {}
    for motion in ("walk", "run"):
        pelvis = _pelvis(_take(motion, seed).poses)
        travel[motion] = np.linalg.norm((pelvis[-1] - pelvis[0])[[0, 2]])
    assert travel["walk"] > 2.0
    assert travel["run"] > travel["walk"]


def test_speed_scales_walking() -> None:
    travel = [
        np.linalg.norm(np.diff(_pelvis(generate("walk", seed=2, speed=s).poses)[[0, -1]], axis=0))
        for s in (0.8, 1.2)
    ]
    assert travel[1] / travel[0] == pytest.approx(1.5, rel=0.02)


@pytest.mark.parametrize("motion", ["walk", "run", "turn", "kick", "golf_swing", "point"])
def test_stance_feet_do_not_slide(motion: str) -> None:
    poses = _take(motion, 1).poses.astype(np.float64)
    for foot in (11, 12):
        grounded = (poses[:-1, foot, 1] < 1e-3) & (poses[1:, foot, 1] < 1e-3)
        step = np.linalg.norm(np.diff(poses[:, foot][:, [0, 2]], axis=0), axis=1)
        assert grounded.any()
        assert step[grounded].max() < 0.003


@pytest.mark.parametrize("seed", SEEDS)
def test_turn_turns_in_place(seed: int) -> None:
    poses = _take("turn", seed).poses.astype(np.float64)
    line = poses[:, 1] - poses[:, 2]
    yaw = np.unwrap(np.arctan2(line[:, 0], line[:, 2]))
    assert abs(yaw[-1] - yaw[0]) > np.radians(90.0)
    pelvis = _pelvis(poses)
    assert np.linalg.norm((pelvis - pelvis[0])[:, [0, 2]], axis=1).max() < 0.5


@pytest.mark.parametrize("seed", SEEDS)
def test_jumping_jacks_raise_the_wrists_over_the_head(seed: int) -> None:
    poses = _take("jumping_jacks", seed).poses
    assert (poses[:, [5, 6], 1].min(axis=1) > poses[:, 0, 1]).any()


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("motion", FLIGHT_MOTIONS)
def test_flight_phases(motion: str, seed: int) -> None:
    feet = _take(motion, seed).poses[:, [11, 12], 1]
    assert (feet.min(axis=1) > 0.02).any()
    assert (feet.min(axis=1) < 1e-3).any()


def test_wave_raises_one_hand_over_the_head() -> None:
    poses = _take("wave", 0).poses
    above = poses[:, [5, 6], 1] > poses[:, [0], 1]
    assert above.any(axis=1).all()
    assert not above.all(axis=1).any()


@pytest.mark.parametrize("seed", SEEDS)
def test_golf_swing_bends_at_the_hips_and_swings_over_both_shoulders(seed: int) -> None:
    poses = _take("golf_swing", seed).poses.astype(np.float64)
    trunk = poses[:, [1, 2]].mean(axis=1) - _pelvis(poses)
    tilt = np.degrees(np.arccos(trunk[:, 1] / np.linalg.norm(trunk, axis=1)))
    assert tilt.max() > 25.0
    feet = poses[:, [11, 12]].mean(axis=1)
    left = poses[0, 11] - poses[0, 12]  # the planted feet: the body's left, the target
    hands = poses[:, [5, 6]]
    side = np.einsum("nk,k->n", hands.mean(axis=1) - feet, left / np.linalg.norm(left))
    raised = hands[:, :, 1].min(axis=1) > poses[:, [1, 2], 1].max(axis=1)
    assert (raised & (side < -0.15)).any()  # the top of the backswing, over the right
    assert (raised & (side > 0.15)).any()  # the finish, over the left
    assert np.linalg.norm(hands[:, 0] - hands[:, 1], axis=1).max() < 0.2  # one grip


@pytest.mark.parametrize("seed", SEEDS)
def test_point_raises_one_arm_at_a_time(seed: int) -> None:
    poses = _take("point", seed).poses
    above = poses[:, [5, 6], 1] - poses[:, [1, 2], 1]  # wrist over its own shoulder, m
    assert (above.max(axis=1) >= 0.0).any()
    assert (above.min(axis=1) < -0.3).all()


def test_takes_start_at_random_places_and_headings() -> None:
    starts = np.array([_pelvis(_take("walk", seed).poses)[0, [0, 2]] for seed in SEEDS])
    assert np.abs(starts).max() < 1.1
    assert len({tuple(np.round(s, 3)) for s in starts}) == len(SEEDS)
    forward = [np.diff(_pelvis(_take("walk", seed).poses)[[0, -1]], axis=0)[0] for seed in SEEDS]
    headings = {round(float(np.arctan2(f[0], f[2])), 2) for f in forward}
    assert len(headings) == len(SEEDS)


def test_library() -> None:
    takes = library(takes_per_motion=2, seconds=1.0)
    assert len(takes) == 2 * len(MOTIONS)
    assert [t.action for t in takes] == [m for m in MOTIONS for _ in range(2)]
    assert len({t.name for t in takes}) == len(takes)
    assert len({t.content_hash for t in takes}) == len(takes)
    again = library(takes_per_motion=2, seconds=1.0)
    assert [t.content_hash for t in again] == [t.content_hash for t in takes]
    assert library(takes_per_motion=0) == []


def test_unknown_motion_is_named() -> None:
    with pytest.raises(ValueError, match="moonwalk") as error:
        generate("moonwalk")
    assert "walk" in str(error.value)


@pytest.mark.parametrize(("seconds", "fps"), [(0.0, 30.0), (-1.0, 30.0), (4.0, 0.0), (0.001, 30.0)])
def test_bad_duration_or_rate(seconds: float, fps: float) -> None:
    with pytest.raises(ValueError):
        generate("walk", seconds=seconds, fps=fps)
