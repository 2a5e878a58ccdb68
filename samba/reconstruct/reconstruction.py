"""13 joints from 8 markers: the Samba paper's data-driven reconstruction (Section 4).

Per frame: align the observed markers into the database frame (`samba.body.alignment`, as
the pose index does), take the K nearest database poses, aligned by the same markers,
grow N pseudo-poses from each (`samba.reconstruct.pseudo_poses`), build the local pose space of the
K * N samples and minimise prior + marker + smoothness energy in it
(`samba.reconstruct.local_space`); the pose goes back to the world frame.

Three paths share every step: `Reconstructor.step` for the live service (one frame at a
time, keeping the two previous estimates of the energy solution for the smoothness
term), `reconstruct_together` for live sessions whose frames arrive together (one
frame of each in one batch) and `Reconstructor.reconstruct` for whole takes offline
(all frames batched; only a 39 x 39 matrix-vector product per frame runs in sequence).
All give the same poses.

Missing markers are NaN. With `hold_frames` a missing marker is first held where it was
last seen (`samba.reconstruct.marker_hold`, the paper's tracker). Retrieval and the
marker term use the markers present; the smoothness term predicts the rest. A frame with
fewer than `min_markers` markers or without a complete left/right marker pair to set the
heading is not reconstructed: the pose is predicted from the previous estimates
(velocity halved every frame, so it comes to rest), or, before any estimate, the
standard pose is placed at the markers seen; it is flagged as predicted and not
confident. No input produces a NaN pose.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from types import ModuleType

import numpy as np

from samba.base import KernelSet, kernels_enabled, usable_cores
from samba.body import N_JOINTS, N_MARKERS, Alignment, has_heading, markers_of, standard_pose
from samba.reconstruct.bone_calibration import BoneCalibration
from samba.reconstruct.configuration import ReconstructionConfig
from samba.reconstruct.joint_smoothing import JointSmoothing
from samba.reconstruct.local_space import (
    POSE_DIMS,
    ROUNDING_VARIANCE,
    TRUNCATED,
    EnergyTerms,
    LocalPoseSpace,
    affine_solution,
    initial_weights,
    solve_lm,
)
from samba.reconstruct.marker_hold import MarkerHold
from samba.reconstruct.neighbours import NeighbourSource
from samba.reconstruct.part_retrieval import refine_with_parts
from samba.reconstruct.pseudo_poses import AngleNoise, pseudo_poses

THREADED_FRAMES = 64
"""Batches of at least this many frames are solved on every core the process may use."""


@dataclass(frozen=True)
class Reconstruction:
    """Reconstructed frames: `poses` (F, 13, 3) world meters, `residual` (F,) RMS marker
    error in meters over the markers used (0 when predicted), `markers_used` (F,) int,
    `confident` (F,) bool, `predicted` (F,) bool (pose predicted, not reconstructed)."""

    poses: np.ndarray
    residual: np.ndarray
    markers_used: np.ndarray
    confident: np.ndarray
    predicted: np.ndarray

    def __len__(self) -> int:
        return len(self.poses)

    def estimate(self, i: int) -> PoseEstimate:
        """Frame i as a `PoseEstimate`."""
        return PoseEstimate(
            pose=self.poses[i],
            residual=float(self.residual[i]),
            markers_used=int(self.markers_used[i]),
            confident=bool(self.confident[i]),
            predicted=bool(self.predicted[i]),
        )


@dataclass(frozen=True)
class PoseEstimate:
    """One reconstructed frame: `pose` (13, 3) world meters, `residual` meters,
    `markers_used`, `confident`, `predicted` as in `Reconstruction`."""

    pose: np.ndarray
    residual: float
    markers_used: int
    confident: bool
    predicted: bool


@dataclass(frozen=True)
class _Solved:
    """Per-frame affine maps from the smoothness target to the pose, world frame:
    pose = offset + gain @ (target - anchor), all (b, 39) / (b, 39, 39) meters."""

    offset: np.ndarray
    gain: np.ndarray
    anchor: np.ndarray


class Reconstructor:
    """Reconstructs 13-joint poses from 8 markers with a pose database.

    `source` gives the K nearest poses (a `samba.db.index.PoseIndex`, or anything with its
    `query`, `poses` and `scale_by_tibia`). The reconstructor keeps the last two
    estimates for the smoothness term, the markers it holds (`held`), the bones it
    calibrates (`calibration`) and the joints it smooths (`smoothing`); `reset` forgets
    them (a new take).
    """

    def __init__(self, source: NeighbourSource, config: ReconstructionConfig | None = None):
        self.source = source
        self.config = config or ReconstructionConfig()
        self.noise = AngleNoise.draw(
            self.config.k, self.config.n, self.config.noise_deg, self.config.seed
        )
        self._history: list[np.ndarray] = []
        self._held = MarkerHold(self.config.hold_frames, self.config.hold_follows)
        self._calibration = BoneCalibration(self.config.calibration_frames)
        self._smoothing = JointSmoothing(self.config.joint_smoothing)
        cfg = self.config
        self._kernel_settings = np.array(
            [
                cfg.variance_kept,
                cfg.variance_floor,
                TRUNCATED,
                ROUNDING_VARIANCE,
                cfg.alpha,
                cfg.beta,
                cfg.beta_missing,
                cfg.bandwidth,
                cfg.min_bandwidth,
                float(cfg.shoulder_origin),
            ]
        )
        """The configuration as `local_solutions_kernel` takes it."""
        if kernels_enabled():
            _kernels().KERNELS.warm_up()
        self.prepare(1)

    def prepare(self, most_missing: int = 1) -> int:
        """Query the standard pose once with every set of 1 to `most_missing` markers
        missing that keeps a left/right pair (and, with parts, each part's markers of
        it), so that an index making masked tables lazily makes them now rather than in
        the first frames of a live capture that lose those markers: such a frame would
        stall by the table's build (30-45 ms at 10^4 poses, seconds at 10^6). The
        constructor prepares single missing markers. Returns the observations queried."""
        sets = [
            missing
            for count in range(1, most_missing + 1)
            for missing in itertools.combinations(range(N_MARKERS), count)
        ]
        markers = np.repeat(markers_of(standard_pose())[None], len(sets) + 1, axis=0)
        for row, missing in enumerate(sets, start=1):
            markers[row, list(missing)] = np.nan
        markers = markers[self.usable(~np.isnan(markers).any(axis=-1))]
        if len(markers) > 1:
            self.source.query(markers[1:], k=1, eps=self.config.eps)
        if self.config.part_k:
            poses = np.repeat(standard_pose()[None], len(markers), axis=0)
            refine_with_parts(
                self.source, markers, poses, 1, self.config.eps, self.config.part_ridge
            )
        return len(markers) - 1

    def reset(self) -> None:
        """Forget the previous estimates, the markers held, the bones calibrated and the
        joints smoothed."""
        self._history = []
        self._held.reset()
        self._calibration.reset()
        self._smoothing.reset()

    @property
    def held(self) -> MarkerHold:
        """A copy of the markers held for the next frames; set it to go back to an
        earlier state (with `history`)."""
        return self._held.copy()

    @held.setter
    def held(self, state: MarkerHold) -> None:
        self._held = state.copy()

    @property
    def calibration(self) -> BoneCalibration:
        """A copy of the bone lengths calibrated so far; set it to go back to an earlier
        state (with `history` and `held`)."""
        return self._calibration.copy()

    @calibration.setter
    def calibration(self, state: BoneCalibration) -> None:
        self._calibration = state.copy()

    @property
    def smoothing(self) -> JointSmoothing:
        """A copy of the smoothed joints' state; set it to go back to an earlier state."""
        return self._smoothing.copy()

    @smoothing.setter
    def smoothing(self, state: JointSmoothing) -> None:
        self._smoothing = state.copy()

    @property
    def history(self) -> list[np.ndarray]:
        """The last two estimates (39,) world meters, newest first (fewer at a take's
        start); set it to go back to an earlier state."""
        return list(self._history)

    @history.setter
    def history(self, estimates: list[np.ndarray]) -> None:
        self._history = list(estimates)[:2]

    def prediction(self) -> np.ndarray | None:
        """The pose (13, 3) world meters the last two estimates predict for the next frame
        at constant velocity (the last estimate after one frame), None before any."""
        if not self._history:
            return None
        if len(self._history) == 1:
            return self._history[0].reshape(N_JOINTS, 3)
        return (2.0 * self._history[0] - self._history[1]).reshape(N_JOINTS, 3)

    def step(self, markers: np.ndarray) -> PoseEstimate:
        """Reconstruct one frame from markers (8, 3), world meters, NaN = missing."""
        return self.reconstruct(np.asarray(markers, dtype=np.float64)[None]).estimate(0)

    def reconstruct(self, markers: np.ndarray) -> Reconstruction:
        """Reconstruct consecutive frames from markers (F, 8, 3), world meters, NaN =
        missing; continues from (and updates) the previous estimates."""
        markers = _checked_markers(markers)
        return _reconstruct(self, [self] * len(markers), markers)

    def usable(self, present: np.ndarray) -> np.ndarray:
        """(F,) frames with enough markers present (F, 8) to be reconstructed."""
        return has_heading(present) & (present.sum(axis=1) >= self.config.min_markers)

    def neighbours(self, markers: np.ndarray) -> tuple[Alignment, np.ndarray, np.ndarray]:
        """The retrieval step for usable frames' markers (b, 8, 3): the observations'
        alignment, the aligned markers (b, 8, 3) and the K nearest poses (b, K, 13, 3),
        each aligned by its own markers masked like the observation's; canonical frame."""
        cfg = self.config
        scale = self.source.scale_by_tibia
        by_shoulders = cfg.shoulder_origin
        alignment = Alignment.from_markers(markers, scale, by_shoulders)
        aligned = alignment.apply(markers)
        _, rows = self.source.query(markers, k=cfg.k, eps=cfg.eps)
        poses = np.asarray(self.source.poses[rows.reshape(-1)], dtype=np.float64)
        seen = markers_of(poses.reshape(len(markers), cfg.k, N_JOINTS, 3))
        seen = np.where(np.isnan(markers)[:, None], np.nan, seen).reshape(-1, N_MARKERS, 3)
        poses = Alignment.from_markers(seen, scale, by_shoulders).apply(poses)
        return alignment, aligned, poses.reshape(len(markers), cfg.k, N_JOINTS, 3)

    def local_spaces(
        self, markers: np.ndarray
    ) -> tuple[Alignment, np.ndarray, LocalPoseSpace, np.ndarray]:
        """The retrieval and pose-space steps for usable frames' markers (b, 8, 3).

        Returns the observations' alignment, the aligned markers (b, 8, 3), the local
        pose spaces and their samples (b, K * N, 13, 3), all in the canonical frame.
        """
        cfg = self.config
        alignment, aligned, neighbours = self.neighbours(markers)
        samples = pseudo_poses(neighbours, self.noise)
        samples = samples.reshape(len(markers), -1, N_JOINTS, 3)
        weights = self.sample_weights(aligned, samples) if cfg.bandwidth else None
        space = LocalPoseSpace.from_samples(samples, cfg.variance_kept, cfg.variance_floor, weights)
        return alignment, aligned, space, samples

    def sample_weights(self, aligned: np.ndarray, samples: np.ndarray) -> np.ndarray:
        """Kernel weights (b, M) of samples (b, M, 13, 3) by the distance d of their markers
        to the aligned observation (b, 8, 3) over the markers present: exp(-(d / h)^2)
        with h = `bandwidth` times the nearest sample's distance, at least
        `min_bandwidth` meters."""
        present = (~np.isnan(aligned).any(axis=-1)).astype(np.float64)
        diff = markers_of(samples) - np.nan_to_num(aligned)[:, None]
        d2 = np.matmul(np.square(diff).sum(axis=-1), present[:, :, None])[:, :, 0]
        h2 = np.maximum(d2.min(axis=1) * self.config.bandwidth**2, self.config.min_bandwidth**2)
        return np.exp(-d2 / h2[:, None])

    def _solve_batch(self, markers: np.ndarray, has_target: np.ndarray) -> _Solved:
        """Everything but the smoothness target, for usable frames (b, 8, 3); frames
        without a target (the first of a take) get no smoothness term. By the compiled
        kernel (`samba.reconstruct.kernels`) unless `kernels_enabled()` says numpy."""
        if not kernels_enabled():
            return self._solve_batch_numpy(markers, has_target)
        cfg = self.config
        _, rows = self.source.query(markers, k=cfg.k, eps=cfg.eps)
        neighbours = np.asarray(self.source.poses[rows.reshape(-1)], dtype=np.float64)
        settings = self._kernel_settings
        neighbours = neighbours.reshape(len(markers), cfg.k, N_JOINTS, 3)
        markers = np.ascontiguousarray(markers)
        has_target = np.ascontiguousarray(has_target)

        def solve(frames: slice) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            return _kernels().local_solutions_kernel(
                markers[frames],
                neighbours[frames],
                has_target[frames],
                self.noise.coefficients,
                bool(self.source.scale_by_tibia),
                settings,
            )

        workers = 1 if len(markers) < THREADED_FRAMES else usable_cores()
        if workers == 1:
            return _Solved(*solve(slice(None)))
        bounds = np.linspace(0, len(markers), workers + 1).astype(int)
        with ThreadPoolExecutor(workers) as pool:  # the kernel releases the GIL
            parts = list(pool.map(solve, [slice(a, b) for a, b in itertools.pairwise(bounds)]))
        return _Solved(*(np.concatenate(arrays) for arrays in zip(*parts, strict=True)))

    def _solve_poses(
        self, markers: np.ndarray, targets: np.ndarray, has_target: np.ndarray
    ) -> np.ndarray:
        """Usable frames' poses (b, 39) world meters, each frame's smoothness target
        (b, 39) world meters known (used where `has_target`): `_solve_batch` and `_apply`
        in one step, the kernel forming no gain matrix (`local_poses_kernel`)."""
        if not kernels_enabled():
            solved = self._solve_batch(markers, has_target)
            moved = np.where(has_target[:, None], targets - solved.anchor, 0.0)
            return solved.offset + np.einsum("bij,bj->bi", solved.gain, moved)
        cfg = self.config
        _, rows = self.source.query(markers, k=cfg.k, eps=cfg.eps)
        neighbours = np.asarray(self.source.poses[rows.reshape(-1)], dtype=np.float64)
        return _kernels().local_poses_kernel(
            np.ascontiguousarray(markers),
            neighbours.reshape(len(markers), cfg.k, N_JOINTS, 3),
            np.ascontiguousarray(targets),
            np.ascontiguousarray(has_target),
            self.noise.coefficients,
            bool(self.source.scale_by_tibia),
            self._kernel_settings,
        )

    def _solve_batch_numpy(self, markers: np.ndarray, has_target: np.ndarray) -> _Solved:
        """`_solve_batch` by numpy: the kernel's reference."""
        alignment, aligned, space, _ = self.local_spaces(markers)
        cfg = self.config
        terms = EnergyTerms(
            aligned,
            np.zeros((len(markers), N_JOINTS, 3)),
            has_target,
            cfg.alpha,
            cfg.beta,
            cfg.beta_missing,
        )
        offset, gain = affine_solution(space, terms)
        # To world: q_w = o + R^T q_c / s with q_c = offset + gain @ (s R (t_w - o)), so
        # the world gain is R^T gain R: per joint, R^T on its rows and R on its columns.
        b = len(markers)
        r = alignment.rotation[:, None]  # (b, 1, 3, 3)
        gain_w = np.matmul(r.swapaxes(-1, -2), gain.reshape(b, N_JOINTS, 3, POSE_DIMS))
        gain_w = np.matmul(gain_w.reshape(b, POSE_DIMS, N_JOINTS, 3), r)
        offset_w = alignment.invert(offset.reshape(b, N_JOINTS, 3)).reshape(b, POSE_DIMS)
        anchor = np.broadcast_to(alignment.origin[:, None], (b, N_JOINTS, 3)).reshape(b, POSE_DIMS)
        return _Solved(offset_w, gain_w.reshape(b, POSE_DIMS, POSE_DIMS), anchor)

    def _apply(self, solved: _Solved, i: int) -> np.ndarray:
        """Frame i's pose (39,), world, given the history."""
        target = self.prediction()
        if target is None:
            return solved.offset[i]
        return solved.offset[i] + solved.gain[i] @ (target.reshape(-1) - solved.anchor[i])

    def _predict(self, markers: np.ndarray, present: np.ndarray) -> np.ndarray:
        """A pose (39,) for a frame that cannot be reconstructed."""
        if len(self._history) == 2:
            return self._history[0] + 0.5 * (self._history[0] - self._history[1])
        if self._history:
            return self._history[0]
        pose = standard_pose()
        if present.any():
            pose += markers[present].mean(axis=0) - markers_of(pose)[present].mean(axis=0)
        return pose.reshape(-1)

    def initial_weights(self, markers: np.ndarray) -> np.ndarray:
        """The paper's initial value w0 (39,) for one usable frame's markers (8, 3)."""
        _, aligned, space, samples = self.local_spaces(markers[None])
        return initial_weights(space, samples[0], aligned[0])

    def solve_lm(self, markers: np.ndarray, target: np.ndarray | None = None) -> np.ndarray:
        """One frame (8, 3) solved by Levenberg-Marquardt from the paper's initial value,
        with smoothness target 2 q_{i-1} - q_{i-2} (13, 3) in world meters or none;
        returns the world pose (13, 3). For comparison with the fast path."""
        alignment, aligned, space, samples = self.local_spaces(markers[None])
        has_target = target is not None
        t = alignment.apply(target[None]) if has_target else np.zeros((1, N_JOINTS, 3))
        cfg = self.config
        terms = EnergyTerms(
            aligned, t, np.array([has_target]), cfg.alpha, cfg.beta, cfg.beta_missing
        )
        w0 = initial_weights(space, samples[0], aligned[0])
        pose = solve_lm(space, terms, w0)
        return alignment.invert(pose[None])[0]


def reconstruct_together(
    reconstructors: Sequence[Reconstructor], markers: np.ndarray
) -> Reconstruction:
    """Frames of several reconstructors computed as one batch: frame i, markers[i] of
    (F, 8, 3) world meters with NaN = missing, continues (and updates) the estimates of
    reconstructors[i], in order, with the poses `reconstructors[i].step(markers[i])` would
    give. Live sessions that search one database do this with the frames that arrive
    together: four frames cost about 1.5 times one (`Reconstructor.step` in a live
    process: 1.6 ms for one, 2.5 ms for four).

    The reconstructors must be of one class, with equal configurations and the same
    source object (`ValueError` otherwise)."""
    markers = _checked_markers(markers)
    if len(reconstructors) != len(markers) or not len(markers):
        raise ValueError(
            f"one frame per reconstructor: {len(reconstructors)} reconstructors, "
            f"{len(markers)} frames"
        )
    first = reconstructors[0]
    if any(
        type(r) is not type(first) or r.source is not first.source or r.config != first.config
        for r in reconstructors
    ):
        raise ValueError("reconstructors run together must share class, configuration and source")
    return _reconstruct(first, list(reconstructors), markers)


def _reconstruct(
    model: Reconstructor, owners: list[Reconstructor], markers: np.ndarray
) -> Reconstruction:
    """Frames (F, 8, 3) in order, frame i continuing owners[i]'s estimates; every owner
    shares the class, configuration and source of `model`."""
    cfg = model.config
    observed = ~np.isnan(markers).any(axis=-1)
    usable = model.usable(observed)
    solved_markers = _held_markers(owners, markers) if cfg.hold_frames else markers
    frames = np.flatnonzero(usable)
    started: set[int] = set()
    has_target = np.empty(len(owners), dtype=bool)
    for i, owner in enumerate(owners):
        has_target[i] = bool(owner._history) or id(owner) in started
        started.add(id(owner))
    poses = np.empty((len(markers), POSE_DIMS))
    slot = np.full(len(markers), -1)
    slot[frames] = np.arange(len(frames))
    live = len(frames) < THREADED_FRAMES and len({id(owner) for owner in owners}) == len(owners)
    if live and frames.size:  # each owner once: the targets are known before the solve
        targets = np.zeros((len(frames), POSE_DIMS))
        for row, i in enumerate(frames):
            if has_target[i]:
                targets[row] = owners[i].prediction().reshape(-1)
        solved = model._solve_poses(solved_markers[frames], targets, has_target[frames])
    elif frames.size:
        solved = model._solve_batch(solved_markers[frames], has_target[frames])
    for i, owner in enumerate(owners):
        if slot[i] < 0:
            q = owner._predict(markers[i], observed[i])
        else:
            q = solved[slot[i]] if live else owner._apply(solved, slot[i])
        poses[i] = q
        owner._history = [q, *owner._history[:1]]
    poses = poses.reshape(-1, N_JOINTS, 3)
    if cfg.part_k and len(frames):
        # Missing markers are filled with the main estimate, so every part is queried.
        seen = solved_markers[frames]
        filled = np.where(np.isnan(seen), markers_of(poses[frames]), seen)
        poses[frames] = refine_with_parts(
            model.source, filled, poses[frames], cfg.part_k, cfg.eps, cfg.part_ridge
        )
    if (cfg.calibration_frames or cfg.joint_smoothing < 1.0) and len(frames):
        poses[frames] = _calibrated_and_smoothed([owners[i] for i in frames], poses[frames])
    diff = np.where(observed[..., None], markers_of(poses) - markers, 0.0)
    squared = np.einsum("fmc,fmc->fm", diff, diff)
    used = np.where(usable, observed.sum(axis=1), 0)
    residual = np.sqrt(squared.sum(axis=1) / np.maximum(used, 1)) * usable
    confident = usable & (used >= 6) & (residual <= cfg.confident_residual)
    return Reconstruction(poses, residual, used, confident, ~usable)


def _held_markers(owners: list[Reconstructor], markers: np.ndarray) -> np.ndarray:
    """Markers (F, 8, 3) with each owner's held markers filled in, frame i by owners[i]."""
    if all(owner is owners[0] for owner in owners):
        return owners[0]._held.fill(markers)
    return np.concatenate([o._held.fill(m[None]) for o, m in zip(owners, markers, strict=True)])


def _calibrated_and_smoothed(owners: list[Reconstructor], poses: np.ndarray) -> np.ndarray:
    """Poses (F, 13, 3) with each owner's calibrated bones, then its smoothed joints,
    frame i by owners[i]."""
    if all(owner is owners[0] for owner in owners):
        return owners[0]._smoothing.apply(owners[0]._calibration.apply(poses))
    return np.concatenate(
        [
            o._smoothing.apply(o._calibration.apply(p[None]))
            for o, p in zip(owners, poses, strict=True)
        ]
    )


def _kernels() -> ModuleType:
    """`samba.reconstruct.kernels`, imported on first use: numba's import (0.2 s) stays off
    commands that never reconstruct (`samba --help`)."""
    import samba.reconstruct.kernels as kernels

    return kernels


def reconstruction_kernels() -> KernelSet:
    """The reconstruction's compiled kernels (`samba.reconstruct.kernels.KERNELS`), for
    `samba warmup`; importing them imports numba."""
    return _kernels().KERNELS


def _checked_markers(markers: np.ndarray) -> np.ndarray:
    """Markers (F, 8, 3) as float64 with every non-finite marker NaN; `ValueError` for
    another shape."""
    markers = np.asarray(markers, dtype=np.float64)
    if markers.ndim != 3 or markers.shape[1:] != (N_MARKERS, 3):
        raise ValueError(f"markers must be (F, 8, 3), got {markers.shape}")
    return np.where(np.isfinite(markers).all(axis=-1, keepdims=True), markers, np.nan)


class NearestPose(Reconstructor):
    """The `nn` baseline: the nearest database pose (K = 1), aligned onto the observation
    by the same alignment, without pseudo-poses or energy."""

    def __init__(self, source: NeighbourSource, config: ReconstructionConfig | None = None):
        super().__init__(source, replace(config or ReconstructionConfig(), k=1, n=1))

    def _solve_batch(self, markers: np.ndarray, has_target: np.ndarray) -> _Solved:
        alignment, _, neighbours = self.neighbours(markers)
        world = alignment.invert(neighbours[:, 0]).reshape(len(markers), POSE_DIMS)
        return _Solved(world, np.zeros((len(markers), POSE_DIMS, POSE_DIMS)), world)

    def _solve_poses(
        self, markers: np.ndarray, targets: np.ndarray, has_target: np.ndarray
    ) -> np.ndarray:
        return self._solve_batch(markers, has_target).offset
