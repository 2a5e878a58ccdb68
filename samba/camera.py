"""`Camera`: a calibrated pinhole camera with OpenCV lens distortion.

Conventions:

* World frame: right-handed, +Y up, meters (see ARCHITECTURE.md).
* Camera frame (OpenCV): x right, y down, z forward along the optical axis; a world point
  goes to the camera frame by ``x_cam = R @ x_world + t``, with ``R`` given as a
  Rodrigues (rotation) vector.
* Pixels (OpenCV): u to the right, v down, pixel centres at integer coordinates, so an
  image of `size` (width, height) covers u in [-0.5, width - 0.5] and v in
  [-0.5, height - 0.5] and its centre is at ((width - 1) / 2, (height - 1) / 2).
* Distortion: OpenCV's five coefficients (k1, k2, p1, p2, k3), radial and tangential,
  applied to the normalised image coordinates before the intrinsics `matrix`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.spatial.transform import Rotation


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=np.float64)
    array.flags.writeable = False
    return array


def _check_size(name: str, size: tuple[int, int]) -> tuple[int, int]:
    """`size` as (width, height) Python ints; ValueError unless two positive integers."""
    try:
        width, height = size
    except (TypeError, ValueError):
        width = height = None
    if not all(isinstance(s, int | np.integer) and s >= 1 for s in (width, height)):
        raise ValueError(
            f"camera {name!r}: size must be (width, height) positive integers, got {size!r}"
        )
    return int(width), int(height)


@dataclass(frozen=True, eq=False)
class Camera:
    """One calibrated camera: intrinsics, pose in the world and lens distortion.

    `size` is (width, height) in pixels, `matrix` the (3, 3) intrinsics K in pixels,
    `rotation` the (3,) Rodrigues vector of the world-to-camera rotation R (radians),
    `translation` the (3,) t in meters with ``x_cam = R @ x_world + t``, `distortion` the
    (5,) OpenCV coefficients (k1, k2, p1, p2, k3), zeros by default. Arrays are stored
    as read-only float64 copies. Build one directly or with `look_at`.
    """

    name: str
    size: tuple[int, int]
    matrix: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(5))

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", _check_size(self.name, self.size))
        for name, shape in (
            ("matrix", (3, 3)),
            ("rotation", (3,)),
            ("translation", (3,)),
            ("distortion", (5,)),
        ):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != shape:
                raise ValueError(
                    f"camera {self.name!r}: {name} must have shape {shape}, got {value.shape}"
                )
            if not np.isfinite(value).all():
                raise ValueError(f"camera {self.name!r}: {name} contains NaN or infinity")
            object.__setattr__(self, name, _readonly(value))
        if self.matrix[2, 2] == 0:
            raise ValueError(f"camera {self.name!r}: matrix has K[2, 2] = 0")

    @classmethod
    def look_at(
        cls,
        name: str,
        position: Sequence[float] | np.ndarray,
        target: Sequence[float] | np.ndarray,
        size: tuple[int, int],
        hfov_deg: float,
        up: Sequence[float] | np.ndarray = (0.0, 1.0, 0.0),
    ) -> Camera:
        """A distortion-free camera at `position` whose optical axis passes through `target`.

        `position`, `target` are world points (3,) in meters, `up` a world direction that
        appears up (towards -v) in the image. `hfov_deg` is the horizontal field of view
        in degrees across the full image width; pixels are square and the principal point
        is the image centre ((width - 1) / 2, (height - 1) / 2).
        """
        position = np.asarray(position, dtype=np.float64)
        target = np.asarray(target, dtype=np.float64)
        up = np.asarray(up, dtype=np.float64)
        if position.shape != (3,) or target.shape != (3,) or up.shape != (3,):
            raise ValueError(f"camera {name!r}: position, target and up must be (3,) vectors")
        if not 0.0 < hfov_deg < 180.0:
            raise ValueError(f"camera {name!r}: hfov_deg must be in (0, 180), got {hfov_deg}")
        forward = target - position
        distance, up_norm = np.linalg.norm(forward), np.linalg.norm(up)
        if distance < 1e-12 or up_norm < 1e-12:
            raise ValueError(f"camera {name!r}: target equals position, or up is zero")
        forward /= distance
        right = np.cross(forward, up / up_norm)
        if np.linalg.norm(right) < 1e-9:
            raise ValueError(f"camera {name!r}: the viewing direction is parallel to up")
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        rotation_matrix = np.stack([right, down, forward])
        width, height = _check_size(name, size)
        focal = (width / 2.0) / np.tan(np.radians(hfov_deg) / 2.0)
        matrix = np.array(
            [[focal, 0.0, (width - 1) / 2.0], [0.0, focal, (height - 1) / 2.0], [0.0, 0.0, 1.0]]
        )
        return cls(
            name=name,
            size=size,
            matrix=matrix,
            rotation=Rotation.from_matrix(rotation_matrix).as_rotvec(),
            translation=-rotation_matrix @ position,
        )

    @cached_property
    def rotation_matrix(self) -> np.ndarray:
        """The world-to-camera rotation R, (3, 3)."""
        return _readonly(Rotation.from_rotvec(self.rotation.copy()).as_matrix())

    @property
    def center(self) -> np.ndarray:
        """The camera's optical centre in the world, (3,) meters: ``-R.T @ t``."""
        return -self.rotation_matrix.T @ self.translation

    @property
    def projection(self) -> np.ndarray:
        """The (3, 4) projection matrix K [R | t] (distortion not included)."""
        return self.matrix @ np.hstack([self.rotation_matrix, self.translation[:, None]])

    @property
    def has_distortion(self) -> bool:
        """Whether any distortion coefficient is non-zero."""
        return bool(np.any(self.distortion != 0.0))

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) in meters to the camera frame (..., 3) in meters."""
        points = np.asarray(points, dtype=np.float64)
        return points @ self.rotation_matrix.T + self.translation

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixel coordinates (..., 2) of world points (..., 3) in meters, with distortion.

        Points on or behind the camera plane (z <= 0) and NaN points give NaN pixels.
        Points outside the image are projected all the same; see `in_image`.
        """
        points = np.asarray(points, dtype=np.float64)
        if points.shape[-1:] != (3,):
            raise ValueError(f"camera {self.name!r}: points must be (..., 3), got {points.shape}")
        cam = self.to_camera(points)
        z = cam[..., 2]
        with np.errstate(invalid="ignore", divide="ignore"):
            z = np.where(z > 0.0, z, np.nan)
            x, y = cam[..., 0] / z, cam[..., 1] / z
        k1, k2, p1, p2, k3 = self.distortion
        if self.has_distortion:
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            x, y = (
                x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
            )
        k = self.matrix
        w = k[2, 0] * x + k[2, 1] * y + k[2, 2]
        u = (k[0, 0] * x + k[0, 1] * y + k[0, 2]) / w
        v = (k[1, 0] * x + k[1, 1] * y + k[1, 2]) / w
        return np.stack([u, v], axis=-1)

    def in_image(self, uv: np.ndarray) -> np.ndarray:
        """Whether pixels (..., 2) lie inside the image; bool (...), False for NaN."""
        uv = np.asarray(uv, dtype=np.float64)
        width, height = self.size
        u, v = uv[..., 0], uv[..., 1]
        return (u >= -0.5) & (u <= width - 0.5) & (v >= -0.5) & (v <= height - 0.5)
