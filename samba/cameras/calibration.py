"""Calibrating a group of cameras from synchronised images of a board.

`calibrate` takes, for every camera, the board corners found in each frame (frame
number -> `BoardView`; frame n of every camera is the same instant) and:

1. calibrates each camera's intrinsics on its own (`calibrate_intrinsics`: OpenCV's
   `calibrateCamera`, distortion k1, k2, p1, p2 with k3 = 0), dropping the images whose
   reprojection error is an outlier (below) from this and every later step;
2. finds the board's pose in every view (`solvePnP`) and chains the cameras' relative
   poses through a camera graph: starting from the first camera, each camera joins
   through the already placed camera with which it shares the most frames, its pose
   relative to that camera averaged over those frames;
3. places the board of every frame from a camera that saw it, and refines all cameras
   and board poses jointly (`samba.cameras.bundle_adjustment`), intrinsics included unless
   `refine_intrinsics` is off;
4. sets the world frame (+Y up, meters): with world "board", from the board lying face
   up on the floor in `floor_frame` (default: the first frame in which any camera sees
   the board): the board plane is y = 0, the origin is the board frame's origin (see
   `samba.cameras.calibration_board`), +X runs along the board's x and +Z along its y; with
   world "camera0", the first camera sits at the origin looking along -Z with its
   image's up along +Y (the board then only sets the scale).

The result reports each camera's RMS reprojection error (pixels) over the corners the
refinement used, and each camera's `Intrinsics` with the error of every image.

Outlier images: after the first `calibrateCamera`, an image whose RMS reprojection error
exceeds max(`OUTLIER_FACTOR` x the median over the camera's images, the median +
`OUTLIER_MARGIN_PX`) is dropped and the lens solved again without it, worst first and
never below `MIN_VIEWS` images (one pass). The median is robust to the outliers
themselves; the margin keeps a camera whose images all fit within a fraction of a pixel
from losing good images to a ratio of small numbers (on sharp images the median is
0.05-0.3 px, and a wrongly numbered or misplaced corner costs its image pixels).

`calibrate_lens` calibrates one camera's intrinsics alone (`samba calibrate
--intrinsics-only`): the camera sits at the origin with rotation and translation zero.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from samba.base import InputError
from samba.cameras.bundle_adjustment import Observations, bundle_adjust
from samba.cameras.calibration_board import Board, BoardView
from samba.cameras.camera import Camera, CameraGroup

WORLDS = ("board", "camera0")
"""How `calibrate` may set the world frame."""
MIN_VIEWS = 4
"""Images of the board each camera needs."""
MAX_INTRINSIC_VIEWS = 40
"""Views (evenly spread over the frames) `calibrate_intrinsics` uses at most."""
MAX_FRAMES = 120
"""Frames (evenly spread, the floor frame always among them) the joint refinement uses."""
OUTLIER_FACTOR = 3.0
"""An image is an outlier above this many times the median per-image error (module
docstring) ..."""
OUTLIER_MARGIN_PX = 1.0
"""... and above the median plus this many pixels."""

Pose = tuple[np.ndarray, np.ndarray]
"""A rigid transform (R (3, 3), t (3,)) taking x to R @ x + t."""
_BOARD_TO_FLOOR = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""The rotation from the board frame to the world for a board lying face up."""
_CAMERA0_TO_WORLD = np.diag([1.0, -1.0, -1.0])
"""The rotation from the first camera's frame to the world of world "camera0"."""


@dataclass(frozen=True)
class Intrinsics:
    """One camera's lens as `calibrate_intrinsics` solved it: `matrix` (3, 3) and
    `distortion` (5,) (k1, k2, p1, p2, k3 = 0), the RMS reprojection error `rms_px` of
    the final solve, pixels; `view_rms_px` each image's RMS error in the first solve
    (image key -> pixels, for the images solved with), `dropped` the keys of the images
    dropped as outliers (worst first) and `limit_px` the error above which an image is an
    outlier (module docstring)."""

    matrix: np.ndarray
    distortion: np.ndarray
    rms_px: float
    view_rms_px: dict[int, float]
    dropped: tuple[int, ...]
    limit_px: float

    @property
    def used(self) -> list[int]:
        """The keys of the images of the final solve, ascending."""
        return [key for key in self.view_rms_px if key not in self.dropped]


@dataclass(frozen=True)
class CalibrationResult:
    """What `calibrate` found: the calibrated `cameras`, each camera's RMS reprojection
    error `rms_px` (c,) in pixels and the number of frames `views` (c,) in which the
    refinement used its view of the board; `world` and `floor_frame` say how the world
    frame was set (`floor_frame` None for world "camera0"; `world` None for one camera's
    lens alone, `calibrate_lens`); `intrinsics` (c) each camera's lens solve, its images
    keyed by frame number."""

    cameras: CameraGroup
    rms_px: np.ndarray
    views: np.ndarray
    world: str | None
    floor_frame: int | None
    intrinsics: tuple[Intrinsics, ...] = ()


def calibrate_intrinsics(
    board: Board,
    views: Mapping[int, BoardView] | Sequence[BoardView],
    size: tuple[int, int],
    name: str = "camera",
) -> Intrinsics:
    """One camera's lens, of image `size` (width, height) pixels, from its views of the
    board: frame number -> view, or a sequence (keyed 0, 1, ... in order).

    Uses at most `MAX_INTRINSIC_VIEWS` views, evenly spread; the distortion is k1, k2,
    p1, p2 with k3 = 0. Outlier images are dropped and the lens solved again (module
    docstring). InputError naming the camera with fewer than `MIN_VIEWS` views.
    """
    keyed = dict(views) if isinstance(views, Mapping) else dict(enumerate(views))
    if len(keyed) < MIN_VIEWS:
        raise InputError(
            name, f"the board was found in {len(keyed)} image(s); calibration needs {MIN_VIEWS}"
        )
    keys = _evenly(sorted(keyed), MAX_INTRINSIC_VIEWS)
    rms, matrix, distortion, errors = _solve_lens(board, [keyed[k] for k in keys], size)
    median = float(np.median(errors))
    limit = max(OUTLIER_FACTOR * median, median + OUTLIER_MARGIN_PX)
    worst_first = sorted(range(len(keys)), key=lambda i: -errors[i])
    dropped = [keys[i] for i in worst_first if errors[i] > limit][: len(keys) - MIN_VIEWS]
    if dropped:
        kept = [keyed[k] for k in keys if k not in dropped]
        rms, matrix, distortion, _ = _solve_lens(board, kept, size)
    return Intrinsics(
        matrix=matrix,
        distortion=distortion,
        rms_px=rms,
        view_rms_px={k: float(e) for k, e in zip(keys, errors, strict=True)},
        dropped=tuple(dropped),
        limit_px=limit,
    )


def _solve_lens(
    board: Board, views: Sequence[BoardView], size: tuple[int, int]
) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """OpenCV's `calibrateCamera` on the views: (RMS error px, matrix (3, 3), distortion
    (5,), each view's RMS error (v,) px)."""
    objects = [board.object_points[v.ids].astype(np.float32) for v in views]
    images = [v.pixels.astype(np.float32).reshape(-1, 1, 2) for v in views]
    rms, matrix, distortion, _, _, _, _, errors = cv2.calibrateCameraExtended(
        objects, images, tuple(size), None, None, flags=cv2.CALIB_FIX_K3
    )
    return float(rms), matrix, distortion.ravel()[:5], errors.ravel()


def calibrate_lens(
    board: Board, views: Mapping[int, BoardView], size: tuple[int, int], name: str
) -> CalibrationResult:
    """One camera's intrinsics alone (`calibrate_intrinsics`), as a result whose camera
    `name` of image `size` (width, height) sits at the origin with rotation and
    translation zero; `world` is None and `rms_px` the lens solve's error."""
    lens = calibrate_intrinsics(board, views, size, name)
    camera = Camera(name, size, lens.matrix, np.zeros(3), np.zeros(3), lens.distortion)
    return CalibrationResult(
        cameras=CameraGroup((camera,)),
        rms_px=np.array([lens.rms_px]),
        views=np.array([len(lens.used)]),
        world=None,
        floor_frame=None,
        intrinsics=(lens,),
    )


def calibrate(
    board: Board,
    detections: Sequence[Mapping[int, BoardView]],
    sizes: Sequence[tuple[int, int]],
    names: Sequence[str],
    world: str = "board",
    floor_frame: int | None = None,
    refine_intrinsics: bool = False,
) -> CalibrationResult:
    """Calibrate c cameras from `detections` (per camera: frame -> its view of the board).

    `sizes` are the cameras' image sizes (width, height), `names` their unique names. See
    the module docstring for the steps, the world frame and the images dropped as
    outliers. InputError (naming the camera) when a camera saw the board in fewer than
    `MIN_VIEWS` frames or never in a frame together with the cameras already placed, and
    (naming the frame) when no camera sees the board in `floor_frame`.
    """
    if world not in WORLDS:
        raise ValueError(f"world must be one of {', '.join(WORLDS)}, got {world!r}")
    if not len(detections) == len(sizes) == len(names) >= 1:
        raise ValueError("detections, sizes and names need one entry per camera (at least one)")
    cameras, lenses = [], []
    for views, size, name in zip(detections, sizes, names, strict=True):
        lens = calibrate_intrinsics(board, views, size, name)
        cameras.append(Camera(name, size, lens.matrix, np.zeros(3), np.zeros(3), lens.distortion))
        lenses.append(lens)
    detections = [  # without the images dropped as outliers
        {frame: view for frame, view in views.items() if frame not in lens.dropped}
        for views, lens in zip(detections, lenses, strict=True)
    ]
    seen = sorted(set().union(*(views.keys() for views in detections)))
    if world == "board":
        floor_frame = seen[0] if floor_frame is None else floor_frame
        if floor_frame not in seen:
            raise InputError(
                f"frame {floor_frame}", "no camera sees the board there to set the floor"
            )
    if world != "board":
        floor_frame = None
    frames = _frames_to_use(detections, seen, floor_frame)
    view_poses = [
        _view_poses(board, camera, views, frames)
        for camera, views in zip(cameras, detections, strict=True)
    ]
    frames = [f for f in frames if any(f in poses for poses in view_poses)]
    if floor_frame is not None and floor_frame not in frames:
        raise InputError(f"frame {floor_frame}", "the board's pose there cannot be found")
    extrinsics = _chain_cameras(view_poses, names)
    cameras = [_posed(camera, pose) for camera, pose in zip(cameras, extrinsics, strict=True)]
    board_poses = _board_poses(view_poses, extrinsics, frames)
    observations = _observations(board, detections, frames)
    cameras, poses, residuals = bundle_adjust(cameras, board_poses, observations, refine_intrinsics)
    if floor_frame is None:  # world "camera0"
        to_world = _compose((_CAMERA0_TO_WORLD, np.zeros(3)), _pose_of(cameras[0]))
    else:
        floor = poses[frames.index(floor_frame)]
        board_to_world = (Rotation.from_rotvec(floor[:3]).as_matrix(), floor[3:])
        to_world = _compose((_BOARD_TO_FLOOR, np.zeros(3)), _inverse(board_to_world))
    cameras = [_moved(camera, to_world) for camera in cameras]
    squared = (residuals**2).sum(axis=1)
    used = [observations.camera == i for i in range(len(cameras))]
    return CalibrationResult(
        cameras=CameraGroup(tuple(cameras)),
        rms_px=np.array([np.sqrt(squared[u].mean()) for u in used]),
        views=np.array([len(np.unique(observations.view[u])) for u in used]),
        world=world,
        floor_frame=floor_frame,
        intrinsics=tuple(lenses),
    )


def _evenly(items: list, count: int) -> list:
    """At most `count` of `items`, evenly spread, first and last included."""
    if len(items) <= count:
        return items
    return [items[i] for i in np.round(np.linspace(0, len(items) - 1, count)).astype(int)]


def _frames_to_use(
    detections: Sequence[Mapping[int, BoardView]], seen: list[int], floor_frame: int | None
) -> list[int]:
    """The frames the refinement uses: at most `MAX_FRAMES`, those seen by two or more
    cameras first (evenly spread), then the others, plus the floor frame; ascending."""
    shared = [f for f in seen if sum(f in views for views in detections) >= 2]
    single = sorted(set(seen) - set(shared))
    chosen = _evenly(shared, MAX_FRAMES)
    chosen += _evenly(single, MAX_FRAMES - len(chosen)) if len(chosen) < MAX_FRAMES else []
    if floor_frame is not None and floor_frame not in chosen:
        chosen.append(floor_frame)
    return sorted(chosen)


def _view_poses(
    board: Board, camera: Camera, views: Mapping[int, BoardView], frames: list[int]
) -> dict[int, Pose]:
    """The board-to-camera pose in each of the frames the camera sees the board in."""
    poses = {}
    for frame in frames:
        view = views.get(frame)
        if view is None:
            continue
        found, rvec, tvec = cv2.solvePnP(
            board.object_points[view.ids],
            view.pixels,
            camera.matrix,
            camera.distortion,
            flags=cv2.SOLVEPNP_IPPE,
        )
        if found:
            poses[frame] = (cv2.Rodrigues(rvec)[0], tvec.ravel())
    return poses


def _chain_cameras(view_poses: Sequence[dict[int, Pose]], names: Sequence[str]) -> list[Pose]:
    """Each camera's world-to-camera pose with the first camera's frame as the world,
    joined through the placed camera sharing the most frames (module docstring)."""
    placed: dict[int, Pose] = {0: (np.eye(3), np.zeros(3))}
    while len(placed) < len(view_poses):
        best = max(
            (
                (len(view_poses[new].keys() & view_poses[old].keys()), new, old)
                for new in range(len(view_poses))
                if new not in placed
                for old in placed
            ),
        )
        shared, new, old = best
        if shared == 0:
            waiting = [names[i] for i in range(len(view_poses)) if i not in placed]
            raise InputError(
                ", ".join(waiting),
                f"never saw the board in the same frame as {names[0]} or a camera "
                "linked to it, so its position cannot be found",
            )
        relatives = [
            _compose(view_poses[new][f], _inverse(view_poses[old][f]))
            for f in sorted(view_poses[new].keys() & view_poses[old].keys())
        ]
        rotation = Rotation.from_matrix(np.stack([r for r, _ in relatives])).mean().as_matrix()
        translation = np.median(np.stack([t for _, t in relatives]), axis=0)
        placed[new] = _compose((rotation, translation), placed[old])
    return [placed[i] for i in range(len(view_poses))]


def _board_poses(
    view_poses: Sequence[dict[int, Pose]], extrinsics: Sequence[Pose], frames: list[int]
) -> np.ndarray:
    """Starting board-to-world poses (v, 6) of the frames, each from the first camera
    that sees the board in it."""
    poses = np.zeros((len(frames), 6))
    for i, frame in enumerate(frames):
        camera = next(c for c, seen in enumerate(view_poses) if frame in seen)
        rotation, translation = _compose(_inverse(extrinsics[camera]), view_poses[camera][frame])
        poses[i] = np.concatenate([Rotation.from_matrix(rotation).as_rotvec(), translation])
    return poses


def _observations(
    board: Board, detections: Sequence[Mapping[int, BoardView]], frames: list[int]
) -> Observations:
    """Every corner every camera saw in the frames, for the refinement."""
    cameras, views, points, pixels = [], [], [], []
    for c, detected in enumerate(detections):
        for v, frame in enumerate(frames):
            view = detected.get(frame)
            if view is None:
                continue
            cameras.append(np.full(len(view.ids), c))
            views.append(np.full(len(view.ids), v))
            points.append(board.object_points[view.ids])
            pixels.append(view.pixels)
    return Observations(
        camera=np.concatenate(cameras),
        view=np.concatenate(views),
        board_points=np.concatenate(points),
        pixels=np.concatenate(pixels),
    )


def _compose(first: Pose, second: Pose) -> Pose:
    """The transform applying `second`, then `first`."""
    return first[0] @ second[0], first[0] @ second[1] + first[1]


def _inverse(pose: Pose) -> Pose:
    """The inverse rigid transform."""
    return pose[0].T, -pose[0].T @ pose[1]


def _pose_of(camera: Camera) -> Pose:
    """The camera's world-to-camera pose."""
    return camera.rotation_matrix, camera.translation


def _posed(camera: Camera, pose: Pose) -> Camera:
    """The camera with world-to-camera pose `pose`."""
    return Camera(
        camera.name,
        camera.size,
        camera.matrix,
        Rotation.from_matrix(pose[0]).as_rotvec(),
        pose[1],
        camera.distortion,
    )


def _moved(camera: Camera, old_to_new: Pose) -> Camera:
    """The same camera described in a new world frame, given the old-to-new transform."""
    return _posed(camera, _compose(_pose_of(camera), _inverse(old_to_new)))
