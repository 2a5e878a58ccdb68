"""`TakeRecorder`: writes a live take to an MCAP file that Foxglove opens (FORMATS.md section 4).

Topics, all JSON with a JSON schema, log times in nanoseconds of each frame's capture time:

* `/pose_raw` (`samba.PoseRaw`): the reconstructed pose, `joints` 13 x [x, y, z] meters in
  the world frame (+Y up), with the frame number and the reconstruction diagnostics.
* `/skeleton` (`foxglove.SceneUpdate`): entity `skeleton` in frame `mocap`, 13 spheres and
  one LINE_LIST of the bones.
* `/markers` (`foxglove.PointCloud`): the triangulated markers present, float32 x, y, z
  meters and a uint32 `marker` field (index into `MARKER_NAMES`).
* `/camera/<id>/markers` (`samba.CameraMarkers`): one camera's 8 x [u, v] pixels, null
  where the marker was not seen.
* `/tf` (`foxglove.FrameTransforms`): once, the static world -> mocap rotation of +90
  degrees about X that shows our +Y up as Foxglove's +Z up.

Take facts (name, fps, start time) go in the `take` metadata record. The file is
append-only: chunks are small and flushed about every second, so a killed recorder
leaves a prefix that `samba.ingest.mcap_take.read_take` recovers.
"""

from __future__ import annotations

import base64
import json
import time
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING, Any

import numpy as np
from mcap.writer import Writer

from samba.body import BONES, JOINT_NAMES, N_JOINTS, N_MARKERS, TORSO_EDGES
from samba.ingest import POSE_TOPIC, SUBJECT_METADATA, TAKE_METADATA
from samba.service.errors import ServiceError

if TYPE_CHECKING:
    from samba.reconstruct import PoseEstimate, SkinOffsets


FRAME_ID = "mocap"
SKELETON_LINES: tuple[tuple[int, int], ...] = (*BONES, *TORSO_EDGES, (0, 1), (0, 2))
"""Joint pairs drawn as lines: the limb bones, the torso edges, head to each shoulder."""
JOINT_DIAMETER = 0.04
"""Sphere diameter of a drawn joint, meters."""

_WORLD_TO_MOCAP = {"x": 0.7071067811865476, "y": 0.0, "z": 0.0, "w": 0.7071067811865476}
_IDENTITY = {
    "position": {"x": 0.0, "y": 0.0, "z": 0.0},
    "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
}
_FLOAT32, _UINT32 = 7, 5  # foxglove NumericType values
_MARKER_POINT = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("marker", "<u4")])
_COLORS = {  # joint and bone colour by the frame's diagnostics, RGBA 0..1
    "confident": {"r": 0.2, "g": 0.8, "b": 0.3, "a": 1.0},
    "unsure": {"r": 1.0, "g": 0.6, "b": 0.1, "a": 1.0},
    "predicted": {"r": 0.6, "g": 0.6, "b": 0.6, "a": 1.0},
}


def _schema(title: str, properties: dict[str, Any]) -> bytes:
    return json.dumps({"title": title, "type": "object", "properties": properties}).encode()


_TIME = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}
_ARRAY = {"type": "array"}
_SCHEMAS: dict[str, bytes] = {
    "samba.PoseRaw": _schema(
        "samba.PoseRaw",
        {
            "timestamp": _TIME,
            "frame": {"type": "integer"},
            "joints": {"type": "array", "description": f"{N_JOINTS} x [x, y, z] meters"},
            "residual_m": {"type": ["number", "null"]},
            "markers_used": {"type": "integer"},
            "confident": {"type": "boolean"},
            "predicted": {"type": "boolean"},
        },
    ),
    "samba.CameraMarkers": _schema(
        "samba.CameraMarkers",
        {
            "timestamp": _TIME,
            "frame": {"type": "integer"},
            "camera": {"type": "string"},
            "markers": {"type": "array", "description": f"{N_MARKERS} x [u, v] pixels or null"},
        },
    ),
    "foxglove.SceneUpdate": _schema(
        "foxglove.SceneUpdate", {"deletions": _ARRAY, "entities": _ARRAY}
    ),
    "foxglove.FrameTransforms": _schema("foxglove.FrameTransforms", {"transforms": _ARRAY}),
    "foxglove.PointCloud": _schema(
        "foxglove.PointCloud",
        {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "pose": {"type": "object"},
            "point_stride": {"type": "integer"},
            "fields": _ARRAY,
            "data": {"type": "string", "contentEncoding": "base64"},
        },
    ),
}
_TOPIC_SCHEMAS = {
    POSE_TOPIC: "samba.PoseRaw",
    "/skeleton": "foxglove.SceneUpdate",
    "/markers": "foxglove.PointCloud",
    "/tf": "foxglove.FrameTransforms",
}


class TakeRecorder:
    """Writes one take, frame by frame, to a new MCAP file; use it as a context manager.

    `path` must not exist yet. `fps` is the take's nominal frame rate, `name` defaults to
    the file's stem. `chunk_size` (uncompressed bytes) and `flush_interval_s` (seconds of
    wall time) bound what a crash can lose: a chunk is written when it grows past
    `chunk_size`, and everything is flushed to the operating system once
    `flush_interval_s` has passed since the last flush.
    """

    def __init__(
        self,
        path: str | Path,
        fps: float,
        name: str | None = None,
        chunk_size: int = 64 * 1024,
        flush_interval_s: float = 1.0,
    ) -> None:
        if not 0 < fps < float("inf"):
            raise ValueError(f"fps must be positive and finite, got {fps}")
        self.path = Path(path)
        self.name = name or self.path.stem
        self.fps = float(fps)
        self.frames_written = 0
        self.subject_written = False
        self._flush_interval_s = flush_interval_s
        try:
            self._file = self.path.open("xb")
        except FileExistsError as exc:
            raise ServiceError(
                str(self.path), "already exists; takes are never overwritten"
            ) from exc
        try:
            self._writer = Writer(self._file, chunk_size=chunk_size)
            self._writer.start(library="samba-mocap")
            self._schemas = {
                schema: self._writer.register_schema(schema, "jsonschema", data)
                for schema, data in _SCHEMAS.items()
            }
            self._channels = {
                topic: self._writer.register_channel(topic, "json", self._schemas[schema])
                for topic, schema in _TOPIC_SCHEMAS.items()
            }
            start = datetime.now(UTC).isoformat(timespec="milliseconds")
            self._writer.add_metadata(
                TAKE_METADATA, {"name": self.name, "fps": repr(self.fps), "start_time": start}
            )
            self._writer.flush()
        except BaseException:
            self._file.close()
            raise
        self._last_flush = time.monotonic()

    def write_frame(
        self,
        capture_time_ns: int,
        estimate: PoseEstimate,
        markers: np.ndarray,
        camera_markers: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        """Record one frame captured at `capture_time_ns` (integer nanoseconds, >= 0).

        `estimate` is the reconstruction (`pose` (13, 3) finite meters, `residual` meters,
        `markers_used`, `confident`, `predicted`); `markers` (8, 3) the triangulated
        markers in meters, NaN where missing; `camera_markers` maps a camera id to its
        (8, 2) detected markers in pixels, NaN where unseen. Flushes when due.
        """
        pose = np.asarray(estimate.pose, dtype=np.float64)
        if pose.shape != (N_JOINTS, 3) or not np.isfinite(pose).all():
            raise ValueError(f"pose must be finite (13, 3) meters, got shape {pose.shape}")
        markers = _checked(markers, (N_MARKERS, 3), "markers")
        cameras = {
            str(camera): _checked(points, (N_MARKERS, 2), f"camera {camera} markers")
            for camera, points in (camera_markers or {}).items()
        }
        t = int(capture_time_ns)
        if t < 0:
            raise ValueError(f"capture time must be >= 0 ns, got {t}")
        stamp = {"sec": t // 1_000_000_000, "nsec": t % 1_000_000_000}
        if self.frames_written == 0:
            self._publish("/tf", t, _transforms(stamp))
        residual = float(estimate.residual)
        self._publish(
            POSE_TOPIC,
            t,
            {
                "timestamp": stamp,
                "frame": self.frames_written,
                "joints": _decimals(pose),
                "residual_m": residual if np.isfinite(residual) else None,
                "markers_used": int(estimate.markers_used),
                "confident": bool(estimate.confident),
                "predicted": bool(estimate.predicted),
            },
        )
        self._publish("/skeleton", t, _scene_update(stamp, pose, _color(estimate)))
        self._publish("/markers", t, _point_cloud(stamp, markers))
        for camera, points in cameras.items():
            message = {
                "timestamp": stamp,
                "frame": self.frames_written,
                "camera": camera,
                "markers": [_decimals(uv) if np.isfinite(uv).all() else None for uv in points],
            }
            self._publish(f"/camera/{camera}/markers", t, message)
        self.frames_written += 1
        if time.monotonic() - self._last_flush >= self._flush_interval_s:
            self.flush()

    def write_subject(self, offsets: SkinOffsets) -> None:
        """Record the subject's skin offsets (`SkinOffsets.as_dict`, JSON) as the take's
        `subject` metadata, which `samba.ingest.read_take` gives back in
        `Take.meta["skin_offsets"]`."""
        document = json.dumps(offsets.as_dict(), separators=(",", ":"))
        self._writer.add_metadata(SUBJECT_METADATA, {"skin_offsets": document})
        self.subject_written = True

    def flush(self) -> None:
        """Write the open chunk and hand everything to the operating system (no fsync):
        a crash after this loses no frame written before it."""
        self._writer.flush()
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Write the summary and footer and close the file; calling it again does nothing."""
        if self._file.closed:
            return
        try:
            self._writer.finish()
        finally:
            self._file.close()

    def __enter__(self) -> TakeRecorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def _publish(self, topic: str, log_time_ns: int, message: dict[str, Any]) -> None:
        if topic not in self._channels:
            schema = self._schemas["samba.CameraMarkers"]
            self._channels[topic] = self._writer.register_channel(topic, "json", schema)
        self._writer.add_message(
            channel_id=self._channels[topic],
            log_time=log_time_ns,
            publish_time=log_time_ns,
            sequence=self.frames_written,
            data=json.dumps(message, separators=(",", ":"), allow_nan=False).encode(),
        )


def _checked(values: np.ndarray, shape: tuple[int, int], what: str) -> np.ndarray:
    values = np.asarray(values, dtype=np.float64)
    if values.shape != shape:
        raise ValueError(f"{what} must be {shape}, got {values.shape}")
    return values


def _decimals(values: np.ndarray) -> list[Any]:
    """Nested lists of the finite `values` as the shortest decimals that read back as the
    same float32 numbers."""
    values = np.asarray(values, dtype=np.float32)
    if values.ndim > 1:
        return [_decimals(row) for row in values]
    return [float(str(v)) for v in values]


def _xyz(point: list[float]) -> dict[str, float]:
    return dict(zip("xyz", point, strict=True))


def _color(estimate: PoseEstimate) -> dict[str, float]:
    if estimate.predicted:
        return _COLORS["predicted"]
    return _COLORS["confident" if estimate.confident else "unsure"]


def _transforms(stamp: dict[str, int]) -> dict[str, Any]:
    transform = {
        "timestamp": stamp,
        "parent_frame_id": "world",
        "child_frame_id": FRAME_ID,
        "translation": {"x": 0.0, "y": 0.0, "z": 0.0},
        "rotation": _WORLD_TO_MOCAP,
    }
    return {"transforms": [transform]}


def _scene_update(stamp: dict[str, int], pose: np.ndarray, color: dict[str, float]) -> dict:
    points = [_xyz(p) for p in _decimals(pose)]
    spheres = [
        {
            "pose": {"position": p, "orientation": _IDENTITY["orientation"]},
            "size": {"x": JOINT_DIAMETER, "y": JOINT_DIAMETER, "z": JOINT_DIAMETER},
            "color": color,
        }
        for p in points
    ]
    bones = {
        "type": 2,  # LINE_LIST
        "pose": _IDENTITY,
        "thickness": 0.015,
        "scale_invariant": False,
        "points": points,
        "color": color,
        "colors": [],
        "indices": [j for pair in SKELETON_LINES for j in pair],
    }
    entity = {
        "timestamp": stamp,
        "frame_id": FRAME_ID,
        "id": "skeleton",
        "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": False,
        "metadata": [{"key": "joints", "value": ",".join(JOINT_NAMES)}],
        "arrows": [],
        "cubes": [],
        "spheres": spheres,
        "cylinders": [],
        "lines": [bones],
        "triangles": [],
        "texts": [],
        "models": [],
    }
    return {"deletions": [], "entities": [entity]}


def _point_cloud(stamp: dict[str, int], markers: np.ndarray) -> dict[str, Any]:
    present = np.flatnonzero(np.isfinite(markers).all(axis=1))
    points = np.zeros(len(present), dtype=_MARKER_POINT)
    for axis, name in enumerate("xyz"):
        points[name] = markers[present, axis]
    points["marker"] = present
    fields = [{"name": n, "offset": 4 * i, "type": _FLOAT32} for i, n in enumerate("xyz")]
    fields.append({"name": "marker", "offset": 12, "type": _UINT32})
    return {
        "timestamp": stamp,
        "frame_id": FRAME_ID,
        "pose": _IDENTITY,
        "point_stride": _MARKER_POINT.itemsize,
        "fields": fields,
        "data": base64.b64encode(points.tobytes()).decode("ascii"),
    }
