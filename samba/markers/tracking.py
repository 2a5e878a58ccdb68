"""Tracking the 8 marker labels in one camera: a nearest-neighbour filter with prediction.

The paper's camera node (Section 5.4) starts the labels from the standard pose, which the
subject holds at the start, and follows each marker with a nearest-neighbour filter.
`MarkerTracker` does that per camera, frame by frame, and never guesses between two
explanations that fit about equally well: it leaves the labels missing (NaN) instead.

A label is in one of four states. *Tracked*: it had its blob in the last frame; it is
predicted with constant velocity (alpha-beta filter, alpha = 1). *Coasting*: lost for at
most `coast_frames`; it keeps its velocity. *Searching*: lost for longer, up to
`max_lost_frames`; it keeps still relative to a neighbour on the body (`FOLLOWS`: a wrist
moves with its shoulder, a foot with its knee ...). *Abandoned*: lost for longer still;
only `reacquire` (found by other means, e.g. another camera's view) brings it back.
A label's gate is `gate_px` around its prediction, growing by `gate_growth_px` per lost
frame up to `max_gate_px`.

Blobs no label takes are followed from frame to frame as anonymous tracks, each with the
labels it may belong to: those whose gate held it, and for a blob that appeared from
nowhere every label lost beyond coasting or with no blob in its gate (its prediction
went astray: a foot kicked while hidden), passed on from frame to frame (merging tracks
pool them). Each frame:

1. the tracked labels take blobs by the smallest total distance (Hungarian, scipy); a
   pair (label, blob) stands unless another pair could swap blobs at nearly the same
   total distance or moves across its path (crossing markers and markers that meet and
   turn back look alike), another blob or a coasting label's prediction is nearly as
   close, or
   the blob continues an anonymous track nearly as well (a marker moving in where the
   label's own vanished);
2. the coasting labels take blobs left over, again by Hungarian; a pair stands only if
   no other label may own the blob and no other blob is nearly as close;
3. a searching label takes a blob left over when it is the only label without one and
   that blob is the only one in its gate.

"Nearly" is within `ambiguity_px` (plus the prediction slack of a lost label, growing
like its gate up to `max_slack_px`). Two markers crossing or merging in the image leave
both labels missing until they are apart again. A label on a blob the detector flags
as two markers merged (`samba.markers.detection.Blobs.merged`: a marker coming out from
behind another one whose label follows it) keeps following it but is not reported.
Output per frame: (8, 2) pixels (OpenCV convention), NaN = missing. Distances are pixels
for a 160x120 image with a 60-degree lens (focal length `REFERENCE_FOCAL_PX`);
`TrackerSettings.for_camera` scales them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields, replace

import numpy as np
from scipy.optimize import linear_sum_assignment

from samba.base import InputError
from samba.body import MARKER_NAMES, N_MARKERS, markers_of, segment_distances, standing_pose
from samba.cameras import Camera

REFERENCE_FOCAL_PX = 80.0 / np.tan(np.radians(30.0))
"""Focal length (px) of a 160-pixel-wide image with a 60-degree lens: the settings' scale."""
REFERENCE_DISTANCE_M = 6.0
"""How far from the camera (m) the reference pixels assume the subject at most: one
farther away looks smaller, and the distances shrink with it (`pixel_scale`). At 4 m,
the held-out and synthetic takes lost fewer markers still, but a martial-arts take's
kick put a knee's label on the foot's blob (one frame, two rows of four)."""


def pixel_scale(camera: Camera, distance_m: float | None = None) -> float:
    """Pixels of `camera` per reference pixel: its focal length over
    `REFERENCE_FOCAL_PX`, times `REFERENCE_DISTANCE_M` over the subject's `distance_m`
    from the camera when that is farther (None: not known), and at least 1 (a marker's
    blob is a few pixels wide whatever the distance)."""
    scale = float(camera.matrix[0, 0]) / REFERENCE_FOCAL_PX
    if distance_m is not None and distance_m > REFERENCE_DISTANCE_M:
        scale *= REFERENCE_DISTANCE_M / distance_m
    return max(scale, 1.0)


def subject_distance(camera: Camera, markers: np.ndarray) -> float:
    """How far (m) the mean of a subject's `markers` (n, 3) meters is from `camera`."""
    return float(np.linalg.norm(np.mean(markers, axis=0) - camera.center))


FOLLOWS: tuple[int, ...] = (1, 0, 0, 1, 0, 1, 4, 5)
"""The marker a searching marker moves with (marker order): the shoulders each other,
wrists and knees their shoulder, feet their knee. Parents come before their children."""

_UNREACHABLE = 1e9
"""Assignment cost of a label-blob pair that is not a candidate."""
_NO_BLOBS = np.zeros(0, dtype=np.int64)


@dataclass(frozen=True)
class TrackerSettings:
    """Gates, gains and time limits of `MarkerTracker`; distances in pixels.

    `gate_px`: how far from its prediction a tracked label may find its blob;
    `gate_growth_px`: gate growth per frame while a label is lost, up to `max_gate_px`;
    the same growth, up to `max_slack_px`, is how far off a lost label's prediction may
    be when it competes with others; `initial_gate_px`: the gate of the first frame,
    around the initial positions (the standard pose of an average body, not the
    subject's own); `ambiguity_px`: how much farther the runner-up blob or label must be
    than the chosen one; `velocity_gain`: the beta of the alpha-beta filter (1 = velocity
    from the last two positions); `coast_frames`: frames a lost label keeps its velocity;
    `max_lost_frames`: frames after which a lost label is abandoned. `guard_swaps`
    False turns the tracker into the paper's plain nearest-neighbour filter (every
    label takes its nearest blob in its gate, by Hungarian, and may swap), the baseline
    the guarded tracker is measured against.
    """

    gate_px: float = 3.0
    gate_growth_px: float = 0.5
    max_gate_px: float = 6.0
    max_slack_px: float = 1.5
    initial_gate_px: float = 6.0
    ambiguity_px: float = 1.0
    velocity_gain: float = 0.7
    coast_frames: int = 3
    max_lost_frames: int = 30
    guard_swaps: bool = True

    _DISTANCES = (
        "gate_px",
        "gate_growth_px",
        "max_gate_px",
        "max_slack_px",
        "initial_gate_px",
        "ambiguity_px",
    )

    def scaled(self, factor: float) -> TrackerSettings:
        """A copy with every distance multiplied by `factor` (gains and limits unchanged)."""
        if not factor > 0:
            raise ValueError(f"scale factor must be positive, got {factor}")
        return replace(self, **{name: getattr(self, name) * factor for name in self._DISTANCES})

    @classmethod
    def for_camera(
        cls, camera: Camera, distance_m: float | None = None, **overrides: float
    ) -> TrackerSettings:
        """The defaults (with `overrides`, distances in reference pixels) scaled to
        `camera` by `pixel_scale`, for a subject `distance_m` from it (None: not known)."""
        unknown = set(overrides) - {f.name for f in fields(cls)}
        if unknown:
            raise ValueError(f"unknown tracker settings: {', '.join(sorted(unknown))}")
        return cls(**overrides).scaled(pixel_scale(camera, distance_m))


@dataclass(frozen=True, eq=False)
class _Frame:
    """One step's view of the blobs: `distance` (8, m) pixels from each active label's
    prediction (inf for an abandoned label), `in_gate` (8, m), `track_distance` (a, m)
    from each anonymous track's prediction, `continues` (a, m) whether a blob continues
    a track, `owners` (m, 8) the labels each blob may belong to."""

    distance: np.ndarray
    in_gate: np.ndarray
    track_distance: np.ndarray
    continues: np.ndarray
    owners: np.ndarray


class MarkerTracker:
    """Keeps the 8 marker labels on the blobs of one camera's frames.

    `initial` (8, 2) pixels: where the labels are in the first frame (NaN: a label
    outside the image, which starts abandoned). Call `step` once per frame, in order.
    """

    def __init__(self, initial: np.ndarray, settings: TrackerSettings | None = None) -> None:
        initial = np.array(initial, dtype=np.float64)
        if initial.shape != (N_MARKERS, 2):
            raise InputError("initial", f"must be ({N_MARKERS}, 2) pixels, got {initial.shape}")
        self.settings = settings or TrackerSettings()
        unknown = np.isnan(initial).any(axis=-1)
        self._position = np.where(unknown[:, None], 0.0, initial)
        self._velocity = np.zeros((N_MARKERS, 2))
        self._last_seen = self._position.copy()
        self._lost = np.where(unknown, self.settings.max_lost_frames + 1, 0)
        self._first = True
        self._anonymous = np.zeros((0, 2))
        self._anonymous_velocity = np.zeros((0, 2))
        self._anonymous_moving = np.zeros(0, dtype=bool)
        self._owners = np.zeros((0, N_MARKERS), dtype=bool)

    @classmethod
    def from_standard_pose(
        cls,
        camera: Camera,
        position: Sequence[float] = (0.0, 0.0),
        heading_deg: float = 0.0,
        height: float = 1.70,
        settings: TrackerSettings | None = None,
    ) -> MarkerTracker:
        """Labels initialised from the standard pose of an average body of `height` m.

        The pose stands on the floor with its hip midpoint at `position` (x, z) meters,
        facing +Z turned by `heading_deg` about +Y (towards +X). Markers outside the image
        start abandoned. `settings` default to `TrackerSettings.for_camera` for the
        subject's distance there (`subject_distance`).
        """
        markers = markers_of(standing_pose(position, heading_deg, height))
        pixels = camera.project(markers)
        pixels[~camera.in_image(pixels)] = np.nan
        distance = subject_distance(camera, markers)
        return cls(pixels, settings or TrackerSettings.for_camera(camera, distance))

    @property
    def lost_frames(self) -> np.ndarray:
        """Frames (8,) int since each label last had a blob (0: found in the last frame)."""
        return self._lost.copy()

    @property
    def anonymous_blobs(self) -> np.ndarray:
        """The blobs (a, 2) pixels of the last frame that no label took."""
        return self._anonymous.copy()

    @property
    def anonymous_motion(self) -> np.ndarray:
        """How far each of `anonymous_blobs` moved since the frame before (a, 2)
        pixels, NaN for a blob that continues no anonymous track."""
        return np.where(self._anonymous_moving[:, None], self._anonymous_velocity, np.nan)

    def reacquire(self, label: int, pixel: Sequence[float]) -> None:
        """Put `label` (marker index) on `pixel` (u, v) of the last frame, found by other
        means (another camera's view): one of `anonymous_blobs`, whose track (and
        velocity) it takes over, or any point, where it starts at rest."""
        pixel = np.asarray(pixel, dtype=np.float64)
        _check_label(label)
        if pixel.shape != (2,) or not np.isfinite(pixel).all():
            raise InputError(MARKER_NAMES[label], f"pixel must be finite (u, v), got {pixel}")
        same = np.linalg.norm(self._anonymous - pixel, axis=-1) < 1e-6
        self._velocity[label] = self._anonymous_velocity[same][0] if same.any() else 0.0
        self._anonymous, self._anonymous_velocity = (
            self._anonymous[~same],
            self._anonymous_velocity[~same],
        )
        self._anonymous_moving = self._anonymous_moving[~same]
        self._owners = self._owners[~same]
        self._owners[:, label] = False
        self._position[label] = self._last_seen[label] = pixel
        self._lost[label] = 0

    def release(self, label: int) -> None:
        """Take `label` (marker index) off its blob: found wrong by other means (its other
        cameras' views meet elsewhere). It searches from the next frame on, as a label
        lost for longer than `coast_frames`, until it is found again (by elimination
        or `reacquire`) or abandoned."""
        _check_label(label)
        self._velocity[label] = 0.0
        self._lost[label] = max(self._lost[label], self.settings.coast_frames + 1)

    def step(self, centroids: np.ndarray, merged: np.ndarray | None = None) -> np.ndarray:
        """The labels' pixels (8, 2) in this frame from its blob centroids (m, 2), NaN =
        missing (lost or ambiguous). `merged` (m,) bool marks blobs that look like two
        markers merged (`Blobs.merged`): a label keeps following such a blob, but is
        not reported on it (its centroid is neither marker's)."""
        blobs = np.asarray(centroids, dtype=np.float64)
        if blobs.ndim != 2 or blobs.shape[1] != 2 or not np.isfinite(blobs).all():
            raise InputError("centroids", f"must be finite (m, 2) pixels, got {blobs.shape}")
        merged = np.zeros(len(blobs), dtype=bool) if merged is None else np.asarray(merged)
        if merged.shape != (len(blobs),) or merged.dtype != np.bool_:
            raise InputError(
                "merged", f"must be ({len(blobs)},) bool, got {merged.dtype} {merged.shape}"
            )
        s = self.settings
        predicted = self._position + self._velocity
        active = self._lost <= s.max_lost_frames
        tracked = active & (self._lost == 0)
        coasting = active & (self._lost <= s.coast_frames)
        searching = active & ~coasting
        if self._first:
            gate = np.full(N_MARKERS, s.initial_gate_px)
        else:
            gate = np.minimum(s.gate_px + s.gate_growth_px * self._lost, s.max_gate_px)
        slack = np.minimum(s.gate_growth_px * self._lost, s.max_slack_px)
        distance = np.where(active[:, None], _distances(predicted, blobs), np.inf)
        in_gate = distance <= gate[:, None]
        track_distance = _distances(self._anonymous + self._anonymous_velocity, blobs)
        continues = track_distance <= s.gate_px
        inherited = (continues[:, :, None] & self._owners[:, None, :]).any(axis=0)
        # a new blob may be any label whose whereabouts are unknown: lost beyond coasting,
        # or with no blob in its gate (its prediction went astray)
        born = ~continues.any(axis=0)
        unknown = ~coasting | ~in_gate.any(axis=1)
        owners = in_gate.T | inherited | (born[:, None] & unknown[None, :])
        frame = _Frame(distance, in_gate, track_distance, continues, owners)

        if not s.guard_swaps:  # the paper's filter: every label takes its nearest blob
            labels, chosen = _nearest_assignment(distance, in_gate)
            self._update_labels(predicted, blobs, labels, chosen)
            out = np.full((N_MARKERS, 2), np.nan)
            out[labels] = blobs[chosen]
            return out
        labels, chosen = _nearest_assignment(distance, in_gate & tracked[:, None])
        paths = (self._position[labels], blobs[chosen])  # where each moves from and to
        keep = _tracked_clear(frame, labels, chosen, paths, coasting, slack, s)
        labels, chosen = labels[keep], chosen[keep]
        free = np.ones(len(blobs), dtype=bool)
        free[chosen] = False
        candidate = in_gate & (coasting & ~tracked)[:, None] & free[None, :]
        returning, found = _nearest_assignment(distance, candidate)
        keep = _returning_clear(frame, returning, found, labels, free, slack, s)
        labels = np.concatenate([labels, returning[keep]])
        chosen = np.concatenate([chosen, found[keep]])
        free[found[keep]] = False
        unlabelled = np.ones(N_MARKERS, dtype=bool)
        unlabelled[labels] = False
        last = np.flatnonzero(unlabelled)
        if len(last) == 1 and searching[last[0]]:  # by elimination, if nothing else fits
            sole = in_gate[last[0]] & free
            if sole.sum() == 1 and not frame.owners[sole][0, labels].any():
                labels, chosen = np.append(labels, last), np.append(chosen, np.flatnonzero(sole))
        assigned = np.zeros(N_MARKERS, dtype=bool)
        assigned[labels] = True
        self._update_labels(predicted, blobs, labels, chosen)
        self._update_anonymous(blobs, chosen, frame, assigned)
        single = ~merged[chosen]
        out = np.full((N_MARKERS, 2), np.nan)
        out[labels[single]] = blobs[chosen[single]]
        return out

    def track(self, frames_centroids: Sequence[np.ndarray]) -> np.ndarray:
        """`step` over a sequence of per-frame centroids (m_f, 2); returns (F, 8, 2)."""
        return np.stack([self.step(c) for c in frames_centroids]).reshape(-1, N_MARKERS, 2)

    def _update_labels(
        self, predicted: np.ndarray, blobs: np.ndarray, labels: np.ndarray, chosen: np.ndarray
    ) -> None:
        s = self.settings
        found = np.zeros(N_MARKERS, dtype=bool)
        found[labels] = True
        measured = blobs[chosen]
        if not self._first:  # the initial positions are a guess, not a measurement
            returning = self._lost[labels] > 0
            # a returning label's velocity is its mean over the gap; a tracked one's filtered
            gap = (measured - self._last_seen[labels]) / (self._lost[labels, None] + 1)
            filtered = self._velocity[labels] + s.velocity_gain * (measured - predicted[labels])
            self._velocity[labels] = np.where(returning[:, None], gap, filtered)
        searching = ~found & (self._lost >= s.coast_frames)
        self._velocity[searching] = 0.0
        previous = self._position
        self._position = predicted.copy()
        self._position[labels] = measured
        for i in np.flatnonzero(searching):  # parents come before their children
            self._position[i] += self._position[FOLLOWS[i]] - previous[FOLLOWS[i]]
        self._last_seen[labels] = measured
        self._lost = np.where(found, 0, self._lost + 1)
        self._first = False

    def _update_anonymous(
        self, blobs: np.ndarray, chosen: np.ndarray, frame: _Frame, assigned: np.ndarray
    ) -> None:
        """Follow the blobs no label took: each continues the nearest anonymous track
        within the gate (taking its velocity) or starts one at rest, and keeps the labels
        it may belong to, minus those placed elsewhere."""
        unclaimed = np.ones(len(blobs), dtype=bool)
        unclaimed[chosen] = False
        velocity = np.zeros_like(blobs)
        continues = np.zeros(len(blobs), dtype=bool)
        if len(self._anonymous) and len(blobs):
            nearest = frame.track_distance.argmin(axis=0)
            continues = frame.continues[nearest, np.arange(len(blobs))]
            velocity[continues] = blobs[continues] - self._anonymous[nearest[continues]]
        self._anonymous = blobs[unclaimed]
        self._anonymous_velocity = velocity[unclaimed]
        self._anonymous_moving = continues[unclaimed]
        self._owners = frame.owners[unclaimed] & ~assigned


def _distances(points: np.ndarray, blobs: np.ndarray) -> np.ndarray:
    """Pairwise distances (n, m) between points (n, 2) and blobs (m, 2), pixels."""
    return np.hypot(points[:, None, 0] - blobs[None, :, 0], points[:, None, 1] - blobs[None, :, 1])


def _check_label(label: int) -> None:
    """`InputError` unless `label` is a marker index, 0..7."""
    if not 0 <= label < N_MARKERS:
        raise InputError("label", f"must be a marker index 0..{N_MARKERS - 1}, got {label}")


def _nearest_assignment(
    distance: np.ndarray, candidate: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Label and blob indices (p,), (p,): the minimum-total-distance assignment among the
    `candidate` (8, m) bool label-blob pairs; `distance` (8, m) pixels."""
    if not candidate.any():
        return _NO_BLOBS, _NO_BLOBS
    labels, chosen = linear_sum_assignment(np.where(candidate, distance, _UNREACHABLE))
    inside = candidate[labels, chosen]
    return labels[inside], chosen[inside]


def _tracked_clear(
    frame: _Frame,
    labels: np.ndarray,
    chosen: np.ndarray,
    paths: tuple[np.ndarray, np.ndarray],
    coasting: np.ndarray,
    slack: np.ndarray,
    settings: TrackerSettings,
) -> np.ndarray:
    """Which pairs (labels[p], chosen[p]) of tracked labels are unambiguous: bool (p,).

    With d the distances and a = `ambiguity_px`, pair (i, k) is ambiguous when another
    pair (j, l) could swap, d[i, l] + d[j, k] < d[i, k] + d[j, l] + a, or its path
    crosses: `paths` (from (p, 2), to (p, 2)), the moves from the labels' last positions
    to their blobs, come within a of each other (markers that cross and markers that meet
    and turn back look the same); another blob k' has d[i, k'] < d[i, k] + a; an
    unassigned coasting (or tracked) label j has d[j, k] < d[i, k] + a + slack[j]; or an
    anonymous track's prediction is within d[i, k] + a + `gate_px` of blob k (its
    velocity is rough).
    """
    a, d = settings.ambiguity_px, frame.distance
    pairs = np.arange(len(labels))
    own = d[labels, chosen]  # (p,)
    crossed = d[labels[:, None], chosen[None, :]]  # (p, p): d[i_p, k_q]
    swap = crossed + crossed.T < own[:, None] + own[None, :] + a
    swap |= _paths_meet(*paths, a)
    swap[pairs, pairs] = False
    rival_blob = d[labels] < (own + a)[:, None]  # (p, m)
    rival_blob[pairs, chosen] = False
    rival_label = coasting[:, None] & (d[:, chosen] < own + a + slack[:, None])  # (8, p)
    rival_label[labels] = False
    anonymous = frame.track_distance[:, chosen].min(axis=0, initial=np.inf)
    return (
        ~swap.any(axis=1)
        & ~rival_blob.any(axis=1)
        & ~rival_label.any(axis=0)
        & ~(anonymous < own + a + settings.gate_px)
    )


def _paths_meet(start: np.ndarray, end: np.ndarray, within: float) -> np.ndarray:
    """Whether the moves start -> end ((p, 2) each) of two labels come within `within`
    pixels of each other: bool (p, p), only pairs whose bounding circles are that close
    measured exactly."""
    middle, reach = (start + end) / 2.0, np.hypot(*(end - start).T) / 2.0
    close = _distances(middle, middle) <= reach[:, None] + reach[None, :] + within
    meet = np.zeros_like(close)
    i, j = np.nonzero(np.triu(close, 1))
    meet[i, j] = segment_distances(start[i], end[i], start[j], end[j]) < within
    return meet | meet.T


def _returning_clear(
    frame: _Frame,
    labels: np.ndarray,
    chosen: np.ndarray,
    assigned: np.ndarray,
    free: np.ndarray,
    slack: np.ndarray,
    settings: TrackerSettings,
) -> np.ndarray:
    """Which pairs (labels[p], chosen[p]) of coasting labels stand: bool (p,).

    Pair (i, k) stands when no label but i (and the `assigned` label indices) may own
    blob k and no other `free` (m,) blob is within d[i, k] + `ambiguity_px` + slack[i]
    of label i.
    """
    pairs = np.arange(len(labels))
    others = frame.owners[chosen].copy()  # (p, 8)
    others[pairs, labels] = False
    others[:, assigned] = False
    reach = frame.distance[labels, chosen] + settings.ambiguity_px + slack[labels]
    rival_blob = (frame.distance[labels] < reach[:, None]) & free[None, :]  # (p, m)
    rival_blob[pairs, chosen] = False
    return ~others.any(axis=1) & ~rival_blob.any(axis=1)
