"""The accuracy protocol of EVALUATION.md: simulated capture, reconstruction, MPJPE.

`capture_take` turns a ground-truth take into what the server would see (two cameras
at 160 x 120, 0.3 px noise, 0.1 px resolution, DLT; optionally 10% dropout and a new
body). `run_method` reconstructs it with a reconstructor, timing every frame of the
live path and the offline batch path. `TakeErrors` holds per-frame, per-joint errors in
meters and the take's scale to the 45 cm reference tibia; `summarize` pools takes into
the numbers every report uses (scaled MPJPE in cm, unscaled meters, marker and
unobserved joints, per joint, time per frame).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from samba.body import JOINT_NAMES, MARKER_JOINTS, UNOBSERVED_JOINTS
from samba.markers import evaluation_cameras, new_user_factors, observe_markers, scale_limbs
from samba.reconstruct import Reconstructor, SkinMarkerReconstructor

EVALUATION_FPS = 30.0
"""Frame rate every test take is evaluated at."""
REFERENCE_TIBIA = 0.45
"""Knee-to-ankle length (m) every take is scaled to before MPJPE in cm (the paper's)."""


@dataclass(frozen=True)
class CapturedTake:
    """A simulated capture: `truth` (F, 13, 3) and `markers` (F, 8, 3) world meters,
    NaN = missing; `name` of the take."""

    name: str
    truth: np.ndarray
    markers: np.ndarray


def capture_take(
    name: str,
    poses: np.ndarray,
    seed: int,
    dropout: float = 0.0,
    new_user: bool = False,
) -> CapturedTake:
    """Observe a take's poses (F, 13, 3) the EVALUATION.md way, deterministic in seed.

    With `new_user` the limb bones are first scaled by random factors in [0.9, 1.1]
    (the truth is the scaled body); `dropout` removes that fraction of markers at random
    from frame 2 on.
    """
    rng = np.random.default_rng(seed)
    truth = np.asarray(poses, dtype=np.float64)
    if new_user:
        truth = scale_limbs(truth, new_user_factors(rng))
    cameras = evaluation_cameras(truth)
    observed = observe_markers(truth, cameras, rng, dropout=dropout)
    return CapturedTake(name, truth, observed.markers)


@dataclass(frozen=True)
class TakeErrors:
    """One take reconstructed by one method: `errors` (F, 13) joint position errors in
    meters, `scale` to the reference tibia, `frame_seconds` (F,) live-path time per
    frame, `batch_seconds` for the whole take offline, `predicted` (F,) bool, `poses`
    (F, 13, 3) the live path's poses, meters."""

    name: str
    errors: np.ndarray
    scale: float
    frame_seconds: np.ndarray
    batch_seconds: float
    predicted: np.ndarray
    poses: np.ndarray

    @property
    def mpjpe_cm(self) -> float:
        """Mean error over joints and frames, scaled to the reference tibia, in cm."""
        return float(self.errors.mean() * self.scale * 100.0)


def tibia_scale(poses: np.ndarray) -> float:
    """Factor that brings the mean knee-to-ankle length of poses (F, 13, 3) to 45 cm."""
    shins = np.linalg.norm(poses[:, [9, 10]] - poses[:, [11, 12]], axis=-1)
    return REFERENCE_TIBIA / float(shins.mean())


def run_method(
    reconstructor: Reconstructor | SkinMarkerReconstructor, take: CapturedTake
) -> TakeErrors:
    """Reconstruct a captured take frame by frame (timed, the live path) and as one batch
    (timed, the offline path); the live poses are scored."""
    reconstructor.reset()
    poses = np.empty_like(take.truth)
    seconds = np.empty(len(take.truth))
    predicted = np.empty(len(take.truth), dtype=bool)
    clock = time.perf_counter
    for i, frame in enumerate(take.markers):
        start = clock()
        estimate = reconstructor.step(frame)
        seconds[i] = clock() - start
        poses[i] = estimate.pose
        predicted[i] = estimate.predicted
    reconstructor.reset()
    start = clock()
    reconstructor.reconstruct(take.markers)
    batch = clock() - start
    errors = np.linalg.norm(poses - take.truth, axis=-1)
    scale = tibia_scale(take.truth)
    return TakeErrors(take.name, errors, scale, seconds, batch, predicted, poses)


def summarize(results: Sequence[TakeErrors]) -> dict[str, object]:
    """Pooled numbers over takes (every frame weighs the same): MPJPE in cm at the
    reference tibia, overall / marker joints / unobserved joints / per joint; the same
    in meters unscaled; live time per frame (median, p99, ms); batch frames per second."""
    errors = np.concatenate([r.errors for r in results])
    scaled = np.concatenate([r.errors * r.scale for r in results]) * 100.0
    seconds = np.concatenate([r.frame_seconds for r in results])
    frames = sum(len(r.errors) for r in results)
    batch = sum(r.batch_seconds for r in results)
    return {
        "frames": frames,
        "mpjpe_cm": float(scaled.mean()),
        "marker_cm": float(scaled[:, list(MARKER_JOINTS)].mean()),
        "unobserved_cm": float(scaled[:, list(UNOBSERVED_JOINTS)].mean()),
        "per_joint_cm": {n: float(scaled[:, j].mean()) for j, n in enumerate(JOINT_NAMES)},
        "mpjpe_m": float(errors.mean()),
        "marker_m": float(errors[:, list(MARKER_JOINTS)].mean()),
        "unobserved_m": float(errors[:, list(UNOBSERVED_JOINTS)].mean()),
        "predicted_frames": int(sum(r.predicted.sum() for r in results)),
        "frame_ms_p50": float(np.median(seconds) * 1e3),
        "frame_ms_p99": float(np.percentile(seconds, 99) * 1e3),
        "batch_fps": float(frames / batch) if batch > 0 else float("nan"),
        "per_take_cm": {r.name: r.mpjpe_cm for r in results},
    }
