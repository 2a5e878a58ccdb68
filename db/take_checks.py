"""What a pose store accepts: the one check of a take's poses, frame rate and frame count
that runs before anything is committed (`check_addable`, called by `PoseStore.add_many`
and by the importers) and on every stored take by `PoseStore.verify`, so that `verify`
finds whatever an import would refuse."""

from __future__ import annotations

import numpy as np

from samba.body import JOINT_INDEX, Take
from samba.db.errors import StoreError

MAX_COORDINATE_M = 10_000.0
"""Largest joint coordinate (meters, either sign) a store holds; beyond it (or NaN) a take
is refused, and stored data is damaged."""
FPS_RANGE = (1.0, 1000.0)
"""Lowest and highest frame rate (frames per second) of a stored take, and of an export."""
MAX_TAKE_FRAMES = 1_000_000
"""Most frames of one take (9.3 hours at 30 fps, 156 MB of poses), stored or exported."""
BONE_RANGE_M = (0.02, 2.0)
"""Shortest and longest median length (meters) of a limb bone: a take outside it is not a
human body (a rig whose offsets are all zero, a wrong unit)."""
BONES = {
    f"{side} {bone}": (JOINT_INDEX[f"{s}_{a}"], JOINT_INDEX[f"{s}_{b}"])
    for s, side in (("l", "left"), ("r", "right"))
    for bone, a, b in (
        ("upper arm", "shoulder", "elbow"),
        ("forearm", "elbow", "wrist"),
        ("thigh", "hip", "knee"),
        ("shin", "knee", "foot"),
    )
}
"""The limb bones checked, with the joint indices at their ends."""


def frame_rate_problem(fps: float) -> str | None:
    """What is wrong with a frame rate `fps` (frames per second) for a take, None when it
    lies in `FPS_RANGE`."""
    low, high = FPS_RANGE
    if low <= fps <= high:  # False for NaN
        return None
    return f"frame rate {fps:g} fps is outside {low:g}-{high:g} fps"


def frame_count_problem(frames: int) -> str | None:
    """What is wrong with a take of `frames` frames, None when it is 1 to `MAX_TAKE_FRAMES`."""
    if frames == 0:
        return "the take holds no poses"
    if frames > MAX_TAKE_FRAMES:
        return f"{frames:,} frames, more than the limit of {MAX_TAKE_FRAMES:,} a take"
    return None


def take_problems(poses: np.ndarray, fps: float) -> list[str]:
    """Every reason a store refuses a take of `poses` (n, 13, 3) meters at `fps` frames per
    second: a frame rate outside `FPS_RANGE`, no frames or more than `MAX_TAKE_FRAMES`, a
    coordinate NaN, infinite or beyond `MAX_COORDINATE_M`, a limb bone whose median length
    is outside `BONE_RANGE_M`. Empty when the take is acceptable."""
    problems = [p for p in (frame_rate_problem(fps), frame_count_problem(len(poses))) if p]
    if not len(poses) or len(poses) > MAX_TAKE_FRAMES:
        return problems
    with np.errstate(invalid="ignore"):
        outside = ~(np.abs(poses) <= MAX_COORDINATE_M)  # True for NaN
    if outside.any():
        worst = np.nan_to_num(np.abs(poses[outside]), nan=np.inf).max()
        count = np.count_nonzero(outside)
        problems.append(
            f"{count} joint coordinate{'s' if count > 1 else ''} NaN, infinite or beyond "
            f"{MAX_COORDINATE_M:g} m (up to {worst:.3g})"
        )
        return problems
    low, high = BONE_RANGE_M
    ends = np.array(list(BONES.values()))
    medians = np.median(np.linalg.norm(poses[:, ends[:, 1]] - poses[:, ends[:, 0]], axis=-1), 0)
    for bone, length in zip(BONES, medians.tolist(), strict=True):
        if not low <= length <= high:
            problems.append(
                f"the {bone} is {length:.3f} m long (median over the take), outside "
                f"{low:g}-{high:g} m: not a human body (zero offsets? the wrong unit?)"
            )
            break
    return problems


def check_addable(take: Take) -> None:
    """`StoreError` naming the take's source and every problem `take_problems` finds when a
    store cannot accept it."""
    problems = take_problems(take.poses, take.fps)
    if problems:
        raise StoreError(take.source or take.name, "; ".join(problems))
