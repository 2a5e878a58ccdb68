"""Markers on the skin: a subject's constant marker offsets, estimated from a calibration
stretch of its own take and removed from every frame before retrieval.

A real marker sits on the skin (the acromion, the lateral knee and ankle, either side of
the wrist), centimetres from the joint centre the pose database holds, and a subject's
proportions differ from the database's. Both make the observed markers a shape the
database has never seen. We model each marker as its joint plus a constant offset in
the frame of the segment the joint rides on (`samba.body.joint_frames`: the trunk for
the shoulders, the forearm for the wrists, the thigh for the knees, the shank for the
feet):

    marker_f = joint_f + R_f @ offset                      (R_f: segment frame at frame f)

**Calibration** (`calibrate_skin_offsets`), alternating least squares over the c frames
of the calibration stretch: with the offsets so far, the corrected markers
`marker - R @ offset` are reconstructed by `best`'s configuration (whatever method then
reconstructs the take: the offsets belong to the subject) with the marker term loosened
to `CALIBRATION_MARKER_SIGMA`, so that the pose keeps the database's body geometry
rather than following the markers, and placed by the markers' centroid (placed by the
shoulder markers, it would carry their own offsets to every joint); then the offsets
that best explain the markers from that pose are, in the least-squares sense, the mean
over frames of `R_f^T (marker_f - joint_f)` (each R_f orthonormal), kept to the
direction in which each marker sits off its joint (`FREE_AXES`) and at most
`MAX_OFFSET` long. The two steps repeat `iterations` times from zero offsets, each
over-relaxed by `RELAXATION`.

**Removal** (`SkinMarkerReconstructor`): live, each frame's markers are corrected with
the segment frames of the pose the previous estimates predict (constant velocity);
offline, a first pass over the raw markers gives the frames for a second pass over the
corrected ones.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from samba.body import MARKER_JOINTS, MARKER_NAMES, N_MARKERS, joint_frames, markers_of
from samba.reconstruct.methods import BEST
from samba.reconstruct.neighbours import NeighbourSource
from samba.reconstruct.reconstruction import (
    PoseEstimate,
    Reconstruction,
    ReconstructionConfig,
    Reconstructor,
)

CALIBRATION_MARKER_SIGMA = 0.05
"""Marker-term sigma (m) of the calibration's reconstruction: loose, so that the pose
stays in the database's geometry and the markers' own offsets show as residuals."""
DEFAULT_ITERATIONS = 8
"""Alternations of the calibration by default."""
MAX_OFFSET = 0.10
"""Longest offset (m) the calibration gives a marker: a skin marker sits within a few
centimetres of its joint (acromion 4-7 cm, epicondyle and malleolus 3-6 cm)."""
RELAXATION = 1.5
"""Each alternation moves the offsets this many times the step to its least-squares fit
(over-relaxed: the plain fixed-point step converges slowly, as the loose reconstruction
still follows the markers a little)."""
FREE_AXES = np.array(
    [
        [0.0, 1.0, 0.0],  # l_shoulder: the acromion sits above the joint, along the trunk
        [0.0, 1.0, 0.0],  # r_shoulder
        [0.0, 0.0, 0.0],  # l_wrist: the wrist markers' midpoint is the joint's
        [0.0, 0.0, 0.0],  # r_wrist
        [1.0, 0.0, 0.0],  # l_knee: the lateral epicondyle, out along the flexion axis
        [1.0, 0.0, 0.0],  # r_knee
        [1.0, 0.0, 0.0],  # l_foot: the lateral malleolus, out along the ankle's axis
        [1.0, 0.0, 0.0],  # r_foot
    ]
)
"""Which components (segment frame x, y, z) of each marker's offset the calibration
fits; the others stay zero. Where Samba's 8 markers sit on the body fixes the direction
of their offsets; fitting only that direction keeps the calibration from mistaking the
database's pose errors for offsets (fitting all three components made real takes worse:
docs/design/reconstruction.md). It also fixes the common shift that a centroid-aligned
reconstruction cannot see."""


@dataclass(frozen=True)
class SkinOffsets:
    """Each marker's offset (8, 3) from its joint, meters, in the frame of the segment it
    rides on (`samba.body.joint_frames`: x to the subject's left, y along the segment
    towards its parent joint (up the trunk), z forward, in the standard pose); `frames`
    the calibration frames they come from."""

    offsets: np.ndarray
    frames: int = 0

    @classmethod
    def none(cls) -> SkinOffsets:
        """No offsets: markers at their joints."""
        return cls(np.zeros((N_MARKERS, 3)))

    def joints(self, markers: np.ndarray, poses: np.ndarray) -> np.ndarray:
        """The joint centres (n, 8, 3) of markers (n, 8, 3) world meters (NaN = missing),
        the segment frames taken from poses (n, 13, 3) near those frames."""
        frames = joint_frames(poses)[:, list(MARKER_JOINTS)]  # (n, 8, 3, 3)
        return markers - np.einsum("nmij,mj->nmi", frames, self.offsets)

    def as_dict(self) -> dict[str, object]:
        """JSON-ready: `offsets_m` per marker name [x, y, z] and `frames`."""
        rows = {
            name: [round(float(v), 5) for v in row]
            for name, row in zip(MARKER_NAMES, self.offsets, strict=True)
        }
        return {"offsets_m": rows, "frames": self.frames}

    @classmethod
    def from_dict(cls, data: dict[str, object]) -> SkinOffsets:
        """The offsets `as_dict` wrote; `ValueError` naming what is wrong."""
        rows = data.get("offsets_m")
        if not isinstance(rows, dict) or set(rows) != set(MARKER_NAMES):
            raise ValueError(f"skin offsets need offsets_m for {', '.join(MARKER_NAMES)}")
        offsets = np.array([rows[name] for name in MARKER_NAMES], dtype=np.float64)
        if offsets.shape != (N_MARKERS, 3) or not np.isfinite(offsets).all():
            raise ValueError("skin offsets must be 8 finite [x, y, z] in meters")
        return cls(offsets, int(data.get("frames", 0)))  # type: ignore[call-overload]

    def report(self) -> str:
        """One line per marker: its offset in cm and its length."""
        lines = []
        for name, row in zip(MARKER_NAMES, self.offsets, strict=True):
            x, y, z = row * 100.0
            size = np.linalg.norm(row) * 100.0
            lines.append(f"  {name:<11} {x:+6.1f} {y:+6.1f} {z:+6.1f} cm  ({size:.1f} cm)")
        return "\n".join(lines)


def calibrate_skin_offsets(
    reconstructor: Reconstructor,
    markers: np.ndarray,
    iterations: int = DEFAULT_ITERATIONS,
    marker_sigma: float = CALIBRATION_MARKER_SIGMA,
) -> SkinOffsets:
    """A subject's skin offsets from the markers (c, 8, 3), world meters (NaN = missing),
    of a calibration stretch, against `reconstructor`'s database (module docstring),
    reconstructing by `best`'s configuration, placed by the markers' centroid, with the
    marker term's sigma `marker_sigma` meters. `reconstructor` itself is not changed.
    `ValueError` when no frame of the stretch can be reconstructed."""
    markers = np.asarray(markers, dtype=np.float64)
    present = ~np.isnan(markers).any(axis=-1)
    if not reconstructor.usable(present).any():
        raise ValueError("no frame of the calibration stretch has enough markers")
    loose = Reconstructor(
        reconstructor.source, replace(BEST, marker_sigma=marker_sigma, shoulder_origin=False)
    )
    used = present & loose.usable(present)[:, None]
    counts = np.maximum(used.sum(axis=0), 1)[:, None]
    offsets = SkinOffsets.none()
    for _ in range(iterations):
        loose.reset()
        poses = SkinMarkerReconstructor(loose, offsets).reconstruct(markers).poses
        frames = joint_frames(poses)[:, list(MARKER_JOINTS)]
        local = np.einsum("nmji,nmj->nmi", frames, markers - markers_of(poses))
        mean = np.where(used[..., None], local, 0.0).sum(axis=0) / counts
        fitted = _at_most(mean * FREE_AXES, MAX_OFFSET)
        step = offsets.offsets + RELAXATION * (fitted - offsets.offsets)
        offsets = SkinOffsets(step, len(markers))
    return offsets


def _at_most(offsets: np.ndarray, length: float) -> np.ndarray:
    """Offsets (8, 3) each shortened to at most `length` meters."""
    norms = np.linalg.norm(offsets, axis=-1, keepdims=True)
    return offsets * np.minimum(1.0, length / np.maximum(norms, 1e-12))


class SkinMarkerReconstructor:
    """A reconstructor whose markers sit on the skin: each frame's markers are moved to
    their joints by `offsets` before `inner` reconstructs them (module docstring).
    Offers what the evaluation and the live session use of a `Reconstructor`: `reset`,
    `step`, `reconstruct`, `config`, `source`."""

    def __init__(self, inner: Reconstructor, offsets: SkinOffsets) -> None:
        self.inner = inner
        self.offsets = offsets

    @property
    def config(self) -> ReconstructionConfig:
        """The inner reconstructor's configuration."""
        return self.inner.config

    @property
    def source(self) -> NeighbourSource:
        """The inner reconstructor's pose database."""
        return self.inner.source

    def reset(self) -> None:
        """Forget the previous estimates (a new take)."""
        self.inner.reset()

    def step(self, markers: np.ndarray) -> PoseEstimate:
        """One frame's markers (8, 3), world meters, NaN = missing: corrected with the
        segment frames of the predicted pose (before any estimate: of a first
        reconstruction of the raw markers, then forgotten), then reconstructed."""
        markers = np.asarray(markers, dtype=np.float64)
        guess = self.inner.prediction()
        if guess is None:
            guess = self.inner.step(markers).pose
            self.inner.reset()
        joints = self.offsets.joints(markers[None], guess[None])[0]
        return self.inner.step(joints)

    def reconstruct(self, markers: np.ndarray) -> Reconstruction:
        """Consecutive frames' markers (F, 8, 3), world meters, NaN = missing, in two
        passes: the raw markers give the segment frames that correct them for the
        second; continues from (and updates) the previous estimates."""
        markers = np.asarray(markers, dtype=np.float64)
        history, held = self.inner.history, self.inner.held
        calibration, smoothing = self.inner.calibration, self.inner.smoothing
        first = self.inner.reconstruct(markers)
        self.inner.history, self.inner.held = history, held
        self.inner.calibration, self.inner.smoothing = calibration, smoothing
        return self.inner.reconstruct(self.offsets.joints(markers, first.poses))
