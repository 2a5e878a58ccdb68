"""Retargeting for the live service: one captured pose in, the avatar's bone rotations out.

`LiveRetarget` gives, frame by frame, the rotations `retarget` gives for the whole take
(up to float rounding). The root differs only in its scale: a stream cannot know the
median leg length of the whole take, so it takes a given leg length or settles on the
median of its first frames.
"""

from __future__ import annotations

import numpy as np

from export.humanoid import HumanoidRig
from export.retarget import leg_length, local_rotations, rest_frames, root_positions
from samba.kinematics import continuous_quaternions
from samba.skeleton import N_JOINTS


class LiveRetarget:
    """Frame-by-frame retargeting for the live service: `step` turns each captured pose
    (13, 3) into local bone rotations of `rig` and its root position.

    Rotations equal `retarget(poses, rig, fps).rotations` of the whole stream so far
    (within 1e-9), signs included: each step's quaternions lie in the hemisphere of the
    previous step's. Only frames already seen matter there: a nearly straight limb keeps
    the bend axis of its last fully bent frame, which `local_rotations` carries from
    step to step (the limbs' axes in their parents' frames), so each step runs it on the
    current pose alone, with the rig's `rest_frames` computed once.

    The root scale is `rig.leg_length / leg_length` as in `retarget`, with the subject's
    `leg_length` (meters) as given or, if None, the median leg length (see
    `retarget.leg_length`) of the frames seen so far until `settle_frames` frames have
    been seen; from then on it stays frozen, so the avatar's steps keep one scale. Roots
    equal `retarget`'s when `leg_length` is that of the whole take.
    """

    def __init__(
        self, rig: HumanoidRig, leg_length: float | None = None, settle_frames: int = 30
    ) -> None:
        if leg_length is not None and not (np.isfinite(leg_length) and leg_length > 0):
            raise ValueError(f"leg_length must be positive and finite meters, got {leg_length}")
        if settle_frames < 1:
            raise ValueError(f"settle_frames must be at least 1, got {settle_frames}")
        self._rig = rig
        self._rest_frames = rest_frames(rig)
        self._given_leg_length = None if leg_length is None else float(leg_length)
        self._settle_frames = settle_frames
        self.reset()

    def reset(self) -> None:
        """Start a new stream: forget the bent frames, the quaternion signs and the
        estimated leg length (a leg length given to the constructor stays)."""
        self._carried: np.ndarray | None = None
        self._previous: np.ndarray | None = None
        self._settling: list[np.ndarray] = []
        self._leg_length = self._given_leg_length

    @property
    def leg_length(self) -> float | None:
        """The subject's leg length (meters) the root scale uses: the given one, or the
        estimate from the frames so far (None before the first frame)."""
        return self._leg_length

    def step(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Retarget the next captured pose (13, 3), meters, finite (+Y up, as `retarget`).

        Returns local bone rotations (17, 4), unit quaternions (x, y, z, w) continuous
        with the previous step's, and the root (Hips) position (3,) in meters.
        """
        pose = np.array(pose, dtype=np.float64)
        if pose.shape != (N_JOINTS, 3):
            raise ValueError(f"LiveRetarget.step needs a pose of shape (13, 3), got {pose.shape}")
        if not np.isfinite(pose).all():
            raise ValueError("LiveRetarget.step needs a finite pose (drop frames with NaN first)")
        rotations, _, self._carried = local_rotations(
            pose[None], self._rig, self._rest_frames, self._carried
        )
        current = rotations[0]
        if self._previous is not None:
            current = continuous_quaternions(np.stack([self._previous, current]))[1]
        self._previous = current
        if self._given_leg_length is None and len(self._settling) < self._settle_frames:
            self._settling.append(pose)
            self._leg_length = leg_length(np.stack(self._settling))
        root = root_positions(pose[None], self._rig, self._leg_length)[0]
        return current.copy(), root
