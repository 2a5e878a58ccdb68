"""Real marker takes on the synthetic stage: a C3D file's 8 skin markers, filmed by the
simulated cameras of `samba node --synthetic FILE.c3d` and `samba demo --motion FILE.c3d`
as they film the built-in motions, so that the live service, its VMC stream and the take
recorder run on real marker motion.

What the cameras film are the take's own markers (`samba.ingest.read_c3d` by a marker
set), not the joints of a pose:

* Time: the markers are resampled onto the rig's frame rate by time, linearly; a marker
  missing (NaN) on either side of a new frame stays missing.
* Place: the lab's floor is the stage's floor (heights are kept: a C3D lab has y = 0 on
  its floor, so the ankle markers of a standing subject are some 7 cm up), and the take
  keeps its own heading; it is moved along the floor so that its mean marker position
  over the whole file stands above the stage's centre (x = z = 0), where
  `samba.markers.spread_cameras` aims the cameras of a take placed so. The placement
  depends on the file alone (not on the frame rate or the length played), so a node
  given the calibration `samba demo --motion FILE.c3d` wrote films the take where the
  demo's cameras look.
* Lead-in (`MarkerMotion.lead_in`, for nodes, whose trackers start from the standard
  pose): a real take has no standing start, so one is made as for the built-in motions:
  the standard pose of an average body as tall as the first complete frame's shoulders
  stand above its feet, on the floor where that frame stands and facing its way, held
  for 0.5 s, then moving into the take's first frame over 0.5 s (each marker on a
  smooth step). Holding the first frame instead would start the trackers on a subject
  that is not in the standard pose (a real take's arms hang, the standard pose's are 45
  degrees out), and they would lose its wrists at once.
* No body: a marker is hidden from a camera only when it is behind it or outside its
  image (`MARKER_TAKE_RENDER`); the body capsules that hide the built-in motions'
  markers need joints a marker take does not have.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from samba.base import InputError
from samba.body import (
    MARKER_JOINTS,
    N_JOINTS,
    facing_directions,
    markers_of,
    standard_pose,
    standing_pose,
)
from samba.ingest import PLUG_IN_GAIT, MarkerSet, read_c3d
from samba.markers import LeadIn, RenderOptions

MARKER_FILE_SUFFIX = ".c3d"
"""The suffix of the marker files the synthetic rig plays in place of a built-in motion."""
HOLD_SECONDS = 0.5
"""How long the made-up standing start holds the standard pose."""
BLEND_SECONDS = 0.5
"""How long it takes from the standard pose into the take's first frame."""
MARKER_TAKE_RENDER = RenderOptions(occlusion=False)
"""How the synthetic cameras film a marker take: no body hides its markers."""
_SHOULDER_RISE_PER_M = float(np.subtract(*markers_of(standard_pose(1.0))[[0, 6], 1]))
"""How far the shoulders of the standard pose stand above its feet, per meter of stature."""


def is_marker_file(motion: str) -> bool:
    """Whether the motion word `motion` (of `--synthetic` or `--motion`) names a C3D
    marker file rather than a built-in motion or a BVH file."""
    return Path(motion).suffix.lower() == MARKER_FILE_SUFFIX


def marker_poses(markers: np.ndarray) -> np.ndarray:
    """Markers (n, 8, 3) meters in the slots of their joints of poses (n, 13, 3), the
    other joints NaN: how the pose-based synthetic cameras (`samba.markers.render_camera`,
    `spread_cameras`), which film only a pose's marker joints, take a marker take."""
    markers = np.asarray(markers, dtype=np.float64)
    poses = np.full((len(markers), N_JOINTS, 3), np.nan)
    poses[:, MARKER_JOINTS] = markers
    return poses


@dataclass(frozen=True, eq=False)
class MarkerMotion:
    """A real marker take placed on the synthetic stage (see the module docstring):
    `markers` (F, 8, 3) meters, +Y up, NaN = missing, at `fps` frames per second;
    `name` the take's (its file's stem), `source` the file."""

    name: str
    source: str
    markers: np.ndarray
    fps: float

    @classmethod
    def read(
        cls,
        path: str | Path,
        fps: float,
        seconds: float | None = None,
        marker_set: MarkerSet = PLUG_IN_GAIT,
    ) -> MarkerMotion:
        """The 8 markers of the C3D file `path` (by `marker_set`) at `fps`, placed on the
        stage, the first `seconds` of them (None: all; a shorter take plays whole).
        `C3dError` naming the file when it cannot be read or its labels do not give the
        8 markers; `InputError` naming `--seconds` when they give no frame."""
        take = read_c3d(path, marker_set)
        centre = np.nanmean(take.markers.reshape(-1, 3), axis=0)
        markers = take.resampled(fps).markers
        if seconds is not None:
            markers = markers[: round(seconds * fps)]
            if not len(markers):
                raise InputError("--seconds", f"{seconds:g} s at {fps:g} fps gives no frames")
        markers = markers - np.array([centre[0], 0.0, centre[2]])
        return cls(take.name, str(path), markers, float(fps))

    def __len__(self) -> int:
        return len(self.markers)

    def lead_in(self) -> LeadIn:
        """The take after a made-up standing start (see the module docstring): `poses`
        (L + F, 13, 3) hold the markers in their joints' slots (`marker_poses`), the
        first L = `HOLD_SECONDS` + `BLEND_SECONDS` of them the start, whose standard
        pose stands at `position` facing `heading_deg`, `height` m tall. `InputError`
        naming the file when no frame holds all 8 markers to stand the start on."""
        complete = ~np.isnan(self.markers).any(axis=(1, 2))
        if not complete.any():
            raise InputError(self.source, "no frame holds all 8 markers to start from")
        first = self.markers[np.argmax(complete)]
        facing = facing_directions(marker_poses(first[None]))[0]
        heading = 0.0 if np.isnan(facing[0]) else float(np.degrees(np.arctan2(*facing[[0, 2]])))
        x, z = (float(v) for v in first[:, [0, 2]].mean(axis=0))
        rise = first[:2, 1].mean() - first[6:, 1].mean()
        height = float(np.clip(rise / _SHOULDER_RISE_PER_M, 0.5, 2.5))
        standing = markers_of(standing_pose((x, z), heading, height))
        hold, blend = round(HOLD_SECONDS * self.fps), round(BLEND_SECONDS * self.fps)
        ease = np.clip((np.arange(hold + blend) - hold + 1.0) / (blend + 1), 0.0, 1.0)
        ease = ease * ease * (3.0 - 2.0 * ease)
        lead = standing + ease[:, None, None] * (self.markers[0] - standing)
        lead[:hold] = standing  # held whole even where the first frame misses a marker
        return LeadIn(
            poses=marker_poses(np.concatenate([lead, self.markers])),
            frames=len(lead),
            position=(x, z),
            heading_deg=heading,
            height=height,
        )
