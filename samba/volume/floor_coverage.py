"""The default capture volume of a calibration: the box over the floor the cameras see.

A visual hull keeps only what enough cameras see, so the region worth carving is the
floor that those cameras all see, from the floor up to a person's reach. The floor
(y = 0, +Y up, meters) is sampled every `FLOOR_STEP` m within `MAX_RANGE` m of some
camera; a floor point counts for a camera when it lies in front of it, inside its image
(where the lens distortion maps it there: far outside the field of view the
distortion's polynomial folds points back in) and within `MAX_RANGE` m of it
(farther, a person is too small in the image to carve).
The capture volume is the box over the points enough cameras see, `REGION_HEIGHT` m
high. On the shared lab's four cameras it is x -0.9..1.3, z -2.5..0.8 m, which holds
its walkway (x -0.6..0.6, z -1.7..-0.5).
"""

from __future__ import annotations

import numpy as np

from samba.base import InputError
from samba.cameras import Camera, CameraGroup

REGION_HEIGHT = 2.2
"""Height (m) of the capture volume above the floor: a person with raised arms."""
FLOOR_STEP = 0.05
"""Spacing (m) of the floor points sampled."""
MAX_RANGE = 8.0
"""Farthest (m) a floor point may lie from a camera that counts as seeing it."""
FOLD_PX = 1.0
"""Largest difference (pixels) between a floor point's pinhole projection and its
undistorted pixel for the lens distortion to count as mapping it into the image."""


def capture_region(
    cameras: CameraGroup, min_views: int | None = None, height: float = REGION_HEIGHT
) -> np.ndarray:
    """The capture volume (2, 3) m, low and high corners (x, y, z): the box over the
    floor points (y = 0) that `min_views` of `cameras` (default: all) see, from the
    floor to `height` m. `InputError` naming the cameras when no floor point is seen
    by that many."""
    required = len(cameras) if min_views is None else min_views
    centres = np.stack([camera.center for camera in cameras])
    low = np.floor((centres[:, [0, 2]].min(axis=0) - MAX_RANGE) / FLOOR_STEP)
    high = np.ceil((centres[:, [0, 2]].max(axis=0) + MAX_RANGE) / FLOOR_STEP)
    x, z = (FLOOR_STEP * np.arange(a, b + 1) for a, b in zip(low, high, strict=True))
    floor = np.stack(np.meshgrid(x, [0.0], z, indexing="ij"), axis=-1).reshape(-1, 3)
    seen = np.zeros(len(floor), dtype=np.int32)
    for camera in cameras:
        near = np.flatnonzero(np.linalg.norm(floor - camera.center, axis=1) <= MAX_RANGE)
        near = near[camera.to_camera(floor[near])[:, 2] > 0]
        seen[near[_in_image(camera, floor[near])]] += 1
    region = floor[seen >= required]
    if not len(region):
        raise InputError(
            f"cameras {', '.join(cameras.names)}",
            f"no floor point within {MAX_RANGE:g} m is seen by {required} of them: give the "
            "capture volume with --bounds",
        )
    low, high = region.min(axis=0), region.max(axis=0)
    high[1] = height
    return np.stack([low, high])


def _in_image(camera: Camera, points: np.ndarray) -> np.ndarray:
    """Whether world points (m, 3) m in front of `camera` project into its image, bool
    (m,): inside it, and where undistorting the pixel gives back the pinhole projection
    within `FOLD_PX` pixels (the distortion does not fold the point in)."""
    pixels = camera.project(points)
    pinhole = np.concatenate([points, np.ones((len(points), 1))], axis=1) @ camera.projection.T
    pinhole = pinhole[:, :2] / pinhole[:, 2:]
    with np.errstate(invalid="ignore"):
        unfolded = np.linalg.norm(camera.undistort(pixels) - pinhole, axis=1) <= FOLD_PX
    return camera.in_image(pixels) & unfolded
