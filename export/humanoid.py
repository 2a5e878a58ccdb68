"""The humanoid skeleton Samba exports to: Unity / VRM humanoid bone names, a rest pose.

Conventions (FORMATS.md §0):

* 17 bones named after Unity's `HumanBodyBones`, so engines map them automatically:
  Hips, Spine, Chest, Neck, Head and, per side, UpperArm, LowerArm, Hand, UpperLeg,
  LowerLeg, Foot. `PARENTS` lists every parent before its children.
* A bone's joint is where it starts: LeftUpperArm sits at the shoulder (our joint 1),
  LeftLowerArm at the elbow, LeftHand at the wrist, LeftUpperLeg at the hip, LeftFoot at
  the ankle, Neck at the middle of the shoulders, Head at our head joint, Hips at the
  middle of the hips. Spine and Chest lie on the line from Hips to Neck.
* The rest pose faces +Z with the subject's left at +X, +Y up, meters, floor at y = 0;
  every rest orientation is the identity (as in BVH and VRM0-normalised avatars), so a
  pose is fully given by local rotations relative to the rest pose plus the Hips position.
* `tips` are the ends of the five leaf bones (top of the head, finger tips, toes) as
  offsets from their joint: BVH End Sites and the mannequin's extremities.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from samba.body import Body

BONE_NAMES: tuple[str, ...] = (
    "Hips",
    "Spine",
    "Chest",
    "Neck",
    "Head",
    "LeftUpperArm",
    "LeftLowerArm",
    "LeftHand",
    "RightUpperArm",
    "RightLowerArm",
    "RightHand",
    "LeftUpperLeg",
    "LeftLowerLeg",
    "LeftFoot",
    "RightUpperLeg",
    "RightLowerLeg",
    "RightFoot",
)
N_BONES = len(BONE_NAMES)
BONE_INDEX: dict[str, int] = {name: i for i, name in enumerate(BONE_NAMES)}
PARENTS: tuple[int, ...] = (-1, 0, 1, 2, 3, 2, 5, 6, 2, 8, 9, 0, 11, 12, 0, 14, 15)
"""Parent bone of each bone (-1 for Hips)."""

TIP_BONES: tuple[int, ...] = (4, 7, 10, 13, 16)
"""The leaf bones that carry a tip: Head, LeftHand, RightHand, LeftFoot, RightFoot."""

CAPTURE_JOINT: dict[int, int] = {
    4: 0,
    5: 1,
    6: 3,
    7: 5,
    8: 2,
    9: 4,
    10: 6,
    11: 7,
    12: 9,
    13: 11,
    14: 8,
    15: 10,
    16: 12,
}
"""Bone index -> the 13-joint skeleton joint at which the bone starts (synthetic bones
Hips, Spine, Chest and Neck are absent)."""


@dataclass(frozen=True)
class HumanoidRig:
    """A humanoid skeleton's rest pose: `rest` (17, 3) joint positions and `tips` (5, 3)
    offsets of the leaf ends from their joints, both in meters in the rest frame.

    `from_body` builds the default avatar's skeleton.
    """

    rest: np.ndarray
    tips: np.ndarray
    name: str = "samba-mannequin"

    def __post_init__(self) -> None:
        rest = np.asarray(self.rest, dtype=np.float64)
        tips = np.asarray(self.tips, dtype=np.float64)
        if rest.shape != (N_BONES, 3) or tips.shape != (len(TIP_BONES), 3):
            raise ValueError(
                f"rig needs rest (17, 3) and tips (5, 3), got {rest.shape}, {tips.shape}"
            )
        if not (np.isfinite(rest).all() and np.isfinite(tips).all()):
            raise ValueError("rig rest positions must be finite")
        rest, tips = rest.copy(), tips.copy()
        rest.setflags(write=False)
        tips.setflags(write=False)
        object.__setattr__(self, "rest", rest)
        object.__setattr__(self, "tips", tips)

    @classmethod
    def from_body(cls, body: Body | None = None, arm_angle_deg: float = 90.0) -> HumanoidRig:
        """The default avatar's skeleton for a body (default 1.70 m): a T-pose when
        `arm_angle_deg` is 90 (arms horizontal), an A-pose for smaller angles."""
        body = body or Body.from_height()
        h = body.height
        pose = body.standard_pose(arm_angle_deg)
        ankle_height = 0.039 * h
        pose[:, 1] += ankle_height
        pelvis = (pose[7] + pose[8]) / 2
        neck = (pose[1] + pose[2]) / 2
        rest = np.empty((N_BONES, 3))
        rest[0] = pelvis
        rest[1] = pelvis + (neck - pelvis) * 0.25
        rest[2] = pelvis + (neck - pelvis) * 0.6
        rest[3] = neck
        for bone, joint in CAPTURE_JOINT.items():
            rest[bone] = pose[joint]
        a = np.radians(arm_angle_deg)
        arm = np.array([np.sin(a), -np.cos(a), 0.0])
        tips = np.array(
            [
                [0.0, 0.10 * h, 0.0],
                0.108 * h * arm,
                0.108 * h * arm * [-1.0, 1.0, 1.0],
                [0.0, -ankle_height, 0.11 * h],
                [0.0, -ankle_height, 0.11 * h],
            ]
        )
        return cls(rest=rest, tips=tips)

    @property
    def parents(self) -> tuple[int, ...]:
        """Parent bone of each bone (-1 for the root)."""
        return PARENTS

    @property
    def names(self) -> tuple[str, ...]:
        """Unity / VRM humanoid bone names, in bone order."""
        return BONE_NAMES

    @cached_property
    def offsets(self) -> np.ndarray:
        """Rest offset (17, 3) of each bone's joint from its parent's joint, meters; the
        root's entry is its rest position. Read only (computed once: the rig is frozen)."""
        parents = np.array(PARENTS)
        out = self.rest.copy()
        out[1:] -= self.rest[parents[1:]]
        out.setflags(write=False)
        return out

    @cached_property
    def leg_length(self) -> float:
        """Mean hip-to-ankle length along the legs in the rest pose, meters."""
        rest = self.rest
        legs = [(11, 12, 13), (14, 15, 16)]
        return float(
            np.mean(
                [
                    np.linalg.norm(rest[k] - rest[h]) + np.linalg.norm(rest[a] - rest[k])
                    for h, k, a in legs
                ]
            )
        )

    @cached_property
    def hips_to_legs(self) -> np.ndarray:
        """Rest offset (3,) from the Hips joint to the middle of the upper-leg joints,
        meters: zero for the mannequin, whose Hips lies between its legs; avatars put
        their Hips joint above, level with or below the legs."""
        offset = (self.rest[11] + self.rest[14]) / 2 - self.rest[0]
        offset.setflags(write=False)
        return offset

    @cached_property
    def ankle_height(self) -> float:
        """Height of the ankles above the floor in the rest pose, meters."""
        return float(self.rest[[13, 16], 1].mean())
