"""`with_size`: a camera's image resampled to another resolution with the same view
(for synthetic captures at several resolutions; `samba.observation.spread_cameras`
places the cameras)."""

from __future__ import annotations

import numpy as np

from samba.camera import Camera


def with_size(camera: Camera, size: tuple[int, int]) -> Camera:
    """The same camera with its image resampled to `size` (width, height) pixels.

    Intrinsics scale about the pixel grid (u' = (u + 0.5) * s - 0.5); the pose and the
    distortion (in normalised coordinates) are unchanged.
    """
    sx, sy = size[0] / camera.size[0], size[1] / camera.size[1]
    scale = np.diag([sx, sy, 1.0])
    shift = np.array([[1.0, 0.0, (sx - 1) / 2], [0.0, 1.0, (sy - 1) / 2], [0.0, 0.0, 1.0]])
    return Camera(
        name=camera.name,
        size=size,
        matrix=shift @ scale @ camera.matrix,
        rotation=camera.rotation,
        translation=camera.translation,
        distortion=camera.distortion,
    )
