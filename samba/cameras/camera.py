"""`Camera`: a calibrated pinhole camera with OpenCV lens distortion; `CameraGroup`: the
ordered, uniquely named cameras of one capture stage.

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

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.spatial.transform import Rotation

UNDISTORT_ITERATIONS = 20
"""Newton steps `Camera.undistort` takes at most."""
UNDISTORT_TOLERANCE = 1e-12
"""Residual (normalised image units) below which `Camera.undistort` has converged."""


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.array(array, dtype=np.float64)
    array.flags.writeable = False
    return array


def distort(x: np.ndarray, y: np.ndarray, distortion: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's radial and tangential lens distortion of normalised image coordinates.

    x, y (...) are the camera-frame x / z and y / z; `distortion` (..., 5) holds
    (k1, k2, p1, p2, k3), broadcast against x and y (one row per point, or one for all).
    Returns the distorted (x, y), which the intrinsics matrix takes to pixels.
    """
    k1, k2, p1, p2, k3 = np.moveaxis(np.asarray(distortion, dtype=np.float64), -1, 0)
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return (
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    )


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

    @cached_property
    def has_distortion(self) -> bool:
        """Whether any distortion coefficient is non-zero (asked on every projection and
        undistortion, so computed once: the coefficients are read only)."""
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
        if self.has_distortion:
            x, y = self._distort(x, y)
        return self._to_pixels(x, y)

    def undistort(self, uv: np.ndarray) -> np.ndarray:
        """Undistorted pixels (..., 2) of distorted pixels uv (..., 2) of this camera.

        The result is where the pinhole camera without lens distortion (same `matrix`,
        pose and size) sees the same ray, so ``undistort(project(X))`` equals the
        projection of X by the `projection` matrix. The inverse of the distortion is
        found per point by Newton's method from the distorted position; NaN pixels,
        and pixels where it does not converge (far outside the image of a strongly
        distorting lens), give NaN.
        """
        uv = np.asarray(uv, dtype=np.float64)
        if uv.shape[-1:] != (2,):
            raise ValueError(f"camera {self.name!r}: pixels must be (..., 2), got {uv.shape}")
        if not self.has_distortion:
            return uv.copy()
        homogeneous = np.concatenate([uv, np.ones_like(uv[..., :1])], axis=-1)
        normalised = homogeneous @ np.linalg.inv(self.matrix).T
        xd, yd = normalised[..., 0] / normalised[..., 2], normalised[..., 1] / normalised[..., 2]
        x, y = xd.copy(), yd.copy()
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            for _ in range(UNDISTORT_ITERATIONS + 1):
                fx, fy = self._distort(x, y)
                ex, ey = fx - xd, fy - yd
                converged = np.hypot(ex, ey) <= UNDISTORT_TOLERANCE * (1.0 + np.hypot(x, y))
                if (converged | np.isnan(ex)).all():
                    break
                (a, b), (c, d) = self._distort_jacobian(x, y)
                det = a * d - b * c
                x, y = x - (d * ex - b * ey) / det, y - (a * ey - c * ex) / det
        return np.where(converged[..., None], self._to_pixels(x, y), np.nan)

    def _distort(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`distort` with this camera's coefficients."""
        return distort(x, y, self.distortion)

    def _distort_jacobian(
        self, x: np.ndarray, y: np.ndarray
    ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """The 2x2 Jacobian ((dxd/dx, dxd/dy), (dyd/dx, dyd/dy)) of `_distort` at x, y (...)."""
        k1, k2, p1, p2, k3 = self.distortion
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        slope = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r2
        cross = 2.0 * x * y * slope + 2.0 * p1 * x + 2.0 * p2 * y
        return (
            (radial + 2.0 * x * x * slope + 2.0 * p1 * y + 6.0 * p2 * x, cross),
            (cross, radial + 2.0 * y * y * slope + 6.0 * p1 * y + 2.0 * p2 * x),
        )

    def _to_pixels(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) of normalised (distorted) image coordinates x, y (...)."""
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


@dataclass(frozen=True, eq=False)
class CameraGroup:
    """The cameras of one capture stage, in a fixed order, with unique names.

    Camera i of the group is camera i of every per-camera batch, such as the pixels
    (c, ..., 2) that `project` returns and triangulation takes. Index a group by
    position or by name; `len` and iteration follow the order.
    """

    cameras: tuple[Camera, ...]

    def __post_init__(self) -> None:
        cameras = tuple(self.cameras)
        if not cameras:
            raise ValueError("a camera group needs at least one camera")
        for camera in cameras:
            if not isinstance(camera, Camera):
                raise ValueError(f"a camera group holds Camera objects, got {camera!r}")
        names = [camera.name for camera in cameras]
        repeated = sorted({name for name in names if names.count(name) > 1})
        if repeated:
            raise ValueError(f"camera names must be unique, repeated: {', '.join(repeated)}")
        object.__setattr__(self, "cameras", cameras)

    @property
    def names(self) -> tuple[str, ...]:
        """The cameras' names, in order."""
        return tuple(camera.name for camera in self.cameras)

    @cached_property
    def projections(self) -> np.ndarray:
        """The (c, 3, 4) projection matrices K [R | t] (distortion not included)."""
        return _readonly(np.stack([camera.projection for camera in self.cameras]))

    def project(self, points: np.ndarray) -> np.ndarray:
        """Pixels (c, ..., 2) of world points (..., 3), meters, in each of the c cameras.

        With distortion; NaN where a point is behind a camera (see `Camera.project`).
        """
        return np.stack([camera.project(points) for camera in self.cameras])

    def undistort(self, uv: np.ndarray) -> np.ndarray:
        """Undistorted pixels (c, ..., 2) of distorted pixels uv (c, ..., 2), camera by camera.

        See `Camera.undistort`; NaN stays NaN.
        """
        uv = np.asarray(uv, dtype=np.float64)
        if uv.ndim < 2 or uv.shape[0] != len(self) or uv.shape[-1] != 2:
            raise ValueError(f"pixels must be ({len(self)}, ..., 2), got {uv.shape}")
        return np.stack([camera.undistort(p) for camera, p in zip(self.cameras, uv, strict=True)])

    def index(self, name: str) -> int:
        """The position of the camera called `name`; KeyError if there is none."""
        for i, camera in enumerate(self.cameras):
            if camera.name == name:
                return i
        raise KeyError(f"no camera named {name!r}; cameras: {', '.join(self.names)}")

    def __getitem__(self, key: int | str) -> Camera:
        """Camera by position (int) or by name (str)."""
        return self.cameras[self.index(key) if isinstance(key, str) else key]

    def __len__(self) -> int:
        return len(self.cameras)

    def __iter__(self) -> Iterator[Camera]:
        return iter(self.cameras)
