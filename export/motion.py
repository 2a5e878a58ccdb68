"""`HumanoidMotion`: a take as local bone rotations of a humanoid rig, the writers' input.

Rotations are unit quaternions in scalar-last order (x, y, z, w), as in
`scipy.spatial.transform.Rotation`, relative to the rig's rest pose (whose orientations
are the identity): bone j's world rotation is W_j = W_parent · L_j, and its world
position is p_parent + W_parent · offset_j. Consecutive frames of each bone lie in the
same quaternion hemisphere, so writers can interpolate them directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from samba.body import (
    continuous_quaternions,
    resample_times,
    sample_linear,
    sample_rotations,
    whole_fps,
)
from samba.db import frame_count_problem, frame_rate_problem
from samba.export.errors import ExportError
from samba.export.humanoid import N_BONES, PARENTS, TIP_BONES, HumanoidRig


@dataclass(frozen=True)
class HumanoidMotion:
    """`rotations` (n, 17, 4) local quaternions (x, y, z, w; normalised on creation) and
    `root` (n, 3) Hips positions in meters, sampled at `fps` frames per second, for `rig`;
    a rate within 0.01% of a whole number is that number (`samba.body.whole_fps`)."""

    rig: HumanoidRig
    rotations: np.ndarray
    root: np.ndarray
    fps: float

    def __post_init__(self) -> None:
        rotations = np.asarray(self.rotations, dtype=np.float64)
        root = np.asarray(self.root, dtype=np.float64)
        n = len(rotations)
        if rotations.shape != (n, N_BONES, 4) or root.shape != (n, 3):
            raise ValueError(
                f"motion needs rotations (n, 17, 4) and root (n, 3), got "
                f"{rotations.shape} and {root.shape}"
            )
        if n == 0:
            raise ValueError("motion has no frames")
        if not self.fps > 0:
            raise ValueError(f"motion fps must be positive, got {self.fps}")
        norms = np.linalg.norm(rotations, axis=-1, keepdims=True)
        if not (np.isfinite(root).all() and np.isfinite(norms).all() and (norms > 0).all()):
            raise ValueError("motion has non-finite root positions or non-finite / zero rotations")
        object.__setattr__(self, "rotations", continuous_quaternions(rotations / norms))
        object.__setattr__(self, "fps", whole_fps(float(self.fps)))
        object.__setattr__(self, "root", root)

    def __len__(self) -> int:
        return len(self.rotations)

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return (len(self) - 1) / self.fps

    def frames(self, start: int, stop: int) -> HumanoidMotion:
        """Frames `start` .. `stop - 1` as a new motion."""
        return HumanoidMotion(self.rig, self.rotations[start:stop], self.root[start:stop], self.fps)

    def resampled(self, fps: float) -> HumanoidMotion:
        """The motion at another frame rate `fps` (frames per second) over the same time
        span: rotations interpolated on the shorter arc, the root linearly. `ExportError`
        naming --fps, before anything is sampled, when the rate is outside
        `samba.db.FPS_RANGE` or the motion would get more than `samba.db.MAX_TAKE_FRAMES`
        frames."""
        frames = int((len(self) - 1) * fps / self.fps) + 1 if fps > 0 else 0
        problem = frame_rate_problem(fps) or frame_count_problem(frames)
        if problem:
            raise ExportError(
                "--fps",
                f"{fps:g} fps for a take of {len(self):,} frames at {self.fps:g} fps: {problem}",
            )
        times = resample_times(len(self), self.fps, fps)
        rotations = sample_rotations(self.rotations, times)
        return HumanoidMotion(self.rig, rotations, sample_linear(self.root, times), fps)

    def world_matrices(self) -> np.ndarray:
        """World rotation matrices (n, 17, 3, 3) of every bone (rest pose = identity)."""
        n = len(self)
        local = Rotation.from_quat(self.rotations.reshape(-1, 4)).as_matrix()
        local = local.reshape(n, N_BONES, 3, 3)
        world = np.empty_like(local)
        for j, p in enumerate(PARENTS):
            world[:, j] = local[:, j] if p < 0 else world[:, p] @ local[:, j]
        return world

    def world_positions(self) -> np.ndarray:
        """World positions (n, 17, 3) of every bone's joint, meters."""
        world = self.world_matrices()
        offsets = self.rig.offsets
        out = np.empty((len(self), N_BONES, 3))
        for j, p in enumerate(PARENTS):
            if p < 0:
                out[:, j] = self.root
            else:
                out[:, j] = out[:, p] + world[:, p] @ offsets[j]
        return out

    def tip_positions(self) -> np.ndarray:
        """World positions (n, 5, 3) of the leaf ends (`humanoid.TIP_BONES` order), meters."""
        world = self.world_matrices()[:, list(TIP_BONES)]
        joints = self.world_positions()[:, list(TIP_BONES)]
        return joints + np.einsum("nbij,bj->nbi", world, self.rig.tips)
