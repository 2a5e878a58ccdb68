"""Canonical alignment of marker sets, shared by the pose index and the reconstruction.

An observation of the 8 markers is moved into the database frame by

    p_canonical = scale * R_y(yaw) @ (p_world - origin)

where `origin` is the centroid of the markers present (or, with `shoulder_origin`, the
midpoint of the shoulder markers when both are present), `yaw` turns the subject about +Y
so that its left-right line points along +X (the subject faces +Z), and `scale`
optionally brings the tibia (knee-to-foot) length to `REFERENCE_TIBIA`. The left-right
line comes from the first complete marker pair in `HEADING_PAIRS` (shoulders, then knees,
feet, wrists); with no complete pair, yaw is 0.

Everything here is computable from the 8 markers alone and works with missing markers
(NaN): applying the same function to database poses with the same markers masked gives
features that are directly comparable to an observation's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from samba.body.skeleton import N_MARKERS

HEADING_PAIRS: tuple[tuple[int, int], ...] = ((0, 1), (4, 5), (6, 7), (2, 3))
"""(left, right) marker pairs tried in order for the heading: shoulders, knees, feet, wrists."""
_LEFT = np.array([pair[0] for pair in HEADING_PAIRS])
_RIGHT = np.array([pair[1] for pair in HEADING_PAIRS])
TIBIA_PAIRS: tuple[tuple[int, int], ...] = ((4, 6), (5, 7))
"""(knee, foot) marker index pairs whose lengths give the tibia."""
REFERENCE_TIBIA = 0.45
"""Tibia length in meters that scale-normalised features are brought to."""


@dataclass(frozen=True)
class Alignment:
    """A batch of world-to-canonical transforms, one per observation.

    `origin` (n, 3) meters, `yaw` (n,) radians about +Y, `scale` (n,) dimensionless.
    Build one with `from_markers`; move points with `apply` (world to canonical) and
    `invert` (canonical to world). Observations with no marker present get a NaN origin.
    """

    origin: np.ndarray
    yaw: np.ndarray
    scale: np.ndarray

    @classmethod
    def from_markers(
        cls, markers: np.ndarray, scale_by_tibia: bool = False, shoulder_origin: bool = False
    ) -> Alignment:
        """The alignment of marker sets (n, 8, 3) in meters, NaN for missing markers.

        `shoulder_origin` puts the origin at the shoulder midpoint of the sets with both
        shoulder markers (the others keep the centroid): a database pose placed by it
        has its shoulders, and so its head, where the observation has them."""
        markers = _as_batch(markers)
        missing = np.isnan(markers)
        if missing.any():
            origin, yaw = _partial_origin_and_yaw(markers, ~missing.any(axis=-1))
        else:
            origin = np.add.reduce(markers, axis=1) * (1.0 / N_MARKERS)
            line = markers[:, 0] - markers[:, 1]
            yaw = np.arctan2(line[:, 2], line[:, 0])
        if shoulder_origin:
            midpoint = 0.5 * (markers[:, 0] + markers[:, 1])
            both = ~np.isnan(midpoint).any(axis=1)
            origin = np.where(both[:, None], midpoint, origin)
        scale = np.ones(len(markers))
        if scale_by_tibia:
            lengths = np.stack(
                [np.linalg.norm(markers[:, k] - markers[:, f], axis=-1) for k, f in TIBIA_PAIRS],
                axis=1,
            )
            known = ~np.isnan(lengths)
            n_known = known.sum(axis=1)
            mean = np.where(known, lengths, 0.0).sum(axis=1) / np.maximum(n_known, 1)
            ok = (n_known > 0) & (mean > 1e-6)
            scale[ok] = REFERENCE_TIBIA / mean[ok]
        return cls(origin=origin, yaw=yaw, scale=scale)

    def __len__(self) -> int:
        return len(self.yaw)

    def _turn(self, factor: np.ndarray, transpose: bool) -> np.ndarray:
        """(n, 3, 3) matrices M with points @ M = factor * R_y(yaw) points, for rows of
        points (n, m, 3); `transpose` gives R_y(-yaw) instead."""
        c, s = np.cos(self.yaw) * factor, np.sin(self.yaw) * factor
        turn = np.zeros((len(self.yaw), 3, 3))
        turn[:, 0, 0] = turn[:, 2, 2] = c
        turn[:, 1, 1] = factor
        minus, plus = ((2, 0), (0, 2)) if transpose else ((0, 2), (2, 0))
        turn[:, minus[0], minus[1]] = -s
        turn[:, plus[0], plus[1]] = s
        return turn

    @property
    def rotation(self) -> np.ndarray:
        """(n, 3, 3) the turn R_y(yaw) as matrices acting on column vectors: canonical
        points are scale * rotation @ (world point - origin)."""
        return self._turn(np.ones(len(self.yaw)), transpose=True)

    def apply(self, points: np.ndarray) -> np.ndarray:
        """World points (n, m, 3) to the canonical frame (n, m, 3); NaN stays NaN."""
        moved = np.asarray(points, dtype=np.float64) - self.origin[:, None, :]
        return np.matmul(moved, self._turn(self.scale, transpose=False))

    def invert(self, points: np.ndarray) -> np.ndarray:
        """Canonical points (n, m, 3) back to the world frame (n, m, 3)."""
        turned = np.matmul(points, self._turn(1.0 / self.scale, transpose=True))
        return turned + self.origin[:, None, :]


def has_heading(present: np.ndarray) -> np.ndarray:
    """Whether each marker set, given which of its markers are present (n, 8) bool, has a
    complete pair of `HEADING_PAIRS` to set its heading: (n,) bool."""
    return (present[:, _LEFT] & present[:, _RIGHT]).any(axis=1)


def align_markers(
    markers: np.ndarray, scale_by_tibia: bool = False
) -> tuple[np.ndarray, Alignment]:
    """Markers (n, 8, 3) or (8, 3) in the canonical frame, same shape, with their `Alignment`."""
    markers = np.asarray(markers, dtype=np.float64)
    batch = _as_batch(markers)
    alignment = Alignment.from_markers(batch, scale_by_tibia=scale_by_tibia)
    aligned = alignment.apply(batch)
    return (aligned[0] if markers.ndim == 2 else aligned), alignment


def _partial_origin_and_yaw(
    markers: np.ndarray, present: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Centroid of the present markers (n, 3) and yaw (n,) from the first complete pair."""
    count = np.add.reduce(present, axis=1)
    filled = np.where(present[..., None], markers, 0.0)
    origin = np.add.reduce(filled, axis=1) / np.maximum(count, 1)[:, None]
    origin[count == 0] = np.nan
    complete = present[:, _LEFT] & present[:, _RIGHT]  # (n, pairs)
    first = complete.argmax(axis=1)
    rows = np.arange(len(markers))
    line = filled[rows, _LEFT[first]] - filled[rows, _RIGHT[first]]
    yaw = np.arctan2(line[:, 2], line[:, 0])
    yaw[~complete[rows, first]] = 0.0
    return origin, yaw


def _as_batch(markers: np.ndarray) -> np.ndarray:
    markers = np.asarray(markers, dtype=np.float64)
    if markers.ndim == 2:
        markers = markers[None]
    if markers.ndim != 3 or markers.shape[1:] != (N_MARKERS, 3):
        raise ValueError(f"markers must be (n, 8, 3) or (8, 3), got {markers.shape}")
    return markers
