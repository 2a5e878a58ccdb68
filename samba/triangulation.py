"""Linear (DLT) triangulation of points seen by several calibrated cameras.

Each view of a point gives two linear equations in its homogeneous world position X:
``u * P[2] @ X = P[0] @ X`` and ``v * P[2] @ X = P[1] @ X``. All views of all points are
stacked into one (n, 2c, 4) batch, every equation row scaled to unit length for
conditioning, and each point's X is the right singular vector of its smallest singular
value. A missing view (NaN pixel) contributes zero rows; a point seen by fewer than two
cameras is NaN.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from samba.camera import Camera

MIN_VIEWS = 2
"""Views a point needs to be triangulated."""


def triangulate(projections: np.ndarray, points: np.ndarray) -> np.ndarray:
    """World points (n, 3) in meters from pixels (c, n, 2) of c cameras (c, 3, 4).

    `projections` are the cameras' K [R | t]; `points` are undistorted pixel coordinates,
    NaN where a camera does not see the point. Points seen by fewer than two cameras come
    out NaN. Any batch shape works: pixels (c, ..., 2) give points (..., 3).
    """
    projections = np.asarray(projections, dtype=np.float64)
    points = np.asarray(points, dtype=np.float64)
    if projections.ndim != 3 or projections.shape[1:] != (3, 4):
        raise ValueError(f"projections must be (c, 3, 4), got {projections.shape}")
    if not np.isfinite(projections).all():
        raise ValueError("projections contain NaN or infinity")
    c = len(projections)
    if points.ndim < 2 or points.shape[0] != c or points.shape[-1] != 2:
        raise ValueError(f"points must be ({c}, ..., 2) for {c} cameras, got {points.shape}")
    batch_shape = points.shape[1:-1]
    uv = points.reshape(c, -1, 2)  # (c, n, 2)
    seen = ~np.isnan(uv).any(axis=-1)  # (c, n)
    uv = np.where(seen[..., None], uv, 0.0)
    # rows[c, n, k] = uv[c, n, k] * P[c, 2] - P[c, k] for k = 0 (u), 1 (v): (c, n, 2, 4)
    rows = uv[..., None] * projections[:, None, None, 2, :] - projections[:, None, :2, :]
    norms = np.linalg.norm(rows, axis=-1, keepdims=True)
    rows = np.where(seen[..., None, None] & (norms > 0), rows / np.maximum(norms, 1e-300), 0.0)
    system = rows.transpose(1, 0, 2, 3).reshape(-1, 2 * c, 4)  # (n, 2c, 4)
    _, _, vh = np.linalg.svd(system, full_matrices=False)
    homogeneous = vh[:, -1, :]  # (n, 4)
    with np.errstate(invalid="ignore", divide="ignore"):
        world = homogeneous[:, :3] / homogeneous[:, 3:]
    world[seen.sum(axis=0) < MIN_VIEWS] = np.nan
    return world.reshape(*batch_shape, 3)


def triangulate_cameras(cameras: Sequence[Camera], points: np.ndarray) -> np.ndarray:
    """World points (n, 3) in meters from pixels (c, n, 2) seen by `cameras` (c of them).

    The pixels must be undistorted (pinhole) coordinates, NaN where a camera misses the
    point; points seen by fewer than two cameras are NaN. Cameras with non-zero
    distortion are refused with ValueError until undistortion exists.
    """
    for camera in cameras:
        if camera.has_distortion:
            raise ValueError(
                f"camera {camera.name!r} has lens distortion; triangulate_cameras needs "
                "undistorted pixels and distortion-free cameras"
            )
    if len(cameras) == 0:
        raise ValueError("triangulate_cameras needs at least one camera")
    return triangulate(np.stack([camera.projection for camera in cameras]), points)
