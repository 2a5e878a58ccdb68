"""Normalisation of mapped joint positions to Samba's frame: meters, right-handed, +Y up.

Units and the up axis are detected from the motion itself (not from rest offsets, which
some rigs lay out along another axis than the one their root rotation turns to up);
every detection can be overridden. After normalisation the foot joints of a standing
subject are near y = 0.
"""

from __future__ import annotations

import numpy as np

from samba.body import JOINT_INDEX

UNITS: dict[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "in": 0.0254,
    "cmu": 0.0254 / 0.45,
}
"""Length units a motion file may use, in meters per unit ("cmu": CMU's 1/0.45 inch)."""
TYPICAL_LEG = 0.85
"""Hip-to-ankle length of an adult in meters, the yardstick for unit detection."""
UP_AXES: dict[str, np.ndarray] = {
    name: sign * np.eye(3)[i]
    for i, axis in enumerate("xyz")
    for name, sign in ((f"+{axis}", 1.0), (f"-{axis}", -1.0))
}
"""Signed axis names ('+y', '-z', ...) as unit vectors."""

_LEGS = [
    (JOINT_INDEX[f"{s}_hip"], JOINT_INDEX[f"{s}_knee"], JOINT_INDEX[f"{s}_foot"]) for s in "lr"
]
_FEET = [JOINT_INDEX["l_foot"], JOINT_INDEX["r_foot"]]


def leg_length(positions: np.ndarray) -> float:
    """Median hip-knee-ankle length of poses (n, 13, 3), in their own unit."""
    lengths = [
        np.linalg.norm(positions[:, k] - positions[:, h], axis=-1)
        + np.linalg.norm(positions[:, f] - positions[:, k], axis=-1)
        for h, k, f in _LEGS
    ]
    return float(np.median(np.concatenate(lengths)))


def detect_units(positions: np.ndarray) -> str:
    """The unit in `UNITS` under which the leg length of poses (n, 13, 3) is closest to adult."""
    leg = leg_length(positions)
    if not leg > 0:
        return "m"
    return min(UNITS, key=lambda u: abs(np.log(leg * UNITS[u] / TYPICAL_LEG)))


def detect_up(positions: np.ndarray) -> str:
    """The signed axis ('+y', '+z', ...) along which the head is above the feet on average."""
    up = positions[:, JOINT_INDEX["head"]] - positions[:, _FEET].mean(axis=1)
    mean = up.mean(axis=0)
    axis = int(np.argmax(np.abs(mean)))
    return ("+" if mean[axis] >= 0 else "-") + "xyz"[axis]


def rotation_to_y_up(up: str) -> np.ndarray:
    """A proper rotation matrix (3, 3) taking the signed axis `up` to +Y."""
    return _rotation_onto_y(UP_AXES[up])


def _rotation_onto_y(direction: np.ndarray) -> np.ndarray:
    """The smallest proper rotation (3, 3) taking the unit vector `direction` to +Y."""
    y = np.array([0.0, 1.0, 0.0])
    if np.allclose(direction, -y):
        return np.diag([1.0, -1.0, -1.0])
    axis = np.cross(direction, y)
    sin = np.linalg.norm(axis)
    if sin < 1e-12:
        return np.eye(3)
    axis /= sin
    cos = float(np.dot(direction, y))
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + sin * k + (1 - cos) * (k @ k)  # Rodrigues


def chirality(positions: np.ndarray) -> float:
    """How right-handed poses (n, 13, 3) in meters, +Y up, look, in [-1, 1].

    In a right-handed frame a subject's forward direction is left x up, and bent knees
    point forward. The result is the mean sign of the knees' forward bulge over frames
    where it exceeds 2 cm; near -1 means mirrored (left-handed) data, 0 means undecided.
    """
    up = np.array([0.0, 1.0, 0.0])
    left = positions[:, JOINT_INDEX["l_hip"]] - positions[:, JOINT_INDEX["r_hip"]]
    forward = np.cross(left, up)
    norm = np.linalg.norm(forward, axis=-1, keepdims=True)
    forward = np.divide(forward, norm, out=np.zeros_like(forward), where=norm > 1e-9)
    signs = []
    for h, k, f in _LEGS:
        bulge = np.einsum(
            "ni,ni->n", positions[:, k] - 0.5 * (positions[:, h] + positions[:, f]), forward
        )
        signs.append(np.sign(bulge[np.abs(bulge) > 0.02]))
    both = np.concatenate(signs)
    return float(both.mean()) if len(both) else 0.0


def floor_height(positions: np.ndarray, fps: float) -> float:
    """Height (m) of the foot joints at ground contact in poses (n, 13, 3), +Y up.

    The 10th percentile of the heights of `foot_contacts` (feet standing still); for a
    take with fewer than 10 contacts, the 5th percentile of the lower foot's height.
    """
    contacts = foot_contacts(positions, fps)
    if len(contacts) >= 10:
        return float(np.percentile(contacts[:, 1], 10))
    return float(np.percentile(positions[:, _FEET, 1].min(axis=1), 5))


def foot_contacts(
    positions: np.ndarray, fps: float, max_speed: float = 0.15, min_seconds: float = 0.1
) -> np.ndarray:
    """Foot positions (m, 3) at ground contact in poses (n, 13, 3), meters, +Y up.

    A foot is in contact where it is the lower of the two feet and has moved slower than
    `max_speed` m/s for at least `min_seconds` in a row (which leaves out the apex of a
    hop, where a foot is slow only for an instant).
    """
    feet = positions[:, _FEET]
    if len(feet) < 2:
        return np.empty((0, 3))
    speed = np.linalg.norm(np.gradient(feet, axis=0), axis=-1) * fps
    height = feet[..., 1]
    slow = (speed < max_speed) & (height <= height.min(axis=1, keepdims=True))
    run = max(int(np.ceil(min_seconds * fps)), 1)
    if len(feet) < run:
        return np.empty((0, 3))
    kernel = np.ones(run, dtype=int)
    steady = np.zeros_like(slow)
    for side in range(2):
        windows = np.convolve(slow[:, side].astype(int), kernel, mode="valid") == run
        for shift in range(run):
            steady[shift : shift + len(windows), side] |= windows
    return feet[steady]


def level_floor(
    positions: np.ndarray, fps: float, max_tilt_deg: float = 8.0, min_spread: float = 1.0
) -> tuple[np.ndarray, float]:
    """Poses (n, 13, 3) turned so that a tilted capture floor becomes level, and the tilt.

    A plane y = a x + b z + c is fitted to the foot contacts (`foot_contacts`), ignoring
    contacts more than 3 cm above it (heels lifting). The poses are rotated about the
    contacts' centroid so the plane becomes horizontal only when the evidence is clear:
    the contacts spread over at least `min_spread` meters, the plane explains most of
    their height variation (residual spread under half the raw spread, which is over
    1 cm), and it tilts by less than `max_tilt_deg`. Returns the poses (unchanged when
    not levelled) and the tilt removed, in degrees.
    """
    contacts = foot_contacts(positions, fps)
    if len(contacts) < 10:
        return positions, 0.0
    horizontal = contacts[:, [0, 2]]
    if np.ptp(horizontal, axis=0).max() < min_spread:
        return positions, 0.0
    keep = np.ones(len(contacts), dtype=bool)
    design = np.column_stack([horizontal, np.ones(len(contacts))])
    for _ in range(3):
        coef, *_ = np.linalg.lstsq(design[keep], contacts[keep, 1], rcond=None)
        residual = contacts[:, 1] - design @ coef
        keep = residual < np.percentile(residual, 10) + 0.03
    raw_spread = np.std(contacts[keep, 1])
    if not (raw_spread > 0.01 and np.std(residual[keep]) < 0.5 * raw_spread):
        return positions, 0.0
    normal = np.array([-coef[0], 1.0, -coef[1]])
    normal /= np.linalg.norm(normal)
    tilt = float(np.degrees(np.arccos(np.clip(normal[1], -1.0, 1.0))))
    if tilt < 1e-3 or tilt > max_tilt_deg:
        return positions, 0.0
    rot = _rotation_onto_y(normal)
    center = contacts.mean(axis=0)
    return (positions - center) @ rot.T + center, tilt


def leading_tpose_frames(positions: np.ndarray, tolerance_deg: float = 20.0) -> int:
    """How many leading poses of (n, 13, 3), +Y up, are a T-pose (both arms straight out).

    An arm counts as out when its shoulder-to-elbow and elbow-to-wrist directions are
    within `tolerance_deg` of horizontal and the wrist is at least 80% of the arm's
    length away from the shoulder sideways.
    """
    limit = np.sin(np.radians(tolerance_deg))
    out = np.ones(len(positions), dtype=bool)
    for s, e, w in ((1, 3, 5), (2, 4, 6)):
        upper = positions[:, e] - positions[:, s]
        lower = positions[:, w] - positions[:, e]
        length = np.linalg.norm(upper, axis=-1) + np.linalg.norm(lower, axis=-1)
        for seg in (upper, lower):
            out &= np.abs(seg[:, 1]) < limit * np.linalg.norm(seg, axis=-1)
        reach = positions[:, w] - positions[:, s]
        out &= np.linalg.norm(reach[:, [0, 2]], axis=-1) > 0.8 * length
    return len(out) if out.all() else int(np.argmin(out))
