"""Model-free volumetric capture (Chu, Jenkins, Matarić 2003): a voxel volume sequence
in, a kinematic model derived from it and its joint angles out.

Per frame, the largest connected part of the volume is embedded by Isomap
(`samba.volume.isomap`), its skeleton curve found by nonlinear spherical shells
(`samba.volume.spherical_shells`) and cut into a frame model (`samba.volume.frame_kinematics`); the
frame models become one common model fitted to every frame (`samba.volume.sequence_model`).
The fitted model is then posed by the paper's axis construction: the root's frame is
the world's; every link's Z axis runs from where the posed model puts its start
towards its fitted end (`pose_model`), its Y axis is Z x (the parent link's X axis)
and X = Y x Z. A link's local rotation is its frame relative to its parent's.
`KinematicMotion` carries what a BVH file needs: the links' names, parents,
rest offsets (each link along its parent's Z axis) and the local rotations.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import butter, filtfilt
from scipy.spatial.transform import Rotation

from samba.base import InputError
from samba.body import continuous_quaternions, forward_kinematics, unit_vectors
from samba.volume.frame_kinematics import SKEWNESS, FrameModel, frame_model
from samba.volume.isomap import LANDMARKS, VoxelGraph, isomap
from samba.volume.sequence_model import SequenceFit, fit_sequence
from samba.volume.spherical_shells import ShellSettings, skeleton_curve
from samba.volume.voxel_grid import VoxelGrid

MIN_VOXELS = 50
"""Fewest voxels in a frame's largest part for it to be captured."""


@dataclass(frozen=True)
class CaptureSettings:
    """Parameters of model and motion capture: the Isomap neighbourhood `epsilon`
    (voxels) and `landmarks`, the spherical `shells` settings and the `skewness`
    threshold that places joints inside branches."""

    epsilon: float = float(np.sqrt(3.0))
    landmarks: int = LANDMARKS
    shells: ShellSettings = field(default_factory=ShellSettings)
    skewness: float = SKEWNESS


@dataclass(frozen=True)
class FrameTimes:
    """Seconds spent per frame in the Isomap step (graph and embedding) and in total."""

    isomap: np.ndarray
    total: np.ndarray


def frame_models(
    volumes: np.ndarray, grid: VoxelGrid, settings: CaptureSettings | None = None
) -> tuple[list[FrameModel], FrameTimes]:
    """Pass 1 over occupancy grids `volumes` (n, nx, ny, nz) bool: the frame models and
    the time each frame took. Raises `InputError` naming the frame whose volume is
    (nearly) empty."""
    settings = settings or CaptureSettings()
    volumes = np.asarray(volumes)
    if volumes.ndim != 4 or volumes.shape[1:] != tuple(grid.shape) or volumes.dtype != bool:
        raise InputError(
            "volumes",
            f"volumes must be (n, {', '.join(map(str, grid.shape))}) bool, "
            f"got {volumes.dtype} {volumes.shape}",
        )
    models, embed, total = [], [], []
    for t, volume in enumerate(volumes):
        start = time.perf_counter()
        indices = grid.indices(volume)
        graph = VoxelGraph.from_indices(indices, settings.epsilon)
        keep = graph.largest()
        if len(keep) < MIN_VOXELS:
            raise InputError(f"frame {t}", f"the volume has {len(keep)} connected voxels")
        part = graph.subgraph(keep)
        embedding = isomap(part, settings.landmarks)
        embedded = time.perf_counter()
        positions = grid.points_at(indices[keep])
        curve = skeleton_curve(embedding, part, positions, settings.shells)
        models.append(frame_model(curve, positions, settings.skewness))
        embed.append(embedded - start)
        total.append(time.perf_counter() - start)
    return models, FrameTimes(isomap=np.asarray(embed), total=np.asarray(total))


@dataclass(frozen=True)
class KinematicMotion:
    """A derived kinematic model and its motion.

    Joint 0 is the root; every other joint starts one link. `names` (J,), `parents`
    (J,) (-1 for the root, parents first), `offsets` (J, 3) meters: a joint's rest
    position in its parent's frame ((0, 0, parent link length), zero under the root);
    `lengths` (J,) the length of the link each joint starts (0 for the root);
    `rotations` (n, J, 4) local quaternions (x, y, z, w), the root's the identity;
    `root` (n, 3) meters; `positions` (n, J + leaves, 3) meters: the fitted joint
    positions then the end of each leaf link, as measured in the volumes; `fps`.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    lengths: np.ndarray
    rotations: np.ndarray
    root: np.ndarray
    positions: np.ndarray
    fps: float

    @property
    def leaves(self) -> list[int]:
        """Joints whose link carries no other link (an End Site each)."""
        return [j for j in range(1, len(self.names)) if j not in self.parents]

    def forward(self) -> np.ndarray:
        """Joint positions (n, J + leaves, 3) meters of the model's fixed link lengths
        posed by `rotations` from `root` (the BVH file's forward kinematics)."""
        n, leaves = len(self.root), self.leaves
        parents = np.array([*self.parents, *leaves])
        identity = np.broadcast_to([0.0, 0.0, 0.0, 1.0], (n, len(leaves), 4))
        rotations = np.concatenate([self.rotations, identity], axis=1)
        ends = np.zeros((len(leaves), 3))
        ends[:, 2] = self.lengths[leaves]
        translations = np.broadcast_to(np.concatenate([self.offsets, ends]), (n, len(parents), 3))
        translations = translations.copy()
        translations[:, 0] = self.root
        return forward_kinematics(parents, rotations, translations)

    def lowpassed(self, cutoff: float) -> KinematicMotion:
        """The motion with joint angles and root low-pass filtered: a zero-phase
        2nd-order Butterworth at `cutoff` Hz over the quaternion components (made
        continuous, renormalised). Takes of fewer than 10 frames are returned as is."""
        if not (0 < cutoff < self.fps / 2):
            raise InputError("--lowpass", f"cutoff must be in (0, {self.fps / 2}) Hz, got {cutoff}")
        if len(self.root) < 10:
            return self
        b, a = butter(2, cutoff / (self.fps / 2))
        q = filtfilt(b, a, continuous_quaternions(self.rotations), axis=0)
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
        return KinematicMotion(
            self.names,
            self.parents,
            self.offsets,
            self.lengths,
            q,
            filtfilt(b, a, self.root, axis=0),
            self.positions,
            self.fps,
        )


def pose_model(fit: SequenceFit, fps: float) -> KinematicMotion:
    """The common model posed in every frame by the paper's axis construction, each
    link as long as its fitted joints lie apart in the median frame (the straight
    distance: the curve between two joints is longer, and a leaf's curve runs on past
    its end into the volume's round tip).

    A link of fixed length cannot follow fitted joints that slide along the body from
    frame to frame (on real footage the legs part at heights 0.24-0.91 m below the root),
    so each link is aimed from where the posed model puts its start at its fitted end,
    parents first, rather than along the fitted joints' own direction: a link's error
    then stays its own instead of carrying on down the chain (on the shared lab's walk
    the posed joints lie 3.9 cm from the fitted ones (median), 8.8 cm along the fitted
    directions, and the feet 9 cm above the walkway where they went 13 cm above it and
    down to 48 cm below it)."""
    model = fit.model
    n = len(fit.root)
    names, parents, starts, ends = ["Root"], [-1], [fit.root], [fit.root]
    last_link: dict[int, int] = {}
    for b, parent_branch in enumerate(model.parents):
        points = fit.branch_points[b]
        previous = 0 if parent_branch < 0 else last_link[parent_branch]
        for i in range(points.shape[1]):
            names.append(f"Branch{b + 1}_Link{i + 1}")
            parents.append(previous)
            starts.append(ends[previous])
            ends.append(points[:, i])
            previous = len(names) - 1
        last_link[b] = previous
    count = len(names)
    length = np.array(
        [0.0, *(np.median(np.linalg.norm(ends[j] - starts[j], axis=-1)) for j in range(1, count))]
    )
    frames = np.zeros((n, count, 3, 3))
    frames[:, 0] = np.eye(3)
    posed = [fit.root]  # where the posed model puts each link's end, (n, 3) each
    for j in range(1, count):
        aim = ends[j] - posed[parents[j]]
        reached = np.linalg.norm(aim, axis=-1) < 1e-6  # the fitted end is where the link starts
        aim[reached] = (ends[j] - starts[j])[reached]
        z = unit_vectors(aim)
        posed.append(posed[parents[j]] + length[j] * z)
        parent_x = frames[:, parents[j], :, 0]
        y = np.cross(z, parent_x)
        weak = np.linalg.norm(y, axis=-1) < 1e-6
        y[weak] = frames[weak, parents[j], :, 1]
        y = unit_vectors(y)
        frames[:, j] = np.stack([np.cross(y, z), y, z], axis=-1)
    local = np.zeros_like(frames)
    local[:, 0] = np.eye(3)
    for j in range(1, count):
        local[:, j] = np.swapaxes(frames[:, parents[j]], -1, -2) @ frames[:, j]
    rotations = Rotation.from_matrix(local.reshape(-1, 3, 3)).as_quat().reshape(n, count, 4)
    offsets = np.zeros((count, 3))
    for j in range(1, count):
        if parents[j] > 0:
            offsets[j, 2] = length[parents[j]]
    leaves = [j for j in range(1, count) if j not in parents]
    positions = np.stack([*starts, *(ends[j] for j in leaves)], axis=1)
    return KinematicMotion(
        names=tuple(names),
        parents=tuple(parents),
        offsets=offsets,
        lengths=length,
        rotations=rotations,
        root=fit.root.copy(),
        positions=positions,
        fps=fps,
    )


@dataclass(frozen=True)
class VolumeCapture:
    """Everything model and motion capture derives from a volume sequence: the frame
    models (pass 1), the common model and its fit (passes 2 and 3), the posed
    `motion`, and per-frame `times`."""

    frames: list[FrameModel]
    fit: SequenceFit
    motion: KinematicMotion
    times: FrameTimes

    @property
    def humanoid_rate(self) -> float:
        """Fraction of frames whose own model has human topology."""
        return float(np.mean([f.is_humanoid() for f in self.frames]))


def capture_volumes(
    volumes: np.ndarray, grid: VoxelGrid, fps: float, settings: CaptureSettings | None = None
) -> VolumeCapture:
    """Model and motion capture of occupancy grids `volumes` (n, nx, ny, nz) bool on
    `grid`, sampled at `fps` frames per second."""
    frames, times = frame_models(volumes, grid, settings)
    fit = fit_sequence(frames)
    return VolumeCapture(frames=frames, fit=fit, motion=pose_model(fit, fps), times=times)
