"""The 13 joints of a human from a model-free volumetric capture
(`samba.volume.capture`), when the derived model has human topology.

Of the common model's five leaf branches, the two whose ends are lowest on average are
the legs, the shortest of the other three (by the mean arc length of the branch, which
the number of joints on it does not change) is the head and the remaining two are the
arms; left and right come from the subject's facing direction in the first frame
(the volume alone cannot tell front from back: given by the user, or the direction the
subject walks, `walked_direction`, people walking forwards). Each limb is the
polyline from its branch's start (the root or a branching node: the top of the trunk
for arms and head, the crotch for legs) through the model's joints to its end (the
tip of the hand, foot or head). A capture joint sits at a fixed fraction of that
polyline's length (`LIMB_FRACTIONS`), except elbows and knees, which take the model's
own joint nearest that fraction when one lies within `SNAP` of it. The shoulders are
not on the arms' polylines: the arms branch from the top of the trunk, between the
shoulders, so each shoulder is that branch start moved out, level, by `SHOULDER_OUT` of
the arm's length, along the horizontal line from the other arm to its own (taken at
`SHOULDER_AXIS_AT` of both arms' lengths, about the elbows). The hips are not on
the legs' polylines: the legs part at the crotch, below and between the hips, so each
hip is the crotch moved out towards its knee's side and up, by fractions of the leg's
length (`HIP_OUT`, `HIP_UP`). With the feet together the legs carve one column and
their branches part far below the hips; a leg carved much shorter than its length then
reaches up from the toe along the volume's curve through the crotch to that length,
and its knee and hip are placed on that reach (`_full_leg`). The fractions, the
shoulders' and hips' offsets and the leg's reach (`LEG_STATURE`, `MERGED_LEG`) were
fitted on takes of seeds 1-5 (seeds 11-13 and
31-34, which `bench/bench_volume.py` reports, were not used): a branch starts where the
volume's curve does and a leaf ends about one local radius inside the volume's tip
(`samba.volume.frame_kinematics.tip_inset`), not at the capsule body's joints.
"""

from __future__ import annotations

import numpy as np

from samba.base import InputError
from samba.body import N_JOINTS
from samba.volume.frame_kinematics import HUMAN_END_BRANCHES, arc_lengths, points_along
from samba.volume.sequence_model import SequenceFit

LIMB_FRACTIONS: dict[str, tuple[float, ...]] = {
    "arm": (0.58, 0.86),
    "leg": (0.40, 0.86),
    "head": (0.54,),
}
"""Fractions of a limb's length from its branch start: arm (elbow, wrist), leg (knee,
ankle), head (the head joint), fitted on seeds 1-5. When leaf ends moved one radius
inside the tips, the wrist's, ankle's and head's were refitted, each to the fraction
minimising its joint's mean error over the exaggerated takes (jumping jacks, wave) of
seeds 1-5: 0.84 -> 0.86, 0.84 -> 0.86, 0.45 -> 0.54 (1.7, 2.4 and 2.7 cm there); the
elbow's and knee's were kept (their best there, 0.59 -> 0.61 and 0.40, hardly moved)."""
SHOULDER_OUT = 0.20
"""How far a shoulder lies out from its arm's branch start, level, as a fraction of the
arm's length (its polyline's, branch start to hand tip)."""
SHOULDER_AXIS_AT = 0.5
"""Where along both arms (fraction of their lengths) the line between them is taken
whose horizontal direction points each shoulder out."""
HIP_OUT = 0.10
"""How far a hip lies out from the crotch, towards its knee's side, as a fraction of the
leg's length (its polyline's, crotch to toe)."""
HIP_UP = 0.10
"""How far the hips lie above the crotch, as a fraction of the leg's length."""
LEG_LENGTH_QUANTILE = 75.0
"""Percentile over the take of a leg's carved length (crotch to toe) taken as its length:
frames with the legs apart give it, frames with the feet together (one column of
voxels, the crotch far down) fall below it."""
LEG_STATURE = 0.58
"""A leg's length (crotch to toe along the volume's curve) as a fraction of the stature
(the head's top above the floor, its 90th percentile over the take)."""
MERGED_LEG = 0.85
"""A leg carved shorter than this fraction of its length is taken to be merged with the
other (the feet together): it reaches up to its full length (`_full_leg`)."""
MIN_WALK = 0.3
"""Shortest horizontal distance (m) between the root's first and last position for
`walked_direction` to take it as the direction the subject faces."""
SNAP = 0.12
"""Largest distance (fraction of the limb) from an elbow's or knee's nominal place to
a model joint that replaces it."""
_JOINTS = {
    ("arm", 1): (3, 5),
    ("arm", -1): (4, 6),
    ("leg", 1): (9, 11),
    ("leg", -1): (10, 12),
}
"""(limb, side: +1 left, -1 right) -> the capture joints along it, in fraction order."""
_HIPS = {1: 7, -1: 8}
"""Side (+1 left, -1 right) -> the hip joint."""
_SHOULDERS = {1: 1, -1: 2}
"""Side (+1 left, -1 right) -> the shoulder joint."""


def humanoid_joints(fit: SequenceFit, facing: np.ndarray) -> np.ndarray:
    """The 13 capture joints (n, 13, 3) meters of a fit with five leaf branches.

    `facing` (3,) is the subject's forward direction in the first frame (only its
    horizontal part counts); the subject's left is up x facing. Raises `InputError`
    when the model does not have five leaf branches.
    """
    model = fit.model
    leaves = [b for b in range(len(model.parents)) if b not in model.parents]
    if len(leaves) != HUMAN_END_BRANCHES:
        raise InputError(
            "volume sequence",
            f"the derived model has {len(leaves)} end branches, not a human's "
            f"{HUMAN_END_BRANCHES} (head, two arms, two legs)",
        )
    forward = np.asarray(facing, dtype=np.float64) * np.array([1.0, 0.0, 1.0])
    if not np.linalg.norm(forward) > 0:
        raise InputError("--facing", f"needs a horizontal direction, got {facing!r}")
    left = np.cross([0.0, 1.0, 0.0], forward / np.linalg.norm(forward))
    limbs = {b: _limb(fit, b) for b in leaves}
    ends = {b: limbs[b][:, -1] for b in leaves}
    legs = sorted(leaves, key=lambda b: ends[b][:, 1].mean())[:2]
    rest = [b for b in leaves if b not in legs]
    head = min(rest, key=lambda b: model.lengths[b])
    arms = [b for b in rest if b != head]
    stature = float(np.percentile(ends[head][:, 1], 90))
    joints = np.zeros((len(fit.root), N_JOINTS, 3))
    joints[:, 0] = _at(limbs[head], LIMB_FRACTIONS["head"][0])
    for kind, pair in (("arm", arms), ("leg", legs)):
        side = np.sign((ends[pair[0]][0] - ends[pair[1]][0]) @ left) or 1.0
        for branch, other, sign in zip(pair, pair[::-1], (side, -side), strict=True):
            carved = limbs[branch]
            full = _full_leg(fit, branch, carved, stature) if kind == "leg" else carved
            fractions = LIMB_FRACTIONS[kind]
            targets = _JOINTS[(kind, int(sign))]
            inner = _model_joint_fractions(fit, branch, full)
            for k, (joint, fraction) in enumerate(zip(targets, fractions, strict=True)):
                snapped = k == 0 and len(inner) and np.min(np.abs(inner - fraction)) <= SNAP
                place = inner[np.argmin(np.abs(inner - fraction))] if snapped else fraction
                ankle = kind == "leg" and k == len(fractions) - 1
                joints[:, joint] = _at(carved if ankle else full, float(place))
            if kind == "leg":
                joints[:, _HIPS[int(sign)]] = _hip(full, joints[:, targets[0]])
            else:
                joints[:, _SHOULDERS[int(sign)]] = _shoulder(carved, limbs[other])
    return joints


def walked_direction(root: np.ndarray) -> np.ndarray | None:
    """The horizontal unit direction (3,) from the first to the last of the root
    positions (n, 3) m, when they lie at least `MIN_WALK` m apart; None otherwise."""
    step = (root[-1] - root[0]) * np.array([1.0, 0.0, 1.0])
    distance = float(np.linalg.norm(step))
    return step / distance if distance >= MIN_WALK else None


def _full_leg(fit: SequenceFit, branch: int, leg: np.ndarray, stature: float) -> np.ndarray:
    """The leg polyline (n, k, 3) of `branch` with its start moved up to the leg's length
    from the toe, along the volume's curve through the crotch towards the root, where
    the leg is carved shorter than `MERGED_LEG` of that length: with the feet together
    the legs carve one column and their branches part far below the hips, which would
    pull hips and knees down. The length is the larger of the take's (its
    `LEG_LENGTH_QUANTILE` percentile) and `LEG_STATURE` of the `stature` (m), for takes
    whose feet never part."""
    own = arc_lengths(leg)[:, -1]
    take = max(np.percentile(own, LEG_LENGTH_QUANTILE), LEG_STATURE * stature)
    length = np.where(own < MERGED_LEG * take, take, own)
    path = [leg[:, ::-1]]
    parent = fit.model.parents[branch]
    while parent >= 0:
        path.append(_limb(fit, parent)[:, -2::-1])
        parent = fit.model.parents[parent]
    up = np.concatenate(path, axis=1)  # toe, ..., crotch, ..., root
    reach = length / np.maximum(arc_lengths(up)[:, -1], 1e-12)
    out = leg.copy()
    out[:, 0] = points_along(up, np.minimum(reach, 1.0)[:, None])[:, 0]
    return out


def _shoulder(arm: np.ndarray, other: np.ndarray) -> np.ndarray:
    """(n, 3) the shoulder of an arm polyline (n, k, 3) given the other arm's (n, m, 3):
    its branch start moved out, level, by `SHOULDER_OUT` of the arm's length along the
    horizontal direction from the other arm to it at `SHOULDER_AXIS_AT`, meters."""
    out = _level_direction(_at(arm, SHOULDER_AXIS_AT) - _at(other, SHOULDER_AXIS_AT))
    return arm[:, 0] + SHOULDER_OUT * out * arc_lengths(arm)[:, -1:]


def _hip(leg: np.ndarray, knee: np.ndarray) -> np.ndarray:
    """(n, 3) the hip of a leg polyline (n, k, 3) from the crotch, whose knee is at
    `knee` (n, 3): out from the crotch towards the knee's side by `HIP_OUT` of the leg's
    length and up by `HIP_UP` of it, meters."""
    crotch = leg[:, 0]
    length = arc_lengths(leg)[:, -1:]
    out = _level_direction(knee - crotch)
    return crotch + (HIP_OUT * out + [0.0, HIP_UP, 0.0]) * length


def _level_direction(vectors: np.ndarray) -> np.ndarray:
    """(n, 3) the horizontal directions (unit, y = 0) of vectors (n, 3)."""
    level = vectors * [1.0, 0.0, 1.0]
    return level / np.maximum(np.linalg.norm(level, axis=-1, keepdims=True), 1e-12)


def _limb(fit: SequenceFit, branch: int) -> np.ndarray:
    """(n, k, 3) the branch's start then its model joints and end, meters."""
    parent = fit.model.parents[branch]
    start = fit.root if parent < 0 else fit.branch_points[parent][:, -1]
    return np.concatenate([start[:, None], fit.branch_points[branch]], axis=1)


def _model_joint_fractions(fit: SequenceFit, branch: int, polyline: np.ndarray) -> np.ndarray:
    """Fractions of the limb polyline's length at its interior model joints (frame mean)."""
    arc = arc_lengths(polyline)
    fractions = arc[:, 1:] / np.maximum(arc[:, -1:], 1e-12)
    return fractions[:, : len(fit.model.joints[branch])].mean(axis=0)


def _at(polyline: np.ndarray, fraction: float) -> np.ndarray:
    """(n, 3) points at `fraction` of each frame's polyline (n, k, 3) length."""
    return points_along(polyline, np.array([fraction]))[:, 0]
