"""Labelling lost markers again across cameras: epipolar geometry plus a 3D prediction.

A camera's tracker (`samba.markers.tracking`) drops a label rather than guess when two
markers cross or merge in its image, and in one image it cannot tell which of the blobs
that come apart again is which: the label stays lost while its marker is in plain view.
Several calibrated cameras can tell. `CrossViewLabeller.step` takes every camera's
labelled pixels and the blobs its tracker left unlabelled, and gives a lost label a blob
when one explanation fits and no other comes near:

* *hypotheses*: for a label lost in camera B but labelled in others, each unlabelled blob
  of B with the label's other views; for a label lost everywhere, each pair of
  unlabelled blobs of two cameras. Each is triangulated (DLT).
* a hypothesis *fits* when every view reprojects within `epipolar_px` (so the blob lies
  on the label's epipolar lines) and its 3D point is within the label's 3D gate of the
  label's prediction (with two views only, `gate_m`: two markers' blobs can meet by
  chance); it *comes near* with twice the reprojection tolerance and the gate plus
  `rival_margin_m`. A label lost for more than `FRESH_FRAMES` has no trusted prediction:
  a hypothesis fits when its point lies within the label's range from its `FOLLOWS`
  neighbour (`SHORTEST_SPAN` of the standing distance up to it plus `span_slack_m`), and
  comes near within `rival_margin_m` more. For a label triangulated in the frame before,
  a new blob whose tracker knows how it moved must also have moved as the label did,
  projected (within `motion_px`): a marker hidden behind another one projects onto that
  one's blob while the two move apart.
* a fitting hypothesis stands when every hypothesis of the same label that comes near
  puts the same blob in each of its new cameras, no hypothesis of another label that
  comes near uses any of its blobs, and no other label lost in its new cameras projects
  as near the blob (within `ambiguity_px`).

Knees and feet that no hypothesis above brings back (every knee's blob has the other
knee's as a rival when the two stand at one height, and a foot is placed against its
knee) are then labelled both legs at once by their shape (`samba.markers.leg_labels`): among the
unlabelled blobs' pairs (and a lone view paired with a blob), the one assignment whose
shins keep the subject's length and whose left leg stands left of the right one, found
again in the next frame (within `LEG_CONFIRM_M`); no blob is given that another marker
projects within `MERGED_FACTOR` times `ambiguity_px` of, unless that marker is a leg
label placed with it on a blob of its own (knees close in one camera).

A label is also dropped from a camera's output when its views disagree
(`_disagreeing`: a tracker that put it on another marker's blob; where the view meets
none of the label's other views while two of those meet, or two that meet have both
been held longer than it, `outvoted` names it, and the stage takes the tracker off that
blob; the other views then stand if they meet), or when a marker lost in that camera, but
triangulated from the others or lost for at most `FRESH_FRAMES`, projects within
`ambiguity_px` of its blob: the blob is probably both markers merged.

The prediction of a label is its last 3D position, moved with its `FOLLOWS` neighbour on
the body (as the tracker's searching labels are) while that neighbour is triangulated;
its gate is `gate_m`, growing by `gate_growth_m` per frame lost up to `max_gate_m`. The
labeller starts from the markers of the standard pose, where the subject stands when
capture starts. Pixels are each camera's raw (distorted) pixels; tolerances are pixels
of a 160-pixel-wide, 60-degree camera (`REFERENCE_FOCAL_PX`), scaled per camera; those
between markers (`ambiguity_px`, `motion_px`) also shrink for a subject starting farther
than `REFERENCE_DISTANCE_M` from the camera (`pixel_scale`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from samba.base import InputError
from samba.body import N_MARKERS
from samba.cameras import CameraGroup, Triangulation
from samba.markers.leg_labels import (
    KNOWN,
    LEG_MARKERS,
    LegBody,
    LegSettings,
    ShinMeter,
    assign_legs,
)
from samba.markers.tracking import FOLLOWS, REFERENCE_FOCAL_PX, pixel_scale, subject_distance

FRESH_FRAMES = 5
"""A marker lost for at most this many frames still has a position trusted enough to
drop a label whose blob it may have merged with."""
SHORTEST_SPAN: tuple[float, ...] = (0.9, 0.9, 0.15, 0.15, 0.4, 0.4, 0.9, 0.9)
"""The shortest distance of each marker from its `FOLLOWS` neighbour, as a fraction of
that distance in the standard pose: the shoulders' and a knee-to-foot distance hardly
change; a wrist comes close to its shoulder, a knee closer in a deep squat."""
RIVAL_ERROR_FACTOR = 2.0
"""A hypothesis comes near when it reprojects within this multiple of `epipolar_px`."""
LEG_CONFIRM_M = 0.15
"""The legs' labelling gives labels only when the frame before found the same labels
within this distance (m) of where it finds them now: a ghost that fits the shins in one
frame seldom fits again where the legs moved (without it a synthetic walk's left knee
went on a ghost of the two wrists' blobs, 64 label swaps); at 30 fps a foot moves up to
about 13 cm a frame."""
MERGED_FACTOR = 4.0
"""A label found by the legs' shape is not given a blob that another marker projects
within this multiple of `ambiguity_px` of: the blob may be both markers merged, or about
to be, and the camera's tracker may then follow the wrong one (at 2, without
`LEG_CONFIRM_M`, a wrist and a foot crossing in one camera swapped labels on a
martial-arts take with two cameras, 11 frames; 3 still did)."""


@dataclass(frozen=True)
class CrossViewSettings:
    """Tolerances of `CrossViewLabeller`: `epipolar_px` reprojection error and
    `ambiguity_px` how near a marker's projection makes a blob possibly its (reference
    pixels, scaled per camera; 1.0 before the legs' labelling, whose labels then kept a
    blob of two feet merged at 160x120); the 3D gate `gate_m`, growing by `gate_growth_m` per
    frame a label is lost up to `max_gate_m`; `rival_margin_m` how much farther than the
    gate a rival hypothesis still counts; `motion_px` how far (reference pixels) a
    blob's move since the frame before may differ from the label's, projected, for the
    blob to be that label's (None: not checked); `legs` the tolerances of labelling both
    legs' lost markers at once by their shape (`samba.markers.leg_labels`; None: not done)."""

    epipolar_px: float = 1.0
    ambiguity_px: float = 1.5
    gate_m: float = 0.10
    gate_growth_m: float = 0.02
    max_gate_m: float = 0.40
    rival_margin_m: float = 0.10
    reach_m: float = 1.0
    span_slack_m: float = 0.05
    motion_px: float | None = 0.5
    legs: LegSettings | None = field(default_factory=LegSettings)


@dataclass(frozen=True)
class Reacquisition:
    """Label `label` (marker index) of camera `camera` (index) put on `pixel` (u, v),
    raw pixels of the current frame."""

    camera: int
    label: int
    pixel: tuple[float, float]


@dataclass(frozen=True, eq=False)
class _Hypotheses:
    """Candidate explanations: `label` (h,), `pixels` (c, h, 2) raw, `blob` (c, h) the
    unlabelled blob each camera adds (-1: none, the label's own view or no view)."""

    label: np.ndarray
    pixels: np.ndarray
    blob: np.ndarray

    @property
    def new(self) -> np.ndarray:
        """(c, h) bool: the cameras where the hypothesis gives the lost label a blob."""
        return self.blob >= 0


class CrossViewLabeller:
    """Finds lost marker labels again from the views of several calibrated cameras.

    `cameras` the camera group; `initial` (8, 3) meters: where the markers are when
    capture starts (the standard pose where the subject stands). Call `step` once per
    frame, in order, after every camera's tracker stepped.
    """

    def __init__(
        self,
        cameras: CameraGroup,
        initial: np.ndarray,
        settings: CrossViewSettings | None = None,
    ) -> None:
        initial = np.array(initial, dtype=np.float64)
        if initial.shape != (N_MARKERS, 3) or not np.isfinite(initial).all():
            raise InputError("initial", f"must be finite ({N_MARKERS}, 3) meters")
        if len(cameras) < 2:
            raise InputError(
                "cameras", f"need at least 2 to label across views, got {len(cameras)}"
            )
        self.cameras = cameras
        self.settings = settings or CrossViewSettings()
        focal = np.array([camera.matrix[0, 0] for camera in cameras])
        self._tolerance = self.settings.epipolar_px * focal / REFERENCE_FOCAL_PX  # (c,)
        # distances between markers shrink with the subject's distance (`pixel_scale`)
        self._scale = np.array([pixel_scale(c, subject_distance(c, initial)) for c in cameras])
        self._ambiguity = self.settings.ambiguity_px * self._scale
        self._last = initial
        standing = np.linalg.norm(initial - initial[list(FOLLOWS)], axis=-1)
        self._span = np.stack(
            [standing * np.array(SHORTEST_SPAN), standing + self.settings.span_slack_m], axis=-1
        )
        self._lost = np.zeros(N_MARKERS, dtype=np.int64)
        self._body = LegBody.from_markers(initial)
        self._shins = ShinMeter()
        self._pending_legs = np.full((N_MARKERS, 3), np.nan)
        self._held = np.zeros((len(cameras), N_MARKERS), dtype=np.int64)
        self.outvoted = np.zeros((len(cameras), N_MARKERS), dtype=bool)
        """(c, 8) bool: the labels the last `step` dropped because their view meets none
        of the marker's other views while two of those meet, or is younger than two
        that meet (`_outvoted`): that camera's tracker follows a wrong blob."""

    def predicted(self, current: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each label's position (8, 3) meters in this frame and its 3D gate (8,) meters,
        given the markers triangulated now `current` (8, 3), NaN where not: a label not
        triangulated is where it was last, moved as its `FOLLOWS` neighbour moved since."""
        s = self.settings
        now = current.copy()
        for i in np.flatnonzero(np.isnan(current).any(axis=-1)):  # parents come first
            parent = FOLLOWS[i]
            moved = now[parent] - self._last[parent]
            now[i] = self._last[i] + np.where(np.isnan(moved), 0.0, moved)
        gate = np.minimum(s.gate_m + s.gate_growth_m * self._lost, s.max_gate_m)
        return now, gate

    def step(
        self,
        labelled: np.ndarray,
        unlabelled: Sequence[np.ndarray],
        motion: Sequence[np.ndarray] | None = None,
    ) -> tuple[np.ndarray, list[Reacquisition]]:
        """Lost labels found again in this frame.

        `labelled` (c, 8, 2) raw pixels of each camera's tracked labels, NaN = lost;
        `unlabelled` per camera the (k_c, 2) raw pixels of blobs its tracker left without a
        label; `motion` per camera how far each of those blobs moved since the frame
        before (k_c, 2) pixels, NaN where not known (`MarkerTracker.anonymous_motion`).
        Returns the labels with the ones found filled in (c, 8, 2), and what was found
        (to hand back to the trackers with `MarkerTracker.reacquire`).
        """
        c = len(self.cameras)
        labelled = np.array(labelled, dtype=np.float64)
        if labelled.shape != (c, N_MARKERS, 2):
            raise InputError(
                "labelled", f"must be ({c}, {N_MARKERS}, 2) pixels, got {labelled.shape}"
            )
        if len(unlabelled) != c:
            raise InputError(
                "unlabelled", f"must hold one blob array per camera ({c}), got {len(unlabelled)}"
            )
        blobs = [np.asarray(b, dtype=np.float64).reshape(-1, 2) for b in unlabelled]
        moves = [
            np.asarray(m, dtype=np.float64).reshape(-1, 2)
            for m in (motion if motion is not None else [np.full_like(b, np.nan) for b in blobs])
        ]
        if [len(m) for m in moves] != [len(b) for b in blobs]:
            raise InputError("motion", "must hold one (k, 2) array per camera, like unlabelled")
        self._held = np.where(np.isnan(labelled).any(axis=-1), 0, self._held + 1)
        current = self._triangulate(labelled).points
        prediction, gate = self.predicted(current)
        hypotheses = _hypotheses(labelled, blobs)
        found: list[Reacquisition] = []
        if len(hypotheses.label):
            views = self._triangulate(hypotheses.pixels)
            fits, near = self._judge(hypotheses, views, current, prediction, gate)
            fits &= self._moving_along(hypotheses, views.points, moves, current)
            fits &= self._clear_of_others(hypotheses, labelled, prediction)
            for h in np.flatnonzero(_standing(hypotheses, fits, near)):
                label = int(hypotheses.label[h])
                for camera in np.flatnonzero(hypotheses.new[:, h]):
                    if np.isnan(labelled[camera, label]).any():  # pairs may repeat a view
                        u, v = hypotheses.pixels[camera, h]
                        labelled[camera, label] = (u, v)
                        found.append(Reacquisition(int(camera), label, (float(u), float(v))))
            if found:
                current = self._triangulate(labelled).points
        if self.settings.legs is not None:
            legs = self._legs(labelled, blobs, current, prediction, self.settings.legs)
            if legs:
                found += legs
                current = self._triangulate(labelled).points
        fresh = np.where((self._lost <= FRESH_FRAMES)[:, None], prediction, np.nan)
        positions = np.where(np.isnan(current), fresh, current)
        self._remember(current, prediction)
        disagreeing = self._disagreeing(labelled)
        self.outvoted = self._outvoted(labelled, disagreeing.any(axis=0))
        if self.outvoted.any():  # the views left may meet now
            labelled[self.outvoted] = np.nan
            disagreeing = self._disagreeing(labelled)
        labelled[self._merged(labelled, positions) | disagreeing] = np.nan
        self._held[np.isnan(labelled).any(axis=-1)] = 0  # a view dropped starts again
        return labelled, found

    def _legs(
        self,
        labelled: np.ndarray,
        blobs: list[np.ndarray],
        current: np.ndarray,
        prediction: np.ndarray,
        settings: LegSettings,
    ) -> list[Reacquisition]:
        """Knee and foot labels not triangulated found by the legs' shape
        (`samba.markers.leg_labels.assign_legs`) in the blobs still unlabelled (`labelled` (c, 8,
        2) raw pixels, filled in place): a label lost in every camera among the pairs of
        those blobs of two cameras, a label seen in one camera among its view paired with
        one of them; pairs that meet within `epipolar_px`. Only an assignment the frame
        before found too (within `LEG_CONFIRM_M`) gives labels. `current` (8, 3) the
        markers triangulated now, `prediction` (8, 3) where the others are predicted
        (`predicted`; trusted for `FRESH_FRAMES`): a label is not given a blob another
        marker may be merged with (`_near_other`; the labels placed together on blobs of
        their own do not count); `settings` those of `assign_legs`."""
        pending, self._pending_legs = self._pending_legs, np.full((N_MARKERS, 3), np.nan)
        views = ~np.isnan(labelled).any(axis=-1)  # (c, 8)
        lost = np.isnan(current[LEG_MARKERS]).any(axis=-1) & (views[:, LEG_MARKERS].sum(0) < 2)
        open_legs = LEG_MARKERS[lost]
        if not len(open_legs):
            return []
        free = [
            b[~(b[:, None] == labelled[camera][None]).all(axis=-1).any(axis=1)]
            for camera, b in enumerate(blobs)
        ]
        pixels, index = _blob_pairs(free)
        owner = np.full(pixels.shape[1], -1)  # -1: any label lost everywhere
        for label in open_legs[views[:, open_legs].any(axis=0)]:
            pix, idx = _view_pairs(labelled[:, label], free)
            pixels = np.concatenate([pixels, pix], axis=1)
            index = np.concatenate([index, idx], axis=1)
            owner = np.concatenate([owner, np.full(idx.shape[1], label)])
        if not pixels.shape[1]:
            return []
        result = self._triangulate(pixels)
        meet = np.nanmax(result.view_error / self._tolerance[:, None], axis=0) <= 1.0
        lost_everywhere = ~views.any(axis=0)
        allowed = np.where(
            owner < 0, lost_everywhere[:, None], np.arange(N_MARKERS)[:, None] == owner
        )
        points, index = result.points[meet], index[:, meet]
        body = self._body.scaled(self._shins.shins)
        choice = assign_legs(current, points, index, allowed[:, meet], body, settings)
        placed = np.flatnonzero(choice != KNOWN)
        fresh = np.where((self._lost <= FRESH_FRAMES)[:, None], prediction, np.nan)
        positions = np.where(np.isnan(current), fresh, current)
        positions[placed] = points[choice[placed]]
        self._pending_legs[placed] = positions[placed]
        with np.errstate(invalid="ignore"):
            moved = np.linalg.norm(positions[placed] - pending[placed], axis=-1)
        if not (moved <= LEG_CONFIRM_M).all():
            return []
        projected = self.cameras.project(positions)  # (c, 8, 2)
        blob_of = np.full((len(self.cameras), N_MARKERS), -1)
        blob_of[:, placed] = index[:, choice[placed]]  # (c, 8): each placed label's blob
        found = []
        for label in placed:
            taken = [
                (camera, free[camera][blob])
                for camera, blob in enumerate(blob_of[:, label])
                if blob >= 0
            ]
            # a label placed with this one on a blob of its own there is no merge
            apart = (blob_of >= 0) & (blob_of != blob_of[:, [label]])  # (c, 8)
            if any(
                self._near_other(projected[camera], label, pixel, camera, apart[camera])
                for camera, pixel in taken
            ):
                continue
            for camera, (u, v) in taken:
                labelled[camera, label] = (u, v)
                found.append(Reacquisition(camera, int(label), (float(u), float(v))))
        return found

    def _near_other(
        self,
        projected: np.ndarray,
        label: int,
        pixel: np.ndarray,
        camera: int,
        apart: np.ndarray,
    ) -> bool:
        """Whether a marker other than `label` and those `apart` (8,) bool (on blobs of
        their own) projects (`projected` (8, 2) raw pixels of `camera`) within
        `MERGED_FACTOR` times `ambiguity_px` of the blob at `pixel` (2,): the blob may be
        both markers merged."""
        others = ~apart
        others[label] = False
        gap = np.linalg.norm(projected[others] - pixel, axis=-1)
        with np.errstate(invalid="ignore"):
            return bool((gap < MERGED_FACTOR * self._ambiguity[camera]).any())

    def _triangulate(self, raw: np.ndarray, gate_px: float | None = None) -> Triangulation:
        """Triangulation of raw pixels (c, n, 2) with the views' errors in pixels; views
        off by more than `gate_px` dropped, worst first (`Triangulation.from_views`)."""
        return Triangulation.from_views(
            self.cameras.projections, self.cameras.undistort(raw), gate_px=gate_px
        )

    def _judge(
        self,
        hypotheses: _Hypotheses,
        result: Triangulation,
        current: np.ndarray,
        prediction: np.ndarray,
        gate: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Which hypotheses (h,) fit, and which come near (both bool), given their
        triangulation `result`."""
        label, margin = hypotheses.label, self.settings.rival_margin_m
        ratio = np.nanmax(result.view_error / self._tolerance[:, None], axis=0)  # (h,)
        off = np.linalg.norm(result.points - prediction[label], axis=-1)
        limit = gate[label]
        reach = np.where(self._lost[label] > 0, self.settings.reach_m, limit)
        span = np.linalg.norm(result.points - current[np.array(FOLLOWS)[label]], axis=-1)
        low, high = self._span[label, 0], self._span[label, 1]
        stale = self._lost[label] > FRESH_FRAMES
        with np.errstate(invalid="ignore"):
            in_body = np.where(np.isnan(span), False, (span >= low) & (span <= high))
            near_body = np.where(
                np.isnan(span), True, (span >= low - margin) & (span <= high + margin)
            )
            # two views can meet by chance (a ghost): near a fresh prediction only within
            # the first gate; a stale label, in either case, within its body range
            two_views = (~np.isnan(hypotheses.pixels).any(axis=-1)).sum(axis=0) == 2
            fresh_limit = np.where(two_views, self.settings.gate_m, limit)
            fits = (ratio <= 1.0) & np.where(stale, in_body, off <= fresh_limit)
            near = (ratio <= RIVAL_ERROR_FACTOR) & np.where(
                stale, near_body, off <= np.maximum(reach, limit + margin)
            )
        return fits, near

    def _moving_along(
        self,
        hypotheses: _Hypotheses,
        points: np.ndarray,
        moves: list[np.ndarray],
        current: np.ndarray,
    ) -> np.ndarray:
        """Which hypotheses (h,) of labels triangulated in the frame before have each new
        blob moving as the label does, projected into that camera (within `motion_px`;
        blobs whose move is not known pass): a marker hidden behind another one projects
        onto that one's blob, but the two move apart. The label's move is from where it
        was to where its other views put it now (`current` (8, 3)), else the
        hypothesis's point (`points` (h, 3))."""
        h = len(hypotheses.label)
        if self.settings.motion_px is None:
            return np.ones(h, dtype=bool)
        label = hypotheses.label
        moved = np.full((len(self.cameras), h, 2), np.nan)
        for camera, blob in enumerate(hypotheses.blob):
            new = blob >= 0
            moved[camera, new] = moves[camera][blob[new]]
        points = np.where(np.isnan(current[label]), points, current[label])
        expected = self.cameras.project(points) - self.cameras.project(self._last[label])
        limit = self.settings.motion_px * self._scale
        with np.errstate(invalid="ignore"):
            off = np.linalg.norm(moved - expected, axis=-1) > limit[:, None]  # (c, h)
        return ~(off.any(axis=0) & (self._lost[label] == 0))

    def _clear_of_others(
        self, hypotheses: _Hypotheses, labelled: np.ndarray, positions: np.ndarray
    ) -> np.ndarray:
        """Which hypotheses (h,) have no other label lost in one of their new cameras
        whose position `positions` (8, 3) projects as near the blob (within
        `ambiguity_px` more) as their own label's: such a blob may be the other marker's,
        or both markers merged."""
        projected = self.cameras.project(positions)  # (c, 8, 2)
        lost = np.isnan(labelled).any(axis=-1)  # (c, 8)
        to_blob = np.linalg.norm(projected[:, None] - hypotheses.pixels[:, :, None], axis=-1)
        to_blob = np.where(np.isnan(to_blob), np.inf, to_blob)  # (c, h, 8)
        h = np.arange(len(hypotheses.label))
        own = to_blob[:, h, hypotheses.label]  # (c, h)
        rival = lost[:, None, :] & (to_blob < (own + self._ambiguity[:, None])[..., None])
        rival[:, h, hypotheses.label] = False
        return ~(rival.any(axis=-1) & hypotheses.new).any(axis=0)

    def _disagreeing(self, labelled: np.ndarray) -> np.ndarray:
        """Labels (c, 8) bool whose views do not meet in one point: a view left more than
        `RIVAL_ERROR_FACTOR` times `epipolar_px` off after the worst views are dropped
        (while two remain), and both views of a label seen twice that disagree so."""
        limit = RIVAL_ERROR_FACTOR * self._tolerance[:, None]
        result = self._triangulate(labelled, gate_px=float(limit.max()))
        seen = ~np.isnan(labelled).any(axis=-1)
        off = seen & (~result.views | (result.view_error > limit))
        pair = result.views.sum(axis=0) == 2
        return off | (seen & (pair & off.any(axis=0))[None, :])

    def _outvoted(self, labelled: np.ndarray, disagree: np.ndarray) -> np.ndarray:
        """Labels (c, 8) bool, of the markers whose views `disagree` (8,) bool, whose view
        meets none of the marker's other views (within `RIVAL_ERROR_FACTOR` times
        `epipolar_px`, two views at a time) while two of those others meet: that
        camera's tracker is on a wrong blob. A view that meets one other view is not
        outvoted by geometry alone (one pair may be a ghost), only when two views that
        meet have both been given out for more frames in a row than it (a view dropped
        starts counting again: a tracker that jumped to another marker's blob keeps its
        label, but its view disagrees then): markers at one height make every pair
        meet, and a label just put on a blob of a marker hiding its own (a subject
        turning side-on) is the likelier mistake."""
        c = len(self.cameras)
        outvoted = np.zeros((c, N_MARKERS), dtype=bool)
        markers = np.flatnonzero(disagree)
        if c < 3 or not len(markers):
            return outvoted
        pairs = list(combinations(range(c), 2))
        views = np.full((c, len(pairs), len(markers), 2), np.nan)
        for p, (a, b) in enumerate(pairs):
            views[a, p], views[b, p] = labelled[a, markers], labelled[b, markers]
        error = self._triangulate(views.reshape(c, -1, 2)).view_error.reshape(c, len(pairs), -1)
        with np.errstate(invalid="ignore"):
            close = error <= RIVAL_ERROR_FACTOR * self._tolerance[:, None, None]
        met = np.stack([close[a, p] & close[b, p] for p, (a, b) in enumerate(pairs)])  # (P, m)
        seen = ~np.isnan(labelled[:, markers]).any(axis=-1)
        held = self._held[:, markers]
        for camera in range(c):
            own = np.array([camera in pair for pair in pairs])
            older = np.stack(
                [(held[a] > held[camera]) & (held[b] > held[camera]) for a, b in pairs]
            )
            lone = ~met[own].any(axis=0) & met[~own].any(axis=0)
            younger = (met & older)[~own].any(axis=0)
            outvoted[camera, markers] = seen[camera] & (lone | younger)
        return outvoted

    def _merged(self, labelled: np.ndarray, positions: np.ndarray) -> np.ndarray:
        """Labels (c, 8) bool whose blob is probably two markers merged: a marker lost in
        that camera whose position (`positions` (8, 3), NaN where unknown) projects
        within `ambiguity_px` of it."""
        projected = self.cameras.project(positions)  # (c, 8, 2)
        lost = np.isnan(labelled).any(axis=-1) & ~np.isnan(projected).any(axis=-1)  # (c, 8)
        gap = np.linalg.norm(labelled[:, :, None] - projected[:, None], axis=-1)  # (c, L, M)
        with np.errstate(invalid="ignore"):
            near = (gap < self._ambiguity[:, None, None]) & lost[:, None, :]
        return near.any(axis=-1)

    def _remember(self, current: np.ndarray, prediction: np.ndarray) -> None:
        """Keep this frame's positions (triangulated, else predicted) for the next one."""
        seen = ~np.isnan(current).any(axis=-1)
        self._shins.add(current)
        self._last = np.where(seen[:, None], current, prediction)
        self._lost = np.where(seen, 0, self._lost + 1)


def _hypotheses(labelled: np.ndarray, blobs: list[np.ndarray]) -> _Hypotheses:
    """Every candidate explanation of a lost label by unlabelled blobs (see the module
    docstring): a blob in a camera where the label is lost, with the label's other views;
    or, for a label lost in every camera, a blob in each of two cameras."""
    c = len(blobs)
    lost = np.isnan(labelled).any(axis=-1)  # (c, 8)
    labels, pixels, indices = [], [], []
    for label in range(N_MARKERS):
        if lost[:, label].all():
            pix, idx = _blob_pairs(blobs)
            labels.append(np.full(idx.shape[1], label))
            pixels.append(pix)
            indices.append(idx)
            continue
        pix, idx = _view_pairs(labelled[:, label], blobs)
        labels.append(np.full(idx.shape[1], label))
        pixels.append(pix)
        indices.append(idx)
    if not labels:
        return _Hypotheses(np.zeros(0, int), np.zeros((c, 0, 2)), np.zeros((c, 0), int))
    return _Hypotheses(
        np.concatenate(labels), np.concatenate(pixels, axis=1), np.concatenate(indices, axis=1)
    )


def _blob_pairs(blobs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Every pair of blobs of two cameras, from per-camera blobs (k_c, 2) raw pixels: their
    pixels (c, h, 2), NaN in the other cameras, and their blob indices (c, h), -1 there."""
    c = len(blobs)
    pixels, indices = [np.zeros((c, 0, 2))], [np.zeros((c, 0), dtype=np.int64)]
    for a, b in combinations(range(c), 2):
        ia, ib = np.meshgrid(np.arange(len(blobs[a])), np.arange(len(blobs[b])))
        ia, ib = ia.ravel(), ib.ravel()
        pix = np.full((c, len(ia), 2), np.nan)
        pix[a], pix[b] = blobs[a][ia], blobs[b][ib]
        idx = np.full((c, len(ia)), -1)
        idx[a], idx[b] = ia, ib
        pixels.append(pix)
        indices.append(idx)
    return np.concatenate(pixels, axis=1), np.concatenate(indices, axis=1)


def _view_pairs(view: np.ndarray, blobs: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """A label's views `view` (c, 2) raw pixels (NaN in the cameras that lost it) with
    each blob (k_c, 2) of one camera that lost it: pixels (c, h, 2) and the blob indices
    (c, h), -1 in the cameras without a new blob."""
    c = len(blobs)
    seen = np.flatnonzero(~np.isnan(view).any(axis=-1))
    pixels, indices = [np.zeros((c, 0, 2))], [np.zeros((c, 0), dtype=np.int64)]
    for camera in range(c):
        if camera in seen:
            continue
        k = len(blobs[camera])
        pix = np.repeat(view[:, None], k, axis=1)
        pix[camera] = blobs[camera]
        idx = np.full((c, k), -1)
        idx[camera] = np.arange(k)
        pixels.append(pix)
        indices.append(idx)
    return np.concatenate(pixels, axis=1), np.concatenate(indices, axis=1)


def _standing(hypotheses: _Hypotheses, fits: np.ndarray, near: np.ndarray) -> np.ndarray:
    """Which fitting hypotheses stand (h,) bool: every near hypothesis of the same label
    agrees on the blob of each camera it shares, and no near hypothesis of another label
    uses one of its blobs."""
    label, blob = hypotheses.label, hypotheses.blob  # (h,), (c, h)
    same_label = label[:, None] == label[None, :]  # (h, h)
    # blob[:, h] vs blob[:, g] in cameras both use: disagree / share
    both = (blob[:, :, None] >= 0) & (blob[:, None, :] >= 0)  # (c, h, g)
    equal = blob[:, :, None] == blob[:, None, :]
    disagree = (both & ~equal).any(axis=0)
    share = (both & equal).any(axis=0)
    conflict = (same_label & disagree) | (~same_label & share)
    conflict &= near[None, :]
    return fits & ~conflict.any(axis=1)
