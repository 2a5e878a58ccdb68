"""Retargeting for the live service: one captured pose in, the avatar's bone rotations out.

`LiveRetarget` gives, frame by frame, the rotations `retarget` gives for the whole take
(up to float rounding). The root differs only in its scale: a stream cannot know the
median leg length of the whole take, so it takes a given leg length or settles on the
median of its first frames.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from samba.body import N_JOINTS
from samba.export.humanoid import N_BONES, HumanoidRig
from samba.export.retargeting import (
    LIMBS,
    leg_length,
    rest_frames,
    root_positions,
    stream_rotations,
)


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
        self._carried = np.full((LIMBS, 3, 2), np.nan)
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
        rotations, roots = retarget_together([self], pose[None])
        return rotations[0], roots[0]


def retarget_together(
    streams: Sequence[LiveRetarget], poses: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The next captured pose of several streams of one rig in one batch: poses (s, 13, 3)
    in meters, finite, row i for streams[i]. Returns what each `streams[i].step(poses[i])`
    returns, stacked: rotations (s, 17, 4) and roots (s, 3). Streams whose rigs share
    a rest pose go in one batch: the live service retargets the sessions whose frames
    arrive together so (the rotations of four poses cost about what one pose's do).
    `ValueError` when a stream comes twice."""
    poses = np.array(poses, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (N_JOINTS, 3) or len(poses) != len(streams):
        raise ValueError(
            f"retargeting needs one pose (13, 3) per stream: {len(streams)} streams, "
            f"poses of shape {poses.shape}"
        )
    if not np.isfinite(poses).all():
        raise ValueError("LiveRetarget.step needs a finite pose (drop frames with NaN first)")
    if len({id(s) for s in streams}) != len(streams):
        raise ValueError("streams retargeted together must be distinct")
    rotations = np.empty((len(streams), N_BONES, 4))
    rigs: dict[bytes, list[int]] = {}  # streams whose rigs have one rest pose
    for i, stream in enumerate(streams):
        rigs.setdefault(stream._rig.rest.tobytes(), []).append(i)
    for rows in rigs.values():
        first = streams[rows[0]]
        carried = np.stack([streams[i]._carried for i in rows])
        rotations[rows], carried = stream_rotations(
            poses[rows], first._rig, first._rest_frames, carried
        )
        for row, i in enumerate(rows):
            streams[i]._carried = carried[row]
    roots = np.empty((len(streams), 3))
    for i, stream in enumerate(streams):
        if stream._previous is not None:
            flip = np.sum(stream._previous * rotations[i], axis=-1) < 0
            rotations[i, flip] *= -1.0
        stream._previous = rotations[i].copy()
        if stream._given_leg_length is None and len(stream._settling) < stream._settle_frames:
            stream._settling.append(poses[i])
            stream._leg_length = leg_length(np.stack(stream._settling))
        assert stream._leg_length is not None
        roots[i] = root_positions(
            poses[i][None], stream._rig, stream._leg_length, rotations[i, :1]
        )[0]
    return rotations, roots
