"""Synthetic images of a calibration board: the calibration tests' scenes and the board
photos `samba examples` writes.

`render_board` draws a `Board` lying in a known pose into a known camera's image: every
(supersampled) output pixel is undistorted with the camera's lens model
(`Camera.undistort`), taken to the board plane by the inverse of the plane's homography
and looked up in the board's texture (`cv2.remap`); the image is then averaged down,
blurred slightly and given sensor noise. `stage_cameras`, `board_poses` and
`floor_pose` build the scene calibrated there: cameras around a capture volume, a board
waved through it facing them, and the board lying on the floor with corner 0 at the
world origin. Lengths are meters, images 640x480 grey uint8.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from samba.cameras.calibration_board import Board
from samba.cameras.camera import Camera

SIZE = (640, 480)
SUPERSAMPLE = 2
BLACK, WHITE, BACKGROUND = 35.0, 215.0, 110.0
"""Grey levels of the board's dark and light squares and of the background."""

Pose = tuple[np.ndarray, np.ndarray]
"""A board pose: rotation (3, 3) and translation (3,) with x_world = R @ x_board + t."""

_FLOOR = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
_texture_cache: dict[tuple[Board, int], tuple[np.ndarray, np.ndarray]] = {}
_undistort_cache: dict[Camera, np.ndarray] = {}


def stage_cameras(
    count: int,
    distortions: Sequence[Sequence[float]] = (),
    radius: float = 2.75,
    height: float = 1.9,
    target: Sequence[float] = (0.3, 0.7, 0.2),
) -> list[Camera]:
    """`count` 640x480 cameras with a 60-degree horizontal field of view on an arc of
    `radius` m about the vertical through `target`, `height` m above the floor, 40
    degrees apart and centred on +Z, aimed at `target`; camera i gets the OpenCV
    distortion coefficients `distortions[i]` where given (zeros otherwise)."""
    cameras = []
    for i in range(count):
        azimuth = np.radians(40.0 * (i - (count - 1) / 2.0))
        position = np.array(
            [target[0] + radius * np.sin(azimuth), height, target[2] + radius * np.cos(azimuth)]
        )
        camera = Camera.look_at(f"cam{i}", position, target, SIZE, 60.0)
        if i < len(distortions):
            camera = Camera(
                camera.name,
                SIZE,
                camera.matrix,
                camera.rotation,
                camera.translation,
                np.array(distortions[i], dtype=np.float64),
            )
        cameras.append(camera)
    return cameras


def floor_pose() -> Pose:
    """The board lying face up on the floor: corner 0 at the origin, its x along world
    +X, its y along world +Z (so the board's z points down, -Y)."""
    return _FLOOR.copy(), np.zeros(3)


def board_poses(
    board: Board,
    cameras: Sequence[Camera],
    count: int,
    rng: np.random.Generator,
    centre: Sequence[float] = (0.3, 1.0, 0.2),
    spread: float = 0.45,
    max_tilt_deg: float = 35.0,
) -> list[Pose]:
    """`count` poses of the board with its centre uniformly within `spread` m of `centre`,
    its face turned towards the cameras' mean position tilted by up to `max_tilt_deg`,
    and a random turn in its own plane."""
    local_centre = board.object_points.mean(axis=0)
    toward = np.mean([c.center for c in cameras], axis=0) - np.array(centre)
    toward /= np.linalg.norm(toward)
    poses = []
    for _ in range(count):
        tilt = Rotation.from_rotvec(
            np.radians(max_tilt_deg) * rng.uniform(0, 1) * _unit_perpendicular(toward, rng)
        )
        face = tilt.apply(toward)  # the board's -z
        z = -face
        x = np.cross(rng.normal(size=3), z)
        x /= np.linalg.norm(x)
        rotation = np.stack([x, np.cross(z, x), z], axis=1)
        position = np.array(centre) + rng.uniform(-spread, spread, 3)
        poses.append((rotation, position - rotation @ local_centre))
    return poses


def _unit_perpendicular(direction: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    axis = np.cross(direction, rng.normal(size=3))
    return axis / np.linalg.norm(axis)


def render_board(
    camera: Camera,
    board: Board,
    pose: Pose,
    rng: np.random.Generator,
    blur_sigma: float = 0.6,
    noise: float = 2.0,
) -> np.ndarray:
    """The grey uint8 (h, w) image `camera` takes of `board` in `pose` (board to world).

    A board seen from behind is not drawn (the image shows the background only).
    """
    width, height = camera.size
    rotation, translation = pose
    normal = rotation[:, 2]
    texture, board_to_texture = _texture(board)
    image = np.full((height * SUPERSAMPLE, width * SUPERSAMPLE), BACKGROUND, np.float32)
    if np.dot(camera.center - translation, normal) < 0:  # the printed face is towards us
        plane = camera.rotation_matrix @ np.column_stack([rotation[:, :2], translation])
        plane[:, 2] += camera.translation
        homography = camera.matrix @ plane  # board plane (x, y, 1) -> undistorted pixels
        to_texture = board_to_texture @ np.linalg.inv(homography)
        grid = _undistorted_grid(camera)
        maps = cv2.perspectiveTransform(grid.reshape(-1, 1, 2), to_texture).reshape(grid.shape)
        maps[~np.isfinite(maps)] = -1e6
        image = cv2.remap(
            texture,
            maps[..., 0],
            maps[..., 1],
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=BACKGROUND,
        )
    image = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
    if blur_sigma > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur_sigma)
    image = image + rng.normal(scale=noise, size=image.shape)
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


def _texture(board: Board) -> tuple[np.ndarray, np.ndarray]:
    """The board's texture as float32 grey levels between BLACK and WHITE, and the
    board-plane-to-texture-pixel matrix."""
    key = (board, 24)
    if key not in _texture_cache:
        texture, to_pixels = board.texture(24)
        grey = BLACK + (WHITE - BLACK) * texture.astype(np.float32) / 255.0
        _texture_cache[key] = grey, to_pixels
    return _texture_cache[key]


def _undistorted_grid(camera: Camera) -> np.ndarray:
    """Undistorted pixel positions (H, W, 2), float32, of the supersampled pixel centres
    of the camera's image (cached per camera object)."""
    if camera not in _undistort_cache:
        width, height = camera.size
        u = (np.arange(width * SUPERSAMPLE) + 0.5) / SUPERSAMPLE - 0.5
        v = (np.arange(height * SUPERSAMPLE) + 0.5) / SUPERSAMPLE - 0.5
        grid = camera.undistort(np.stack(np.meshgrid(u, v), axis=-1))
        _undistort_cache[camera] = grid.astype(np.float32)
    return _undistort_cache[camera]
