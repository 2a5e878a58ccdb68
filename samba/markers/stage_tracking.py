"""Keeping the 8 marker labels in every camera of a capture stage at once.

`StageTracker` steps one `samba.markers.tracking.MarkerTracker` per camera on that
camera's blobs and then, unless cross-view labelling is off, the
`samba.markers.cross_view_labels.CrossViewLabeller` on the blobs the trackers left unlabelled
(with how they moved), handing the labels it finds back to the
trackers and taking a tracker off a blob where two other cameras see that label
elsewhere (`MarkerTracker.release`): a tracker that followed a marker's blob after its
own marker was hidden would otherwise keep the wrong label once those views are lost.
The offline camera chain (`samba.markers.camera_chain`) and the live server's
labelling (`samba.service.frame_pipeline`) both run it once per frame.

It starts either from the standard pose where the subject stands (`from_standard_pose`),
or from labels a camera node already put on the blobs (`from_labels`: the nodes started
from that pose themselves); then the cross-view labeller starts at the first frame whose
8 markers all triangulate. A camera whose frame is missing (None; e.g. its packet was
lost) skips that frame: its tracker is not stepped and its labels are missing.

Labels the camera nodes already put on blobs (`known`) stand: each camera's tracker is
put on them (`MarkerTracker.reacquire`) before the cross-view labelling, which then only
adds the labels the nodes lost (and drops a label whose views disagree). A node that
follows every frame keeps the labels through frames the server never gets, and the
server keeps finding the ones it lost.

A stage that has lost the subject (fewer than `MIN_TRIANGULATED` markers triangulate: it
left, or every view was blocked) looks for it again in every frame's blobs: standing in
the standard pose anywhere on the stage, facing the front as at the start
(`samba.markers.standard_pose_search`; the front is the start's heading, or with `from_labels`
the heading of the first frame whose markers all triangulated). When found, every
camera's tracker and the cross-view labelling start again from there, once the search
has found the subject standing still (`STILL_FRAMES`). Two cameras
search too: on 300 random standing subjects (0.3 px noise, 3 stray spots per camera)
the search found 89% with no label on a wrong blob (three cameras: 90%, one frame with
a wrong label), and on 395 frames of four CMU takes in other poses it fired 8 times,
each time labelling every blob right (three cameras: 10 times, 4 with a wrong label).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from samba.base import InputError
from samba.body import N_MARKERS, markers_of, standing_pose
from samba.cameras import CameraGroup, triangulate_cameras
from samba.markers.cross_view_labels import CrossViewLabeller, CrossViewSettings
from samba.markers.standard_pose_search import SHOULDERS, StandardPoseSearch, heading_of
from samba.markers.tracking import MarkerTracker, TrackerSettings, subject_distance

MIN_TRIANGULATED = 3
"""Fewer markers triangulated than this (the fewest a reconstruction uses) and the stage
has lost the subject: it searches for the standard pose."""
STILL_FRAMES = 5
"""The search's find is taken once it has found the subject in this many frames in a
row, turned by at most `STILL_DEG` over them: a subject coming back stands in the
standard pose, while one turning on the spot shows an A-pose that looks the same from
behind at every heading, and a find of it facing the front can be one facing away with
left and right swapped (a synthetic turn with two cameras: 450 label swaps)."""
STILL_DEG = 10.0
"""Most the subject's heading (degrees) may change over the `STILL_FRAMES` finds."""


class StageTracker:
    """The 8 labels in every camera of `cameras`, from each frame's blobs.

    `trackers` one `MarkerTracker` per camera; `initial` (8, 3) meters where the markers
    are when capture starts, or None to start the cross-view labelling at the first
    frame whose markers all triangulate; `cross_view` its settings (None: each camera's
    tracker alone); `search` whether a stage that lost the subject looks for it in the
    standard pose (with the cross-view labelling only); `refit` tracker overrides in
    reference pixels, or None: given, every time the cross-view labelling starts the
    trackers' settings are made again for the subject's distance from each camera
    (`TrackerSettings.for_camera`), for trackers started before it was known.
    Call `step` once per frame, in order.
    """

    def __init__(
        self,
        cameras: CameraGroup,
        trackers: Sequence[MarkerTracker],
        initial: np.ndarray | None = None,
        cross_view: CrossViewSettings | None = None,
        search: bool = True,
        refit: Mapping[str, float] | None = None,
    ) -> None:
        if len(trackers) != len(cameras):
            raise InputError(
                "trackers", f"need one per camera ({len(cameras)}), got {len(trackers)}"
            )
        self.cameras = cameras
        self.trackers = list(trackers)
        self._cross_view = cross_view
        self._labeller = None
        self._searches = search
        self._refit = refit
        self._search: StandardPoseSearch | None = None
        self._finds: list[float] = []
        self.searches = 0
        """How often the subject was found again in the standard pose."""
        if cross_view is not None and initial is not None:
            self._start_labeller(initial)

    @classmethod
    def from_standard_pose(
        cls,
        cameras: CameraGroup,
        position: Sequence[float] = (0.0, 0.0),
        heading_deg: float = 0.0,
        height: float = 1.70,
        tracker: Mapping[str, float] | None = None,
        cross_view: CrossViewSettings | None = None,
        search: bool = True,
    ) -> StageTracker:
        """Every camera's labels started from the standard pose of an average body of
        `height` m standing at `position` (x, z) meters, facing +Z turned by
        `heading_deg` about +Y; `tracker` overrides of the tracker settings in reference
        pixels (`TrackerSettings.for_camera`); `cross_view` and `search` as for the
        constructor."""
        where = (position, heading_deg, height)
        markers = markers_of(standing_pose(*where))
        trackers = [
            MarkerTracker.from_standard_pose(
                camera,
                *where,
                TrackerSettings.for_camera(
                    camera, subject_distance(camera, markers), **(tracker or {})
                ),
            )
            for camera in cameras
        ]
        return cls(cameras, trackers, markers, cross_view, search)

    @classmethod
    def from_labels(
        cls,
        cameras: CameraGroup,
        labels: np.ndarray,
        tracker: Mapping[str, float] | None = None,
        cross_view: CrossViewSettings | None = None,
    ) -> StageTracker:
        """Every camera's labels started where `labels` (c, 8, 2) raw pixels put them
        (NaN: not known, the label starts abandoned); the cross-view labelling starts at
        the first frame whose 8 markers all triangulate, and the trackers' settings are
        then fitted to the subject's distance (`refit`)."""
        labels = np.asarray(labels, dtype=np.float64)
        if labels.shape != (len(cameras), N_MARKERS, 2):
            raise InputError(
                "labels", f"must be ({len(cameras)}, {N_MARKERS}, 2) pixels, got {labels.shape}"
            )
        trackers = [
            MarkerTracker(start, TrackerSettings.for_camera(camera, **(tracker or {})))
            for camera, start in zip(cameras, labels, strict=True)
        ]
        return cls(cameras, trackers, None, cross_view, refit=tracker or {})

    def step(
        self,
        centroids: Sequence[np.ndarray | None],
        known: np.ndarray | None = None,
        merged: Sequence[np.ndarray | None] | None = None,
    ) -> np.ndarray:
        """The labels (c, 8, 2) raw pixels of this frame, NaN = missing, from each
        camera's blob centroids (m, 2) raw pixels (None: no frame from that camera) and
        the labels `known` (c, 8, 2) already (NaN: not known), each one of the blobs;
        `merged` per camera (m,) bool (or None) the blobs that look like two markers
        merged, on which no label is reported (`MarkerTracker.step`)."""
        if len(centroids) != len(self.cameras):
            raise InputError(
                "centroids",
                f"need one blob array (or None) per camera ({len(self.cameras)}), "
                f"got {len(centroids)}",
            )
        labelled = np.full((len(self.cameras), N_MARKERS, 2), np.nan)
        unlabelled, motion = [], []
        for camera, (tracker, blobs) in enumerate(zip(self.trackers, centroids, strict=True)):
            if blobs is None:
                unlabelled.append(np.zeros((0, 2)))
                motion.append(np.zeros((0, 2)))
                continue
            labelled[camera] = tracker.step(blobs, None if merged is None else merged[camera])
            if known is not None:
                labelled[camera] = _put_on(tracker, labelled[camera], known[camera])
            unlabelled.append(tracker.anonymous_blobs)
            motion.append(tracker.anonymous_motion)
        if self._cross_view is None:
            return labelled
        if self._labeller is None:
            points = triangulate_cameras(list(self.cameras), labelled)
            if np.isnan(points).any():
                return labelled
            self._start_labeller(points)
        assert self._labeller is not None
        labelled, found = self._labeller.step(labelled, unlabelled, motion)
        for event in found:
            self.trackers[event.camera].reacquire(event.label, event.pixel)
        for camera, label in zip(*np.nonzero(self._labeller.outvoted), strict=True):
            self.trackers[camera].release(int(label))
        seen = (~np.isnan(labelled).any(axis=-1)).sum(axis=0) >= 2
        if self._search is not None and seen.sum() < MIN_TRIANGULATED:
            return self._search_again(centroids, labelled)
        self._finds.clear()  # the finds must come in a row, while the subject is lost
        return labelled

    def _start_labeller(self, points: np.ndarray) -> None:
        """Start the cross-view labelling at markers `points` (8, 3) meters, and the
        search for the standard pose facing as their shoulders do; with `refit`, fit the
        trackers' settings to the subject's distance there."""
        assert self._cross_view is not None
        self._labeller = CrossViewLabeller(self.cameras, points, self._cross_view)
        if self._refit is not None:
            for camera, tracker in zip(self.cameras, self.trackers, strict=True):
                distance = subject_distance(camera, points)
                tracker.settings = TrackerSettings.for_camera(camera, distance, **self._refit)
        if self._searches and self._search is None:
            heading = heading_of(points[list(SHOULDERS)])
            self._search = StandardPoseSearch(self.cameras, heading_deg=heading)

    def _search_again(
        self, centroids: Sequence[np.ndarray | None], labelled: np.ndarray
    ) -> np.ndarray:
        """The labels (c, 8, 2) of the subject found in the standard pose among this
        frame's blobs `centroids`, every tracker and the labeller started again there;
        `labelled` as they were when it is not found."""
        assert self._search is not None
        found = self._search.find(centroids)
        if found is None:
            self._finds.clear()
            return labelled
        self._finds = [*self._finds, heading_of(found.points[list(SHOULDERS)])][-STILL_FRAMES:]
        spread = np.degrees(np.ptp(np.unwrap(np.radians(self._finds))))
        if len(self._finds) < STILL_FRAMES or spread > STILL_DEG:
            return labelled
        self._finds.clear()
        self.trackers = [
            MarkerTracker(start, tracker.settings)
            for tracker, start in zip(self.trackers, found.labels, strict=True)
        ]
        self._start_labeller(found.points)
        self.searches += 1
        return found.labels


def _put_on(tracker: MarkerTracker, labels: np.ndarray, known: np.ndarray) -> np.ndarray:
    """`labels` (8, 2) pixels of `tracker`'s last frame with the `known` ones (8, 2, NaN:
    not known) put in their place, in the tracker too; a label of the tracker's on a blob
    a known label took is dropped from the output."""
    given = ~np.isnan(known).any(axis=-1)
    if not given.any():
        return labels
    differs = given & ~(np.abs(labels - known) <= 1e-6).all(axis=-1)
    for label in np.flatnonzero(differs):
        tracker.reacquire(int(label), known[label])
    out = np.where(given[:, None], known, labels)
    taken = (np.abs(out[:, None] - known[None]) <= 1e-6).all(axis=-1)  # (8, 8)
    np.fill_diagonal(taken, False)
    out[~given & taken.any(axis=-1)] = np.nan
    return out
