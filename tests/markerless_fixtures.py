"""The synthetic stage of the `samba db tree` and `samba track-video` tests: one 640x480
camera 3.6 m in front of home, a subject of 1.75 m (the men's-L body model), and colour
footage of a held-out take (`samba.silhouette.person_render`) written as an image folder or an
MJPG video.

`footage` renders once per test session (about 2 s); the files are written per test
module.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

import cv2
import numpy as np

from samba.body.body_model import BodyModel
from samba.cameras.calibration_file import write_calibration
from samba.cameras.camera import Camera, CameraGroup
from samba.silhouette.evaluation import staged
from samba.silhouette.person_render import empty_stage_frames, person_frames, stage_background
from samba.silhouette.view import SilhouetteView
from samba.synthetic.motions import generate

CAMERA = Camera.look_at("front", (0.0, 1.2, 3.6), (0.0, 0.9, 0.0), (640, 480), 55.0)
HEIGHT = 1.75
"""The subject's stature, meters: `--height` of the commands."""
BODY = BodyModel.for_subject(HEIGHT)
FPS = 15.0
TREE_HEADINGS = 180.0
"""`samba db tree --headings` of the tests' tree: each pose facing the camera and turned
away (the held-out takes face the camera; more headings only slow the build)."""
EMPTY_FRAMES = 8
"""Frames of the empty stage filmed before the subject steps in."""
SENSOR_NOISE = 3.0
"""Grey levels of Gaussian noise on every frame, empty or not."""


def write_camera_calibration(path: Path, camera: Camera = CAMERA) -> Path:
    """A calibration file at `path` holding only `camera`; returns `path`."""
    write_calibration(path, CameraGroup((camera,)))
    return path


@dataclass(frozen=True)
class Footage:
    """A held-out take filmed by `CAMERA`: the `truth` poses (n, 13, 3) m, its colour
    `frames` (n, 480, 640, 3) uint8 BGR and `empty` (`EMPTY_FRAMES`, 480, 640, 3) uint8
    frames of the same stage without the subject."""

    truth: np.ndarray
    frames: np.ndarray
    empty: np.ndarray


@cache
def footage(motion: str = "wave", seconds: float = 3.0, seed: int = 202) -> Footage:
    """`seconds` of a `motion` take (seeded apart from the store's takes) at `FPS`,
    staged at home facing the camera with the subject's height, filmed with sensor noise."""
    take = generate(motion, seconds, FPS, seed=seed).poses.astype(np.float64)
    truth = staged(take, SilhouetteView(CAMERA), HEIGHT)
    rng = np.random.default_rng(seed)
    background = stage_background(CAMERA.size, rng)
    frames = person_frames(truth, CAMERA, BODY, background, rng, noise=SENSOR_NOISE)
    empty = empty_stage_frames(background, EMPTY_FRAMES, rng, SENSOR_NOISE)
    return Footage(truth, frames, empty)


def write_image_folder(folder: Path, frames: np.ndarray) -> Path:
    """`frames` (n, H, W, 3) uint8 BGR as `folder`/00000.png ... (created); returns it."""
    folder.mkdir(parents=True)
    for i, frame in enumerate(frames):
        cv2.imwrite(str(folder / f"{i:05d}.png"), frame, [cv2.IMWRITE_PNG_COMPRESSION, 0])
    return folder


def write_mjpg_video(path: Path, frames: np.ndarray, fps: float = FPS) -> bool:
    """`frames` (n, H, W, 3) uint8 BGR as an MJPG .avi at `path`; False when this OpenCV
    build cannot write one."""
    height, width = frames.shape[1:3]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (width, height))
    if not writer.isOpened():
        return False
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path.is_file() and path.stat().st_size > 0


def mpjpe_cm(estimated: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Per-frame mean joint error (n,) in cm of poses (n, 13, 3) m against the truth."""
    return np.linalg.norm(np.asarray(estimated) - truth, axis=-1).mean(axis=1) * 100.0
