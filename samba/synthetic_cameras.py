"""Cameras for synthetic captures: placed like EVALUATION.md's, any number and any size.

`spread_cameras` puts 2..N cameras around a take as EVALUATION.md places its two (1.5 m
high, 60-degree lens, aimed at the mean marker position, as close as 3.5 m + 0.25 m steps
allow while 99.5% of the marker views stay in the images): cam0 and cam1 exactly where
`samba.observation.evaluation_cameras` puts them, the others around the back.
`with_size` resamples a camera's image to another resolution with the same view.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from samba.camera import Camera
from samba.observation import (
    CAMERA_HEIGHT,
    DISTANCE_STEP,
    HFOV_DEG,
    IMAGE_SIZE,
    MAX_DISTANCE,
    MIN_COVERAGE,
    SEPARATION_DEG,
    START_DISTANCE,
    marker_coverage,
    mean_facing,
)
from samba.skeleton import markers_of


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


def spread_cameras(
    poses: np.ndarray, count: int = 2, size: tuple[int, int] = IMAGE_SIZE
) -> list[Camera]:
    """`count` >= 2 cameras around a take's poses (n, 13, 3) meters, EVALUATION.md style.

    All are at y = 1.5 m with a 60-degree lens, aimed at the mean marker position, at the
    shortest horizontal distance 3.5 + 0.25 k m from it at which >= 99.5% of the marker
    views fall inside all images. cam0 and cam1 stand 37.5 degrees either side of the
    mean facing direction (exactly `evaluation_cameras` when `count` is 2 at 160x120);
    the others spread over the back, 180 +- 37.5 degrees from the facing.
    """
    if count < 2:
        raise ValueError(f"spread_cameras needs at least 2 cameras, got {count}")
    poses = np.asarray(poses, dtype=np.float64)
    half = SEPARATION_DEG / 2.0
    back = [180.0] if count == 3 else list(np.linspace(180.0 - half, 180.0 + half, count - 2))
    turns = Rotation.from_euler("y", np.array([half, -half, *back])[:, None], degrees=True)
    directions = turns.apply(mean_facing(poses))
    aim = markers_of(poses).reshape(-1, 3).mean(axis=0)
    distance = START_DISTANCE
    while distance <= MAX_DISTANCE:
        cameras = [
            Camera.look_at(
                name=f"cam{i}",
                position=np.array([aim[0], CAMERA_HEIGHT, aim[2]]) + distance * direction,
                target=aim,
                size=size,
                hfov_deg=HFOV_DEG,
            )
            for i, direction in enumerate(directions)
        ]
        if marker_coverage(poses, cameras) >= MIN_COVERAGE:
            return cameras
        distance += DISTANCE_STEP
    raise ValueError(f"the take's markers do not fit {count} cameras within {MAX_DISTANCE} m")
