"""Labelling lost knee and foot markers by the legs' shape, both legs at once.

Label by label, two cameras cannot tell the legs apart: the knees stand at about the same
height, so each knee's blob in one camera lies on both knees' epipolar lines in the
other, every hypothesis of one knee has a rival of the other, and a foot has nothing to
be placed against while its knee is lost (`samba.markers.cross_view_labels`). Once both legs
are lost in every camera they stay lost while in plain view. Taken together the legs
have a shape: a shin keeps its length, so a knee and a foot belong together only at the
subject's shin length apart (`ShinMeter` measures it on the frames where both
triangulate), a knee is nearer its shoulder than its foot is, and the left knee and foot
stand to the left of the right ones across the shoulder line. Blobs paired the wrong way
across two cameras (ghosts, which lie in front of and behind the true markers) put both
knees on one line of sight, without that sideways gap.

`assign_legs` tries every way of giving the lost leg labels candidate points (pairs of
unlabelled blobs of two cameras that meet, or a label's remaining view with a blob of
another camera; each blob used once) and keeps the labels only when every way that fits
puts each of them at the same place: each shin within `shin_tolerance_m` of its length,
each knee within its standing distance (plus `reach_slack_m`, scaled to the measured
shins) of its shoulder and nearer it than its foot, and the left knee and foot at least
`side_margin_m` left of the right ones along the shoulder line. Legs side by side in the
line of sight, or a leg marker without a candidate, give no labels that frame. Legs
crossed over (the left foot right of the right one) are labelled as if they were not:
a crossed stance held while both legs are lost comes back swapped.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product

import numpy as np

from samba.body import N_MARKERS

LEGS: tuple[tuple[int, int, int], ...] = ((0, 4, 6), (1, 5, 7))
"""(shoulder, knee, foot) marker indices of the left and the right side."""
_SHOULDERS, _KNEES, _FEET = np.array(LEGS).T
LEG_MARKERS = np.sort(np.concatenate([_KNEES, _FEET]))
"""The knee and foot markers (4,), the ones `assign_legs` places."""
KNOWN = -1
"""`assign_legs`' choice for a marker it was not asked to place (triangulated already)."""


@dataclass(frozen=True)
class LegSettings:
    """Tolerances of `assign_legs`, meters: `shin_tolerance_m` on a shin's length,
    `reach_slack_m` beyond a knee's standing distance from its shoulder,
    `side_margin_m` the least sideways gap between the left and right knees and feet,
    and `same_m` how near two fitting assignments must put each label to agree."""

    shin_tolerance_m: float = 0.03
    reach_slack_m: float = 0.05
    side_margin_m: float = 0.05
    same_m: float = 0.05


@dataclass(frozen=True)
class LegBody:
    """The lengths `assign_legs` checks, meters: `shins` (2,) knee to foot and `reach`
    (2,) the farthest a knee gets from its shoulder, left then right."""

    shins: np.ndarray
    reach: np.ndarray

    @classmethod
    def from_markers(cls, standing: np.ndarray) -> LegBody:
        """The lengths of markers (8, 3) meters of a subject standing."""
        standing = np.asarray(standing, dtype=np.float64)
        return cls(
            shins=np.linalg.norm(standing[_KNEES] - standing[_FEET], axis=-1),
            reach=np.linalg.norm(standing[_SHOULDERS] - standing[_KNEES], axis=-1),
        )

    def scaled(self, shins: np.ndarray) -> LegBody:
        """The body with the `shins` (2,) meters measured on the subject (NaN: keep this
        one's) and its reach scaled by as much."""
        measured = np.where(np.isnan(shins), self.shins, shins)
        return LegBody(measured, self.reach * measured / self.shins)


class ShinMeter:
    """The subject's shin lengths, meters: the mean knee-to-foot distance (2,) of the
    frames whose knee and foot of a side triangulated (`add`); NaN before any."""

    def __init__(self) -> None:
        self._total = np.zeros(2)
        self._count = np.zeros(2)

    def add(self, current: np.ndarray) -> None:
        """Count a frame's triangulated markers (8, 3) meters, NaN where not."""
        shins = np.linalg.norm(current[_KNEES] - current[_FEET], axis=-1)
        seen = np.isfinite(shins)
        self._total[seen] += shins[seen]
        self._count[seen] += 1

    @property
    def shins(self) -> np.ndarray:
        """The mean shin lengths (2,) so far, left then right; NaN for a side not seen."""
        with np.errstate(invalid="ignore"):
            return self._total / self._count


def assign_legs(
    current: np.ndarray,
    points: np.ndarray,
    blobs: np.ndarray,
    allowed: np.ndarray,
    body: LegBody,
    settings: LegSettings | None = None,
) -> np.ndarray:
    """The candidate point given to each knee and foot label not triangulated, or none
    (see the module).

    `current` (8, 3) meters: the markers triangulated this frame (NaN where not); the
    shoulders must be among them. `points` (p, 3) meters: candidate points; `blobs` (c,
    p) the unlabelled blob of each camera each is made of (-1: none), so that no two
    labels share a blob; `allowed` (8, p) bool: the candidates each label may take (a
    knee or foot to place without one: nothing is placed). Returns (8,) the
    candidate index per label, `KNOWN` for a label not placed; all `KNOWN` when no
    assignment fits or when two that fit disagree.
    """
    s = settings or LegSettings()
    none = np.full(N_MARKERS, KNOWN)
    shoulders = current[_SHOULDERS]
    if not np.isfinite(shoulders).all() or len(points) == 0:
        return none
    across = shoulders[0] - shoulders[1]
    across[1] = 0.0
    if not np.linalg.norm(across) > 1e-6:
        return none
    across /= np.linalg.norm(across)
    sides = [_side_options(current, points, allowed, i, body, s) for i in range(2)]
    fitting = []
    for (left, left_at), (right, right_at) in product(*sides):
        chosen = np.concatenate([left, right])
        used = chosen[chosen >= 0]
        if not len(used) or len(set(used.tolist())) < len(used) or _share_blobs(blobs, used):
            continue
        gap = (left_at - right_at) @ across  # (2,): knees, feet
        if (gap >= s.side_margin_m).all():
            fitting.append((chosen, np.concatenate([left_at, right_at])))
    if not fitting:
        return none
    first = fitting[0][1]
    if any(np.linalg.norm(at - first, axis=-1).max() > s.same_m for _, at in fitting):
        return none
    out = none.copy()
    out[np.stack([_KNEES, _FEET], axis=1).ravel()] = fitting[0][0]
    return out


def _side_options(
    current: np.ndarray,
    points: np.ndarray,
    allowed: np.ndarray,
    side: int,
    body: LegBody,
    s: LegSettings,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The (knee, foot) choices of one side that fit: candidate indices (2,) (`KNOWN`
    where triangulated) and their positions (2, 3); a side with nothing to place keeps
    its triangulated knee and foot."""
    shoulder, knee, foot = LEGS[side]
    open_labels = np.isnan(current[[knee, foot]]).any(axis=-1)
    if not open_labels.any():
        return [(np.array([KNOWN, KNOWN]), current[[knee, foot]])]
    options = [
        np.flatnonzero(allowed[label]) if missing else np.array([KNOWN])
        for label, missing in zip((knee, foot), open_labels, strict=True)
    ]
    k, f = (grid.ravel() for grid in np.meshgrid(*options, indexing="ij"))
    knees = np.where((k >= 0)[:, None], points[k], current[knee])
    feet = np.where((f >= 0)[:, None], points[f], current[foot])
    shin = np.linalg.norm(knees - feet, axis=-1)
    reach = np.linalg.norm(knees - current[shoulder], axis=-1)
    fits = (
        (np.abs(shin - body.shins[side]) <= s.shin_tolerance_m)
        & (reach <= body.reach[side] + s.reach_slack_m)
        & (reach < np.linalg.norm(feet - current[shoulder], axis=-1))
        & ((k < 0) | (k != f))
    )
    return [(np.array([k[i], f[i]]), np.stack([knees[i], feet[i]])) for i in np.flatnonzero(fits)]


def _share_blobs(blobs: np.ndarray, chosen: np.ndarray) -> bool:
    """Whether candidates `chosen` (m,) use one blob of a camera twice (`blobs` (c, p))."""
    for camera in blobs:
        used = camera[chosen]
        used = used[used >= 0]
        if len(np.unique(used)) < len(used):
            return True
    return False
