"""The standing start of a synthetic capture: the subject first holds the standard pose.

The paper's trackers start from the standard pose, which the subject holds when capture
begins (Section 5.4). `standing_lead_in` prepends that start to any take: the subject's
own standard pose (segment lengths from the take's first pose) held for a moment, then
turning and moving into the take's first pose.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from samba.body import N_JOINTS, Body, facing_directions, mean_facing


@dataclass(frozen=True, eq=False)
class LeadIn:
    """A take with the standing start prepended: `poses` (L + F, 13, 3) meters, of which
    the first `frames` are the lead-in; the subject stands with its hip midpoint at
    `position` (x, z) meters, facing +Z turned by `heading_deg` about +Y, and is
    `height` meters tall (the stature of an average body of the same head height)."""

    poses: np.ndarray
    frames: int
    position: tuple[float, float]
    heading_deg: float
    height: float


def standing_lead_in(
    poses: np.ndarray, fps: float, hold_seconds: float = 0.5, blend_seconds: float = 0.5
) -> LeadIn:
    """Prepend the subject's standard pose, held then blended into poses (F, 13, 3).

    The subject's segment lengths come from the first pose. Its standard pose stands on
    the floor under the first pose's hip midpoint facing the take's mean facing direction
    (where `spread_cameras` puts the cameras), held for `hold_seconds`, then turns and
    moves into the first pose over `blend_seconds`: the heading turns the short way
    round while the joints, relative to the hip midpoint and heading, ease from one pose
    to the other.
    """
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (N_JOINTS, 3) or len(poses) == 0:
        raise ValueError(f"poses must be (F, 13, 3) with F >= 1, got {poses.shape}")
    first = poses[0]
    body = _body_of(first)
    start_heading = _heading_deg(mean_facing(poses))
    first_heading = _heading_deg(facing_directions(first[None])[0])
    hips = (first[7] + first[8]) / 2.0
    floor = np.array([hips[0], 0.0, hips[2]])
    first_local = Rotation.from_euler("y", -first_heading, degrees=True).apply(first - floor)
    standing = body.standard_pose()
    standing[:, [0, 2]] -= (standing[7, [0, 2]] + standing[8, [0, 2]]) / 2.0
    hold, blend = round(hold_seconds * fps), round(blend_seconds * fps)
    ease = np.arange(hold + blend) - hold + 1.0
    ease = np.clip(ease / (blend + 1), 0.0, 1.0)
    ease = ease * ease * (3.0 - 2.0 * ease)
    turn = (first_heading - start_heading + 180.0) % 360.0 - 180.0
    local = (1 - ease)[:, None, None] * standing + ease[:, None, None] * first_local
    headings = Rotation.from_euler("y", (start_heading + ease * turn)[:, None], degrees=True)
    lead = np.stack([h.apply(pose) for h, pose in zip(headings, local, strict=True)]) + floor
    return LeadIn(
        poses=np.concatenate([lead, poses]),
        frames=len(lead),
        position=(float(hips[0]), float(hips[2])),
        heading_deg=start_heading,
        height=body.height,
    )


def _heading_deg(facing: np.ndarray) -> float:
    """Heading (degrees about +Y from +Z towards +X) of a horizontal facing (3,); 0 if NaN."""
    return 0.0 if np.isnan(facing[0]) else float(np.degrees(np.arctan2(facing[0], facing[2])))


def _body_of(pose: np.ndarray) -> Body:
    """The segment lengths (m) of one pose (13, 3), left and right averaged, and the
    stature of an average body with the same head height in the standard pose."""

    def length(a: int, b: int) -> float:
        return float(np.linalg.norm(pose[a] - pose[b]))

    shoulders, hips = (pose[1] + pose[2]) / 2, (pose[7] + pose[8]) / 2
    body = Body(
        height=1.0,
        shoulder_width=length(1, 2),
        hip_width=length(7, 8),
        upper_arm=(length(1, 3) + length(2, 4)) / 2,
        forearm=(length(3, 5) + length(4, 6)) / 2,
        thigh=(length(7, 9) + length(8, 10)) / 2,
        shin=(length(9, 11) + length(10, 12)) / 2,
        torso=float(np.linalg.norm(shoulders - hips)),
        neck=float(np.linalg.norm(pose[0] - shoulders)),
    )
    head_height = body.thigh + body.shin + body.torso + body.neck
    average_head_height = Body.from_height(1.0).standard_pose()[0, 1]  # per meter of stature
    return replace(body, height=float(np.clip(head_height / average_head_height, 0.5, 2.5)))
