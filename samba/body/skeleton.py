"""The 13-joint skeleton every part of Samba shares.

Conventions (see ARCHITECTURE.md):

* Joint order: 0 head, 1 l_shoulder, 2 r_shoulder, 3 l_elbow, 4 r_elbow, 5 l_wrist,
  6 r_wrist, 7 l_hip, 8 r_hip, 9 l_knee, 10 r_knee, 11 l_foot, 12 r_foot (foot = ankle).
* A pose is a float array of shape (13, 3); many poses are (n, 13, 3).
* World frame: right-handed, +Y up, meters. A subject in the standard pose faces +Z,
  so its left side is at +X. y = 0 is the height of the foot joints (ankles) of a
  standing subject.
* The 8 markers are joints 1, 2, 5, 6, 9, 10, 11, 12; a missing marker is NaN.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from enum import IntEnum

import numpy as np
from scipy.spatial.transform import Rotation

JOINT_NAMES: tuple[str, ...] = (
    "head",
    "l_shoulder",
    "r_shoulder",
    "l_elbow",
    "r_elbow",
    "l_wrist",
    "r_wrist",
    "l_hip",
    "r_hip",
    "l_knee",
    "r_knee",
    "l_foot",
    "r_foot",
)
N_JOINTS = len(JOINT_NAMES)
JOINT_INDEX: dict[str, int] = {name: i for i, name in enumerate(JOINT_NAMES)}
_UP = np.array([0.0, 1.0, 0.0])

MARKER_JOINTS: tuple[int, ...] = (1, 2, 5, 6, 9, 10, 11, 12)
"""Joint index of each of the 8 markers, in marker order."""
MARKER_NAMES: tuple[str, ...] = tuple(JOINT_NAMES[j] for j in MARKER_JOINTS)
N_MARKERS = len(MARKER_JOINTS)
UNOBSERVED_JOINTS: tuple[int, ...] = tuple(j for j in range(N_JOINTS) if j not in MARKER_JOINTS)

BONES: tuple[tuple[int, int], ...] = (
    (1, 3),  # left upper arm
    (3, 5),  # left forearm
    (2, 4),  # right upper arm
    (4, 6),  # right forearm
    (7, 9),  # left thigh
    (9, 11),  # left shin
    (8, 10),  # right thigh
    (10, 12),  # right shin
)
"""Rigid limb bones as (parent joint, child joint); their lengths never change in a take."""

TORSO_EDGES: tuple[tuple[int, int], ...] = ((1, 2), (7, 8), (1, 7), (2, 8))
"""Edges of the torso quadrilateral (shoulder line, hip line, sides); not rigid."""

MIRROR: tuple[int, ...] = (0, 2, 1, 4, 3, 6, 5, 8, 7, 10, 9, 12, 11)
"""Joint permutation that swaps left and right."""


class JointType(IntEnum):
    """Degrees of freedom a joint gets when pseudo-poses perturb it (twist is ignored)."""

    END = 0
    HINGE = 1
    BALL = 2


JOINT_TYPES: tuple[JointType, ...] = (
    JointType.BALL,  # head: the neck chain, 2-DOF
    JointType.BALL,  # shoulders, 2-DOF
    JointType.BALL,
    JointType.HINGE,  # elbows, 1-DOF
    JointType.HINGE,
    JointType.END,  # wrists
    JointType.END,
    JointType.BALL,  # hips, 2-DOF
    JointType.BALL,
    JointType.HINGE,  # knees, 1-DOF
    JointType.HINGE,
    JointType.END,  # feet
    JointType.END,
)


@dataclass(frozen=True)
class Body:
    """Segment lengths of a subject, in meters.

    `from_height` fills them from anthropometric ratios of stature (Drillis & Contini);
    `scaled` varies them per limb, as the synthetic motions and new-user tests need.
    """

    height: float
    shoulder_width: float
    hip_width: float
    upper_arm: float
    forearm: float
    thigh: float
    shin: float
    torso: float
    """Vertical distance from the hip line to the shoulder line."""
    neck: float
    """Distance from the shoulder midpoint up to the head joint."""

    @classmethod
    def from_height(cls, height: float = 1.70) -> Body:
        """Average proportions for a standing height in meters."""
        if not 0.5 <= height <= 2.5:
            raise ValueError(f"body height {height} m is outside 0.5..2.5 m")
        return cls(
            height=height,
            shoulder_width=0.200 * height,
            hip_width=0.095 * height,
            upper_arm=0.186 * height,
            forearm=0.146 * height,
            thigh=0.245 * height,
            shin=0.246 * height,
            torso=0.288 * height,
            neck=0.080 * height,
        )

    def scaled(self, factors: dict[str, float]) -> Body:
        """A copy with the named segments multiplied by the given factors."""
        return replace(self, **{k: getattr(self, k) * f for k, f in factors.items()})

    def standard_pose(self, arm_angle_deg: float = 45.0) -> np.ndarray:
        """The A-pose tracking starts from: upright, facing +Z, feet under the hips.

        The arms hang straight in the frontal plane at `arm_angle_deg` from vertical.
        Returns a (13, 3) float64 array in meters with the feet at y = 0.
        """
        hip_y = self.thigh + self.shin
        shoulder_y = hip_y + self.torso
        a = np.radians(arm_angle_deg)
        arm_dir = np.array([np.sin(a), -np.cos(a), 0.0])
        pose = np.zeros((N_JOINTS, 3))
        for side, sx in ((0, 1.0), (1, -1.0)):
            shoulder = np.array([sx * self.shoulder_width / 2, shoulder_y, 0.0])
            hip = np.array([sx * self.hip_width / 2, hip_y, 0.0])
            mirror = np.array([sx, 1.0, 1.0])
            pose[1 + side] = shoulder
            pose[3 + side] = shoulder + self.upper_arm * arm_dir * mirror
            pose[5 + side] = shoulder + (self.upper_arm + self.forearm) * arm_dir * mirror
            pose[7 + side] = hip
            pose[9 + side] = hip - [0.0, self.thigh, 0.0]
            pose[11 + side] = hip - [0.0, self.thigh + self.shin, 0.0]
        pose[0] = [0.0, shoulder_y + self.neck, 0.0]
        return pose


def standard_pose(height: float = 1.70, arm_angle_deg: float = 45.0) -> np.ndarray:
    """The standard A-pose of an average body of `height` meters, shape (13, 3), meters."""
    return Body.from_height(height).standard_pose(arm_angle_deg)


def standing_pose(
    position: Sequence[float] = (0.0, 0.0), heading_deg: float = 0.0, height: float = 1.70
) -> np.ndarray:
    """The standard pose (13, 3) meters of an average body of `height` m standing on the
    floor with its hip midpoint at `position` (x, z) meters, facing +Z turned by
    `heading_deg` about +Y (towards +X): where the subject stands when capture starts."""
    pose = Body.from_height(height).standard_pose()
    turn = Rotation.from_euler("y", heading_deg, degrees=True)
    return turn.apply(pose) + np.array([position[0], 0.0, position[1]])


def bone_lengths(poses: np.ndarray) -> np.ndarray:
    """Lengths of the 8 limb `BONES` for poses of shape (..., 13, 3); returns (..., 8)."""
    poses = np.asarray(poses)
    parents = [p for p, _ in BONES]
    children = [c for _, c in BONES]
    return np.linalg.norm(poses[..., children, :] - poses[..., parents, :], axis=-1)


def mirror_poses(poses: np.ndarray) -> np.ndarray:
    """Left/right mirror images of poses (..., 13, 3): x negated, left and right swapped."""
    poses = np.asarray(poses)
    out = poses[..., MIRROR, :].copy()
    out[..., 0] *= -1.0
    return out


def markers_of(poses: np.ndarray) -> np.ndarray:
    """The 8 marker positions (..., 8, 3) of poses (..., 13, 3)."""
    return np.asarray(poses)[..., MARKER_JOINTS, :]


def pose_batch(poses: np.ndarray) -> np.ndarray:
    """Poses as a float64 array (n, 13, 3); ValueError naming the shape otherwise."""
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (N_JOINTS, 3):
        raise ValueError(f"poses must be (n, 13, 3), got {poses.shape}")
    return poses


def facing_directions(poses: np.ndarray) -> np.ndarray:
    """Unit horizontal facing direction (n, 3) of poses (n, 13, 3); NaN if undefined.

    The facing is the horizontal part of (l_shoulder - r_shoulder) x up: +Z for a subject
    whose left shoulder is at +X (the standard pose). Frames whose shoulder line is
    vertical give NaN.
    """
    poses = pose_batch(poses)
    across = poses[:, JOINT_INDEX["l_shoulder"]] - poses[:, JOINT_INDEX["r_shoulder"]]
    facing = np.cross(across, _UP)
    facing[:, 1] = 0.0
    norm = np.linalg.norm(facing, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm > 1e-9, facing / norm, np.nan)


def mean_facing(poses: np.ndarray) -> np.ndarray:
    """The normalised mean (3,) of the per-frame unit facing directions of poses (n, 13, 3).

    Falls back to +Z when the facings cancel out (a take that turns full circle evenly).
    """
    facings = facing_directions(poses)
    known = ~np.isnan(facings[:, 0])
    mean = facings[known].sum(axis=0) / max(int(known.sum()), 1)
    norm = np.linalg.norm(mean)
    if not norm > 1e-6:
        return np.array([0.0, 0.0, 1.0])
    return mean / norm
