"""`FramePipeline`: what a capture session computes for each frame.

From the marker pixels of a frame's cameras (`CameraMarkers`): find the labels the nodes
lost (`samba.markers.stage_tracking`, unless the session keeps the nodes' labels), undistort
the labels, triangulate the 8 markers (DLT with outlier gating), reconstruct the 13
joints with the session's pose database and method
(`samba.reconstruct.reconstruction.Reconstructor.step`, the same code as the offline
reconstruction), retarget them to the avatar (`samba.export.live_retarget`) and hand the VMC
bundles to the network. It holds all of a session's CPU work and none of its
bookkeeping, so a server can run it beside its event loop in a worker process
(`samba.service.pipeline_workers`); `samba.service.session.CaptureSession` keeps the rest.
`process_together` computes one frame each of several sessions that share their pose
index and method with one batched reconstruction and one batched retargeting.

Times are wall-clock seconds (`time.time()`); a frame's latency runs from the arrival
of its last packet to the moment its VMC bundles have been sent.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from samba.body import N_MARKERS
from samba.cameras import Triangulation, read_calibration
from samba.export import HumanoidRig, LiveRetarget, read_avatar_rig, retarget_together
from samba.markers import CrossViewSettings, StageTracker
from samba.reconstruct import (
    PoseEstimate,
    ReconstructionConfig,
    SkinOffsets,
    method,
    reconstruct_together,
)
from samba.service.session_config import SessionConfig
from samba.service.session_indexes import SessionIndexes
from samba.service.subject_calibration import SubjectCalibration
from samba.service.vmc import VmcSender, frame_bundles, unity_values

PREPARED_MISSING = 2
"""A session prepares the pose index for up to this many missing markers when it opens
(`Reconstructor.prepare`; 0.6 s for `samba`, 2 s for `best` at 10^4 poses), so that the
first occlusions of a capture do not stall frames while masked tables are built."""


@dataclass(frozen=True, eq=False)
class CameraMarkers:
    """One frame's marker pixels from every camera of a session: `labels` (c, 8, 2) raw
    pixels as the nodes labelled them (NaN: missing, or no packet from that camera);
    `blobs` per camera the (n, 2) raw pixels its node left unlabelled, None where no
    packet came."""

    labels: np.ndarray
    blobs: tuple[np.ndarray | None, ...]

    @classmethod
    def from_labels(cls, labels: np.ndarray) -> CameraMarkers:
        """Labels (c, 8, 2) from every camera, without unlabelled blobs."""
        return cls(np.asarray(labels), tuple(np.zeros((0, 2)) for _ in labels))

    def centroids(self) -> list[np.ndarray | None]:
        """Every blob each camera saw (n, 2), labelled or not; None where no packet came."""
        return [
            None if extra is None else np.concatenate([own[~np.isnan(own).any(axis=-1)], extra])
            for own, extra in zip(self.labels, self.blobs, strict=True)
        ]


FrameInput = CameraMarkers | np.ndarray
"""What a pipeline computes a frame from: a marker session's `CameraMarkers`, or a pose
session's pose (13, 3) m."""


@dataclass(frozen=True)
class FrameOutput:
    """One computed frame: `labels` (c, 8, 2) the raw pixels triangulated (the server's
    labels or the nodes'; (0, 8, 2) for a pose session), `markers` (8, 3) triangulated
    meters (NaN = missing), the reconstruction `estimate`, the `latency` in seconds from
    the frame's last packet to its VMC bundles sent, `vmc_errors`, the VMC datagrams
    the network refused so far in this session, `found_again`: whether the server's
    labelling found the subject again in this frame after losing it (`StageTracker`),
    and `subject`: the session's skin offsets once calibrated (`calibrate_s`)."""

    labels: np.ndarray
    markers: np.ndarray
    estimate: PoseEstimate
    latency: float
    vmc_errors: int
    found_again: bool = False
    subject: SkinOffsets | None = None


class AvatarStream:
    """A session's avatar output: retargets each pose (13, 3) m to the avatar of
    `config.avatar` (default: the built-in humanoid) and sends it as VMC bundles to
    `config.vmc`, time stamped in seconds from `clock_zero`."""

    def __init__(self, config: SessionConfig, clock_zero: float) -> None:
        self.clock_zero = clock_zero
        self.rig = (
            HumanoidRig.from_body() if config.avatar is None else read_avatar_rig(config.avatar)
        )
        self.retarget = LiveRetarget(self.rig)
        self.vmc = VmcSender(config.vmc)

    def send(self, pose: np.ndarray, frame_time: float) -> int:
        """Send the avatar in `pose` captured at `frame_time` (s); returns the VMC
        datagrams the network has refused so far."""
        rotations, root = self.retarget.step(pose)
        return self.emit(rotations, root, frame_time)

    def emit(self, rotations: np.ndarray, root: np.ndarray, frame_time: float) -> int:
        """Send the avatar's retargeted local bone `rotations` (17, 4) (x, y, z, w) and
        `root` (3,) m captured at `frame_time` (s); returns what `send` returns."""
        positions, unity_rotations = unity_values(root, rotations, self.rig)
        self.vmc.send(frame_bundles(positions, unity_rotations, frame_time - self.clock_zero))
        return sum(self.vmc.errors.values())

    def close(self) -> None:
        """Close the VMC socket."""
        self.vmc.close()


class FramePipeline:
    """One marker session's per-frame computation; see the module docstring.

    Opens the calibration and the pose database (read only) and the VMC socket; raises
    `InputError` subclasses naming the file when one cannot be used. VMC time stamps
    count seconds from `clock_zero` (wall clock, s).
    """

    def __init__(
        self, config: SessionConfig, clock_zero: float, indexes: SessionIndexes | None = None
    ) -> None:
        assert config.calibration is not None and config.database is not None
        self.config = config
        self.cameras = read_calibration(config.calibration)
        self._projections = self.cameras.projections
        chosen = method(config.method)
        indexes = SessionIndexes() if indexes is None else indexes
        self.reconstructor = chosen.build(indexes.index(config.database, chosen.mirrored_database))
        self.reconstructor.prepare(PREPARED_MISSING)
        self.avatar = AvatarStream(config, clock_zero)
        self._stage: StageTracker | None = None
        self.server_labels = config.server_labels(len(self.cameras))
        """Whether the server finds the labels the nodes lost (`labels`)."""
        frames = round(config.calibrate_s * config.fps)
        self.subject = (
            SubjectCalibration(self.reconstructor, frames, config.name) if frames else None
        )
        """The subject calibration of a session with `calibrate_s` (None without)."""

    @property
    def database_poses(self) -> int:
        """How many poses the reconstruction searches."""
        return len(self.reconstructor.source.poses)

    @property
    def reconstruction_key(self) -> tuple[int, ReconstructionConfig, type]:
        """Equal for the pipelines whose frames `process_together` reconstructs in one
        batch: same index object (`SessionIndexes`), method configuration and class."""
        r = self.reconstructor
        return id(r.source), r.config, type(r)

    def process(self, frame: CameraMarkers, frame_time: float, last_arrival: float) -> FrameOutput:
        """Compute one frame from the cameras' marker pixels `frame`, captured at
        `frame_time` and complete at `last_arrival` (s)."""
        (output,) = process_together([(self, frame, frame_time, last_arrival)])
        if isinstance(output, Exception):
            raise output
        return output

    def _observe(self, frame: CameraMarkers) -> _Observed:
        """The frame's labels and triangulated markers."""
        searches = 0 if self._stage is None else self._stage.searches
        labels = self._label(frame)
        found_again = self._stage is not None and self._stage.searches > searches
        views = Triangulation.from_views(
            self._projections,
            self.cameras.undistort(labels),
            gate_px=self.config.gate_px or None,
        )
        return _Observed(labels, views.points, found_again)

    def _send(
        self,
        observed: _Observed,
        estimate: PoseEstimate,
        retargeted: tuple[np.ndarray, np.ndarray],
        frame_time: float,
        last_arrival: float,
    ) -> FrameOutput:
        """Send the avatar of a reconstructed and `retargeted` frame (`AvatarStream.emit`);
        its output."""
        errors = self.avatar.emit(*retargeted, frame_time)
        latency = time.time() - last_arrival
        subject = None if self.subject is None else self.subject.offsets
        return FrameOutput(
            observed.labels,
            observed.markers,
            estimate,
            latency,
            errors,
            observed.found_again,
            subject,
        )

    def joints(self, markers: np.ndarray) -> np.ndarray:
        """The markers (8, 3) to reconstruct from triangulated ones: moved to their joints
        by the subject's skin offsets once calibrated (`SubjectCalibration.joints`)."""
        return markers if self.subject is None else self.subject.joints(markers)

    def _label(self, frame: CameraMarkers) -> np.ndarray:
        """The labels (c, 8, 2) to triangulate: the nodes' (without `server_labels`, and
        until every camera has sent a frame), else the nodes' with the ones they lost
        found again by the server from all the blobs."""
        if not self.server_labels:
            return frame.labels
        if self._stage is None:
            if any(blobs is None for blobs in frame.blobs):
                return frame.labels
            self._stage = StageTracker.from_labels(
                self.cameras, frame.labels, cross_view=CrossViewSettings()
            )
        return self._stage.step(frame.centroids(), known=frame.labels)

    def close(self) -> None:
        """Close the VMC socket."""
        self.avatar.close()


class PosePipeline:
    """One pose session's per-frame computation: the markerless node tracked the body
    already, so each pose (13, 3) m only goes to the avatar (`AvatarStream`)."""

    database_poses = 0
    """A pose session searches no database."""

    def __init__(self, config: SessionConfig, clock_zero: float) -> None:
        self.avatar = AvatarStream(config, clock_zero)

    def process(self, pose: np.ndarray, frame_time: float, last_arrival: float) -> FrameOutput:
        """Send the node's `pose` (13, 3) m captured at `frame_time`, complete at
        `last_arrival` (s); its markers are all missing (NaN)."""
        estimate = PoseEstimate(np.asarray(pose, dtype=np.float64), 0.0, 0, True, False)
        errors = self.avatar.send(estimate.pose, frame_time)
        markers = np.full((N_MARKERS, 3), np.nan)
        labels = np.zeros((0, N_MARKERS, 2))
        return FrameOutput(labels, markers, estimate, time.time() - last_arrival, errors)

    def close(self) -> None:
        """Close the VMC socket."""
        self.avatar.close()


@dataclass(frozen=True)
class _Observed:
    """A frame's `labels` (c, 8, 2) px, triangulated `markers` (8, 3) m and `found_again`
    (see `FrameOutput`)."""

    labels: np.ndarray
    markers: np.ndarray
    found_again: bool


FrameJob = tuple[FramePipeline, CameraMarkers, float, float]
"""A frame to compute: (pipeline, frame, frame_time, last_arrival) as `FramePipeline.process`
takes them."""


def process_together(jobs: Sequence[FrameJob]) -> list[FrameOutput | Exception]:
    """Compute one frame each of distinct marker sessions whose pipelines share a
    `reconstruction_key`, with the reconstructions in one batch
    (`samba.reconstruct.reconstruction.reconstruct_together`) and the retargeting in another
    (`samba.export.live_retarget.retarget_together`): the same outputs as one at a time, four
    frames for about twice the cost of one. Outputs come in the jobs' order; each
    frame's latency runs to the moment its VMC bundles leave. A frame whose own steps
    (labelling, triangulation) raise comes back as the exception, and the others go on;
    an exception in the batched steps propagates."""
    outputs: dict[int, FrameOutput | Exception] = {}
    kept: list[int] = []
    observed: list[_Observed] = []
    for i, (pipeline, frame, _, _) in enumerate(jobs):
        try:
            observed.append(pipeline._observe(frame))
        except Exception as exc:  # this frame's input or labelling state alone
            outputs[i] = exc
        else:
            kept.append(i)
    if kept:
        markers = [jobs[i][0].joints(o.markers) for i, o in zip(kept, observed, strict=True)]
        result = reconstruct_together([jobs[i][0].reconstructor for i in kept], np.stack(markers))
        retargets = [jobs[i][0].avatar.retarget for i in kept]
        rotations, roots = retarget_together(retargets, result.poses)
        for row, i in enumerate(kept):
            pipeline, _, frame_time, last_arrival = jobs[i]
            outputs[i] = pipeline._send(
                observed[row],
                result.estimate(row),
                (rotations[row], roots[row]),
                frame_time,
                last_arrival,
            )
    return [outputs[i] for i in range(len(jobs))]


def open_pipeline(
    config: SessionConfig, clock_zero: float, indexes: SessionIndexes | None = None
) -> FramePipeline | PosePipeline:
    """The pipeline of a session's `input` kind; marker sessions take their pose index
    from `indexes` (None: one of their own)."""
    if config.input == "poses":
        return PosePipeline(config, clock_zero)
    return FramePipeline(config, clock_zero, indexes)
