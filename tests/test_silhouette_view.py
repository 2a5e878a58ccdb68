"""Tests of `samba.silhouette.view`: where a silhouette stands, and the normalised frame in
which silhouettes are compared."""

from __future__ import annotations

import numpy as np
import pytest
from silhouette_fixtures import BODY, CAMERA, view

from samba.base.errors import InputError
from samba.body.body_model import ANKLE_HEIGHT_FRACTION
from samba.body.skeleton import standard_pose
from samba.cameras.camera import Camera
from samba.silhouette.render import render_silhouettes
from samba.silhouette.view import HOME_AIM_HEIGHT, HOME_DISTANCE, SilhouetteView

STANDING = standard_pose(BODY.height) + np.array([0.0, ANKLE_HEIGHT_FRACTION * BODY.height, 0.0])
"""The A-pose at the world origin, facing the camera, its soles on the floor."""


def _silhouette(offset: tuple[float, float, float]) -> np.ndarray:
    """The silhouette (240, 320) of the standing body moved by `offset` (3,) meters."""
    return render_silhouettes((STANDING + offset)[None], view().camera, BODY)[0]


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


def _height(mask: np.ndarray) -> int:
    """Rows (pixels) from the top to the bottom of a silhouette."""
    rows = np.flatnonzero(mask.any(axis=1))
    return int(rows[-1] - rows[0] + 1)


def test_floor_points_invert_the_projection_of_floor_points() -> None:
    the_view = view()
    x, z = np.meshgrid(np.linspace(-1.0, 1.0, 7), np.linspace(-4.0, 0.5, 6))
    points = np.stack([x, np.zeros_like(x), z], axis=-1)
    pixels = the_view.camera.project(points)
    assert the_view.camera.in_image(pixels).all()
    back = the_view.floor_points(pixels)
    assert back.shape == points.shape
    assert np.abs(back - points).max() * 1000 < 0.01  # mm


def test_floor_points_are_nan_above_the_horizon() -> None:
    the_view = view()
    top_row = np.array([[160.0, 0.0], [10.0, 5.0]])  # the camera looks 4 degrees down
    assert np.isnan(the_view.floor_points(top_row)).all()
    assert np.isfinite(the_view.floor_points(np.array([160.0, 230.0]))).all()


def test_home_defaults_to_the_floor_under_the_aim_point() -> None:
    # The camera aims at the subject's middle: home is under the point of the optical
    # axis HOME_AIM_HEIGHT above the floor (CAMERA aims at (0, 0.9, 0)).
    the_view = SilhouetteView(CAMERA)
    np.testing.assert_allclose(the_view.home, [0.0, 0.0, 0.0], atol=1e-9)
    down = Camera.look_at("down", (0.0, 2.5, 3.0), (0.0, 0.0, 0.0), (320, 240), 55.0)
    aim = 3.0 * (1 - (2.5 - HOME_AIM_HEIGHT) / 2.5)
    np.testing.assert_allclose(SilhouetteView(down).home, [0.0, 0.0, aim], atol=1e-9)
    level = Camera.look_at("level", (1.0, 1.2, 2.0), (1.0, 1.2, 0.0), (320, 240), 55.0)
    np.testing.assert_allclose(
        SilhouetteView(level).home, [1.0, 0.0, 2.0 - HOME_DISTANCE], atol=1e-9
    )


def test_the_view_resamples_the_camera() -> None:
    big = Camera.look_at("big", (0.0, 1.1, 3.0), (0.0, 0.9, 0.0), (1280, 960), 55.0)
    the_view = SilhouetteView(big, home=np.zeros(3))
    assert the_view.camera.size == the_view.size == (320, 240)
    np.testing.assert_allclose(the_view.home_pixel, view().home_pixel, atol=1e-9)


def test_a_home_the_camera_cannot_see_raises() -> None:
    with pytest.raises(InputError, match="cam: the camera does not see the floor"):
        SilhouetteView(CAMERA, home=np.array([0.0, 0.0, 5.0]))  # behind the camera


@pytest.mark.parametrize("shift", [(0.5, 0.0, 0.0), (-0.5, 0.0, 0.0), (0.0, 0.0, -0.5)])
def test_a_silhouette_moved_on_the_floor_normalises_to_the_same_mask(
    shift: tuple[float, float, float],
) -> None:
    the_view = view()
    home_mask, home_place = the_view.normalise(_silhouette((0.0, 0.0, 0.0)))
    moved_mask, moved_place = the_view.normalise(_silhouette(shift))
    assert _iou(home_mask, moved_mask) > 0.9
    assert np.linalg.norm(moved_place.floor - home_place.floor - shift) < 0.02  # m
    assert moved_place.floor[1] == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(
        the_view.camera.project(moved_place.floor), moved_place.anchor, atol=1e-6
    )


def test_a_subject_twice_as_far_normalises_to_the_same_size() -> None:
    the_view = view()
    near = _silhouette((0.0, 0.0, 0.0))
    far = _silhouette((0.0, 0.0, -3.0))  # 6 m from the camera instead of 3 m
    assert _height(far) < 0.6 * _height(near)
    near_mask, near_place = the_view.normalise(near)
    far_mask, far_place = the_view.normalise(far)
    assert far_place.scale / near_place.scale == pytest.approx(2.0, rel=0.05)
    assert _height(far_mask) == pytest.approx(_height(near_mask), rel=0.05)
    assert far_mask.sum() == pytest.approx(near_mask.sum(), rel=0.1)
    assert _iou(near_mask, far_mask) > 0.8
    assert far_place.floor[2] - near_place.floor[2] == pytest.approx(-3.0, abs=0.05)


def test_a_taller_subject_normalises_to_the_body_models_size() -> None:
    # A subject 5% taller than the body model: told its size, the normalised frame
    # brings it to the model's; its anchor and floor point do not change.
    the_view = view()
    model, _ = the_view.normalise(_silhouette((0.0, 0.0, 0.0)))
    floor = STANDING[[7, 8]].mean(axis=0) * np.array([1.0, 0.0, 1.0])
    taller = floor + 1.05 * (STANDING - floor)
    big = BODY.scaled(1.05)
    mask = render_silhouettes(taller[None], the_view.camera, big)[0]
    told, told_place = the_view.normalise(mask, 1.05)
    as_is, place = the_view.normalise(mask)
    assert _height(as_is) == pytest.approx(1.05 * _height(model), abs=2)
    assert abs(_height(told) - _height(model)) <= 1
    assert _iou(told, model) > _iou(as_is, model) + 0.03
    assert told_place.scale == pytest.approx(place.scale / 1.05)
    np.testing.assert_allclose(told_place.floor, place.floor)
    assert (told_place.size, place.size) == (1.05, 1.0)
    with pytest.raises(InputError, match="size: the subject's size must be > 0"):
        the_view.normalise(mask, 0.0)


def test_the_anchor_is_the_trunk_column_over_the_lowest_pixel() -> None:
    the_view = view()
    mask = np.zeros((240, 320), dtype=bool)
    mask[100:200, 140:161] = True  # a trunk 21 px wide, centred on column 150
    mask[120:125, 100:220] = True  # outstretched arms do not move the anchor
    mask[200:230, 145:148] = True  # a leg reaching row 229
    place = the_view.placement(mask)
    np.testing.assert_allclose(place.anchor, [150.0, 229.0], atol=0.5)
    normalised, _ = the_view.normalise(mask)
    rows = np.flatnonzero(normalised.any(axis=1))
    assert abs(rows[-1] - the_view.home_pixel[1]) <= 1.0


def test_bad_silhouettes_raise_input_errors_naming_the_silhouette() -> None:
    the_view = view()
    good = _silhouette((0.0, 0.0, 0.0))
    above_horizon = np.zeros((240, 320), dtype=bool)
    above_horizon[10:40, 150:170] = True
    for bad, problem in (
        (np.zeros((240, 320), dtype=bool), "the mask is empty"),
        (good[:120], r"expected a \(240, 320\) bool mask, got \(120, 320\)"),
        (good.astype(np.uint8), "bool mask"),
        (above_horizon, "above the horizon"),
    ):
        for method in (the_view.placement, the_view.normalise):
            with pytest.raises(InputError, match=problem) as caught:
                method(bad)
            assert caught.value.source == "silhouette"
