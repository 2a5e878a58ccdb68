"""Colour video frames of the body model on a stage: the synthetic camera of markerless
capture (tests, demos, `samba track-video` examples).

The background is a textured wall in BGR (OpenCV order) with a soft light gradient;
each body part is painted in its own clothing colour (`PART_COLOURS`, after
`render_part_labels`: nearer parts cover farther ones), with sensor noise on top.
Frames are (n, H, W, 3) uint8 at the camera's image size.
"""

from __future__ import annotations

import cv2
import numpy as np

from samba.body import BodyModel
from samba.cameras import Camera
from samba.silhouette.render import render_part_labels

PART_COLOURS = np.array(
    [
        [150, 60, 40],  # torso: blue shirt
        [120, 160, 210],  # head: skin
        [150, 60, 40],  # arms: shirt sleeves
        [150, 60, 40],
        [60, 50, 45],  # legs: dark trousers
        [60, 50, 45],
    ],
    dtype=np.uint8,
)
"""BGR colour of each part of `samba.body.body_model.PART_NAMES`."""


def stage_background(size: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """An empty stage (H, W, 3) uint8 BGR of `size` (width, height): a grey-beige wall
    with blotchy texture and a light gradient from left to right."""
    width, height = size
    texture = cv2.GaussianBlur(rng.normal(0.0, 1.0, (height, width)), (0, 0), 3.0)
    texture = texture / (np.abs(texture).max() + 1e-9)
    gradient = np.linspace(0.85, 1.1, width)[None, :]
    base = np.array([170.0, 185.0, 195.0])
    wall = (base[None, None, :] + 18.0 * texture[..., None]) * gradient[..., None]
    return np.clip(wall, 0, 255).astype(np.uint8)


def empty_stage_frames(
    background: np.ndarray, count: int, rng: np.random.Generator, noise: float = 3.0
) -> np.ndarray:
    """`count` frames (count, H, W, 3) uint8 of the empty stage `background` (H, W, 3)
    uint8, each with Gaussian sensor noise of `noise` grey levels."""
    grain = rng.normal(0.0, noise, (count, *background.shape))
    return np.clip(background + grain, 0, 255).astype(np.uint8)


def person_frames(
    poses: np.ndarray,
    camera: Camera,
    body: BodyModel,
    background: np.ndarray,
    rng: np.random.Generator,
    noise: float = 3.0,
) -> np.ndarray:
    """Frames (n, H, W, 3) uint8 of `body` in `poses` (n, 13, 3) m seen by `camera` in
    front of `background` (H, W, 3) uint8, with Gaussian sensor noise of `noise` grey
    levels. The true silhouettes are `render_silhouettes` of the same poses."""
    labels = render_part_labels(poses, camera, body)
    clean = np.where(labels[..., None] >= 0, PART_COLOURS[np.maximum(labels, 0)], background[None])
    frames = rng.standard_normal(clean.shape, dtype=np.float32)  # float32: 3x faster
    frames *= noise
    frames += clean
    return np.clip(frames, 0, 255, out=frames).astype(np.uint8)
