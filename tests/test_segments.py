"""Segment distances: the point-to-segment shortcut against the general segment pair."""

from __future__ import annotations

import numpy as np
import pytest

from samba.body.segments import point_segment_distances, segment_distances


def test_point_segment_distances_equal_those_of_a_point_and_a_segment() -> None:
    rng = np.random.default_rng(3)
    points = rng.normal(size=(30, 3))
    starts = rng.normal(size=(5, 3))
    ends = starts + rng.normal(size=(5, 3))
    ends[1] = starts[1]  # a segment that is a point
    general = segment_distances(points[:, None], points[:, None], starts[None], ends[None])
    np.testing.assert_allclose(
        point_segment_distances(points[:, None], starts, ends), general, atol=1e-12
    )


def test_point_segment_distances_clamp_to_the_ends() -> None:
    start, end = np.array([[0.0, 0.0]]), np.array([[2.0, 0.0]])
    points = np.array([[1.0, 3.0], [-3.0, 4.0], [5.0, 0.0]])
    assert point_segment_distances(points[:, None], start, end)[:, 0] == pytest.approx(
        [3.0, 5.0, 3.0]
    )
