"""Tests of the pose thinning of the silhouette tree, `samba.silhouette.pose_selection`.

The greedy must equal a brute force written from its definition, keep a set that covers
every dropped pose and holds no two poses alike, thin slow motion hard and leave very
different poses alone; bad input errors name the input and the problem.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from samba.base.errors import InputError
from samba.body.skeleton import bone_lengths, standard_pose
from samba.silhouette.pose_selection import DIRECTION_NAMES, bone_directions, distinct_poses, turned
from samba.synthetic.motions import MOTIONS, generate


def _max_angles(directions: np.ndarray, others: np.ndarray) -> np.ndarray:
    """Largest bone angle in degrees (m, k) between poses of unit directions (m, 12, 3)
    and (k, 12, 3)."""
    cosines = np.einsum("mbc,kbc->mkb", directions, others)
    return np.degrees(np.arccos(np.clip(cosines, -1.0, 1.0))).max(axis=2)


def _brute_force(poses: np.ndarray, min_degrees: float) -> np.ndarray:
    """The greedy straight from its definition: keep a pose unless a kept one is within
    `min_degrees` of it in every bone."""
    directions = bone_directions(poses)
    kept: list[int] = []
    for pose in range(len(poses)):
        closest = _max_angles(directions[pose : pose + 1], directions[kept]).min(initial=np.inf)
        if closest >= min_degrees:
            kept.append(pose)
    return np.array(kept, dtype=int)


@cache
def _slow_takes() -> np.ndarray:
    """2880 poses: slow motions at 60 fps, each also turned by 4°, so that many pose
    pairs sit near the limit in one bone or another."""
    motions = ("arm_swing", "golf_swing", "point", "turn", "walk", "wave", "kick", "squat")
    takes = [
        generate(motion, seconds=3.0, fps=60.0, seed=seed, speed=0.8).poses
        for seed, motion in enumerate(motions)
    ]
    return turned(np.concatenate(takes), np.array([0.0, 4.0]))


def _swung(pose: np.ndarray, joints: list[int], pivot: np.ndarray, degrees: float) -> np.ndarray:
    """A copy of `pose` (13, 3) with `joints` turned about the Z axis through `pivot`."""
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    out = pose.copy()
    x, y = (pose[joints] - pivot)[:, 0], (pose[joints] - pivot)[:, 1]
    out[joints, 0], out[joints, 1] = pivot[0] + c * x - s * y, pivot[1] + s * x + c * y
    return out


def test_directions_of_the_standard_pose() -> None:
    directions = bone_directions(standard_pose(1.70, arm_angle_deg=30.0)[None])[0]
    assert directions.shape == (12, 3) and len(DIRECTION_NAMES) == 12
    assert np.allclose(np.linalg.norm(directions, axis=1), 1.0)
    s, c = np.sin(np.radians(30.0)), np.cos(np.radians(30.0))
    expected = {
        "left upper arm": (s, -c, 0.0),
        "right forearm": (-s, -c, 0.0),
        "left shin": (0.0, -1.0, 0.0),
        "trunk": (0.0, 1.0, 0.0),
        "neck": (0.0, 1.0, 0.0),
        "shoulder line": (1.0, 0.0, 0.0),
        "hip line": (1.0, 0.0, 0.0),
    }
    for name, direction in expected.items():
        assert np.allclose(directions[DIRECTION_NAMES.index(name)], direction), name


def test_turned_poses_keep_their_shape_and_place() -> None:
    poses = generate("point", seconds=0.2, seed=1).poses.astype(np.float64)
    degrees = np.array([0.0, 90.0, -45.0])
    out = turned(poses, degrees)
    assert out.shape == (len(poses) * 3, 13, 3)
    assert np.allclose(out[0::3], poses)
    assert np.allclose(bone_lengths(out), np.repeat(bone_lengths(poses), 3, axis=0))
    hips = out[:, [7, 8]].mean(axis=1)
    assert np.allclose(hips, np.repeat(poses[:, [7, 8]].mean(axis=1), 3, axis=0))
    assert np.allclose(out[:, :, 1], np.repeat(poses[:, :, 1], 3, axis=0))
    # Turned by 90°, a body whose shoulder line pointed at +X points it at -Z.
    line = bone_directions(turned(standard_pose()[None], degrees))[:, -2]
    assert np.allclose(line, [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [np.sqrt(0.5), 0.0, np.sqrt(0.5)]])


@pytest.mark.parametrize("min_degrees", [5.0, 2.0, 12.0])
def test_equals_the_brute_force_greedy(min_degrees: float) -> None:
    poses = _slow_takes()
    kept = distinct_poses(poses, min_degrees)
    assert kept.dtype.kind == "i"
    assert np.array_equal(kept, _brute_force(poses, min_degrees))
    assert 0.02 * len(poses) < len(kept) < 0.8 * len(poses)  # a real thinning


def test_a_covering_pose_that_is_not_the_nearest_counts() -> None:
    query = standard_pose()
    one_bone = _swung(query, [5], query[3], 5.5)  # the left forearm 5.5° off: nearest
    neck = query[[1, 2]].mean(axis=0)
    four_bones = _swung(query, [0], neck, 4.9)  # 4.9° off in 4 bones: within
    for foot, knee in ((11, 9), (12, 10)):
        four_bones = _swung(four_bones, [foot], query[knee], 4.9)
    four_bones = _swung(four_bones, [6], query[4], 4.9)
    others = turned(standard_pose(arm_angle_deg=80.0)[None], 5.2 * np.arange(69))
    poses = np.concatenate([[one_bone, four_bones], others, [query]])
    assert list(distinct_poses(poses)) == list(range(len(poses) - 1))
    assert np.array_equal(distinct_poses(poses), _brute_force(poses, 5.0))


def test_kept_poses_cover_the_dropped_ones_and_differ_from_each_other() -> None:
    poses = _slow_takes()
    kept = distinct_poses(poses)
    directions = bone_directions(poses)
    among_kept = _max_angles(directions[kept], directions[kept])
    np.fill_diagonal(among_kept, np.inf)
    assert among_kept.min() >= 5.0
    dropped = np.setdiff1d(np.arange(len(poses)), kept)
    assert _max_angles(directions[dropped], directions[kept]).min(axis=1).max() < 5.0


def test_slow_motion_shrinks_and_different_poses_do_not() -> None:
    slow = generate("squat", seconds=4.0, fps=60.0, seed=2, speed=0.8).poses
    assert len(distinct_poses(slow)) < 0.2 * len(slow)
    rng = np.random.default_rng(7)
    takes = [generate(motion, seed=11 + i).poses for i, motion in enumerate(MOTIONS)]
    frames = np.concatenate(takes)[rng.choice(len(MOTIONS) * 120, 300, replace=False)]
    varied = np.concatenate(
        [turned(pose[None], rng.uniform(0.0, 360.0, 1)) for pose in frames.astype(np.float64)]
    )
    assert len(distinct_poses(varied)) >= 0.95 * len(varied)


def test_the_order_decides_which_pose_stays() -> None:
    pose = standard_pose()[None]
    near = turned(pose, np.array([0.0, 3.0, 7.0]))  # 3° apart, then 4° apart
    assert list(distinct_poses(near)) == [0, 2]
    assert list(distinct_poses(near[::-1])) == [0, 2]
    assert list(distinct_poses(near[[1, 0, 2]])) == [0]
    assert distinct_poses(np.zeros((0, 13, 3))).shape == (0,)


@pytest.mark.parametrize(
    ("poses", "problem"),
    [
        (np.zeros((4, 12, 3)), r"shape \(n, 13, 3\), got \(4, 12, 3\)"),
        (standard_pose(), r"shape \(n, 13, 3\), got \(13, 3\)"),
        (np.where(np.arange(3)[:, None, None] == 2, np.nan, standard_pose()), "pose 2 .*NaN"),
    ],
)
def test_bad_poses_are_named(poses: np.ndarray, problem: str) -> None:
    for call in (bone_directions, distinct_poses, lambda p: turned(p, np.array([0.0]))):
        with pytest.raises(InputError, match=f"^poses: .*{problem}"):
            call(poses)


def test_a_bone_without_length_is_named() -> None:
    poses = np.repeat(standard_pose()[None], 3, axis=0)
    poses[1, 4] = poses[1, 6]  # the right forearm collapsed to a point
    for call in (bone_directions, distinct_poses):
        with pytest.raises(InputError, match=r"^poses: pose 1: the right forearm has no length"):
            call(poses)


@pytest.mark.parametrize("min_degrees", [0.0, -5.0, float("nan"), 181.0])
def test_bad_min_degrees_is_named(min_degrees: float) -> None:
    with pytest.raises(InputError, match=r"^min_degrees: must be in \(0, 180\] degrees"):
        distinct_poses(standard_pose()[None], min_degrees)


@pytest.mark.parametrize("degrees", [np.zeros((2, 2)), np.array([0.0, np.inf])])
def test_bad_degrees_are_named(degrees: np.ndarray) -> None:
    with pytest.raises(InputError, match=r"^degrees: must be a 1-D array of finite angles"):
        turned(standard_pose()[None], degrees)
