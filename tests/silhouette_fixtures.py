"""A small shape tree shared by the silhouette-tracking tests: one camera 3 m in front of
home, the men's-M body, the 200 poses of a short synthetic library at six headings.

`build_small_tree` builds it once per test session (the result is cached); test modules
wrap it in their fixtures.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from samba.body.body_model import BodyModel, scaled_to
from samba.cameras.camera import Camera
from samba.silhouette.pose_selection import turned
from samba.silhouette.shape_tree import ShapeTree, at_home, facing
from samba.silhouette.view import SilhouetteView
from samba.synthetic.motions import library

CAMERA = Camera.look_at("cam", (0.0, 1.1, 3.0), (0.0, 0.9, 0.0), (320, 240), 55.0)
HOME = np.array([0.0, 0.0, 0.0])
BODY = BodyModel.for_subject(1.70)
HEADINGS = np.arange(-180.0, 180.0, 60.0)
"""Turns (degrees) of the tree's poses after they face the camera."""
TAKE_FRAMES = 20
"""Poses per take of `library_poses` (2 s at 10 fps)."""
SQUAT_TAKE = 4
"""Index of the squat in `samba.synthetic.motions.MOTIONS` (a take that stays in place)."""


def library_poses() -> np.ndarray:
    """The database poses (200, 13, 3) meters: one 2 s take of every synthetic motion at
    10 fps, in `samba.synthetic.motions.MOTIONS` order (`TAKE_FRAMES` poses each)."""
    return np.concatenate([take.poses for take in library(1, 2.0, 10.0, seed=1)])


def view() -> SilhouetteView:
    """The view of the tests' camera with home at the world origin."""
    return SilhouetteView(CAMERA, home=HOME)


def facing_angles(poses: np.ndarray) -> np.ndarray:
    """Degrees (n,) in -180..180 from the direction to the camera to the front of each
    pose (n, 13, 3) (the hip line, left minus right, crossed with +Y), seen from above;
    0 for a pose facing the camera."""
    poses = np.asarray(poses, dtype=np.float64)
    left = poses[:, 7] - poses[:, 8]
    to_camera = CAMERA.center - poses[:, [7, 8]].mean(axis=1)
    front = np.degrees(np.arctan2(-left[:, 2], left[:, 0]))
    wanted = np.degrees(np.arctan2(to_camera[:, 0], to_camera[:, 2]))
    return (front - wanted + 180.0) % 360.0 - 180.0


def source_poses(tree_poses: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Index (m,) into the database `poses` (n, 13, 3) of each tree pose (m, 13, 3): the
    database pose, scaled to `BODY`, with the same joint heights and horizontal joint
    distances from the hip midpoint (which turning and moving on the floor keep)."""

    def invariants(p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, dtype=np.float64)
        offset = p - p[:, [7, 8]].mean(axis=1, keepdims=True)
        return np.concatenate([p[..., 1], np.hypot(offset[..., 0], offset[..., 2])], axis=1)

    database = invariants(scaled_to(poses, BODY.height))
    tree = invariants(tree_poses)
    gaps = ((tree[:, None] - database[None]) ** 2).sum(axis=-1)
    return gaps.argmin(axis=1)


@dataclass(frozen=True)
class SmallBuild:
    """The small tree with what it was built from: the database `poses` (n, 13, 3), the
    `candidates` (n * headings, 13, 3) the build should thin (each pose scaled to the
    body, standing at home, facing the camera, then turned by each heading) and the
    `progress` calls (done, total) of the build."""

    tree: ShapeTree
    poses: np.ndarray
    candidates: np.ndarray
    progress: list[tuple[int, int]]


@cache
def build_small_tree() -> SmallBuild:
    """The small tree (about 700 leaves, built in 3 to 10 s) and its inputs, built once."""
    poses = library_poses()
    the_view = view()
    calls: list[tuple[int, int]] = []
    tree = ShapeTree.build(
        poses,
        the_view,
        BODY,
        headings=HEADINGS,
        progress=lambda done, total: calls.append((done, total)),
    )
    standing = at_home(scaled_to(poses, BODY.height), HOME)
    candidates = turned(facing(standing, the_view), HEADINGS)
    return SmallBuild(tree, poses, candidates, calls)
