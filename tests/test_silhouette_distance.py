"""Tests of the silhouette distances `samba.silhouette.distance` (Okada et al., Sec. 2.2)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy import ndimage, sparse

from samba.base.errors import InputError
from samba.silhouette.distance import (
    CORE_ALPHA,
    DISTANCES,
    SilhouetteWeights,
    downsampled,
    model_weighted_distances,
    shape_skeleton,
    silhouette_matrix,
)

SIZE = (320, 240)
TORSO = (136, 60, 184, 150)
"""Torso rectangle x0, y0, x1, y1 in pixels: 49 px wide."""
TORSO_WIDTH = TORSO[2] - TORSO[0] + 1
ARM_WIDTH = 11
"""Width of the arms in pixels (rectangles drawn along their axes)."""
ARM_LENGTH = 90
SHOULDER = np.array([TORSO[0] + 4, TORSO[1] + 6])
"""(u, v) where the left-of-image arm leaves the torso; the other arm mirrors it."""


def _arm_end(arm_deg: float, side: int) -> np.ndarray:
    """The hand (u, v) of the arm on `side` (-1 left of the torso, +1 right) raised
    20 + arm_deg degrees below horizontal."""
    angle = np.radians(20.0 + arm_deg)
    start = _shoulder(side)
    return start + ARM_LENGTH * np.array([side * np.cos(angle), np.sin(angle)])


def _shoulder(side: int) -> np.ndarray:
    """(u, v) of the shoulder on `side` (-1 left of the torso, +1 right)."""
    return SHOULDER if side < 0 else np.array([2 * 160 - SHOULDER[0], SHOULDER[1]])


def figure(arm_deg: float = 0.0, shift: tuple[int, int] = (0, 0)) -> np.ndarray:
    """A person silhouette (240, 320) bool: rectangular torso and neck, round head,
    capsule legs 15 px thick and rectangular arms `ARM_WIDTH` px wide; the left-of-image
    arm rotated by `arm_deg` (degrees, downwards) and the whole figure shifted by
    `shift` (du, dv) pixels."""
    image = np.zeros(SIZE[::-1], np.uint8)
    du, dv = shift
    offset = np.array(shift)
    x0, y0, x1, y1 = TORSO
    cv2.rectangle(image, (x0 + du, y0 + dv), (x1 + du, y1 + dv), 1, -1)
    cv2.circle(image, (160 + du, 38 + dv), 15, 1, -1)
    cv2.rectangle(image, (154 + du, 45 + dv), (166 + du, 60 + dv), 1, -1)
    for top, foot in (((148, 148), (140, 228)), ((172, 148), (180, 228))):
        cv2.line(image, (top[0] + du, top[1] + dv), (foot[0] + du, foot[1] + dv), 1, 15)
    for side, angle in ((-1, arm_deg), (1, 0.0)):
        start, end = _shoulder(side) + offset, _arm_end(angle, side) + offset
        along = (end - start) / ARM_LENGTH
        across = np.array([-along[1], along[0]]) * (ARM_WIDTH - 1) / 2
        corners = np.stack([start + across, end + across, end - across, start - across])
        cv2.fillConvexPoly(image, np.rint(corners).astype(np.int32), 1)
    return image.astype(bool)


def _ridge_weight(weights: np.ndarray, points: np.ndarray) -> float:
    """Median over `points` (m, 2) (u, v) of the largest weight within 2 px: the weight
    on the skeleton across a body part whose axis passes through the points."""
    grown = ndimage.maximum_filter(weights, size=5)
    u, v = np.rint(points).astype(int).T
    return float(np.median(grown[v, u]))


def _axis_points(start: np.ndarray, end: np.ndarray, first: float, last: float) -> np.ndarray:
    """Points (20, 2) on the segment start-end from fraction `first` to `last`."""
    t = np.linspace(first, last, 20)[:, None]
    return start + t * (end - start)


ARM_AXIS = _axis_points(_shoulder(-1), _arm_end(0.0, -1), 0.35, 0.85)
TORSO_AXIS = _axis_points(np.array([160, 95]), np.array([160, 115]), 0.0, 1.0)


def _naive_distance(observed: np.ndarray, model: np.ndarray, weights: np.ndarray) -> float:
    """Eq. 5 pixel by pixel: the mean over the image of the weights where the two differ."""
    height, width = observed.shape
    total = 0.0
    for y in range(height):
        for x in range(width):
            if observed[y, x] != model[y, x]:
                total += float(weights[y, x])
    return total / (height * width)


@pytest.mark.parametrize("kind", DISTANCES)
def test_identical_silhouettes_are_at_distance_zero(kind: str) -> None:
    observed = figure()
    weights = SilhouetteWeights.from_mask(observed, kind)
    dense = weights.distances(observed[None])
    assert dense.shape == (1,) and abs(dense[0]) < 1e-12
    one_pixel = weights.distances(figure(shift=(1, 0))[None])[0]
    assert one_pixel > 0
    assert abs(weights.distances(silhouette_matrix(observed[None]))[0]) < 1e-2 * one_pixel


def test_xor_is_the_symmetric_fraction_of_differing_pixels() -> None:
    a, b = figure(), figure(arm_deg=25.0, shift=(3, -2))
    ab = SilhouetteWeights.from_mask(a, "xor").distances(b[None])[0]
    ba = SilhouetteWeights.from_mask(b, "xor").distances(a[None])[0]
    assert ab == pytest.approx(ba, abs=1e-15)
    assert ab == pytest.approx(np.count_nonzero(a != b) / a.size, abs=1e-15)


@pytest.mark.parametrize("shift", [(0, 0), (0, 25)])
def test_weights_follow_the_papers_distance_transforms(shift: tuple[int, int]) -> None:
    """Core weights (Eq. 6) are D(S_i) + 5 D(S_i bar) with exact Euclidean transforms
    (D(S_i) zero inside, D(S_i bar) zero outside; the image border, which cuts the legs
    of the shifted figure, is no contour); the normalised weights (Eq. 7) share the
    outside term and peak at alpha~ = 25 (320 px wide) inside."""
    observed = figure(shift=shift)
    weights = SilhouetteWeights.from_mask(observed, "core").weights
    outside = ndimage.distance_transform_edt(~observed)  # zero inside
    inside = ndimage.distance_transform_edt(observed)  # zero outside
    assert np.abs(weights - (outside + CORE_ALPHA * inside)).max() < 1e-3
    normalised = SilhouetteWeights.from_mask(observed, "normalised")
    assert normalised.alpha == pytest.approx(25.0)
    assert np.abs(normalised.weights - outside)[~observed].max() < 1e-3
    assert normalised.weights[observed].max() == pytest.approx(25.0)


@pytest.mark.parametrize("kind", DISTANCES)
def test_dense_sparse_and_a_pixel_loop_agree(kind: str) -> None:
    pyramid = downsampled(
        np.stack([figure(), figure(30.0), figure(shift=(4, 2)), figure(-15.0, (-6, 0))]), (80, 60)
    )
    observed, models = pyramid[0], pyramid[1:]
    weights = SilhouetteWeights.from_mask(observed, kind)
    dense = weights.distances(models)
    from_sparse = weights.distances(silhouette_matrix(models))
    as_float64 = weights.distances(sparse.csr_array(models.reshape(3, -1).astype(np.float64)))
    naive = [_naive_distance(observed, model, weights.weights) for model in models]
    assert dense.dtype == np.float64 and dense.shape == (3,)
    assert np.allclose(dense, naive, rtol=1e-9, atol=0)
    assert np.allclose(as_float64, naive, rtol=1e-9, atol=0)
    assert np.allclose(from_sparse, naive, rtol=1e-5, atol=0)


def test_normalised_weights_are_equal_on_the_skeleton_of_arms_and_torso() -> None:
    observed = figure()
    core = SilhouetteWeights.from_mask(observed, "core").weights
    normalised = SilhouetteWeights.from_mask(observed, "normalised").weights
    arm, torso = _ridge_weight(normalised, ARM_AXIS), _ridge_weight(normalised, TORSO_AXIS)
    assert arm == pytest.approx(torso, rel=0.10)
    ratio = _ridge_weight(core, TORSO_AXIS) / _ridge_weight(core, ARM_AXIS)
    assert ratio == pytest.approx(TORSO_WIDTH / ARM_WIDTH, rel=0.15)


def test_a_misplaced_arm_weighs_more_under_the_normalised_distance() -> None:
    """The paper's point: relative to a body shifted by 2 px, an arm 30 degrees off
    costs more under "normalised" than under "core", so the limbs weigh in."""
    observed = figure()
    models = np.stack([figure(arm_deg=30.0), figure(shift=(2, 0))])
    ratios = {}
    for kind in DISTANCES:
        arm, shifted = SilhouetteWeights.from_mask(observed, kind).distances(models)
        ratios[kind] = arm / shifted
    print("arm 30 deg off / body 2 px off:", {k: round(float(r), 2) for k, r in ratios.items()})
    assert ratios["normalised"] > 1.2 * ratios["core"]


@pytest.mark.parametrize("size", [(320, 240), (160, 120)])
def test_every_limb_has_a_skeleton(size: tuple[int, int]) -> None:
    """Skeleton pixels lie within 1.5 px of most of each arm's axis, and of each leg's."""
    scale = size[0] / SIZE[0]
    mask = downsampled(figure(), size)
    skeleton = shape_skeleton(mask)
    near = ndimage.distance_transform_edt(~skeleton) <= 1.5 + 0.5 * (scale < 1)
    limbs = {
        "left arm": (_shoulder(-1), _arm_end(0.0, -1)),
        "right arm": (_shoulder(1), _arm_end(0.0, 1)),
        "left leg": (np.array([148, 148]), np.array([140, 228])),
        "right leg": (np.array([172, 148]), np.array([180, 228])),
    }
    for name, (start, end) in limbs.items():
        points = _axis_points(start, end, 0.35, 0.85) * scale + (scale - 1) / 2
        u, v = np.rint(points).astype(int).T
        assert near[v, u].mean() >= 0.9, name
    assert skeleton.sum() < 0.2 * mask.sum()


def test_silhouette_matrix_rows_are_the_flattened_silhouettes() -> None:
    masks = np.stack([figure(), figure(45.0), np.zeros(SIZE[::-1], bool)])
    matrix = silhouette_matrix(masks)
    assert isinstance(matrix, sparse.csr_array)
    assert matrix.shape == (3, SIZE[0] * SIZE[1]) and matrix.dtype == np.float32
    assert matrix.nnz == masks.sum()
    assert np.array_equal(matrix.toarray(), masks.reshape(3, -1).astype(np.float32))


def test_downsampled_pyramid_keeps_area_and_half_covered_pixels() -> None:
    mask = figure()
    for size in ((160, 120), (80, 60)):
        small = downsampled(mask[None], size)
        assert small.shape == (1, size[1], size[0]) and small.dtype == bool
        scale = (SIZE[0] / size[0]) ** 2
        assert small.sum() * scale == pytest.approx(mask.sum(), rel=0.08)
    block = np.zeros((8, 8), bool)
    block[:2, :] = True  # the top 4x4 blocks are half covered
    block[4, 4] = True  # a quarter of one pixel of the bottom-right block
    assert np.array_equal(downsampled(block, (2, 2)), [[True, True], [False, False]])


@pytest.mark.parametrize("kind", DISTANCES)
def test_model_weighted_distances_weigh_the_xor_by_each_models_own_map(kind: str) -> None:
    observed = figure()
    models = np.stack([figure(30.0), figure(shift=(4, 2)), figure(-15.0, (-6, 0)), figure()])
    each = [SilhouetteWeights.from_mask(m, kind).distances(observed[None])[0] for m in models]
    np.testing.assert_allclose(model_weighted_distances(models, observed, kind), each, rtol=1e-6)
    assert model_weighted_distances(models[3:], observed, kind)[0] == 0.0


def test_bad_inputs_raise_typed_errors() -> None:
    observed = figure()
    weights = SilhouetteWeights.from_mask(observed)
    cases = {
        "models": lambda: weights.distances(downsampled(observed[None], (80, 60))),
        "models ": lambda: weights.distances(silhouette_matrix(observed[None, ::2])),
        "models  ": lambda: weights.distances(observed),
        "mask": lambda: SilhouetteWeights.from_mask(np.zeros((240, 320), bool)),
        "mask ": lambda: SilhouetteWeights.from_mask(np.ones((240, 320), bool)),
        "mask  ": lambda: SilhouetteWeights.from_mask(observed.astype(np.uint8)),
        "kind": lambda: SilhouetteWeights.from_mask(observed, "hamming"),
        "alpha": lambda: SilhouetteWeights.from_mask(observed, "core", alpha=-1.0),
        "alpha ": lambda: SilhouetteWeights.from_mask(observed, "xor", alpha=5.0),
        "masks": lambda: silhouette_matrix(observed),
        "size": lambda: downsampled(observed, (640, 480)),
        "models   ": lambda: model_weighted_distances(np.zeros((1, 240, 320), bool), observed),
        "observed": lambda: model_weighted_distances(observed[None], observed.astype(np.uint8)),
        "models    ": lambda: model_weighted_distances(observed[None], observed[::2]),
    }
    for name, call in cases.items():
        with pytest.raises(InputError) as error:
            call()
        assert error.value.source == name.strip()
