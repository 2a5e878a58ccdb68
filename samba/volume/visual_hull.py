"""Volume capture by silhouette carving (Chu, Jenkins & Mataric, CVPR 2003, section 2).

Cameras stand around three sides of a rectangular capture volume divided into a
`VoxelGrid`, each seeing roughly all of it (`volume_cameras`). `VisualHull`
precomputes per camera a look-up table from each voxel to the pixel its centre
projects to; carving a frame counts, for every voxel, the cameras whose silhouette
holds that pixel (or, with a `tolerance`, lies within that many pixels of it: a
calibration a few pixels off carves thin parts away), and keeps the voxels counted by
enough cameras. `human_volumes`
renders and carves the synthetic human volume sequence of poses of the capsule body.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from samba.base import InputError
from samba.body import BodyModel
from samba.cameras import Camera, CameraGroup
from samba.silhouette import noisy_silhouettes, render_silhouettes
from samba.volume.voxel_grid import VoxelGrid

OUTSIDE = -1
"""Look-up table entry of a voxel behind a camera or projecting outside its image."""
HFOV_DEG = 60.0
"""Horizontal field of view of the `volume_cameras`, degrees."""
CAMERA_HEIGHT = 1.8
"""Height of the `volume_cameras` above the floor (y = 0), meters."""
AZIMUTHS: tuple[tuple[str, float], ...] = (
    ("front", 0.0),
    ("left", 90.0),
    ("right", -90.0),
    ("front_left", 45.0),
    ("front_right", -45.0),
)
"""Name and azimuth (degrees from +Z towards +X about the vertical through the volume
centre) of the `volume_cameras`, taken in this order: the front (+Z, where the standard
pose faces), the subject's left and right, then the front diagonals."""
FRAME_MARGIN = 0.03
"""Fraction of the image width and height `volume_cameras` keeps free around the volume."""
DISTANCE_STEP = 0.05
"""Step (m) by which `volume_cameras` moves the cameras back until the volume fits."""


class VisualHull:
    """Silhouette carving of a `VoxelGrid` seen by calibrated cameras.

    Built once per camera set: for each camera, the flat pixel index ``v * W + u``
    (int32) of the pixel nearest to where each voxel centre projects (with lens
    distortion), or `OUTSIDE` (-1) when the centre is behind the camera or outside the
    image. Only voxels some camera sees are stored (a voxel no camera sees is never
    kept), as a (c, m) table over those m voxels.
    """

    def __init__(self, grid: VoxelGrid, cameras: CameraGroup | Sequence[Camera]) -> None:
        """Precompute the look-up tables of `grid` in each of `cameras` (order kept)."""
        self.grid = grid
        self.cameras = cameras if isinstance(cameras, CameraGroup) else CameraGroup(tuple(cameras))
        centers = grid.centers()
        tables = np.stack([_pixel_table(camera, centers) for camera in self.cameras])
        self._voxels = np.flatnonzero((tables != OUTSIDE).any(axis=0))
        self._tables = np.ascontiguousarray(tables[:, self._voxels])

    @property
    def tables(self) -> np.ndarray:
        """The look-up tables (c, nx * ny * nz) int32: flat pixel index or `OUTSIDE`."""
        tables = np.full((len(self.cameras), self.grid.count), OUTSIDE, dtype=np.int32)
        tables[:, self._voxels] = self._tables
        return tables

    def carve(
        self, silhouettes: Sequence[np.ndarray], min_views: int | None = None, tolerance: int = 0
    ) -> np.ndarray:
        """The occupancy (nx, ny, nz) bool of one frame's `silhouettes`.

        `silhouettes` holds one (H, W) bool mask per camera, in camera order, of that
        camera's image size. A voxel is kept when its centre's pixel is in the
        silhouette, or within `tolerance` pixels of it, in at least `min_views` cameras
        (default: all of them).
        """
        self._check_count(silhouettes)
        masks = [self._checked_masks(i, mask, 2) for i, mask in enumerate(silhouettes)]
        if not isinstance(tolerance, int | np.integer) or tolerance < 0:
            raise InputError("tolerance", f"must be an integer >= 0 pixels, got {tolerance!r}")
        if tolerance:
            disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * tolerance + 1,) * 2)
            masks = [cv2.dilate(mask.view(np.uint8), disc).view(bool) for mask in masks]
        return self._carve([mask.reshape(-1) for mask in masks], self._required(min_views))

    def carve_many(
        self, silhouettes: Sequence[np.ndarray], min_views: int | None = None
    ) -> np.ndarray:
        """The occupancies (n, nx, ny, nz) bool of n frames, as `carve` frame by frame.

        `silhouettes` holds per camera an (n, H, W) bool stack of its masks, e.g. an
        array (c, n, H, W) when all cameras have one image size.
        """
        self._check_count(silhouettes)
        stacks = [self._checked_masks(i, stack, 3) for i, stack in enumerate(silhouettes)]
        frames = {len(stack) for stack in stacks}
        if len(frames) != 1:
            raise InputError("silhouettes", f"cameras have different frame counts {frames}")
        required = self._required(min_views)
        flat = [stack.reshape(len(stack), -1) for stack in stacks]
        volumes = np.zeros((frames.pop(), *self.grid.shape), dtype=bool)
        for frame, volume in enumerate(volumes):
            volume[...] = self._carve([masks[frame] for masks in flat], required)
        return volumes

    def _carve(self, masks: list[np.ndarray], required: int) -> np.ndarray:
        """Occupancy (nx, ny, nz) of flat masks (H * W,) per camera, `required` views.

        Cameras are taken in turn; once a voxel can no longer reach `required` hits it
        is dropped, so later cameras look up fewer voxels (with every camera required,
        only the voxels inside all silhouettes so far). Each mask gets a False
        appended, which `OUTSIDE` (-1) indexes.
        """
        count = len(masks)
        alive = None  # indices into self._voxels of the voxels still in play; None: all
        hits = np.zeros(len(self._voxels), dtype=np.uint8)
        for camera, mask in enumerate(masks):
            table = self._tables[camera]
            pixels = table if alive is None else table.take(alive)
            hits += np.append(mask, False).take(pixels)
            needed = required - (count - 1 - camera)  # hits without which a voxel is out
            if needed > 0:
                keep = np.flatnonzero(hits >= needed)
                alive, hits = (keep if alive is None else alive[keep]), hits[keep]
        occupancy = np.zeros(self.grid.count, dtype=bool)
        occupancy[self._voxels[alive]] = True
        return occupancy.reshape(self.grid.shape)

    def _checked_masks(self, index: int, masks: np.ndarray, ndim: int) -> np.ndarray:
        """Camera `index`'s masks as a bool array (..., H, W) of `ndim` dimensions."""
        masks = np.asarray(masks)
        camera = self.cameras[index]
        width, height = camera.size
        if masks.ndim != ndim or masks.shape[-2:] != (height, width) or masks.dtype != bool:
            wanted = "(H, W)" if ndim == 2 else "(n, H, W)"
            raise InputError(
                f"silhouettes of camera {camera.name!r}",
                f"need {wanted} bool masks of its image size {width}x{height} "
                f"(W x H), got {masks.dtype} {masks.shape}",
            )
        return masks

    def _check_count(self, masks: Sequence[np.ndarray]) -> None:
        """`InputError` unless there is one entry of masks per camera."""
        if len(masks) != len(self.cameras):
            raise InputError(
                "silhouettes",
                f"need masks of {len(self.cameras)} cameras "
                f"({', '.join(self.cameras.names)}), got {len(masks)}",
            )

    def _required(self, min_views: int | None) -> int:
        """`min_views` checked, defaulting to every camera."""
        count = len(self.cameras)
        if min_views is None:
            return count
        if not isinstance(min_views, int | np.integer) or not 1 <= min_views <= count:
            raise InputError("min_views", f"must be an integer in 1..{count}, got {min_views!r}")
        return int(min_views)


def _pixel_table(camera: Camera, points: np.ndarray) -> np.ndarray:
    """Flat index (m,) int32 of the pixel nearest to each point (m, 3) m, or `OUTSIDE`."""
    width, height = camera.size
    with np.errstate(invalid="ignore"):
        pixel = np.floor(camera.project(points) + 0.5)  # NaN behind the camera
        inside = (pixel >= 0).all(axis=1) & (pixel[:, 0] < width) & (pixel[:, 1] < height)
    index = np.where(inside, pixel[:, 1] * width + pixel[:, 0], OUTSIDE)
    return index.astype(np.int32)


def human_volumes(
    poses: np.ndarray,
    cameras: CameraGroup | Sequence[Camera],
    body: BodyModel,
    grid: VoxelGrid,
    noise: float = 0.0,
    seed: int = 0,
) -> np.ndarray:
    """The synthetic human volume sequence (n, nx, ny, nz) bool of poses (n, 13, 3), m.

    Each camera's silhouettes of the capsule `body` are rendered (`render_silhouettes`;
    the poses should have the body's stature, see `samba.body.body_model.scaled_to`), spoilt
    by `noisy_silhouettes` at level `noise` (0: clean) with one generator seeded by
    `seed` drawn camera after camera, and carved in `grid`, keeping the voxels inside
    every camera's silhouette.
    """
    hull = VisualHull(grid, cameras)
    rng = np.random.default_rng(seed)
    masks = [
        noisy_silhouettes(render_silhouettes(poses, camera, body), rng, noise)
        for camera in hull.cameras
    ]
    return hull.carve_many(masks)


def volume_cameras(
    grid: VoxelGrid, count: int = 4, size: tuple[int, int] = (320, 240)
) -> CameraGroup:
    """`count` (1..5) cameras around three sides of the capture volume of `grid`.

    The paper's setup: cameras of `size` (width, height) px with a `HFOV_DEG` lens at
    `CAMERA_HEIGHT` m, at the `AZIMUTHS` (front, left, right, front-left, front-right),
    all aimed at the centre of the grid's box and each at the shortest horizontal
    distance from it (in `DISTANCE_STEP` m steps) at which the whole box lies in the
    image with a `FRAME_MARGIN` border.
    """
    if not isinstance(count, int | np.integer) or not 1 <= count <= len(AZIMUTHS):
        raise InputError("count", f"must be an integer in 1..{len(AZIMUTHS)}, got {count!r}")
    low, high = grid.bounds
    centre = 0.5 * (low + high)
    corners = np.stack(np.meshgrid(*zip(low, high, strict=True), indexing="ij"), -1)
    corners = corners.reshape(-1, 3)
    width, height = size
    margin = np.array([FRAME_MARGIN * width, FRAME_MARGIN * height])
    cameras = []
    for name, azimuth in AZIMUTHS[:count]:
        direction = np.array([np.sin(np.radians(azimuth)), 0.0, np.cos(np.radians(azimuth))])
        distance = 0.5 * np.linalg.norm((high - low)[[0, 2]]) + DISTANCE_STEP
        while True:
            position = np.array([centre[0], CAMERA_HEIGHT, centre[2]]) + distance * direction
            camera = Camera.look_at(name, position, centre, size, HFOV_DEG)
            pixels = camera.project(corners)
            with np.errstate(invalid="ignore"):
                fits = (pixels >= margin - 0.5).all() & (pixels <= size - margin - 0.5).all()
            if fits:
                break
            distance += DISTANCE_STEP
        cameras.append(camera)
    return CameraGroup(tuple(cameras))
