"""Marker takes from C3D files: every labelled point in meters, +Y up, and the 8 markers of
a marker set (`samba.ingest.marker_sets`).

Read with the `c3d` package (pure Python, on the package index, reads the C3D spec's
processor types, scales and parameter sections): on damaged files it raises Python
exceptions, where the compiled `ezc3d` crashed the process on 1 of 60 fuzzed copies of
a shared take. Any of them becomes a `C3dError` naming the file.

* Units from `POINT:UNITS` (mm, cm, m); an unknown unit is refused.
* A point whose residual is negative is missing: NaN, never a sentinel number.
* Labels lose their subject prefix ("Male:LSHO" -> "LSHO") and padding.
* The lab's up axis is not in the file: it is the axis along which the shoulders stand
  above the feet, and the points are turned (right-handed) so that it is +Y.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from samba.body import resample_times, sample_linear
from samba.ingest.errors import C3dError
from samba.ingest.marker_sets import PLUG_IN_GAIT, MarkerSet

UNITS: dict[str, float] = {"mm": 0.001, "cm": 0.01, "m": 1.0}
"""`POINT:UNITS` values read, with their size in meters."""


@dataclass
class MarkerTake:
    """Real markers of one take: `points` (n, m, 3) every labelled point, meters, +Y up,
    NaN where missing, named by `labels` (m,); `markers` (n, 8, 3) our eight markers
    (`samba.body.MARKER_NAMES` order) by the marker set `marker_set`, at `fps`;
    `warnings` what the reader noticed, `meta` facts about the source."""

    name: str
    points: np.ndarray
    labels: tuple[str, ...]
    markers: np.ndarray
    fps: float
    source: str
    marker_set: str
    warnings: list[str] = field(default_factory=list)
    meta: dict[str, str] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.points)

    def point(self, label: str) -> np.ndarray:
        """The trajectory (n, 3) of the point `label`; `KeyError` if the take has none."""
        return self.points[:, self.labels.index(label)]

    def resampled(self, fps: float) -> MarkerTake:
        """The take at `fps` frames per second: points and markers linearly interpolated
        in time (a point missing on either side of a new frame stays missing); an integer
        rate ratio (120 to 30) picks frames."""
        times = resample_times(len(self), self.fps, fps)
        return replace(
            self,
            points=sample_linear(self.points, times),
            markers=sample_linear(self.markers, times),
            fps=float(fps),
        )


def read_c3d(path: str | Path, marker_set: MarkerSet = PLUG_IN_GAIT) -> MarkerTake:
    """The marker take in the C3D file `path`, its 8 markers by `marker_set`. Raises
    `C3dError` naming the file for a file that cannot be read, is no C3D, holds no
    points, has an unknown unit, or whose labels the marker set cannot serve."""
    path = Path(path)
    source = str(path)
    points, labels, fps, unit = _read_points(path, source)
    points = points * UNITS[unit]
    markers = marker_set.markers(points, labels, source)
    turn = _up_turn(markers, source)
    points, markers = points @ turn.T, markers @ turn.T
    missing = float(np.isnan(markers[..., 0]).mean())
    warnings_ = [f"{missing:.1%} of the 8 markers missing"] if missing else []
    return MarkerTake(
        name=path.stem,
        points=points,
        labels=labels,
        markers=markers,
        fps=fps,
        source=str(path.resolve()),
        marker_set=marker_set.name,
        warnings=warnings_,
        meta={"units": unit, "format": "c3d"},
    )


def _read_points(path: Path, source: str) -> tuple[np.ndarray, tuple[str, ...], float, str]:
    """Points (n, m, 3) in file units with NaN for missing ones, labels, rate, unit."""
    import c3d  # the reader loads only when a C3D file is read

    try:
        stream = path.open("rb")
    except OSError as exc:
        raise C3dError(source, f"cannot read file: {exc.strerror or exc}") from exc
    with stream, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "no analog data", which marker files need not have
        try:
            reader = c3d.Reader(stream)
            frames = [points for _, points, _ in reader.read_frames()]
            labels = tuple(_label(label) for label in reader.point_labels)
            fps = float(reader.point_rate)
            units = reader.get("POINT:UNITS")
            unit = units.string_value.strip().lower() if units is not None else ""
        except Exception as exc:  # the c3d package raises many kinds on damaged files
            problem = f"not a readable C3D file ({type(exc).__name__}: {exc})"
            raise C3dError(source, problem) from None
    if not frames or not labels:
        raise C3dError(source, "holds no 3D points")
    if unit not in UNITS:
        raise C3dError(source, f"POINT:UNITS is {unit!r}; known units are {', '.join(UNITS)}")
    if not 0 < fps < float("inf"):
        raise C3dError(source, f"POINT:RATE is {fps!r}, not a frame rate")
    data = np.stack(frames).astype(np.float64)
    if data.shape[1] != len(labels):
        raise C3dError(source, f"{len(labels)} labels for {data.shape[1]} points")
    points = data[..., :3]
    points[(data[..., 3] < 0) | ~np.isfinite(points).all(axis=-1)] = np.nan
    return points, labels, fps, unit


def _label(label: str) -> str:
    """A point label without padding and subject prefix ("Male:LSHO " -> "LSHO")."""
    return str(label).strip().rsplit(":", 1)[-1].strip()


def _up_turn(markers: np.ndarray, source: str) -> np.ndarray:
    """The rotation (3, 3) that takes the lab's up axis (shoulders above feet, on the
    mean over the take) to +Y, keeping the frame right-handed."""
    shoulders = np.nanmean(markers[:, :2], axis=(0, 1))
    feet = np.nanmean(markers[:, 6:8], axis=(0, 1))
    rise = shoulders - feet
    if not np.isfinite(rise).all():
        raise C3dError(source, "the shoulder and foot markers are missing in every frame")
    axis = int(np.argmax(np.abs(rise)))
    sign = np.sign(rise[axis])
    turns = {  # (up axis, sign) -> matrix taking that axis to +Y, right-handed
        (0, 1.0): [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
        (0, -1.0): [[0, 1, 0], [-1, 0, 0], [0, 0, 1]],
        (1, 1.0): [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        (1, -1.0): [[1, 0, 0], [0, -1, 0], [0, 0, -1]],
        (2, 1.0): [[1, 0, 0], [0, 0, 1], [0, -1, 0]],
        (2, -1.0): [[1, 0, 0], [0, 0, -1], [0, 1, 0]],
    }
    return np.array(turns[(axis, float(sign))], dtype=np.float64)
