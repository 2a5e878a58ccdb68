"""The pose index's compiled scan (`samba.db.kernels.scan_kernel`) finds what its numpy
reference (`_Tree._scan`) and brute force find: the same rows at the same distances, for
full and masked marker tables, single queries and batches."""

from __future__ import annotations

import numpy as np
import pytest

from samba.base import kernels_enabled
from samba.body import align_markers
from samba.db.index import PoseIndex, marker_features
from samba.synthetic.motions import library

pytestmark = pytest.mark.skipif(
    not kernels_enabled(), reason="numba kernels are off (SAMBA_KERNELS=numpy or no numba)"
)


@pytest.fixture(scope="module")
def index() -> PoseIndex:
    """An index of the synthetic motions (about 2,000 poses)."""
    return PoseIndex.build(np.concatenate([t.poses for t in library(2, 4.0)]))


@pytest.mark.parametrize("batch", [1, 7, 130])
@pytest.mark.parametrize("missing", [(), (3,), (2, 6)])
def test_scan_kernel_agrees_with_numpy_and_brute_force(
    index: PoseIndex, batch: int, missing: tuple[int, ...], monkeypatch: pytest.MonkeyPatch
) -> None:
    rng = np.random.default_rng(batch)
    poses = index.poses[rng.integers(0, len(index), batch)]
    markers = poses[:, [1, 2, 5, 6, 9, 10, 11, 12]] + rng.normal(0.0, 0.02, (batch, 8, 3))
    markers[:, list(missing)] = np.nan
    distances, rows = index.query(markers, k=10)
    monkeypatch.setenv("SAMBA_KERNELS", "numpy")
    expected_distances, expected_rows = index.query(markers, k=10)
    np.testing.assert_allclose(distances, expected_distances, rtol=1e-12)  # sums reordered
    # Rows agree but for ties (the synthetic motions repeat poses): each row found is at
    # the distance reported, recomputed from the features.
    assert (rows == expected_rows).mean() > 0.5
    keep = ~np.isnan(markers[0]).any(axis=-1)
    table = marker_features(index.poses, keep, False)
    query = align_markers(markers)[0][:, keep].reshape(batch, -1).astype(np.float32)
    found = np.linalg.norm((table[rows] - query[:, None]).astype(np.float64), axis=-1)
    np.testing.assert_allclose(found, distances, rtol=1e-12)
    index.scan_limit = 0  # the cells' search, exact: brute force's answer
    try:
        index.query(markers, k=10)
        index.wait_for_masked_tables()
        cell_distances, _ = index.query(markers, k=10)
    finally:
        index.scan_limit = len(index)
    np.testing.assert_allclose(distances, cell_distances, rtol=1e-12)


@pytest.mark.parametrize("eps", [0.0, 0.5])
def test_cells_are_exact_and_eps_bounds_the_error(index: PoseIndex, eps: float) -> None:
    # Masked tables too are searched by cells once the index is larger than the scan
    # limit: from the full table's cells until the mask's own are made in the background
    # (exact up to the float32 rounding of the features), then from those.
    rng = np.random.default_rng(11)
    markers = index.poses[rng.integers(0, len(index), 60)][:, [1, 2, 5, 6, 9, 10, 11, 12]]
    markers = markers + rng.normal(0.0, 0.03, markers.shape)
    markers[::2, 4] = np.nan
    markers[1::4, 0] = np.nan  # a shoulder lost: the heading comes from the knees
    truth, _ = index.query(markers, k=10)  # the full table's cells and the masked scans
    index.scan_limit = 0
    try:
        first, _ = index.query(markers, k=10)
        index.wait_for_masked_tables()
        found, _ = index.query(markers, k=10, eps=eps)
        one_by_one = np.array([index.query(m, k=10, eps=eps)[0] for m in markers])
    finally:
        index.scan_limit = len(index)
    np.testing.assert_allclose(first, truth, rtol=0, atol=1e-6)
    np.testing.assert_allclose(one_by_one, found, rtol=1e-12)  # a live frame's single call
    if eps == 0:
        np.testing.assert_allclose(found, truth, rtol=1e-12)
    else:
        assert np.all(found <= truth * (1 + eps) + 1e-12)
        assert np.mean(np.isclose(found, truth, rtol=1e-12)) > 0.9


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("missing", [(3,), (0, 6), (0, 1)])
def test_masked_features_kernel_agrees_with_numpy(
    index: PoseIndex, dtype: type, missing: tuple[int, ...]
) -> None:
    from samba.db.kernels import marker_features_kernel

    keep = np.ones(8, dtype=bool)
    keep[list(missing)] = False
    poses = np.asarray(index.poses, dtype=dtype)
    for scale in (False, True):
        got = marker_features_kernel(poses, keep, scale)
        expected = marker_features(poses, keep, scale)
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6)


@pytest.mark.parametrize("scale_by_tibia", [False, True])
def test_masks_the_full_cells_cannot_answer_wait_for_their_tables(scale_by_tibia: bool) -> None:
    # Without a left/right pair (heading from the world) or, scaled by tibia, without a
    # knee, the full table's features do not give the masked ones: the query waits for
    # the mask's table and answers as the masked scan does.
    poses = np.concatenate([t.poses for t in library(1, 3.0)])
    index = PoseIndex.build(poses, scale_by_tibia=scale_by_tibia)
    rng = np.random.default_rng(5)
    markers = poses[rng.integers(0, len(poses), 12)][:, [1, 2, 5, 6, 9, 10, 11, 12]]
    markers = markers + rng.normal(0.0, 0.02, markers.shape)
    markers[:6, [1, 3, 5, 7]] = np.nan  # one side only: no pair
    markers[6:, 4] = np.nan  # a knee lost
    truth = index.query(markers, k=5)
    index.scan_limit = 0
    found = index.query(markers, k=5)
    waited = slice(None) if scale_by_tibia else slice(0, 6)  # unscaled, a knee is projected
    np.testing.assert_allclose(found[0][waited], truth[0][waited], rtol=1e-12)
    np.testing.assert_allclose(found[0], truth[0], rtol=0, atol=1e-6)


def test_observations_are_aligned_as_numpy_aligns_them() -> None:
    from samba.db.kernels import aligned_markers_kernel

    rng = np.random.default_rng(3)
    markers = rng.normal(0.0, 0.5, (40, 8, 3))
    markers[::3, 0] = np.nan  # a shoulder lost: centroid origin, heading from the knees
    markers[1::5, [2, 5]] = np.nan
    markers[2::7, [1, 3, 5, 7]] = np.nan  # no pair: no heading
    for scale in (False, True):
        expected, _ = align_markers(markers, scale_by_tibia=scale)
        np.testing.assert_allclose(
            aligned_markers_kernel(markers, scale), expected, rtol=0, atol=1e-12
        )
