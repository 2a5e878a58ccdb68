"""`SilhouetteView`: one camera watching a subject on the floor, and the normalised frame in
which silhouettes are compared.

The shape tree renders its silhouettes once, with the subject standing at a fixed floor
point (`home`); the subject then moves about the stage. Every silhouette — the tree's
and each observed one — is brought into one normalised image by a similarity transform
computed from the silhouette alone, so that both go through exactly the same step:

* its anchor is (column of its core, row of its lowest pixel): the core is the interior
  region farthest from the outline (in the trunk whatever the limbs do), the lowest pixel
  is where the feet meet the floor;
* the anchor moves to the home point's pixel, and the image scales about it by the depth
  of the anchor's floor point over the home depth (a subject twice as far away looks
  half as big), and by the body model's stature over the subject's when they differ
  (the tree's silhouettes are the model's: a subject 2% taller than it is brought to
  its size).

The anchor's floor point is where the subject stands: the tracker turns a tree pose
(rendered at home) into a world pose by moving it there (`Placement.floor`) and scaling
it to the subject's stature (`Placement.size`).

Pixels follow the OpenCV convention of `samba.cameras.camera.Camera`; world coordinates are
meters, +Y up, the floor at y = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from samba.base import InputError
from samba.cameras import Camera, with_size

VIEW_SIZE = (320, 240)
"""(width, height) of the normalised silhouette images: the finest level of the tree."""
CORE_FRACTION = 0.9
"""The core is the mean column of the pixels at least this fraction of the deepest
pixel's distance from the outline (steadier than the single deepest pixel)."""
HOME_AIM_HEIGHT = 0.9
"""A camera is taken to aim at the middle of the subject: by default the home point is
under the point where the optical axis is this many meters above the floor."""
HOME_DISTANCE = 3.0
"""Meters from the camera to the home point when the optical axis never passes at
`HOME_AIM_HEIGHT` in front of the camera."""


@dataclass(frozen=True)
class Placement:
    """Where a silhouette stands: its `anchor` (2,) in pixels, the `scale` that brings it
    to the home depth and the body model's size, the `floor` point (3,) in meters under
    the anchor, and the subject's `size`: its stature over the body model's."""

    anchor: np.ndarray
    scale: float
    floor: np.ndarray
    size: float = 1.0


class SilhouetteView:
    """A camera, resampled to `size`, watching a subject whose home is a floor point.

    `home` (3,) meters defaults to the floor point under the optical axis at
    `HOME_AIM_HEIGHT` (or the one `HOME_DISTANCE` ahead when the axis stays level at
    that height or moves away from it). `InputError` when the camera cannot see the
    floor around home.
    """

    def __init__(
        self,
        camera: Camera,
        home: np.ndarray | None = None,
        size: tuple[int, int] = VIEW_SIZE,
    ) -> None:
        self.camera = with_size(camera, size)
        self.size = size
        if home is None:
            home = self._default_home()
        self.home = np.array([home[0], 0.0, home[2]], dtype=np.float64)
        self.home_pixel = self.camera.project(self.home)
        self.home_depth = float(self.camera.to_camera(self.home)[2])
        if not (np.isfinite(self.home_pixel).all() and self.home_depth > 0):
            raise InputError(camera.name, "the camera does not see the floor at the home point")

    def _default_home(self) -> np.ndarray:
        centre = self.camera.center
        axis = self.camera.rotation_matrix[2]
        rise = HOME_AIM_HEIGHT - centre[1]
        if abs(axis[1]) > 1e-6 and rise / axis[1] > 0:
            return centre + axis * rise / axis[1]
        ahead = np.array([axis[0], 0.0, axis[2]])
        return centre + ahead / np.linalg.norm(ahead) * HOME_DISTANCE

    def floor_points(self, pixels: np.ndarray) -> np.ndarray:
        """Floor points (..., 3) in meters seen at `pixels` (..., 2) of the view (the
        distortion-free pinhole rays); NaN where the ray misses the floor ahead."""
        pixels = np.asarray(pixels, dtype=np.float64)
        rays = np.concatenate([pixels, np.ones_like(pixels[..., :1])], axis=-1)
        rays = rays @ np.linalg.inv(self.camera.matrix).T @ self.camera.rotation_matrix
        centre = self.camera.center
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -centre[1] / rays[..., 1]
        t = np.where(t > 0, t, np.nan)
        return centre + rays * t[..., None]

    def placement(self, mask: np.ndarray, size: float = 1.0) -> Placement:
        """The anchor, scale and floor point of a silhouette `mask` (H, W) bool of the
        view's size, of a subject `size` times as tall as the body model; `InputError`
        for an empty mask, one whose feet are above the horizon, or a size that is not a
        positive number."""
        if not (np.isfinite(size) and size > 0):
            raise InputError("size", f"the subject's size must be > 0, got {size}")
        mask = self._check(mask)
        rows = np.flatnonzero(mask.any(axis=1))
        columns = np.flatnonzero(mask.any(axis=0))
        box = np.pad(mask[rows[0] : rows[-1] + 1, columns[0] : columns[-1] + 1], 1)
        inside = cv2.distanceTransform(box.view(np.uint8), cv2.DIST_L2, 3)
        _, core = np.nonzero(inside >= CORE_FRACTION * inside.max())
        anchor = np.array([float(core.mean() + columns[0] - 1), float(rows[-1])])
        floor = self.floor_points(anchor)
        depth = float(self.camera.to_camera(floor)[2])
        if not depth > 0:
            raise InputError("silhouette", "its lowest point is above the horizon")
        return Placement(anchor, depth / self.home_depth / size, floor, size)

    def normalise(self, mask: np.ndarray, size: float = 1.0) -> tuple[np.ndarray, Placement]:
        """`mask` (H, W) bool moved and scaled into the normalised frame, with its
        placement; `size` is the subject's stature over the body model's."""
        placement = self.placement(mask, size)
        s = placement.scale
        shift = self.home_pixel - s * placement.anchor
        warp = np.array([[s, 0.0, shift[0]], [0.0, s, shift[1]]])
        moved = cv2.warpAffine(
            mask.view(np.uint8), warp, self.size, flags=cv2.INTER_NEAREST, borderValue=0
        )
        return moved.astype(bool), placement

    def _check(self, mask: np.ndarray) -> np.ndarray:
        mask = np.asarray(mask)
        width, height = self.size
        if mask.shape != (height, width) or mask.dtype != bool:
            raise InputError(
                "silhouette",
                f"expected a ({height}, {width}) bool mask, got {mask.shape} {mask.dtype}",
            )
        if not mask.any():
            raise InputError("silhouette", "the mask is empty: nobody is in view")
        return np.ascontiguousarray(mask)
