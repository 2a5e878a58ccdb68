"""The synthetic capture of EVALUATION.md ("Observation model"): cameras, 2D noise, dropout.

* `evaluation_cameras`: two 160x120 pinhole cameras, 60 degrees horizontal field of view,
  75 degrees apart about the take's mean facing direction, 1.5 m above the floor, aimed at
  the take's mean marker position from the shortest distance (3.5 m, then 0.25 m steps)
  at which >= 99.5% of the marker views fall inside the images.
* `observe_markers`: project the 8 markers, add Gaussian pixel noise, round to the blob
  centroid's resolution, drop out-of-view and randomly dropped markers, and triangulate
  the 3D markers by DLT.
* `scale_limbs` / `new_user_factors`: the new-user variant, limb bones scaled per bone.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from samba.body import BONES, N_MARKERS, markers_of, mean_facing, pose_batch
from samba.cameras import Camera, triangulate_cameras

IMAGE_SIZE: tuple[int, int] = (160, 120)
"""(width, height) in pixels of the evaluation cameras."""
HFOV_DEG = 60.0
"""Horizontal field of view of the evaluation cameras, degrees."""
SEPARATION_DEG = 75.0
"""Angle between the two evaluation cameras about the vertical through the aim point."""
CAMERA_HEIGHT = 1.5
"""Height of the evaluation cameras above the floor (y = 0), meters."""
START_DISTANCE = 3.5
"""First horizontal camera distance from the aim point tried, meters."""
DISTANCE_STEP = 0.25
"""Step by which the camera distance grows until the markers fit, meters."""
MIN_COVERAGE = 0.995
"""Fraction of marker views that must fall inside the images."""
MAX_DISTANCE = 100.0
"""Distance beyond which `evaluation_cameras` gives up, meters."""
LIMB_FACTOR_RANGE = (0.9, 1.1)
"""Range of the new-user variant's per-bone scale factors."""


@dataclass(frozen=True, eq=False)
class ObservedMarkers:
    """What the synthetic capture saw of a take of n frames through c cameras.

    `pixels` (c, n, 8, 2): marker pixel coordinates per camera, NaN where out of view or
    dropped. `markers` (n, 8, 3): the triangulated markers in world meters, NaN where
    fewer than two cameras saw the marker.
    """

    pixels: np.ndarray
    markers: np.ndarray

    @property
    def present(self) -> np.ndarray:
        """Whether each 3D marker was reconstructed, bool (n, 8)."""
        return ~np.isnan(self.markers).any(axis=-1)


def marker_coverage(poses: np.ndarray, cameras: Sequence[Camera]) -> float:
    """Fraction of marker views (8 markers x n frames x c cameras) inside the images."""
    markers = markers_of(pose_batch(poses))
    inside = [camera.in_image(camera.project(markers)) for camera in cameras]
    return float(np.mean(inside))


def evaluation_cameras(poses: np.ndarray) -> list[Camera]:
    """The two evaluation cameras "cam0" and "cam1" for a take's poses (n, 13, 3), meters.

    Both are 160x120, 60 degrees horizontal field of view, distortion-free, at y = 1.5 m,
    aimed at the mean marker position, and placed 37.5 degrees either side of the mean
    facing direction (cam0 towards the subject's left, cam1 towards its right) at the
    smallest horizontal distance 3.5 + 0.25 k m (k = 0, 1, ...) from the aim point at
    which at least 99.5% of the marker views fall inside both images.
    """
    return spread_cameras(poses, 2, IMAGE_SIZE)


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


def observe_markers(
    poses: np.ndarray,
    cameras: Sequence[Camera],
    rng: np.random.Generator,
    noise_px: float = 0.3,
    resolution_px: float = 0.1,
    dropout: float = 0.0,
    dropout_from: int = 2,
) -> ObservedMarkers:
    """The 8 markers of poses (n, 13, 3), meters, as seen and triangulated by `cameras`.

    Each marker's projection gets Gaussian noise of `noise_px` pixels (sigma) and is then
    rounded to a multiple of `resolution_px` (0 turns either off). Pixels outside an image
    are missing. Then `dropout` (a fraction in [0, 1]) of the 3D marker observations
    (frame, marker) from frame index `dropout_from` on, chosen at random without
    replacement, are removed from every camera. The 3D markers come from DLT
    triangulation; fewer than two views leave a marker NaN. Cameras must be
    distortion-free. `rng` draws the noise first, then the dropout.
    """
    poses = pose_batch(poses)
    if len(cameras) == 0:
        raise ValueError("observe_markers needs at least one camera")
    if not noise_px >= 0 or not resolution_px >= 0:
        raise ValueError(
            f"noise_px and resolution_px must be >= 0, got {noise_px}, {resolution_px}"
        )
    if not 0.0 <= dropout <= 1.0:
        raise ValueError(f"dropout must be a fraction in [0, 1], got {dropout}")
    if dropout_from < 0:
        raise ValueError(f"dropout_from must be >= 0, got {dropout_from}")
    markers = markers_of(poses)
    pixels = np.stack([camera.project(markers) for camera in cameras])  # (c, n, 8, 2)
    if noise_px > 0:
        pixels = pixels + rng.normal(scale=noise_px, size=pixels.shape)
    if resolution_px > 0:
        pixels = np.round(pixels / resolution_px) * resolution_px
    for i, camera in enumerate(cameras):
        pixels[i][~camera.in_image(pixels[i])] = np.nan
    if dropout > 0:
        eligible = np.flatnonzero(np.arange(len(poses)) >= dropout_from)
        slots = len(eligible) * N_MARKERS
        chosen = rng.choice(slots, size=round(dropout * slots), replace=False)
        pixels[:, eligible[chosen // N_MARKERS], chosen % N_MARKERS] = np.nan
    return ObservedMarkers(pixels=pixels, markers=triangulate_cameras(cameras, pixels))


def scale_limbs(poses: np.ndarray, factors: np.ndarray) -> np.ndarray:
    """Poses (n, 13, 3) with each limb bone of `BONES` scaled by its factor (8,).

    Scaling a bone moves its child joint along the bone and every joint below it (the
    upper arm's factor moves elbow and wrist, the shin's only the foot) by the same
    offset, so the other bones keep their lengths and directions. The head, shoulders
    and hips are unchanged; the feet are not put back on the floor. Returns float64.
    """
    poses = pose_batch(poses).copy()
    factors = np.asarray(factors, dtype=np.float64)
    if factors.shape != (len(BONES),):
        raise ValueError(f"factors must be ({len(BONES)},), one per bone, got {factors.shape}")
    if not (np.isfinite(factors).all() and (factors > 0).all()):
        raise ValueError(f"factors must be positive and finite, got {factors}")
    for (parent, child), factor in zip(BONES, factors, strict=True):
        offset = (factor - 1.0) * (poses[:, child] - poses[:, parent])
        poses[:, _below(child)] += offset[:, None, :]
    return poses


def new_user_factors(rng: np.random.Generator) -> np.ndarray:
    """Random per-bone scale factors (8,), uniform in [0.9, 1.1], in `BONES` order."""
    return rng.uniform(*LIMB_FACTOR_RANGE, size=len(BONES))


def _below(joint: int) -> list[int]:
    """`joint` and every joint below it along `BONES`."""
    out = [joint]
    for parent, child in BONES:
        if parent in out:
            out.append(child)
    return out
