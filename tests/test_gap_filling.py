"""Gap filling of marker trajectories: short inner gaps interpolated, others left."""

from __future__ import annotations

import numpy as np

from samba.markers import fill_gaps


def test_short_inner_gaps_are_interpolated_and_the_others_left_missing() -> None:
    t = np.arange(100, dtype=np.float64)
    markers = np.stack([np.stack([t, 2 * t, -t], axis=-1), np.stack([t, t, t], axis=-1)], axis=1)
    holed = markers.copy()
    holed[10:15, 0] = np.nan  # 5 frames: filled
    holed[40:71, 0] = np.nan  # 31 frames: too long
    holed[:3, 1] = np.nan  # at the start: nothing to interpolate from
    holed[97:, 1] = np.nan  # at the end
    holed[50, 1, 2] = np.nan  # one coordinate gone is the marker gone
    filled, mask = fill_gaps(holed, longest=30)
    assert np.allclose(filled[10:15, 0], markers[10:15, 0])  # a straight line comes back
    assert np.allclose(filled[50, 1], markers[50, 1])
    assert np.isnan(filled[40:71, 0]).all() and np.isnan(filled[:3, 1]).all()
    assert np.isnan(filled[97:, 1]).all()
    expected = np.zeros((100, 2), dtype=bool)
    expected[10:15, 0] = expected[50, 1] = True
    assert np.array_equal(mask, expected)
    assert np.array_equal(filled[~np.isnan(holed).any(-1)], holed[~np.isnan(holed).any(-1)])
