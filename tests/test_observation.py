"""Tests of the synthetic observation model `samba.markers.observation` (EVALUATION.md)."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from samba.body.skeleton import (
    BONES,
    bone_lengths,
    facing_directions,
    markers_of,
    mean_facing,
    standard_pose,
)
from samba.cameras.camera import Camera
from samba.markers.observation import (
    ObservedMarkers,
    evaluation_cameras,
    marker_coverage,
    new_user_factors,
    observe_markers,
    scale_limbs,
)
from samba.synthetic.motions import generate

TORSO_JOINTS = (0, 1, 2, 7, 8)  # head, shoulders, hips


@cache
def _walk(seed: int = 1) -> np.ndarray:
    return generate("walk", seconds=3, fps=30, seed=seed).poses


def _turned(poses: np.ndarray, yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    turn = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return poses @ turn.T


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _horizontal(v: np.ndarray) -> np.ndarray:
    return np.array([v[0], 0.0, v[2]])


def test_facing_of_the_standard_pose_is_plus_z() -> None:
    pose = standard_pose()
    assert pose[1, 0] > 0  # left shoulder at +X
    np.testing.assert_allclose(facing_directions(pose[None]), [[0.0, 0.0, 1.0]], atol=1e-12)
    yaw = np.radians(70.0)
    np.testing.assert_allclose(
        mean_facing(_turned(np.stack([pose, pose]), yaw)),
        [np.sin(yaw), 0.0, np.cos(yaw)],
        atol=1e-12,
    )


def _camera_distances(poses: np.ndarray, cameras: list[Camera]) -> tuple[np.ndarray, list]:
    """The aim point (3,) and each camera's horizontal offset (3,) from it."""
    aim = markers_of(poses.astype(np.float64)).reshape(-1, 3).mean(axis=0)
    return aim, [_horizontal(camera.center - aim) for camera in cameras]


@pytest.mark.parametrize("seed", [1, 0])
def test_evaluation_cameras_follow_the_protocol(seed: int) -> None:
    poses = _walk(seed)
    cameras = evaluation_cameras(poses)
    assert len(cameras) == 2
    aim, offsets = _camera_distances(poses, cameras)
    distances = [np.linalg.norm(o) for o in offsets]
    cos = offsets[0] @ offsets[1] / (distances[0] * distances[1])
    assert np.degrees(np.arccos(cos)) == pytest.approx(75.0, abs=1e-6)
    facing = mean_facing(poses)
    for camera, offset, distance in zip(cameras, offsets, distances, strict=True):
        assert camera.size == (160, 120)
        assert not camera.has_distortion
        assert camera.center[1] == pytest.approx(1.5, abs=1e-9)
        # 37.5 degrees either side of the mean facing, i.e. in front of the subject
        assert offset @ facing / distance == pytest.approx(np.cos(np.radians(37.5)), abs=1e-9)
        np.testing.assert_allclose(camera.project(aim), [79.5, 59.5], atol=1e-6)
        hfov = 2 * np.degrees(np.arctan(80.0 / camera.matrix[0, 0]))
        assert hfov == pytest.approx(60.0)
    assert distances[0] == pytest.approx(distances[1], abs=1e-9)
    steps = (distances[0] - 3.5) / 0.25
    assert steps > -1e-9 and steps == pytest.approx(round(steps), abs=1e-6)
    assert marker_coverage(poses, cameras) >= 0.995
    if round(steps) > 0:  # the distance is the smallest that fits
        closer = [
            Camera.look_at(c.name, c.center - 0.25 * o / d, aim, c.size, 60.0)
            for c, o, d in zip(cameras, offsets, distances, strict=True)
        ]
        assert marker_coverage(poses, closer) < 0.995


def test_a_travelling_take_pushes_the_cameras_back() -> None:
    poses = _walk(0)  # walks far enough that 3.5 m does not frame it
    _, offsets = _camera_distances(poses, evaluation_cameras(poses))
    assert np.linalg.norm(offsets[0]) > 3.5 + 0.2


def test_noise_free_observation_reproduces_the_markers() -> None:
    poses = _walk()
    cameras = evaluation_cameras(poses)
    observed = observe_markers(
        poses, cameras, np.random.default_rng(0), noise_px=0.0, resolution_px=0.0
    )
    assert isinstance(observed, ObservedMarkers)
    assert observed.pixels.shape == (2, len(poses), 8, 2)
    assert observed.markers.shape == (len(poses), 8, 3)
    assert observed.present.mean() >= 0.99
    truth = markers_of(poses).astype(np.float64)
    assert np.nanmax(np.abs(observed.markers - truth)) < 1e-6


def test_default_noise_gives_a_centimetre_level_error() -> None:
    # 0.3 px at ~3.5 m with a 139 px focal length is ~7.6 mm per view; with two views
    # 75 degrees apart the 3D RMS comes to ~1.6 times that.
    poses = _walk()
    cameras = evaluation_cameras(poses)
    observed = observe_markers(poses, cameras, np.random.default_rng(0))
    error = np.linalg.norm(observed.markers - markers_of(poses), axis=-1)
    rms = np.sqrt(np.nanmean(error**2))
    assert 0.005 < rms < 0.025
    # pixels are on the 0.1 px grid
    pixels = observed.pixels[~np.isnan(observed.pixels)]
    np.testing.assert_allclose(pixels * 10, np.round(pixels * 10), atol=1e-6)


def test_same_seed_same_observation() -> None:
    poses = _walk()
    cameras = evaluation_cameras(poses)
    a = observe_markers(poses, cameras, np.random.default_rng(7), dropout=0.1)
    b = observe_markers(poses, cameras, np.random.default_rng(7), dropout=0.1)
    np.testing.assert_array_equal(a.pixels, b.pixels)
    np.testing.assert_array_equal(a.markers, b.markers)


def test_dropout_removes_a_tenth_of_the_markers_from_frame_two_on() -> None:
    poses = _walk()
    cameras = evaluation_cameras(poses)
    full = observe_markers(poses, cameras, np.random.default_rng(3))
    dropped = observe_markers(poses, cameras, np.random.default_rng(3), dropout=0.1)
    assert full.present.all()
    assert dropped.present[:2].all()
    missing = 1.0 - dropped.present[2:].mean()
    assert missing == pytest.approx(0.1, abs=0.01)
    # a dropped marker is gone from every camera; the others are untouched
    gone = ~dropped.present
    assert np.isnan(dropped.pixels[:, gone]).all()
    np.testing.assert_array_equal(dropped.pixels[:, ~gone], full.pixels[:, ~gone])


def test_out_of_view_markers_are_missing() -> None:
    poses = _walk()
    centre = markers_of(poses).reshape(-1, 3).mean(axis=0)
    poses = poses - np.array([centre[0], 0.0, centre[2]])  # walk through the origin
    close = [
        Camera.look_at(f"c{i}", (x, 1.5, 1.5), (0.0, 1.0, 0.0), (160, 120), 60.0)
        for i, x in enumerate((-0.5, 0.5))
    ]
    observed = observe_markers(poses, close, np.random.default_rng(0))
    for i, camera in enumerate(close):
        seen = ~np.isnan(observed.pixels[i]).any(axis=-1)
        assert 0.1 < seen.mean() < 0.9
        assert camera.in_image(observed.pixels[i][seen]).all()
    views = (~np.isnan(observed.pixels).any(axis=-1)).sum(axis=0)
    assert (observed.present == (views >= 2)).all()


def test_bad_observation_arguments_are_refused() -> None:
    poses = _walk()
    cameras = evaluation_cameras(poses)
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="dropout"):
        observe_markers(poses, cameras, rng, dropout=1.5)
    with pytest.raises(ValueError, match="noise_px"):
        observe_markers(poses, cameras, rng, noise_px=-1.0)
    with pytest.raises(ValueError, match="poses"):
        observe_markers(poses[:, :8], cameras, rng)


def test_scale_limbs_scales_each_bone_by_its_factor() -> None:
    poses = _walk()
    factors = new_user_factors(np.random.default_rng(5))
    scaled = scale_limbs(poses, factors)
    assert scaled.shape == poses.shape
    np.testing.assert_allclose(
        bone_lengths(scaled), bone_lengths(poses.astype(np.float64)) * factors, rtol=1e-12
    )
    np.testing.assert_array_equal(scaled[:, TORSO_JOINTS], poses[:, TORSO_JOINTS])
    # each bone keeps its direction
    for parent, child in BONES:
        before = poses[:, child] - poses[:, parent]
        after = scaled[:, child] - scaled[:, parent]
        np.testing.assert_allclose(_unit(after), _unit(before.astype(np.float64)), atol=1e-6)


def test_scale_limbs_moves_only_the_joints_below_the_bone() -> None:
    pose = standard_pose()[None]
    factors = np.ones(8)
    factors[0] = 1.1  # left upper arm: moves the left elbow and wrist only
    scaled = scale_limbs(pose, factors)
    moved = np.flatnonzero(np.abs(scaled - pose).max(axis=-1)[0] > 0)
    assert moved.tolist() == [3, 5]
    upper_arm = pose[0, 3] - pose[0, 1]
    np.testing.assert_allclose(scaled[0, 5] - pose[0, 5], 0.1 * upper_arm, atol=1e-12)
    np.testing.assert_array_equal(scale_limbs(pose, np.ones(8)), pose)


def test_new_user_factors_are_seeded_and_in_range() -> None:
    factors = new_user_factors(np.random.default_rng(0))
    assert factors.shape == (8,)
    assert ((factors >= 0.9) & (factors <= 1.1)).all()
    np.testing.assert_array_equal(factors, new_user_factors(np.random.default_rng(0)))
    many = np.concatenate([new_user_factors(np.random.default_rng(s)) for s in range(50)])
    assert many.min() < 0.92 and many.max() > 1.08
