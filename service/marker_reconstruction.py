"""Offline reconstruction of a marker take (`samba reconstruct`): a C3D file or a take the
live service recorded, reconstructed into a 13-joint take and written as MCAP (a take
like the live service's, with the subject's skin offsets in its metadata), BVH, USD or
glTF (through `samba.export`).

The markers are put on the reconstruction's frame rate (the database's: 30 fps by
default), gaps up to `MAX_FILLED_GAP_S` are filled (`samba.markers.fill_gaps`), the
subject's skin offsets are calibrated over a stretch of the take
(`samba.reconstruct.calibrate_skin_offsets`; the first 2 s unless told otherwise) and
removed from every frame (`SkinMarkerReconstructor`), and the take is reconstructed in
chunks of `CHUNK_FRAMES` (the batch path, continuing from chunk to chunk) under a
progress bar, whole or a part at a time (`frames`; the parts `joined` on a cluster).
Every frame gets a pose: frames without enough markers are predicted and flagged so
(`Reconstruction.predicted`). The poses are moved so that the floor (the feet's height
at ground contact) is at y = 0, the ankles' height of Samba's convention.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from samba.export import Avatar, retarget, write_export
from samba.ingest import MarkerTake, floor_height
from samba.markers import fill_gaps
from samba.reconstruct import (
    PoseEstimate,
    Reconstruction,
    Reconstructor,
    SkinMarkerReconstructor,
    SkinOffsets,
    calibrate_skin_offsets,
)
from samba.service.errors import ServiceError
from samba.service.take_recorder import TakeRecorder

CHUNK_FRAMES = 64
"""Frames reconstructed per batch (and per step of the progress bar)."""
MAX_FILLED_GAP_S = 1.0
"""Marker gaps up to this long (seconds) are filled by linear interpolation first."""


@dataclass(frozen=True)
class MarkerReconstruction:
    """A reconstructed marker take: `take` (its markers at the reconstruction's rate),
    `filled` (n, 8) which of its marker samples were gaps filled by interpolation,
    `poses` (n, 13, 3) world meters with the floor at y = 0, per frame `residual` (m),
    `markers_used`, `confident` and `predicted`, the subject's skin `offsets`, and the
    height `floor` (m) by which the take was lowered to put its floor at y = 0."""

    take: MarkerTake
    filled: np.ndarray
    poses: np.ndarray
    residual: np.ndarray
    markers_used: np.ndarray
    confident: np.ndarray
    predicted: np.ndarray
    offsets: SkinOffsets
    floor: float

    def estimate(self, i: int) -> PoseEstimate:
        """Frame i as a `PoseEstimate`."""
        return PoseEstimate(
            self.poses[i],
            float(self.residual[i]),
            int(self.markers_used[i]),
            bool(self.confident[i]),
            bool(self.predicted[i]),
        )

    def summary(self) -> str:
        """What was reconstructed, in a few lines."""
        n = len(self.poses)
        predicted = int(self.predicted.sum())
        missing = float(np.isnan(self.take.markers[..., 0]).mean())
        filled = float(self.filled.mean())
        fitted = self.residual[~self.predicted]
        residual = f"{np.median(fitted) * 100:.1f} cm" if len(fitted) else "none"
        lines = [
            f"{self.take.name}: {n} frames at {self.take.fps:g} fps ({n / self.take.fps:.1f} s), "
            f"{missing:.1%} of marker samples missing, {filled:.1%} filled (gaps up to "
            f"{MAX_FILLED_GAP_S:g} s, linearly)",
            f"  reconstructed {n - predicted}, predicted {predicted} (too few markers); "
            f"confident {self.confident.mean():.1%}; median marker residual {residual}",
        ]
        if self.offsets.frames:
            lines.append(f"  skin offsets from {self.offsets.frames} calibration frames:")
            lines.append(self.offsets.report())
        return "\n".join(lines)


def reconstruct_marker_take(
    take: MarkerTake,
    reconstructor: Reconstructor,
    calibration: tuple[float, float] | None = (0.0, 2.0),
    progress: bool | None = None,
    frames: tuple[int, int] | None = None,
    settle: int = 0,
) -> MarkerReconstruction:
    """Reconstruct `take` (its markers (n, 8, 3) meters, NaN = missing, at the rate to
    reconstruct at) with `reconstructor`, the skin offsets calibrated over the
    `calibration` stretch (start, stop) in seconds (None: markers taken as joint
    centres). `ServiceError` naming the take when the stretch is outside it or has no
    frame with enough markers. `progress` None shows the bar on a terminal only.

    With `frames` (first, stop) only those frames are kept, a part of the take for
    `joined`: the `settle` frames before `first` are reconstructed first and thrown away,
    so that the reconstruction's state (previous estimates, markers held) comes close to
    that of the whole take's reconstruction, and so are the take's first
    `calibration_frames` (the bones calibrated on them are those of the whole take).
    The part's `take` holds those frames, and its poses are not lowered (floor 0): the
    floor is that of the whole take."""
    longest = int(MAX_FILLED_GAP_S * take.fps)
    markers, filled = fill_gaps(np.asarray(take.markers, dtype=np.float64), longest)
    offsets = SkinOffsets.none()
    if calibration is not None:
        start, stop = (round(t * take.fps) for t in calibration)
        stretch = f"calibration stretch {calibration[0]:g}-{calibration[1]:g} s"
        if start >= len(markers):
            raise ServiceError(take.source, f"{stretch} starts after the take's end")
        try:
            offsets = calibrate_skin_offsets(reconstructor, markers[start:stop])
        except ValueError as exc:
            raise ServiceError(take.source, f"{stretch}: {exc}") from None
    subject = SkinMarkerReconstructor(reconstructor, offsets)
    subject.reset()
    first, stop = frames or (0, len(markers))
    lead = max(0, first - settle)
    _reconstructed(subject, markers, 0, min(lead, reconstructor.config.calibration_frames))
    _reconstructed(subject, markers, lead, first)
    bar = tqdm(total=stop - first, unit="frame", disable=None if progress is None else not progress)
    with bar:
        parts = _reconstructed(subject, markers, first, stop, bar)
    if frames is not None:
        take = replace(take, points=take.points[first:stop], markers=take.markers[first:stop])
    result = MarkerReconstruction(
        take,
        filled[first:stop],
        np.concatenate([p.poses for p in parts]),
        np.concatenate([p.residual for p in parts]),
        np.concatenate([p.markers_used for p in parts]),
        np.concatenate([p.confident for p in parts]),
        np.concatenate([p.predicted for p in parts]),
        offsets,
        0.0,
    )
    return result if frames is not None else joined([result])


def joined(parts: Sequence[MarkerReconstruction]) -> MarkerReconstruction:
    """The reconstruction of a take from its consecutive `parts` (not lowered, as
    `reconstruct_marker_take` returns them with `frames`), its poses lowered so that the
    floor of all of them is at y = 0; the skin offsets, labels and metadata are those of
    the first part."""
    first = parts[0]
    poses = np.concatenate([p.poses for p in parts])
    floor = floor_height(poses, first.take.fps)
    poses[..., 1] -= floor
    take = first.take
    if len(parts) > 1:
        points = np.concatenate([p.take.points for p in parts])
        take = replace(take, points=points, markers=np.concatenate([p.take.markers for p in parts]))
    return MarkerReconstruction(
        take,
        np.concatenate([p.filled for p in parts]),
        poses,
        np.concatenate([p.residual for p in parts]),
        np.concatenate([p.markers_used for p in parts]),
        np.concatenate([p.confident for p in parts]),
        np.concatenate([p.predicted for p in parts]),
        first.offsets,
        floor,
    )


def _reconstructed(
    subject: SkinMarkerReconstructor,
    markers: np.ndarray,
    first: int,
    stop: int,
    bar: tqdm | None = None,
) -> list[Reconstruction]:
    """Frames `first` to `stop` of `markers` (n, 8, 3) reconstructed by `subject`,
    continuing from its state, in batches of `CHUNK_FRAMES` (each a step of `bar`)."""
    parts = []
    for start in range(first, stop, CHUNK_FRAMES):
        parts.append(subject.reconstruct(markers[start : min(start + CHUNK_FRAMES, stop)]))
        if bar is not None:
            bar.update(len(parts[-1]))
    return parts


def write_reconstruction(
    result: MarkerReconstruction, out: Path, fmt: str, avatar: Avatar, unit: str = "m"
) -> None:
    """Write the reconstruction to `out`: `fmt` "mcap" as a take (every frame's pose,
    diagnostics and markers, the skin offsets as `subject` metadata), or "bvh", "glb",
    "usd" through the exporters onto `avatar` (BVH lengths in `unit`)."""
    fps = result.take.fps
    if fmt != "mcap":
        write_export(fmt, out, retarget(result.poses, avatar.rig, fps), avatar.mesh, unit)
        return
    markers = result.take.markers - [0.0, result.floor, 0.0]  # in the poses' frame
    with TakeRecorder(out, fps, name=result.take.name) as recorder:
        recorder.write_subject(result.offsets)
        for i in range(len(result.poses)):
            recorder.write_frame(round(i * 1e9 / fps), result.estimate(i), markers[i])
