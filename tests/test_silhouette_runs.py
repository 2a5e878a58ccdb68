"""Tests of `samba.silhouette.runs`: silhouettes stored as runs, compared in O(runs)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from samba.base.errors import InputError
from samba.silhouette.distance import DISTANCES, SilhouetteWeights
from samba.silhouette.runs import RowSums, SilhouetteRuns

SIZE = (80, 60)


def _shapes(count: int, seed: int, size: tuple[int, int] = SIZE) -> np.ndarray:
    """Random silhouettes (count, H, W) bool drawn with OpenCV: ellipses, thick lines
    and polygons, with holes; silhouette 0 is empty, silhouette 1 fills the right
    border column, silhouette 2 touches the left border and the bottom row."""
    rng = np.random.default_rng(seed)
    width, height = size
    masks = np.zeros((count, height, width), dtype=np.uint8)
    for image in masks[3:]:
        for _ in range(rng.integers(1, 5)):
            centre = (int(rng.integers(0, width)), int(rng.integers(0, height)))
            axes = (int(rng.integers(1, width // 3)), int(rng.integers(1, height // 3)))
            cv2.ellipse(image, centre, axes, float(rng.uniform(0, 180)), 0, 360, 1, -1)
        start, end = rng.integers(0, [width, height], size=(2, 2))
        cv2.line(image, tuple(map(int, start)), tuple(map(int, end)), 1, int(rng.integers(1, 6)))
        polygon = rng.integers(0, [width, height], size=(5, 2)).astype(np.int32)
        cv2.fillPoly(image, [polygon], 1)
        hole = (int(rng.integers(0, width)), int(rng.integers(0, height)))
        cv2.circle(image, hole, int(rng.integers(1, 6)), 0, -1)
    masks[1, 5:40, width - 12 :] = 1
    masks[1, 20, :] = 1
    cv2.rectangle(masks[2], (0, height // 2), (9, height - 1), 1, -1)
    return masks.astype(bool)


@pytest.fixture(scope="module")
def masks() -> np.ndarray:
    """30 random silhouettes of `SIZE`, as `_shapes` draws them."""
    return _shapes(30, seed=4)


def test_masks_round_trip_exactly(masks: np.ndarray) -> None:
    runs = SilhouetteRuns.from_masks(masks)
    assert len(runs) == len(masks)
    assert runs.size == SIZE
    assert not masks[0].any() and masks[1][:, -1].any() and masks[2][-1, 0]
    np.testing.assert_array_equal(runs.to_masks(), masks)


def test_top_rows_are_each_silhouettes_first_row(masks: np.ndarray) -> None:
    with_empty = np.concatenate([masks[:3], np.zeros_like(masks[:1]), masks[3:]])
    tops = SilhouetteRuns.from_masks(with_empty).top_rows()
    expected = [np.flatnonzero(m.any(axis=1))[0] if m.any() else m.shape[0] for m in with_empty]
    np.testing.assert_array_equal(tops, expected)
    assert tops[3] == with_empty.shape[1]  # an empty one: the image height


def test_one_run_per_horizontal_stretch_of_foreground() -> None:
    mask = np.zeros((1, 4, 10), dtype=bool)
    mask[0, 0, 2:5] = True  # one run
    mask[0, 2, [0, 1, 5, 9]] = True  # three runs, the last at the right border
    runs = SilhouetteRuns.from_masks(mask)
    assert len(runs.starts) == 4
    assert runs.nbytes == runs.offsets.nbytes + 8 * 4
    np.testing.assert_array_equal(runs.to_masks(), mask)


@pytest.mark.parametrize("kind", DISTANCES)
def test_distances_equal_the_dense_weighted_xor(masks: np.ndarray, kind: str) -> None:
    runs = SilhouetteRuns.from_masks(masks)
    for observed in (masks[3], masks[1], masks[2]):
        weights = SilhouetteWeights.from_mask(observed, kind)
        expected = weights.distances(masks)
        got = runs.distances(RowSums.from_weights(weights))
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)
        assert got[0] == pytest.approx(weights.constant / observed.size)  # empty model


def test_distances_of_chosen_silhouettes_in_any_order(masks: np.ndarray) -> None:
    runs = SilhouetteRuns.from_masks(masks)
    sums = RowSums.from_weights(SilhouetteWeights.from_mask(masks[5], "normalised"))
    everything = runs.distances(sums)
    picked = np.array([7, 0, 0, 29, 3, 7, 1])
    np.testing.assert_allclose(runs.distances(sums, picked), everything[picked], rtol=1e-12)
    assert runs.distances(sums, np.array([0, 0])) == pytest.approx([everything[0]] * 2)
    assert runs.distances(sums, np.zeros(0, dtype=int)).shape == (0,)


def test_subset_and_concatenate_agree_with_the_masks(masks: np.ndarray) -> None:
    runs = SilhouetteRuns.from_masks(masks)
    picked = np.array([4, 0, 4, 29, 1])
    np.testing.assert_array_equal(runs.subset(picked).to_masks(), masks[picked])
    assert len(runs.subset(np.zeros(0, dtype=int))) == 0
    parts = [runs.subset(np.arange(0, 10)), runs.subset(np.arange(10, 30))]
    joined = SilhouetteRuns.concatenate(parts)
    np.testing.assert_array_equal(joined.offsets, runs.offsets)
    np.testing.assert_array_equal(joined.starts, runs.starts)
    np.testing.assert_array_equal(joined.ends, runs.ends)
    other = SilhouetteRuns.from_masks(_shapes(6, seed=9))
    both = SilhouetteRuns.concatenate([runs.subset(picked), other])
    np.testing.assert_array_equal(both.to_masks()[len(picked) :], other.to_masks())
    sums = RowSums.from_weights(SilhouetteWeights.from_mask(masks[8], "core"))
    np.testing.assert_allclose(
        both.distances(sums), np.concatenate([runs.distances(sums, picked), other.distances(sums)])
    )


def test_concatenate_needs_run_sets_of_one_size(masks: np.ndarray) -> None:
    runs = SilhouetteRuns.from_masks(masks)
    smaller = SilhouetteRuns.from_masks(_shapes(3, seed=1, size=(40, 30)))
    with pytest.raises(ValueError, match="one size"):
        SilhouetteRuns.concatenate([runs, smaller])
    with pytest.raises(ValueError, match="one or more"):
        SilhouetteRuns.concatenate([])


def test_bad_inputs_raise_input_errors(masks: np.ndarray) -> None:
    with pytest.raises(InputError, match="silhouettes"):
        SilhouetteRuns.from_masks(masks.astype(np.uint8))
    with pytest.raises(InputError, match="silhouettes"):
        SilhouetteRuns.from_masks(masks[0])
    runs = SilhouetteRuns.from_masks(masks)
    other_size = np.zeros((30, 40), dtype=bool)
    other_size[10:20, 10:20] = True
    sums = RowSums.from_weights(SilhouetteWeights.from_mask(other_size, "xor"))
    with pytest.raises(InputError, match=r"silhouettes: size \(80, 60\)"):
        runs.distances(sums)
