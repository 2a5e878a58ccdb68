"""Distances between line segments, in any dimension, batched."""

from __future__ import annotations

import numpy as np

_TINY = 1e-18
"""Squared length below which a segment is a point."""


def segment_distances(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """Shortest distances (...) between segments p0-p1 and q0-q1, points (..., d).

    The closest-point method of Ericson (Real-Time Collision Detection, 5.1.9), clamped
    to both segments and broadcast over the leading axes; either segment may be a point.
    """
    d1, d2 = p1 - p0, q1 - q0
    offset = p0 - q0
    a = np.sum(d1 * d1, axis=-1)
    e = np.sum(d2 * d2, axis=-1)
    f = np.sum(d2 * offset, axis=-1)
    c = np.sum(d1 * offset, axis=-1)
    b = np.sum(d1 * d2, axis=-1)
    line_p, line_q = a > _TINY, e > _TINY
    safe_a, safe_e = np.where(line_p, a, 1.0), np.where(line_q, e, 1.0)
    denominator = a * e - b * b
    safe_denominator = np.where(denominator > _TINY, denominator, 1.0)
    s = np.where(denominator > _TINY, np.clip((b * f - c * e) / safe_denominator, 0.0, 1.0), 0.0)
    t = np.where(line_q, (b * s + f) / safe_e, 0.0)
    s = np.where(line_q & (t < 0.0), np.clip(-c / safe_a, 0.0, 1.0), s)
    s = np.where(line_q & (t > 1.0), np.clip((b - c) / safe_a, 0.0, 1.0), s)
    s = np.where(line_q, s, np.clip(-c / safe_a, 0.0, 1.0))  # q a point: nearest on p
    s = np.where(line_p, s, 0.0)
    t = np.where(line_p, np.clip(t, 0.0, 1.0), np.clip(f / safe_e, 0.0, 1.0))
    gap = p0 + d1 * s[..., None] - (q0 + d2 * t[..., None])
    return np.linalg.norm(gap, axis=-1)


def point_segment_distances(points: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """Distances (...) from points (..., d) to the segments p0-p1 (..., d), broadcast over
    the leading axes (points (n, 1, d) against segments (m, d) give (n, m)): the
    `segment_distances` of a point and a segment, with less work per pair."""
    step = p1 - p0
    offset = points - p0
    squared = np.maximum((step * step).sum(axis=-1), _TINY)
    along = np.clip((offset * step).sum(axis=-1) / squared, 0.0, 1.0)
    return np.linalg.norm(offset - along[..., None] * step, axis=-1)
