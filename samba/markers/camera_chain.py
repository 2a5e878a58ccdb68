"""The measurement chain end to end on synthetic video: render, detect, track, triangulate.

`run_chain` films a take's poses with the synthetic rig (`samba.markers.render`), finds the
blobs of every frame (`samba.markers.detection`, flagging blobs of two markers merged),
keeps the 8 labels per camera (`samba.markers.tracking`) and triangulates them by DLT
(`samba.cameras.triangulation`), as the
camera nodes and the server will. The subject first stands in the standard pose
(`samba.markers.lead_in`), and each camera's tracker starts from the standard pose of an average
body of the subject's height at that place and heading. Before the subject steps in,
each camera films the empty stage; what is bright there is masked (`static_mask`). With
a `video_folder`, every camera's frames go through a lossless video file and back.

`ChainResult` scores the chain against the truth: RMS 3D error where at least two cameras
see a marker, missing-marker rates, label swaps and phantoms.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from samba.body import N_MARKERS, markers_of
from samba.cameras import Camera, CameraGroup, read_frames, triangulate, write_video
from samba.markers.cross_view_labels import CrossViewSettings
from samba.markers.detection import MERGED_AREA_RATIO, Blobs, detect_markers, static_mask
from samba.markers.lead_in import LeadIn, standing_lead_in
from samba.markers.render import RenderOptions, film_empty_stage, render
from samba.markers.stage_tracking import StageTracker
from samba.markers.tracking import REFERENCE_FOCAL_PX

EMPTY_STAGE_FRAMES = 10
"""Frames of the empty stage each camera films to build its static-spot mask."""
SWAP_TOLERANCE_PX = 1.0
"""A label farther than this from its own marker (pixels at `REFERENCE_FOCAL_PX`,
scaled per camera), nearer another marker and within twice this of it is a swap."""


@dataclass(frozen=True)
class ChainSettings:
    """How `run_chain` films and measures: the rig's `render` options, tracker settings
    `tracker` in reference pixels (scaled per camera by `TrackerSettings.for_camera`),
    the standing lead-in: `hold_seconds` in the standard pose, then `blend_seconds`
    moving into the take's first pose; the cross-view labelling of lost labels
    (`cross_view`; None: each camera's tracker alone), and whether a stage that lost the
    subject looks for it in the standard pose (`search`, `StageTracker`); and at how
    many times the frame's median blob area a blob is taken for two markers merged
    (`merged_area_ratio`, `Blobs.merged`; None: never)."""

    render: RenderOptions = field(default_factory=RenderOptions)
    tracker: dict[str, float] = field(default_factory=dict)
    hold_seconds: float = 0.5
    blend_seconds: float = 0.5
    cross_view: CrossViewSettings | None = field(default_factory=CrossViewSettings)
    search: bool = True
    merged_area_ratio: float | None = MERGED_AREA_RATIO


@dataclass(frozen=True, eq=False)
class ChainResult:
    """The chain's output over the take's F frames (the lead-in removed).

    `truth` (F, 8, 3) and `markers` (F, 8, 3) world meters, NaN = not reconstructed;
    `tracked` (c, F, 8, 2) each camera's labelled pixels, NaN = missing; `truth_pixels`
    (c, F, 8, 2) and `visible` (c, F, 8) what each camera really showed; `focal_px` (c,)
    the cameras' focal lengths (for the swap tolerance).
    """

    truth: np.ndarray
    markers: np.ndarray
    tracked: np.ndarray
    truth_pixels: np.ndarray
    visible: np.ndarray
    focal_px: np.ndarray

    @property
    def seen_by_two(self) -> np.ndarray:
        """(F, 8) bool: at least two cameras see the marker."""
        return self.visible.sum(axis=0) >= 2

    @property
    def reconstructed(self) -> np.ndarray:
        """(F, 8) bool: the chain gave the marker a 3D position."""
        return ~np.isnan(self.markers).any(axis=-1)

    def rms_error(self) -> float:
        """RMS 3D error in meters over reconstructed markers that two cameras see."""
        both = self.reconstructed & self.seen_by_two
        errors = np.linalg.norm(self.markers - self.truth, axis=-1)[both]
        return float(np.sqrt(np.mean(errors**2))) if len(errors) else float("nan")

    def missing_rate(self) -> float:
        """Fraction of (frame, marker) without a 3D position."""
        return float(1.0 - self.reconstructed.mean())

    def lost_rate(self) -> float:
        """Fraction of the (frame, marker) that two cameras see left without a 3D position:
        what detection and tracking lose beyond occlusion and the field of view."""
        seen = self.seen_by_two
        return float((seen & ~self.reconstructed).sum() / max(int(seen.sum()), 1))

    def swaps(self) -> int:
        """Labels (over cameras and frames) on another marker: within twice
        `SWAP_TOLERANCE_PX` (scaled) of another visible marker's true pixel, nearer it
        than their own, and farther than `SWAP_TOLERANCE_PX` from their own."""
        tolerance = (SWAP_TOLERANCE_PX * self.focal_px / REFERENCE_FOCAL_PX)[:, None, None]
        own = np.linalg.norm(self.tracked - self.truth_pixels, axis=-1)  # (c, F, 8)
        own = np.where(np.isnan(own), np.inf, own)
        others = np.where(self.visible[:, :, None, :, None], self.truth_pixels[:, :, None], np.nan)
        gaps = np.linalg.norm(self.tracked[:, :, :, None] - others, axis=-1)  # (c, F, 8, 8)
        gaps[:, :, np.arange(N_MARKERS), np.arange(N_MARKERS)] = np.nan
        nearest_other = np.fmin.reduce(gaps, axis=-1)
        with np.errstate(invalid="ignore"):
            wrong = (nearest_other < own) & (own > tolerance) & (nearest_other <= 2 * tolerance)
        return int(wrong.sum())

    def phantoms(self) -> int:
        """Labels (over cameras and frames) reported where the camera does not see their
        marker: a blob taken that is not the label's."""
        reported = ~np.isnan(self.tracked).any(axis=-1)
        return int((reported & ~self.visible).sum())


def detect_camera(
    camera: Camera, frames: np.ndarray, settings: ChainSettings, seed: int
) -> list[Blobs]:
    """The blobs of every frame (F, H, W) of one camera, with the static spots of the
    empty stage masked."""
    rng = np.random.default_rng([seed, EMPTY_STAGE_FRAMES])
    mask = static_mask(film_empty_stage(camera, settings.render, EMPTY_STAGE_FRAMES, rng))
    return [
        detect_markers(frame, mask=mask, name=f"{camera.name} frame {i}")
        for i, frame in enumerate(frames)
    ]


def track_cameras(
    cameras: CameraGroup,
    blobs: Sequence[Sequence[Blobs]],
    lead_in: LeadIn,
    settings: ChainSettings,
) -> np.ndarray:
    """Every camera's labelled pixels (c, F, 8, 2) from its blobs per frame
    (`blobs[camera][frame]`); no label is reported on a blob that looks like two markers
    merged (`Blobs.merged` at `settings.merged_area_ratio`). Each tracker starts from the standard
    pose where the lead-in stands; with `settings.cross_view`, lost labels are found
    again across the cameras every frame (`CrossViewLabeller`) and handed back to the
    trackers, and with `settings.search` a lost subject is found again (`StageTracker`)."""
    stage = StageTracker.from_standard_pose(
        cameras,
        lead_in.position,
        lead_in.heading_deg,
        lead_in.height,
        settings.tracker,
        settings.cross_view,
        settings.search,
    )
    frames = len(blobs[0])
    out = np.full((len(cameras), frames, N_MARKERS, 2), np.nan)
    for f in range(frames):
        found = [camera[f] for camera in blobs]
        out[:, f] = stage.step(
            [b.centroids for b in found],
            merged=[b.merged(settings.merged_area_ratio) for b in found],
        )
    return out


def run_chain(
    poses: np.ndarray,
    cameras: Sequence[Camera],
    fps: float,
    settings: ChainSettings | None = None,
    seed: int = 0,
    video_folder: str | Path | None = None,
) -> ChainResult:
    """Film poses (F, 13, 3) meters at `fps` with `cameras`, detect, track, triangulate.

    Cameras must be distortion-free (the tracked pixels are triangulated as they are).
    With `video_folder`, each camera's frames are written there as `<camera name>.avi`
    (lossless FFV1) and read back before detection. Deterministic in `seed`.
    """
    settings = settings or ChainSettings()
    lead_in = standing_lead_in(poses, fps, settings.hold_seconds, settings.blend_seconds)
    views = render(lead_in.poses, cameras, settings.render, seed)
    blobs = []
    for view in views:
        frames = view.frames
        if video_folder is not None:
            path = Path(video_folder) / f"{view.camera.name}.avi"
            write_video(frames, path, fps)
            frames = read_frames(path)
        blobs.append(detect_camera(view.camera, frames, settings, seed))
    tracked = track_cameras(CameraGroup(tuple(cameras)), blobs, lead_in, settings)
    take = slice(lead_in.frames, None)
    return ChainResult(
        truth=markers_of(lead_in.poses[take]),
        markers=triangulate(np.stack([c.projection for c in cameras]), tracked[:, take]),
        tracked=tracked[:, take],
        truth_pixels=np.stack([v.pixels[take] for v in views]),
        visible=np.stack([v.visible[take] for v in views]),
        focal_px=np.array([c.matrix[0, 0] for c in cameras]),
    )
