"""Tests of DLT triangulation `samba.cameras.triangulation`."""

from __future__ import annotations

import numpy as np
import pytest

from samba.cameras.camera import Camera
from samba.cameras.triangulation import Triangulation, triangulate, triangulate_cameras

SIZE = (160, 120)


def _ring(count: int, size: tuple[int, int] = SIZE, radius: float = 4.0) -> list[Camera]:
    """`count` cameras on a ring around the origin at varied heights, all aimed at it."""
    cameras = []
    for i in range(count):
        angle = 2 * np.pi * i / count + 0.3
        position = (radius * np.sin(angle), 1.0 + 0.4 * i, radius * np.cos(angle))
        cameras.append(Camera.look_at(f"cam{i}", position, (0.0, 1.0, 0.0), size, 60.0))
    return cameras


def _points(n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).uniform([-0.8, 0.0, -0.8], [0.8, 2.0, 0.8], (n, 3))


def _pixels(cameras: list[Camera], points: np.ndarray) -> np.ndarray:
    return np.stack([camera.project(points) for camera in cameras])


@pytest.mark.parametrize("count", [2, 3, 4])
def test_noise_free_views_recover_the_points(count: int) -> None:
    cameras = _ring(count)
    points = _points(500)
    pixels = _pixels(cameras, points)
    assert pixels.shape == (count, 500, 2)
    recovered = triangulate_cameras(cameras, pixels)
    assert recovered.shape == (500, 3)
    assert np.abs(recovered - points).max() < 1e-9


def test_large_images_and_distant_points_stay_accurate() -> None:
    cameras = _ring(3, size=(3840, 2160), radius=30.0)
    points = _points(200, seed=1) + np.array([5.0, 0.0, -3.0])
    recovered = triangulate_cameras(cameras, _pixels(cameras, points))
    assert np.abs(recovered - points).max() < 1e-9


def test_missing_views_give_nan_only_below_two_views() -> None:
    cameras = _ring(4)
    points = _points(400, seed=2)
    pixels = _pixels(cameras, points)
    missing = np.random.default_rng(3).random((4, 400)) < 0.5
    pixels[missing] = np.nan
    pixels[0, :10, 1] = np.nan  # half a NaN pixel is a missing view too
    missing[0, :10] = True
    views = (~missing).sum(axis=0)
    assert set(views) == {0, 1, 2, 3, 4}
    recovered = triangulate_cameras(cameras, pixels)
    nan = np.isnan(recovered)
    assert (nan.all(axis=1) == (views < 2)).all()
    assert (nan.any(axis=1) == (views < 2)).all()
    assert np.abs(recovered[views >= 2] - points[views >= 2]).max() < 1e-9


def test_noisy_views_give_a_small_error() -> None:
    cameras = [
        Camera.look_at(f"cam{i}", (4.0 * np.sin(a), 1.5, 4.0 * np.cos(a)), (0, 1, 0), SIZE, 60.0)
        for i, a in enumerate(np.radians([-37.5, 37.5]))
    ]
    points = _points(2000, seed=4)
    pixels = _pixels(cameras, points) + np.random.default_rng(5).normal(0.0, 0.3, (2, 2000, 2))
    error = np.linalg.norm(triangulate_cameras(cameras, pixels) - points, axis=1)
    assert 0.001 < np.sqrt(np.mean(error**2)) < 0.03


def test_batch_shapes_are_kept() -> None:
    cameras = _ring(2)
    points = _points(30, seed=6).reshape(5, 6, 3)
    pixels = np.stack([camera.projection for camera in cameras])
    recovered = triangulate(pixels, _pixels(cameras, points))
    assert recovered.shape == (5, 6, 3)
    assert np.abs(recovered - points).max() < 1e-9
    assert triangulate(pixels, np.zeros((2, 0, 2))).shape == (0, 3)


def test_bad_inputs_are_refused() -> None:
    cameras = _ring(2)
    projections = np.stack([camera.projection for camera in cameras])
    with pytest.raises(ValueError, match="points"):
        triangulate(projections, np.zeros((3, 4, 2)))
    with pytest.raises(ValueError, match="projections"):
        triangulate(projections[:, :, :3], np.zeros((2, 4, 2)))
    with pytest.raises(ValueError, match="points"):
        triangulate_cameras(cameras, np.zeros((3, 4, 2)))


def test_distorted_cameras_are_undistorted_before_triangulation() -> None:
    ring = _ring(3, size=(640, 480))
    cameras = [
        Camera(c.name, c.size, c.matrix, c.rotation, c.translation, np.array(d))
        for c, d in zip(
            ring,
            ([-0.25, 0.08, 0.001, -0.002, 0.0], [0.12, -0.05, 0.0, 0.0, 0.01], [0.0] * 5),
            strict=True,
        )
    ]
    points = _points(300, seed=8)
    raw = _pixels(cameras, points)
    assert np.abs(raw - _pixels(ring, points)).max() > 1.0  # the lenses do bend the image
    assert np.abs(triangulate_cameras(cameras, raw) - points).max() < 1e-6


def _projections(cameras: list[Camera]) -> np.ndarray:
    return np.stack([camera.projection for camera in cameras])


def test_reprojection_errors_are_reported_per_view_and_per_point() -> None:
    cameras = _ring(3, size=(640, 480))
    points = _points(300, seed=3)
    pixels = _pixels(cameras, points)
    pixels[1, :10] = np.nan  # camera 1 misses the first ten points
    result = Triangulation.from_views(_projections(cameras), pixels)
    assert np.abs(result.points - points).max() < 1e-9
    assert result.error.shape == (300,) and np.nanmax(result.error) < 1e-6
    assert np.isnan(result.view_error[1, :10]).all() and not result.views[1, :10].any()
    assert result.views[:, 10:].all()


def test_gating_drops_outlier_views_and_keeps_the_point() -> None:
    rng = np.random.default_rng(4)
    cameras = _ring(4, size=(640, 480))
    points = _points(400, seed=4)
    pixels = _pixels(cameras, points) + rng.normal(0.0, 0.3, (4, 400, 2))
    pixels[2, :50] += 35.0  # a wrong blob in camera 2
    plain = np.linalg.norm(triangulate(_projections(cameras), pixels) - points, axis=-1)
    gated = Triangulation.from_views(_projections(cameras), pixels, refine=True, gate_px=3.0)
    error = np.linalg.norm(gated.points - points, axis=-1)
    assert not gated.views[2, :50].any() and gated.views[:, 50:].all()
    assert error[:50].mean() < 0.2 * plain[:50].mean()
    assert error.mean() < 0.01 and np.nanmax(gated.error) < 3.0


def test_gating_never_drops_below_two_views() -> None:
    cameras = _ring(2, size=(640, 480))
    points = _points(20, seed=5)
    pixels = _pixels(cameras, points)
    pixels[0] += 50.0
    gated = Triangulation.from_views(_projections(cameras), pixels, gate_px=1.0)
    assert gated.views.all() and np.isfinite(gated.points).all()
    assert (gated.error > 1.0).all()


def test_refinement_lowers_the_reprojection_error() -> None:
    rng = np.random.default_rng(6)
    cameras = _ring(4, size=(320, 240))
    points = _points(500, seed=6)
    pixels = _pixels(cameras, points) + rng.normal(0.0, 1.0, (4, 500, 2))
    plain = Triangulation.from_views(_projections(cameras), pixels)
    refined = Triangulation.from_views(_projections(cameras), pixels, refine=True)
    assert (refined.error <= plain.error + 1e-9).all()
    assert refined.error.mean() < plain.error.mean()


def test_triangulation_keeps_batch_shapes() -> None:
    cameras = _ring(3)
    points = _points(24, seed=7).reshape(3, 8, 3)
    pixels = np.stack([camera.project(points) for camera in cameras])
    result = Triangulation.from_views(_projections(cameras), pixels, refine=True, gate_px=2.0)
    assert result.points.shape == (3, 8, 3) and result.error.shape == (3, 8)
    assert result.views.shape == (3, 3, 8) and result.view_error.shape == (3, 3, 8)
    assert np.abs(result.points - points).max() < 1e-9
