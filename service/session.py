"""`CaptureSession`: one subject's live capture, from camera packets to avatar poses.

Each packet first passes the session's `ReplayGuard` (new, not a copy, on the server's
clock; a node's new epoch restarts its camera in the frame sync), and a marker packet
loses the markers and blobs outside its camera's image (`keep_inside`, counted). Per
frame assembled by `FrameSync` (one packet per camera, or at least `min_cameras`
after waiting `wait_ms`), the session hands the cameras' marker pixels, labelled and
unlabelled (`CameraMarkers`), to its `FramePipeline` (labelling, triangulation,
reconstruction, retargeting, VMC out; in the event loop
or in a worker process, see `samba.service.pipeline_workers`). A session whose `input` is
"poses" takes the pose packets of one markerless node instead (whatever camera id it
sends), and its `PosePipeline` only retargets and sends them. When the computed frame comes
back (`complete`), the session counts it, sends it to the viewer and writes it to the
take being recorded.

Times are wall-clock seconds (`time.time()`, the clock the server stamps arriving
datagrams with); the latency of a frame runs from the arrival of its last packet to
the moment its VMC bundles have been handed to the network.
"""

from __future__ import annotations

import logging
import re
import time
from contextlib import AbstractContextManager
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from samba.body import N_MARKERS
from samba.cameras import read_calibration
from samba.reconstruct import SkinOffsets
from samba.service.errors import ServiceError
from samba.service.frame_pipeline import CameraMarkers, FrameInput, FrameOutput
from samba.service.frame_sync import FrameSync, SyncedFrame
from samba.service.image_bounds import keep_inside
from samba.service.metrics import LabelCounts, LatencyWindow
from samba.service.packet import MarkerPacket, Packet, PosePacket
from samba.service.replay_guard import DEFAULT_MAX_SKEW_S, ReplayGuard, Verdict
from samba.service.session_config import SessionConfig
from samba.service.take_recorder import TakeRecorder
from samba.service.viewer import ViewerHub, frame_message

LOG = logging.getLogger(__name__)

TAKE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}")
"""A take name given to `start_take`: it becomes the file name `<name>.mcap`."""


class Pipelines(Protocol):
    """Where sessions' frames are computed (`samba.service.pipeline_workers`)."""

    def open(self, config: SessionConfig, clock_zero: float) -> int: ...

    def submit(
        self, session: str, sequence: int, values: FrameInput, frame_time: float, arrival: float
    ) -> None: ...

    def together(self) -> AbstractContextManager[None]: ...

    def close_session(self, session: str) -> None: ...

    def worker_pids(self) -> list[int]: ...

    def shutdown(self) -> None: ...


@dataclass(frozen=True)
class TakeInfo:
    """A take of this session: its `path`, `name`, `frames` written and whether it is
    still `recording`."""

    path: Path
    name: str
    frames: int
    recording: bool

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict of this take."""
        return {
            "name": self.name,
            "path": str(self.path),
            "frames": self.frames,
            "recording": self.recording,
        }


class CaptureSession:
    """A running capture session; see the module docstring.

    Reads the calibration and opens the session's pipeline in `pipelines` (which opens
    the pose database read only and the VMC socket); raises `ServiceError` /
    `InputError` naming the file when one cannot be used. `takes_dir` is where
    `start_take` writes; frames go to `viewer` while the session has viewer clients;
    `max_skew_s` is the replay guard's window around the server clock (s).
    """

    def __init__(
        self,
        config: SessionConfig,
        takes_dir: str | Path,
        pipelines: Pipelines,
        viewer: ViewerHub | None = None,
        max_skew_s: float = DEFAULT_MAX_SKEW_S,
    ) -> None:
        self.config = config
        self.takes_dir = Path(takes_dir)
        self._viewer = viewer
        self.poses = config.input == "poses"
        self.cameras = None if self.poses else read_calibration(config.calibration)
        if self.cameras is not None and config.min_cameras > len(self.cameras):
            raise ServiceError(
                str(config.calibration),
                f"session {config.name!r} wants min_cameras {config.min_cameras}, but the "
                f"calibration has {len(self.cameras)} camera(s)",
            )
        self.started = time.time()
        self._pipelines = pipelines
        self.database_poses = pipelines.open(config, self.started)
        count = 1 if self.cameras is None else len(self.cameras)
        self.sync = FrameSync(
            range(count),
            config.fps,
            wait_s=config.wait_ms / 1e3,
            min_cameras=1 if self.poses else config.min_cameras,  # poses: the one node
        )
        self.guard = ReplayGuard(max_skew_s)
        self.markers_outside = 0
        self.blobs_outside = 0
        self.latency = LatencyWindow()
        self.labels = LabelCounts()
        self.frames_out = 0
        self.frames_failed = 0
        self.predicted_frames = 0
        self.vmc_errors = 0
        self.subject: SkinOffsets | None = None
        """The subject's skin offsets once the calibration (`calibrate_s`) reached a frame."""
        self._sequence = 0
        self._in_flight: dict[int, SyncedFrame] = {}
        self._recorder: TakeRecorder | None = None
        self._takes: list[TakeInfo] = []

    @property
    def name(self) -> str:
        """The session's name (the packets' session id)."""
        return self.config.name

    def accepts(self, packet: Packet) -> bool:
        """Whether `packet` is of the kind this session's nodes send (`input`)."""
        return isinstance(packet, PosePacket) == self.poses

    def on_packet(self, packet: Packet, arrival: float) -> Verdict:
        """Take one decoded packet of the kind the session `accepts`, that arrived at
        `arrival` (UNIX seconds), and submit the frames it completes or pushes out.
        Returns the replay guard's verdict: a packet it drops changes nothing else."""
        verdict = self.guard.check(packet, arrival)
        if not verdict.accepted:
            return verdict
        if isinstance(packet, PosePacket):
            packet = replace(packet, camera=0)  # one node: its camera id is informative
        elif self.cameras is not None and packet.camera < len(self.cameras):
            packet = self._inside(packet)
        if verdict is Verdict.RESTART:
            self.sync.restart(packet.camera)
        for frame in self.sync.add(packet, arrival):
            self._submit(frame)
        return verdict

    def _inside(self, packet: MarkerPacket) -> MarkerPacket:
        """`packet` without the markers and blobs outside its camera's image, counted."""
        assert self.cameras is not None
        packet, markers, blobs = keep_inside(packet, self.cameras[packet.camera])
        self.markers_outside += markers
        self.blobs_outside += blobs
        return packet

    def on_timer(self, now: float) -> None:
        """Submit the frames whose wait for late cameras has run out at `now` (s)."""
        for frame in self.sync.expire(now):
            self._submit(frame)

    def deadline(self) -> float | None:
        """When `on_timer` is next due (s), None if no frame is waiting."""
        return self.sync.deadline()

    def _submit(self, frame: SyncedFrame) -> None:
        values: FrameInput
        if self.cameras is None:
            values = frame.packets[0].pose
        else:
            labels = np.full((len(self.cameras), N_MARKERS, 2), np.nan)
            blobs: list[np.ndarray | None] = [None] * len(self.cameras)
            for camera, packet in frame.packets.items():
                labels[camera] = packet.markers
                blobs[camera] = packet.blobs
            values = CameraMarkers(labels, tuple(blobs))
        self._sequence += 1
        self._in_flight[self._sequence] = frame
        self._pipelines.submit(self.name, self._sequence, values, frame.time, frame.last_arrival)

    def complete(self, sequence: int, output: FrameOutput) -> None:
        """Take the pipeline's `output` for frame `sequence`: count it, record it, show it
        (a frame no longer in flight is ignored)."""
        frame = self._in_flight.pop(sequence, None)
        if frame is None:
            return
        estimate, markers = output.estimate, output.markers
        self.latency.add(output.latency)
        self.frames_out += 1
        self.predicted_frames += estimate.predicted
        self.vmc_errors = output.vmc_errors
        cameras = list(frame.packets)
        if not self.poses:
            sent = np.stack([frame.packets[c].markers for c in cameras])
            self.labels.add(sent, output.labels[cameras], output.found_again)
        if output.subject is not None:
            self.subject = output.subject
        if self._recorder is not None:
            if output.subject is not None and not self._recorder.subject_written:
                self._recorder.write_subject(output.subject)
            self._recorder.write_frame(
                max(0, round(frame.time * 1e9)),
                estimate,
                markers,
                {str(c): output.labels[c] for c in cameras} if not self.poses else {},
            )
        if self._viewer is not None and self._viewer.clients(self.name):
            self._viewer.publish(
                self.name,
                frame_message(
                    self.name,
                    self.frames_out,
                    frame.time,
                    estimate.pose,
                    markers,
                    output.latency * 1e3,
                    estimate.confident,
                    estimate.predicted,
                ),
            )

    def fail(self, sequence: int, reason: str) -> None:
        """Frame `sequence` could not be computed: count it as failed and log why."""
        if self._in_flight.pop(sequence, None) is not None:
            self.frames_failed += 1
            LOG.error("session %s: a frame was lost: %s", self.name, reason)

    # -- takes ---------------------------------------------------------------------------

    def start_take(self, name: str | None = None) -> TakeInfo:
        """Start recording to `<takes_dir>/<name>.mcap` (default name: session name and
        UTC time). `ServiceError` when a take is already recording, the name is not
        1..64 of `[A-Za-z0-9._-]`, or the file exists."""
        if self._recorder is not None:
            raise ServiceError(self.name, f"take {self._recorder.name!r} is already recording")
        if name is None:
            name = f"{self.name}_{datetime.now(UTC):%Y%m%d-%H%M%S}"
        if not TAKE_NAME.fullmatch(name):
            raise ServiceError(
                name, "a take name is 1..64 of [A-Za-z0-9._-] starting with a letter or digit"
            )
        self.takes_dir.mkdir(parents=True, exist_ok=True)
        self._recorder = TakeRecorder(self.takes_dir / f"{name}.mcap", self.config.fps, name)
        return self._take_info(self._recorder, recording=True)

    def stop_take(self) -> TakeInfo:
        """Stop recording and close the file; `ServiceError` when no take is recording."""
        if self._recorder is None:
            raise ServiceError(self.name, "no take is recording")
        recorder, self._recorder = self._recorder, None
        recorder.close()
        info = self._take_info(recorder, recording=False)
        self._takes.append(info)
        return info

    def flush_take(self) -> None:
        """Hand the recording take's buffered frames to the operating system (no-op when
        nothing records): the server does this every second, so that a crash loses at
        most the last second even when frames stop coming."""
        if self._recorder is not None:
            self._recorder.flush()

    @property
    def recording(self) -> TakeInfo | None:
        """The take being recorded, None when none is."""
        return None if self._recorder is None else self._take_info(self._recorder, True)

    def takes(self) -> list[TakeInfo]:
        """The takes recorded since the session started, the current one last."""
        current = self.recording
        return [*self._takes] if current is None else [*self._takes, current]

    def close(self) -> None:
        """Stop a recording take (its file stays complete) and close the pipeline."""
        if self._recorder is not None:
            self.stop_take()
        self._pipelines.close_session(self.name)

    @staticmethod
    def _take_info(recorder: TakeRecorder, recording: bool) -> TakeInfo:
        return TakeInfo(recorder.path, recorder.name, recorder.frames_written, recording)

    # -- reporting -----------------------------------------------------------------------

    def status(self) -> dict[str, Any]:
        """A JSON-ready description of the session: config, cameras, state."""
        c = self.config
        return {
            "name": c.name,
            "input": c.input,
            "cameras": [
                {"id": i, "name": cam.name, "size": list(cam.size)}
                for i, cam in enumerate(self.cameras or ())
            ],
            "calibration": None if c.calibration is None else str(c.calibration),
            "database": None if c.database is None else str(c.database),
            "database_poses": self.database_poses,
            "method": c.method,
            "fps": c.fps,
            "vmc": [f"{host}:{port}" for host, port in c.vmc],
            "recording": None if self.recording is None else self.recording.name,
            "frames_out": self.frames_out,
        }

    def metrics(self) -> dict[str, Any]:
        """A JSON-ready snapshot of the session's counters (`labels`: `LabelCounts`, None
        for a poses session) and latency percentiles."""
        counts = self.sync.counts
        return {
            "frames_out": self.frames_out,
            "frames_predicted": self.predicted_frames,
            "frames_failed": self.frames_failed,
            "subject_calibrated": self.subject is not None,
            "frames_in_flight": len(self._in_flight),
            "sync": dict(vars(counts)),
            "outside_image": {"markers": self.markers_outside, "blobs": self.blobs_outside},
            "labels": None if self.poses else self.labels.summary(),
            "latency": self.latency.summary(),
            "vmc_send_errors": self.vmc_errors,
            "uptime_s": round(time.time() - self.started, 3),
        }
