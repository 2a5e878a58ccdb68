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
progress bar. Every frame gets a pose: frames without enough markers are predicted and
flagged so (`Reconstruction.predicted`). The poses are moved so that the floor (the
feet's height at ground contact) is at y = 0, the ankles' height of Samba's convention.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from samba.export import Avatar, retarget, write_export
from samba.ingest import MarkerTake, floor_height
from samba.markers import fill_gaps
from samba.reconstruct import (
    PoseEstimate,
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
) -> MarkerReconstruction:
    """Reconstruct `take` (its markers (n, 8, 3) meters, NaN = missing, at the rate to
    reconstruct at) with `reconstructor`, the skin offsets calibrated over the
    `calibration` stretch (start, stop) in seconds (None: markers taken as joint
    centres). `ServiceError` naming the take when the stretch is outside it or has no
    frame with enough markers. `progress` None shows the bar on a terminal only."""
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
    parts = []
    bar = tqdm(total=len(markers), unit="frame", disable=None if progress is None else not progress)
    with bar:
        for first in range(0, len(markers), CHUNK_FRAMES):
            parts.append(subject.reconstruct(markers[first : first + CHUNK_FRAMES]))
            bar.update(len(parts[-1]))
    poses = np.concatenate([p.poses for p in parts])
    floor = floor_height(poses, take.fps)
    poses[..., 1] -= floor
    return MarkerReconstruction(
        take,
        filled,
        poses,
        np.concatenate([p.residual for p in parts]),
        np.concatenate([p.markers_used for p in parts]),
        np.concatenate([p.confident for p in parts]),
        np.concatenate([p.predicted for p in parts]),
        offsets,
        floor,
    )


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
