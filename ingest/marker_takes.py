"""Marker takes from any file that holds them: a C3D file (`samba.ingest.c3d_take`) or a
take the live service recorded (its `/markers` topic: the triangulated 8 markers).

`read_marker_take` picks the reader by the file's suffix. A recorded take's markers keep
their recorded timing: frames dropped in the recording are put back on a regular grid
as `samba.ingest.mcap_take.read_take` does for its poses (interpolated across short gaps).
"""

from __future__ import annotations

import base64
from pathlib import Path

import numpy as np
from mcap.records import Message

from samba.body import MARKER_NAMES, N_MARKERS
from samba.ingest.c3d_take import MarkerTake, read_c3d
from samba.ingest.errors import TakeFileError
from samba.ingest.input_files import clipped
from samba.ingest.json_messages import json_message
from samba.ingest.marker_sets import PLUG_IN_GAIT, MarkerSet
from samba.ingest.mcap_take import on_the_clock, read_topic

MARKER_TOPIC = "/markers"
"""Topic of the triangulated markers in a recorded take (`foxglove.PointCloud`: x, y, z
float32 and the marker's number uint32 per present marker)."""
_POINT = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("marker", "<u4")])


def read_marker_take(path: str | Path, marker_set: MarkerSet = PLUG_IN_GAIT) -> MarkerTake:
    """The marker take in `path`: a `.c3d` file (its 8 markers by `marker_set`) or a take
    recorded by `samba serve` (`.mcap`). Raises `C3dError` / `TakeFileError` naming the
    file, or `TakeFileError` for another suffix."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".c3d":
        return read_c3d(path, marker_set)
    if suffix == ".mcap":
        return read_recorded_markers(path)
    raise TakeFileError(str(path), "marker takes are .c3d files or takes recorded by samba (.mcap)")


def read_recorded_markers(path: str | Path) -> MarkerTake:
    """The 8 markers (n, 8, 3) meters, NaN = missing, that the live service triangulated
    and recorded in the take `path`, on a regular grid at the take's fps. `TakeFileError`
    naming the file when it cannot be read, is not a take or holds no markers."""
    path = Path(path)
    recorded = read_topic(path, MARKER_TOPIC, _markers)
    if not recorded.values:
        raise TakeFileError(str(path), f"holds no {MARKER_TOPIC} messages (no recorded markers)")
    frames, times, fps, meta = recorded.values, recorded.times, recorded.fps, recorded.meta
    markers, gaps = on_the_clock(np.stack(frames), np.array(times, dtype=np.int64), fps, str(path))
    markers = np.asarray(markers, dtype=np.float64)
    notes = [gaps] if gaps else []
    if recorded.cut:
        notes.append(f"file cut short or damaged ({recorded.cut}): read {len(frames)} frames")
    return MarkerTake(
        name=meta.get("name") or path.stem,
        points=markers,
        labels=MARKER_NAMES,
        markers=markers,
        fps=fps,
        source=str(path.resolve()),
        marker_set="samba",
        warnings=notes,
        meta={"format": "mcap"},
    )


def _markers(message: Message, source: str, index: int) -> np.ndarray:
    """The (8, 3) markers of a `/markers` message, meters, NaN where absent."""
    where = f"{MARKER_TOPIC} message {index}"
    cloud = json_message(message.data, source, where)
    try:
        if cloud["point_stride"] != _POINT.itemsize:
            raise ValueError(f"point stride {cloud['point_stride']}, not {_POINT.itemsize}")
        points = np.frombuffer(base64.b64decode(cloud["data"], validate=True), dtype=_POINT)
    except (KeyError, ValueError, TypeError) as exc:
        raise TakeFileError(source, f"{where} is malformed: {clipped(str(exc))}") from None
    if (points["marker"] >= N_MARKERS).any():
        raise TakeFileError(source, f"{where} names a marker beyond the {N_MARKERS}")
    markers = np.full((N_MARKERS, 3), np.nan)
    for axis, name in enumerate("xyz"):
        markers[points["marker"], axis] = points[name]
    return markers
