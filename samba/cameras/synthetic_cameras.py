"""Synthetic cameras: `with_size`, a camera's image resampled to another resolution with
the same view (for synthetic captures at several resolutions;
`samba.markers.observation.spread_cameras` places the cameras), and `detected_blobs`, what an
ideal blob detector reports of markers without rendering them."""

from __future__ import annotations

import numpy as np

from samba.cameras.camera import Camera, CameraGroup


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


def detected_blobs(
    cameras: CameraGroup,
    markers: np.ndarray,
    rng: np.random.Generator,
    noise_px: float = 0.3,
    stray: int = 0,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """The markers (8, 3) m as blob centroids: their pixels (c, 8, 2) in every camera
    with Gaussian noise of `noise_px`, and each camera's blobs (m_c, 2), the pixels
    inside its image and `stray` bright spots anywhere in it, in random order. Markers
    hide nothing and never merge."""
    pixels = cameras.project(markers)
    pixels = pixels + rng.normal(0.0, noise_px, pixels.shape)
    blobs = []
    for camera, uv in zip(cameras, pixels, strict=True):
        spots = rng.uniform((0, 0), camera.size, (stray, 2))
        blobs.append(rng.permutation(np.concatenate([uv[camera.in_image(uv)], spots])))
    return pixels, blobs
