"""Tests of the pinhole camera model `samba.cameras.camera`."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from samba.cameras.camera import Camera, CameraGroup

SIZE = (160, 120)
CENTRE = ((SIZE[0] - 1) / 2, (SIZE[1] - 1) / 2)


def _front_camera(**kwargs: object) -> Camera:
    """A 160x120, 60-degree camera 5 m in front of the origin (on +Z), looking at it."""
    return Camera.look_at("front", (0.0, 0.0, 5.0), (0.0, 0.0, 0.0), SIZE, 60.0, **kwargs)


def _distorted(distortion: list[float]) -> Camera:
    return Camera(
        name="lens",
        size=(640, 480),
        matrix=np.array([[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]]),
        rotation=np.zeros(3),
        translation=np.zeros(3),
        distortion=np.array(distortion),
    )


def test_look_at_projects_the_target_to_the_image_centre() -> None:
    target = np.array([0.3, 1.0, -0.2])
    for position in ([3.0, 1.5, 2.0], [-2.0, 0.5, -3.0], [0.1, 4.0, 0.3]):
        camera = Camera.look_at("c", position, target, SIZE, 60.0)
        np.testing.assert_allclose(camera.project(target), CENTRE, atol=1e-9)
        np.testing.assert_allclose(camera.center, position, atol=1e-12)


def test_image_axes_follow_the_opencv_convention() -> None:
    camera = _front_camera()  # looks along -Z, so world +X is to the right, +Y up
    u_right, v_right = camera.project([1.0, 0.0, 0.0])
    u_up, v_up = camera.project([0.0, 1.0, 0.0])
    assert u_right > CENTRE[0] and v_right == pytest.approx(CENTRE[1])
    assert v_up < CENTRE[1] and u_up == pytest.approx(CENTRE[0])
    r = camera.rotation_matrix
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    np.testing.assert_allclose(r[2], [0.0, 0.0, -1.0], atol=1e-12)  # optical axis = -Z


def test_horizontal_field_of_view_spans_the_image_width() -> None:
    camera = _front_camera()
    edge = 5.0 * np.tan(np.radians(30.0))
    uv = camera.project([[edge, 0.0, 0.0], [-edge, 0.0, 0.0]])
    np.testing.assert_allclose(uv[:, 0], [SIZE[0] - 0.5, -0.5], atol=1e-9)
    assert camera.matrix[0, 0] == camera.matrix[1, 1]


def test_points_in_front_project_inside_and_behind_give_nan() -> None:
    camera = _front_camera()
    points = np.array([[0.5, -0.4, 1.0], [0.0, 0.0, 6.0], [0.0, 0.0, 5.0], [np.nan, 0.0, 0.0]])
    uv = camera.project(points)
    assert camera.in_image(uv[0])
    assert np.isnan(uv[1:]).all()
    assert not camera.in_image(uv[1:]).any()
    assert not camera.in_image([[-1.0, 10.0], [10.0, SIZE[1]]]).any()
    assert camera.in_image([[-0.5, -0.5], [SIZE[0] - 0.5, SIZE[1] - 0.5]]).all()


def test_project_keeps_the_batch_shape() -> None:
    camera = _front_camera()
    points = np.random.default_rng(0).uniform(-0.5, 0.5, (4, 5, 3))
    uv = camera.project(points)
    assert uv.shape == (4, 5, 2)
    assert camera.in_image(uv).shape == (4, 5)
    np.testing.assert_allclose(uv[2, 3], camera.project(points[2, 3]))


def test_projection_matrix_agrees_with_project() -> None:
    camera = Camera.look_at("c", (2.0, 1.5, 3.0), (0.0, 1.0, 0.0), SIZE, 50.0)
    points = np.random.default_rng(1).uniform(-1.0, 1.0, (20, 3))
    homogeneous = np.hstack([points, np.ones((20, 1))]) @ camera.projection.T
    np.testing.assert_allclose(
        homogeneous[:, :2] / homogeneous[:, 2:], camera.project(points), atol=1e-9
    )


def test_distortion_matches_a_hand_computation() -> None:
    # Radial only: normalised (0.1, 0) -> r^2 = 0.01, factor 1 + 0.1 * 0.01 + 0.01 * 1e-4.
    camera = _distorted([0.1, 0.01, 0.0, 0.0, 0.0])
    u, v = camera.project([0.1, 0.0, 1.0])
    assert u == pytest.approx(320.0 + 500.0 * 0.1 * 1.001001, abs=1e-9)
    assert v == pytest.approx(240.0, abs=1e-9)
    # Tangential only: normalised (0.1, 0.2) -> r^2 = 0.05, x'y' = 0.02.
    camera = _distorted([0.0, 0.0, 0.01, 0.02, 0.0])
    u, v = camera.project([0.2, 0.4, 2.0])
    x = 0.1 + 2 * 0.01 * 0.02 + 0.02 * (0.05 + 2 * 0.01)
    y = 0.2 + 0.01 * (0.05 + 2 * 0.04) + 2 * 0.02 * 0.02
    assert u == pytest.approx(320.0 + 500.0 * x, abs=1e-9)
    assert v == pytest.approx(240.0 + 510.0 * y, abs=1e-9)
    # k3 enters as r^6.
    camera = _distorted([0.0, 0.0, 0.0, 0.0, 0.5])
    u, _ = camera.project([0.2, 0.0, 1.0])
    assert u == pytest.approx(320.0 + 500.0 * 0.2 * (1 + 0.5 * 0.04**3), abs=1e-9)


def test_distortion_matches_opencv() -> None:
    cv2 = pytest.importorskip("cv2")
    camera = Camera(
        name="lens",
        size=(640, 480),
        matrix=np.array([[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]]),
        rotation=np.array([0.1, -0.2, 0.05]),
        translation=np.array([0.1, -0.3, 2.0]),
        distortion=np.array([-0.2, 0.05, 0.001, -0.002, 0.01]),
    )
    points = np.random.default_rng(2).uniform(-0.5, 0.5, (50, 3))
    expected, _ = cv2.projectPoints(
        points, camera.rotation, camera.translation, camera.matrix, camera.distortion
    )
    np.testing.assert_allclose(camera.project(points), expected[:, 0], atol=1e-8)


def test_distortion_free_by_default() -> None:
    camera = _front_camera()
    assert camera.distortion.shape == (5,)
    assert not camera.has_distortion
    assert _distorted([0.1, 0.0, 0.0, 0.0, 0.0]).has_distortion


def test_bad_fields_name_the_camera_and_the_field() -> None:
    good = {
        "name": "cam7",
        "size": (160, 120),
        "matrix": np.eye(3),
        "rotation": np.zeros(3),
        "translation": np.zeros(3),
    }
    for field, value in (
        ("matrix", np.eye(4)),
        ("rotation", np.zeros(4)),
        ("translation", np.zeros((3, 1))),
        ("distortion", np.zeros(4)),
        ("size", (160,)),
        ("size", (160.5, 120)),
        ("rotation", np.array([0.0, np.nan, 0.0])),
    ):
        with pytest.raises(ValueError, match=rf"cam7.*{field}"):
            Camera(**{**good, field: value})
    with pytest.raises(ValueError, match="cam7"):
        Camera.look_at("cam7", (0.0, 3.0, 0.0), (0.0, 0.0, 0.0), SIZE, 60.0)  # looks along up


def test_camera_is_immutable() -> None:
    camera = _front_camera()
    with pytest.raises(dataclasses.FrozenInstanceError):
        camera.name = "other"  # type: ignore[misc]
    with pytest.raises(ValueError):
        camera.matrix[0, 0] = 1.0
    rotation = np.array([0.1, 0.2, 0.3])
    camera = Camera("c", SIZE, np.eye(3), rotation, np.zeros(3))
    rotation[0] = 5.0
    assert camera.rotation[0] == 0.1


LENSES = (
    [-0.25, 0.08, 0.0, 0.0, -0.01],  # strong barrel
    [0.1, -0.02, 0.0, 0.0, 0.0],  # pincushion
    [-0.2, 0.05, 0.001, -0.002, 0.01],  # with tangential terms
)


def _lens_camera(distortion: list[float]) -> Camera:
    return Camera(
        name="lens",
        size=(640, 480),
        matrix=np.array([[500.0, 0.0, 321.0], [0.0, 510.0, 238.0], [0.0, 0.0, 1.0]]),
        rotation=np.array([0.1, -0.2, 0.05]),
        translation=np.array([0.1, -0.3, 2.0]),
        distortion=np.array(distortion),
    )


@pytest.mark.parametrize("distortion", LENSES)
def test_undistort_inverts_the_distortion_of_project(distortion: list[float]) -> None:
    camera = _lens_camera(distortion)
    points = np.random.default_rng(3).uniform(-1.0, 1.0, (4000, 3))
    distorted = camera.project(points)
    inside = camera.in_image(distorted)
    homogeneous = np.hstack([points, np.ones((len(points), 1))]) @ camera.projection.T
    pinhole = homogeneous[:, :2] / homogeneous[:, 2:]
    undistorted = camera.undistort(distorted[inside])
    assert inside.sum() > 1000
    assert np.abs(undistorted - pinhole[inside]).max() < 1e-6


def test_undistort_agrees_with_opencv_and_keeps_nan_and_shape() -> None:
    cv2 = pytest.importorskip("cv2")
    camera = _lens_camera(LENSES[2])
    grid = np.stack(np.meshgrid(np.arange(0, 640, 40.0), np.arange(0, 480, 40.0)), axis=-1)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    expected = cv2.undistortImagePoints(
        grid.reshape(-1, 1, 2), camera.matrix, camera.distortion, criteria
    ).reshape(grid.shape)
    undistorted = camera.undistort(grid)
    assert undistorted.shape == grid.shape
    # OpenCV's fixed-point iteration stops short at the corners of the image (~0.01 px).
    np.testing.assert_allclose(undistorted, expected, atol=0.05)
    batch = np.array([[[np.nan, 5.0], [100.0, 200.0]]])
    out = camera.undistort(batch)
    assert out.shape == (1, 2, 2) and np.isnan(out[0, 0]).all() and np.isfinite(out[0, 1]).all()
    plain = _front_camera()
    np.testing.assert_array_equal(plain.undistort(grid), grid)


def test_camera_group_orders_names_and_projects_in_batches() -> None:
    cameras = [
        Camera.look_at(f"c{i}", (3.0 * np.sin(a), 1.5, 3.0 * np.cos(a)), (0, 1, 0), SIZE, 60.0)
        for i, a in enumerate((0.0, 1.0, 2.0))
    ]
    group = CameraGroup(cameras)
    assert len(group) == 3 and group.names == ("c0", "c1", "c2")
    assert [c.name for c in group] == ["c0", "c1", "c2"]
    assert group["c1"] is cameras[1] and group[2] is cameras[2] and group.index("c2") == 2
    with pytest.raises(KeyError, match="c9"):
        group["c9"]
    assert group.projections.shape == (3, 3, 4)
    np.testing.assert_array_equal(group.projections[1], cameras[1].projection)
    points = np.random.default_rng(4).uniform(-0.5, 0.5, (5, 7, 3)) + np.array([0.0, 1.0, 0.0])
    pixels = group.project(points)
    assert pixels.shape == (3, 5, 7, 2)
    np.testing.assert_array_equal(pixels[2], cameras[2].project(points))
    np.testing.assert_array_equal(group.undistort(pixels), pixels)
    with pytest.raises(ValueError, match=r"unique.*c0"):
        CameraGroup([cameras[0], cameras[1], cameras[0]])
    with pytest.raises(ValueError, match="at least one"):
        CameraGroup([])
    with pytest.raises(dataclasses.FrozenInstanceError):
        group.cameras = ()  # type: ignore[misc]
