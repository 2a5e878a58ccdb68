"""`read_take`: a take recorded by the live service (`samba.service.take_recorder.TakeRecorder`)
back as a `Take`, even from a killed recorder.

The file is read as a stream of records, not through its summary, so a file without a
footer (the recorder died before `close`) yields every frame of its complete chunks.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np
from mcap.records import Channel, McapRecord, Message, Metadata
from mcap.stream_reader import StreamReader
from mcap.writer import MCAP0_MAGIC

from samba.body import N_JOINTS, Take
from samba.db import frame_count_problem, frame_rate_problem
from samba.ingest.errors import TakeFileError
from samba.ingest.input_files import MAX_FILE_BYTES, clipped, open_input, quoted
from samba.ingest.json_messages import json_message

POSE_TOPIC = "/pose_raw"
"""Topic of the reconstructed poses (`samba.PoseRaw` JSON: `joints` 13 x [x, y, z] meters)."""
TAKE_METADATA = "take"
"""Name of the metadata record holding `name`, `fps` and `start_time` (ISO 8601, UTC)."""
SUBJECT_METADATA = "subject"
"""Name of the metadata record holding the subject's `skin_offsets` (JSON), if any."""
GAP_PERIODS = 1.5
"""A step between recorded frames longer than this many frame periods is a gap of
dropped frames."""
MAX_INTERPOLATED_GAP_S = 0.5
"""Gaps up to this long (seconds) are bridged by interpolating the poses on either side;
across a longer one the last pose before it is held."""


def read_take(path: str | Path, max_bytes: int = MAX_FILE_BYTES) -> Take:
    """The take recorded in the MCAP file `path`: poses (n, 13, 3) float32 meters from
    `/pose_raw`, fps and name from the `take` metadata, rig "live".

    The poses keep their recorded timing: where frames were dropped (a step between
    recorded capture times longer than `GAP_PERIODS` frame periods) the take is resampled
    on the recorded timestamps to a regular grid at its fps, interpolating the poses
    across gaps up to `MAX_INTERPOLATED_GAP_S` and holding the last pose across longer
    ones, with a warning in `Take.warnings` saying what was done; `Take.source_frames`
    counts the frames recorded.

    A file cut short (no footer) gives the frames before the cut, with a warning in
    `Take.warnings` saying so and how many frames were recovered. The subject's skin
    offsets, when the take has them, are in `Take.meta["skin_offsets"]` (JSON). Raises
    `TakeFileError` naming the file when it cannot be read (not a regular file, over
    `max_bytes` bytes), is not MCAP, or holds no recorded frame.
    """
    path = Path(path)
    source = str(path)
    recorded = read_topic(path, POSE_TOPIC, _pose, max_bytes)
    if not recorded.values:
        cut = recorded.cut
        raise TakeFileError(
            source, "holds no recorded frame" + (f" (cut short: {cut})" if cut else "")
        )
    poses, times, fps, cut = recorded.values, recorded.times, recorded.fps, recorded.cut
    meta, subject = recorded.meta, recorded.subject
    warnings = []
    regular, gaps = on_the_clock(np.stack(poses), np.array(times, dtype=np.int64), fps, source)
    if gaps:
        warnings.append(gaps)
    if cut is not None and _ends_whole(path):
        warnings.append(
            f"file damaged inside ({cut}): recovered the {len(poses)} frames before the "
            "damaged chunk; the frames after it are lost"
        )
    elif cut is not None:
        warnings.append(
            f"file cut short (no MCAP footer; the recorder was killed?): recovered {len(poses)} "
            f"frames up to the last complete chunk ({cut})"
        )
    return Take(
        name=meta.get("name") or path.stem,
        poses=regular,
        source_frames=len(poses),
        fps=fps,
        source=str(path.resolve()),
        rig="live",
        warnings=warnings,
        meta={"start_time": meta.get("start_time", ""), "format": "mcap", **subject},
    )


@dataclass(frozen=True)
class RecordedTopic:
    """What `read_topic` read of a take: the `take` metadata `meta` (with a valid `fps`),
    the `subject` metadata (empty without), the decoded messages `values` of the topic
    with their capture `times` (ns), and `cut`: what stopped the reading early (None
    after a whole file)."""

    meta: dict[str, str]
    subject: dict[str, str]
    values: list[np.ndarray]
    times: list[int]
    fps: float
    cut: str | None


def read_topic(
    path: Path,
    topic: str,
    decode: Callable[[Message, str, int], np.ndarray],
    max_bytes: int = MAX_FILE_BYTES,
) -> RecordedTopic:
    """Every message of `topic` in the take recorded in the MCAP file `path`, decoded by
    `decode(message, source, index)`, read as a stream of records (a file without a
    footer gives its complete chunks). `TakeFileError` naming the file when it cannot be
    read (not a regular file, over `max_bytes` bytes), is not MCAP, or has no take
    metadata with a frame rate a store accepts (`samba.db.frame_rate_problem`)."""
    source = str(path)
    stream = open_input(path, max_bytes, TakeFileError)
    meta: dict[str, str] | None = None
    subject: dict[str, str] = {}
    channels: set[int] = set()
    values: list[np.ndarray] = []
    times: list[int] = []
    with stream:
        records = _RecordStream(stream, os.fstat(stream.fileno()).st_size)
        for record in records:
            if isinstance(record, Metadata) and record.name == TAKE_METADATA:
                meta = dict(record.metadata)
            elif isinstance(record, Metadata) and record.name == SUBJECT_METADATA:
                subject = dict(record.metadata)
            elif isinstance(record, Channel) and record.topic == topic:
                channels.add(record.id)
            elif isinstance(record, Message) and record.channel_id in channels:
                values.append(decode(record, source, len(values)))
                times.append(record.log_time)
    if records.count == 0:
        raise TakeFileError(source, f"not an MCAP file ({records.error})")
    if meta is None:
        raise TakeFileError(source, "no take metadata: not a take recorded by samba")
    try:
        fps = float(meta.get("fps", ""))
    except ValueError:
        raise TakeFileError(
            source, f"take metadata has no valid fps: {quoted(str(meta.get('fps')))}"
        ) from None
    problem = frame_rate_problem(fps)
    if problem:
        raise TakeFileError(source, f"take metadata: {problem}")
    return RecordedTopic(meta, subject, values, times, fps, records.error)


def on_the_clock(
    poses: np.ndarray, times_ns: np.ndarray, fps: float, source: str
) -> tuple[np.ndarray, str]:
    """Poses (n, 13, 3) (or any frames (n, k, 3), such as markers) captured at `times_ns`
    (n,) integer nanoseconds, on a regular grid at `fps` frames per second from the first
    capture to the last, and what was done in words ("" when the frames were already
    regular: returned unchanged).

    Frames out of order are sorted and frames of one capture time kept once. A gap
    (a step over `GAP_PERIODS` periods) up to `MAX_INTERPOLATED_GAP_S` long is bridged by
    linear interpolation; across a longer one the last pose before it is held.
    `TakeFileError` naming the take file `source` when the grid would hold more frames
    than a take may (`samba.db.MAX_TAKE_FRAMES`)."""
    order = np.argsort(times_ns, kind="stable")
    times_ns, keep = np.unique(times_ns[order], return_index=True)
    poses = poses[order][keep]
    seconds = (times_ns - times_ns[0]) / 1e9
    steps = np.diff(seconds)
    period = 1.0 / fps
    gap_steps = steps > GAP_PERIODS * period
    if not gap_steps.any():
        return poses, ""
    frames = int(np.floor(seconds[-1] * fps + 0.5)) + 1
    problem = frame_count_problem(frames)
    if problem:
        raise TakeFileError(source, f"spans {seconds[-1]:.6g} s at {fps:g} fps: {problem}")
    grid = np.arange(frames) / fps
    after = np.clip(np.searchsorted(seconds, grid, side="right"), 1, len(seconds) - 1)
    before = after - 1
    span = seconds[after] - seconds[before]
    weight = np.clip((grid - seconds[before]) / span, 0.0, 1.0)
    weight[span > MAX_INTERPOLATED_GAP_S] = 0.0  # hold the last pose across a long gap
    resampled = poses[before] + weight[:, None, None] * (poses[after] - poses[before])
    held = int((steps > MAX_INTERPOLATED_GAP_S).sum())
    missing = int(np.round(steps[gap_steps] * fps).sum() - gap_steps.sum())
    note = (
        f"{int(gap_steps.sum())} gaps of dropped frames (longest {steps.max():.2f} s, about "
        f"{missing} frames missing): resampled on the recorded timestamps to {len(grid)} "
        f"frames at {fps:g} fps ({grid[-1]:.2f} s), poses interpolated across gaps up to "
        f"{MAX_INTERPOLATED_GAP_S:g} s"
    )
    if held:
        note += f", the last pose held across {held} longer"
    return resampled.astype(np.float32), note


def _ends_whole(path: Path) -> bool:
    """Whether the file ends with MCAP's closing magic bytes: written to the end, so a
    record that stopped the reading is damage inside it, not a cut."""
    with path.open("rb") as stream:
        stream.seek(max(path.stat().st_size - len(MCAP0_MAGIC), 0))
        return stream.read() == MCAP0_MAGIC


class _RecordStream:
    """Iterates the records of an MCAP file of `size` bytes until its end or the first
    undecodable byte. Afterwards `count` is the number of records read and `error`
    describes what stopped the stream early (None after a complete file)."""

    def __init__(self, stream: BinaryIO, size: int) -> None:
        reader = StreamReader(stream, validate_crcs=True, record_size_limit=size)
        self._records = iter(reader.records)
        self.count = 0
        self.error: str | None = None

    def __iter__(self) -> Iterator[McapRecord]:
        while True:
            try:
                record = next(self._records)
            except StopIteration:
                return
            except Exception as exc:  # mcap, struct, zstandard and lz4 each raise their own
                self.error = clipped(f"{type(exc).__name__}: {exc}".removesuffix(": "))
                return
            self.count += 1
            yield record


def _pose(message: Message, source: str, index: int) -> np.ndarray:
    """The (13, 3) joints of a `/pose_raw` message, float32 meters."""
    where = f"/pose_raw message {index}"
    document = json_message(message.data, source, where)
    try:
        joints = np.array(document["joints"], dtype=np.float32)
    except KeyError:
        raise TakeFileError(source, f"{where} has no 'joints'") from None
    except (ValueError, TypeError) as exc:
        raise TakeFileError(source, f"{where} is malformed: {clipped(str(exc))}") from exc
    if joints.shape != (N_JOINTS, 3):
        raise TakeFileError(source, f"{where}: joints of shape {joints.shape}, not (13, 3)")
    if not np.isfinite(joints).all():
        raise TakeFileError(source, f"{where}: joints hold NaN or infinity")
    return joints
