"""`FramePipeline`: what a capture session computes for each frame.

From the marker pixels of a frame's cameras (`CameraMarkers`): find the labels the nodes
lost (`samba.stage_tracking`, unless the session keeps the nodes' labels), undistort
the labels, triangulate the 8 markers (DLT with outlier gating), reconstruct the 13
joints with the session's pose database and method
(`samba.reconstruction.Reconstructor.step`, the same code as the offline
reconstruction), retarget them to the avatar (`export.live_retarget`) and hand the VMC
bundles to the network. It holds all of a session's CPU work and none of its
bookkeeping, so a server can run it beside its event loop in a worker process
(`service.pipeline_workers`); `service.session.CaptureSession` keeps the rest.

Times are wall-clock seconds (`time.time()`); a frame's latency runs from the arrival
of its last packet to the moment its VMC bundles have been sent.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from db.index import PoseIndex
from db.store import PoseStore
from export.avatar_file import read_avatar_rig
from export.humanoid import HumanoidRig
from export.live_retarget import LiveRetarget
from samba.calibration_file import read_calibration
from samba.cross_view_labels import CrossViewSettings
from samba.methods import method
from samba.reconstruction import PoseEstimate
from samba.skeleton import N_MARKERS, mirror_poses
from samba.stage_tracking import StageTracker
from samba.triangulation import Triangulation
from service.session_config import SessionConfig
from service.vmc import VmcSender, frame_bundles, unity_values

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
    the network refused so far in this session, and `found_again`: whether the server's
    labelling found the subject again in this frame after losing it (`StageTracker`)."""

    labels: np.ndarray
    markers: np.ndarray
    estimate: PoseEstimate
    latency: float
    vmc_errors: int
    found_again: bool = False


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

    def __init__(self, config: SessionConfig, clock_zero: float) -> None:
        assert config.calibration is not None and config.database is not None
        self.config = config
        self.cameras = read_calibration(config.calibration)
        self._projections = self.cameras.projections
        chosen = method(config.method)
        store = PoseStore.open(config.database)
        index = store.index
        if chosen.mirrored_database:
            poses = np.asarray(store.poses)
            index = PoseIndex.build(
                np.concatenate([poses, mirror_poses(poses)]), scale_by_tibia=store.scale_by_tibia
            )
        self.reconstructor = chosen.build(index)
        self.reconstructor.prepare(PREPARED_MISSING)
        self.avatar = AvatarStream(config, clock_zero)
        self._stage: StageTracker | None = None
        self.server_labels = config.labels == "server" or (
            config.labels == "auto" and len(self.cameras) >= 3
        )
        """Whether the server finds the labels the nodes lost (`labels`)."""

    @property
    def database_poses(self) -> int:
        """How many poses the reconstruction searches."""
        return len(self.reconstructor.source.poses)

    def process(self, frame: CameraMarkers, frame_time: float, last_arrival: float) -> FrameOutput:
        """Compute one frame from the cameras' marker pixels `frame`, captured at
        `frame_time` and complete at `last_arrival` (s)."""
        searches = 0 if self._stage is None else self._stage.searches
        labels = self._label(frame)
        found_again = self._stage is not None and self._stage.searches > searches
        views = Triangulation.from_views(
            self._projections,
            self.cameras.undistort(labels),
            gate_px=self.config.gate_px or None,
        )
        markers = views.points
        estimate = self.reconstructor.step(markers)
        errors = self.avatar.send(estimate.pose, frame_time)
        latency = time.time() - last_arrival
        return FrameOutput(labels, markers, estimate, latency, errors, found_again)

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


def open_pipeline(config: SessionConfig, clock_zero: float) -> FramePipeline | PosePipeline:
    """The pipeline of a session's `input` kind."""
    if config.input == "poses":
        return PosePipeline(config, clock_zero)
    return FramePipeline(config, clock_zero)
