"""Joint refinement of cameras and board poses from board corners seen in many images.

The unknowns are every camera's pose (rotation vector and translation, the first
camera's held fixed to pin the world down), optionally every camera's intrinsics (fx,
fy, cx, cy and the distortion k1, k2, p1, p2; skew and k3 are kept) and the pose of the
board in every view. The residuals are the pixel differences between the observed
corners and their projections; `scipy.optimize.least_squares` minimises them with a
soft-L1 loss (quadratic up to `OUTLIER_PX`, so a misdetected corner cannot pull the
solution far) and a sparse finite-difference Jacobian.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix
from scipy.spatial.transform import Rotation

from samba.cameras.camera import Camera, distort

OUTLIER_PX = 1.0
"""Residual size (pixels) beyond which the soft-L1 loss grows linearly."""
LSMR_TOLERANCE = 1e-10
"""Tolerance of the sparse solver of each step; scipy's default (1e-6) gives inexact steps
that took five times as many iterations to converge with the intrinsics refined."""
_POSE, _INTRINSICS = 6, 8


@dataclass(frozen=True)
class Observations:
    """m board corners seen in images: `camera` (m,) and `view` (m,) index the camera and
    the board pose, `board_points` (m, 3) are the corners in the board frame (meters) and
    `pixels` (m, 2) where the camera saw them (distorted pixels)."""

    camera: np.ndarray
    view: np.ndarray
    board_points: np.ndarray
    pixels: np.ndarray


def bundle_adjust(
    cameras: Sequence[Camera],
    board_poses: np.ndarray,
    observations: Observations,
    refine_intrinsics: bool = False,
    max_evaluations: int = 200,
) -> tuple[list[Camera], np.ndarray, np.ndarray]:
    """Refined cameras, board poses (v, 6) and the final pixel residuals (m, 2).

    `board_poses` (v, 6) are the starting board poses, rotation vector then translation
    (meters), taking board points to the world: ``x = R @ x_board + t``. The cameras'
    intrinsics matrices must have the last row (0, 0, 1). Residuals are projection minus
    observation, pixels.
    """
    board_poses = np.asarray(board_poses, dtype=np.float64)
    problem = _Problem(cameras, len(board_poses), observations, refine_intrinsics)
    start = problem.pack(cameras, board_poses)
    solution = least_squares(
        problem.residuals,
        start,
        jac_sparsity=problem.sparsity(),
        method="trf",
        x_scale="jac",
        loss="soft_l1",
        f_scale=OUTLIER_PX,
        max_nfev=max_evaluations,
        tr_options={"atol": LSMR_TOLERANCE, "btol": LSMR_TOLERANCE},
    )
    refined, poses = problem.unpack(solution.x)
    residuals = problem.residuals(solution.x).reshape(-1, 2)
    return refined, poses, residuals


class _Problem:
    """The parameter layout and residual function of one bundle adjustment:
    [poses of cameras 1..c-1 (6 each)] [intrinsics of every camera (8 each), when
    refined] [board poses (6 each)]."""

    def __init__(
        self,
        cameras: Sequence[Camera],
        views: int,
        observations: Observations,
        refine_intrinsics: bool,
    ) -> None:
        self.cameras = list(cameras)
        self.views = views
        self.obs = observations
        self.refine_intrinsics = refine_intrinsics
        count = len(self.cameras)
        self.intrinsics_at = (count - 1) * _POSE
        self.poses_at = self.intrinsics_at + (count * _INTRINSICS if refine_intrinsics else 0)
        self.size = self.poses_at + views * _POSE
        self.skew = np.array([c.matrix[0, 1] for c in self.cameras])
        self.k3 = np.array([c.distortion[4] for c in self.cameras])

    def pack(self, cameras: Sequence[Camera], board_poses: np.ndarray) -> np.ndarray:
        """The parameter vector of cameras and board poses (v, 6)."""
        parts = [np.concatenate([c.rotation, c.translation]) for c in cameras[1:]]
        if self.refine_intrinsics:
            parts += [_intrinsics_of(c) for c in cameras]
        parts.append(board_poses.ravel())
        return np.concatenate([np.ravel(p) for p in parts])

    def unpack(self, params: np.ndarray) -> tuple[list[Camera], np.ndarray]:
        """The cameras and board poses (v, 6) of a parameter vector."""
        extrinsics, intrinsics, poses = self._split(params)
        cameras = []
        for i, camera in enumerate(self.cameras):
            matrix, distortion = camera.matrix, camera.distortion
            if self.refine_intrinsics:
                fx, fy, cx, cy, k1, k2, p1, p2 = intrinsics[i]
                matrix = np.array([[fx, camera.matrix[0, 1], cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
                distortion = np.array([k1, k2, p1, p2, camera.distortion[4]])
            cameras.append(
                Camera(
                    camera.name,
                    camera.size,
                    matrix,
                    extrinsics[i, :3],
                    extrinsics[i, 3:],
                    distortion,
                )
            )
        return cameras, poses

    def _split(self, params: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(camera poses (c, 6), intrinsics (c, 8), board poses (v, 6)) of a parameter vector."""
        first = self.cameras[0]
        fixed = np.concatenate([first.rotation, first.translation])[None]
        moving = params[: self.intrinsics_at].reshape(-1, _POSE)
        extrinsics = np.concatenate([fixed, moving])
        if self.refine_intrinsics:
            intrinsics = params[self.intrinsics_at : self.poses_at].reshape(-1, _INTRINSICS)
        else:
            intrinsics = np.stack([_intrinsics_of(c) for c in self.cameras])
        return extrinsics, intrinsics, params[self.poses_at :].reshape(-1, _POSE)

    def residuals(self, params: np.ndarray) -> np.ndarray:
        """Projection minus observation of every corner, pixels, flattened (2 m,)."""
        extrinsics, intrinsics, poses = self._split(params)
        obs = self.obs
        board_rotation = Rotation.from_rotvec(poses[:, :3]).as_matrix()[obs.view]
        world = np.einsum("mij,mj->mi", board_rotation, obs.board_points) + poses[obs.view, 3:]
        camera_rotation = Rotation.from_rotvec(extrinsics[:, :3]).as_matrix()[obs.camera]
        local = np.einsum("mij,mj->mi", camera_rotation, world) + extrinsics[obs.camera, 3:]
        x, y = local[:, 0] / local[:, 2], local[:, 1] / local[:, 2]
        k = intrinsics[obs.camera]
        coefficients = np.column_stack([k[:, 4:8], self.k3[obs.camera]])
        x, y = distort(x, y, coefficients)
        u = k[:, 0] * x + self.skew[obs.camera] * y + k[:, 2]
        v = k[:, 1] * y + k[:, 3]
        return (np.column_stack([u, v]) - obs.pixels).ravel()

    def sparsity(self) -> coo_matrix:
        """Which parameters each residual depends on, a (2 m, parameters) 0/1 matrix."""
        obs = self.obs
        m = len(obs.camera)
        blocks = [self.poses_at + obs.view[:, None] * _POSE + np.arange(_POSE)]
        moving = obs.camera > 0
        camera_block = (obs.camera[:, None] - 1) * _POSE + np.arange(_POSE)
        blocks.append(np.where(moving[:, None], camera_block, -1))
        if self.refine_intrinsics:
            blocks.append(
                self.intrinsics_at + obs.camera[:, None] * _INTRINSICS + np.arange(_INTRINSICS)
            )
        columns = np.concatenate(blocks, axis=1)  # (m, k), -1 where absent
        rows = np.repeat(np.arange(m), columns.shape[1])
        columns = columns.ravel()
        keep = columns >= 0
        rows, columns = rows[keep], columns[keep]
        rows = np.concatenate([2 * rows, 2 * rows + 1])
        columns = np.concatenate([columns, columns])
        return coo_matrix((np.ones(len(rows)), (rows, columns)), shape=(2 * m, self.size))


def _intrinsics_of(camera: Camera) -> np.ndarray:
    """(fx, fy, cx, cy, k1, k2, p1, p2) of a camera."""
    k = camera.matrix
    return np.array([k[0, 0], k[1, 1], k[0, 2], k[1, 2], *camera.distortion[:4]])
