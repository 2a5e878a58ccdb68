"""The frame of the body segment each joint rides on, from the 13 joints of a pose.

A skin marker or an anatomical landmark moves with one segment; an offset expressed in
that segment's frame stays (nearly) constant while the body moves. The 13 joints give
every segment's long axis but not its twist, so the frames are built twist-free:

* the trunk frame: x from the right to the left side (shoulders and hips), y up the
  trunk (hip midpoint to shoulder midpoint, made orthogonal to x), z = x cross y
  (forward: the standard pose's trunk frame is the world frame);
* a limb segment's frame: the trunk frame turned by the shortest rotation (the swing)
  that takes the trunk's down axis to the segment's direction (parent joint to child).
  It is the trunk frame when the limb hangs straight down; when the limb points straight
  up, the swing is half a turn about the trunk's forward axis.

`SEGMENT_OF` says which segment each joint rides on: head, shoulders and hips the trunk;
elbows the upper arm; wrists the forearm; knees the thigh; feet the shank.
"""

from __future__ import annotations

import numpy as np

from samba.body.skeleton import N_JOINTS, pose_batch

TRUNK = (-1, -1)
"""`SEGMENT_OF` entry of the joints that ride on the trunk."""
SEGMENT_OF: tuple[tuple[int, int], ...] = (
    TRUNK,  # head
    TRUNK,  # l_shoulder
    TRUNK,  # r_shoulder
    (1, 3),  # l_elbow: upper arm
    (2, 4),  # r_elbow
    (3, 5),  # l_wrist: forearm
    (4, 6),  # r_wrist
    TRUNK,  # l_hip
    TRUNK,  # r_hip
    (7, 9),  # l_knee: thigh
    (8, 10),  # r_knee
    (9, 11),  # l_foot: shank
    (10, 12),  # r_foot
)
"""Per joint, the (parent, child) joints of the limb segment it rides on, or `TRUNK`."""
_TINY = 1e-12


def trunk_frames(poses: np.ndarray) -> np.ndarray:
    """Trunk frames (n, 3, 3) of poses (n, 13, 3) meters: columns x (to the left), y (up
    the trunk), z (forward), world coordinates; NaN where the pose has NaN."""
    poses = pose_batch(poses)
    left = poses[:, [1, 7]].sum(axis=1) - poses[:, [2, 8]].sum(axis=1)
    up = poses[:, [1, 2]].sum(axis=1) - poses[:, [7, 8]].sum(axis=1)
    x = _unit(left)
    y = _unit(up - (up * x).sum(axis=-1, keepdims=True) * x)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def joint_frames(poses: np.ndarray) -> np.ndarray:
    """The frame (n, 13, 3, 3) of the segment each joint of poses (n, 13, 3) rides on
    (`SEGMENT_OF`): rotation matrices whose columns are the segment's axes in world
    coordinates, so that `frame @ offset` turns a segment-frame offset (3,) into world."""
    poses = pose_batch(poses)
    trunk = trunk_frames(poses)
    frames = np.repeat(trunk[:, None], N_JOINTS, axis=1)
    for joint, (parent, child) in enumerate(SEGMENT_OF):
        if parent >= 0:
            direction = _unit(poses[:, child] - poses[:, parent])
            local = np.einsum("nij,ni->nj", trunk, direction)  # in trunk coordinates
            frames[:, joint] = trunk @ _swing_from_down(local)
    return frames


def _swing_from_down(b: np.ndarray) -> np.ndarray:
    """Shortest rotations (n, 3, 3) taking (0, -1, 0) to the unit vectors b (n, 3)."""
    a = np.array([0.0, -1.0, 0.0])
    v = np.cross(a, b)
    c = b @ a
    k = np.zeros((len(b), 3, 3))
    k[:, 0, 1], k[:, 0, 2] = -v[:, 2], v[:, 1]
    k[:, 1, 0], k[:, 1, 2] = v[:, 2], -v[:, 0]
    k[:, 2, 0], k[:, 2, 1] = -v[:, 1], v[:, 0]
    flipped = c < -1.0 + 1e-9
    scale = 1.0 / np.where(flipped, 1.0, 1.0 + c)
    rotation = np.eye(3) + k + (k @ k) * scale[:, None, None]
    rotation[flipped] = np.diag([-1.0, -1.0, 1.0])  # straight up: half a turn about z
    return rotation


def _unit(v: np.ndarray) -> np.ndarray:
    """Vectors (n, 3) scaled to unit length; NaN where a vector has no length."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm > _TINY, v / norm, np.nan)
