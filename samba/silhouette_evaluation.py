"""Accuracy of single-camera silhouette tracking on synthetic captures of held-out takes.

The protocol follows EVALUATION.md where it applies: takes the tree was not built from,
MPJPE over the 13 joints in cm after scaling each take so its mean knee-to-ankle length
is 45 cm, time per frame single-threaded. What differs for one camera:

* the subject is the body model the tracker uses, at its height (the paper picks the
  model from the user's height, entered or measured), placed in front of the camera by
  `staged`: turned so that it faces the camera on average (or shows it a given side)
  and standing, on average, at the view's home point; a take that travels (walking)
  can be held in place, as on a treadmill, so that it stays in view;
* the observed silhouettes are the renderer's, spoilt by `noisy_silhouettes` at `noise`
  and cleaned by `clean_silhouette`, as background subtraction gives them;
* a tracking failure is a frame whose MPJPE exceeds `FAILURE_CM`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from samba.body_model import scaled_to
from samba.shape_tree import ShapeTree
from samba.silhouette_extraction import clean_silhouette
from samba.silhouette_render import noisy_silhouettes, render_silhouettes
from samba.silhouette_tracker import SilhouetteTracker, TrackerSettings
from samba.silhouette_view import SilhouetteView

FAILURE_CM = 15.0
"""A frame whose MPJPE (cm, tibia 45 cm) exceeds this is a tracking failure."""
TIBIA_CM = 45.0


def staged(
    poses: np.ndarray,
    view: SilhouetteView,
    height: float,
    turn_deg: float = 0.0,
    in_place: bool = False,
) -> np.ndarray:
    """A take's poses (n, 13, 3) m put in front of `view`'s camera: scaled to `height`
    m, turned about the vertical so that its first frame faces the camera (the player
    faces the screen when the game starts) plus `turn_deg` degrees (90: the camera sees
    its left side), moved so that its mean hip midpoint stands at the home point;
    `in_place` also removes the hip midpoint's travel on the floor."""
    poses = scaled_to(poses, height)
    root = poses[:, [7, 8]].mean(axis=1)
    if in_place:
        travel = root - root.mean(axis=0)
        travel[:, 1] = 0.0
        poses = poses - travel[:, None]
        root = root - travel
    centre = root.mean(axis=0)
    left = poses[0, 7] - poses[0, 8]
    to_camera = view.camera.center - centre
    angle = (
        np.arctan2(to_camera[0], to_camera[2])
        - np.arctan2(-left[2], left[0])
        + np.radians(turn_deg)
    )
    c, s = np.cos(angle), np.sin(angle)
    offset = poses - centre
    x = c * offset[..., 0] + s * offset[..., 2]
    z = -s * offset[..., 0] + c * offset[..., 2]
    home = np.array([view.home[0], centre[1], view.home[2]])
    return home + np.stack([x, offset[..., 1], z], axis=-1)


def observed_silhouettes(
    poses: np.ndarray, tree: ShapeTree, noise: float, rng: np.random.Generator
) -> np.ndarray:
    """What background subtraction would give of the tree's body model in `poses`
    (n, 13, 3) m, seen by the tree's camera: (n, H, W) bool."""
    clean = render_silhouettes(poses, tree.view.camera, tree.body)
    return np.stack([clean_silhouette(m) for m in noisy_silhouettes(clean, rng, noise)])


@dataclass(frozen=True)
class TrackingResult:
    """One tracked take: `errors` (n, 13) cm (tibia 45 cm), `root_relative` (n, 13) cm
    with the hip midpoints aligned, and `seconds` (n,) per frame."""

    name: str
    errors: np.ndarray
    root_relative: np.ndarray
    seconds: np.ndarray

    @property
    def mpjpe(self) -> float:
        """Mean error over joints and frames, cm."""
        return float(self.errors.mean())

    @property
    def failure_rate(self) -> float:
        """Fraction of frames whose MPJPE exceeds `FAILURE_CM`."""
        return float(np.mean(self.errors.mean(axis=1) > FAILURE_CM))


def track_take(
    name: str,
    poses: np.ndarray,
    tree: ShapeTree,
    settings: TrackerSettings | None = None,
    noise: float = 0.5,
    seed: int = 0,
) -> TrackingResult:
    """Track the silhouettes of staged `poses` (n, 13, 3) m with a fresh tracker on one
    thread and score every frame against the truth."""
    masks = observed_silhouettes(poses, tree, noise, np.random.default_rng(seed))
    tracker = SilhouetteTracker(tree, settings)
    estimates, seconds = [], []
    with threadpool_limits(1):
        for mask in masks:
            start = time.perf_counter()
            estimates.append(tracker.step(mask).pose)
            seconds.append(time.perf_counter() - start)
    estimated = np.array(estimates)
    tibia = np.linalg.norm(poses[:, [9, 10]] - poses[:, [11, 12]], axis=-1).mean()
    scale = TIBIA_CM / tibia
    errors = np.linalg.norm(estimated - poses, axis=-1) * scale
    aligned = _root_relative(estimated) - _root_relative(poses)
    return TrackingResult(name, errors, np.linalg.norm(aligned, axis=-1) * scale, np.array(seconds))


def _root_relative(poses: np.ndarray) -> np.ndarray:
    return poses - poses[:, [7, 8]].mean(axis=1, keepdims=True)
