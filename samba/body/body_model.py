"""`BodyModel`: the 3D body whose silhouettes the single-camera tracker compares with video.

The body is a set of capsules (line segments with a radius) hung on the 13 joints of a
pose: the pose gives the bone lengths, the model the girths. Capsules, in
`CAPSULE_NAMES` order, each belonging to one body part of `PART_NAMES`:

* torso: a pelvis from hip to hip; an abdomen and a chest, each two capsules side by
  side (so the trunk is wider side to side than front to back) along the spine from the
  hip midpoint to the shoulder midpoint, the chest pair spread along the shoulder line
  and the abdomen pair along the hip line; a shoulder capsule from shoulder to shoulder.
* head: a neck from the shoulder midpoint to the head joint, and the head, a capsule
  along the neck direction. The head joint sits between the chin and the eyes; the top
  of the head is `HEAD_TOP_FRACTION` of the stature above it.
* arms: upper arm (shoulder to elbow), forearm (elbow to wrist, extended past the wrist
  for the hand).
* legs: thigh (hip to knee), shin (knee to ankle) and a foot, a capsule under the ankle
  pointing forward (perpendicular to the shin and the hip line) with its sole
  `ANKLE_HEIGHT_FRACTION` of the stature below the ankle.

A standing pose of stature h (see `standing_heights`) thus renders from the sole to the
top of the head at height h. Sizes follow the dress-size idea of Okada et al. (JIS
L4004 men, L4005 women, L4001 children): `BodyModel.catalog` holds men's, women's and
children's sizes given by stature and chest, waist and hip girths, from which the radii
derive. Units: meters throughout; girths are circumferences in meters.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from samba.base import InputError
from samba.body.kinematics import unit_vectors
from samba.body.skeleton import N_JOINTS, Body

PART_NAMES: tuple[str, ...] = ("torso", "head", "l_arm", "r_arm", "l_leg", "r_leg")
"""Body parts the tracker's motion model and occlusion test work with."""

KINDS: tuple[str, ...] = ("men", "women", "children")
"""Kinds of body models in the catalogue (the size systems they come from)."""

_CAPSULES: tuple[tuple[str, str, str], ...] = (
    # capsule, part, BodyModel field holding its radius
    ("pelvis", "torso", "pelvis_radius"),
    ("abdomen_l", "torso", "abdomen_radius"),
    ("abdomen_r", "torso", "abdomen_radius"),
    ("chest_l", "torso", "chest_radius"),
    ("chest_r", "torso", "chest_radius"),
    ("shoulders", "torso", "shoulder_radius"),
    ("neck", "head", "neck_radius"),
    ("head", "head", "head_radius"),
    ("l_upper_arm", "l_arm", "upper_arm_radius"),
    ("l_forearm", "l_arm", "forearm_radius"),
    ("r_upper_arm", "r_arm", "upper_arm_radius"),
    ("r_forearm", "r_arm", "forearm_radius"),
    ("l_thigh", "l_leg", "thigh_radius"),
    ("l_shin", "l_leg", "shin_radius"),
    ("l_foot", "l_leg", "foot_radius"),
    ("r_thigh", "r_leg", "thigh_radius"),
    ("r_shin", "r_leg", "shin_radius"),
    ("r_foot", "r_leg", "foot_radius"),
)
CAPSULE_NAMES: tuple[str, ...] = tuple(name for name, _, _ in _CAPSULES)
"""The capsules of the body, in the order `BodyModel.capsules` returns them."""
CAPSULE_PARTS: np.ndarray = np.array([PART_NAMES.index(part) for _, part, _ in _CAPSULES])
"""Index in `PART_NAMES` of the part each capsule of `CAPSULE_NAMES` belongs to, (K,)."""
CAPSULE_PARTS.flags.writeable = False

_UNIT_BODY = Body.from_height(1.0)
ANKLE_TO_HEAD_FRACTION = _UNIT_BODY.thigh + _UNIT_BODY.shin + _UNIT_BODY.torso + _UNIT_BODY.neck
"""Ankle-to-head-joint length of a standing body as a fraction of its stature."""
ANKLE_HEIGHT_FRACTION = 0.039
"""Height of the ankle above the sole as a fraction of stature (Drillis & Contini)."""
HEAD_TOP_FRACTION = 1.0 - ANKLE_TO_HEAD_FRACTION - ANKLE_HEIGHT_FRACTION
"""Distance from the head joint to the top of the head as a fraction of stature."""
CHIN_FRACTION = 0.028
"""Distance from the chin up to the head joint as a fraction of stature."""
HAND_FRACTION = 0.09
"""Reach of the (slightly curled) hand past the wrist as a fraction of stature."""
HEEL_FRACTION = 0.045
"""Reach of the heel behind the ankle as a fraction of stature."""
TOE_FRACTION = 0.107
"""Reach of the toes in front of the ankle as a fraction of stature."""

ABDOMEN_SPAN = (0.12, 0.42)
"""Where the abdomen capsules' axes start and end, as fractions of the way along the
spine from the hip midpoint to the shoulder midpoint."""
CHEST_SPAN = (0.50, 0.80)
"""Where the chest capsules' axes start and end along the spine (as `ABDOMEN_SPAN`)."""
CHEST_ASPECT = 1.4
"""Chest breadth over chest depth."""
WAIST_ASPECT = 1.3
"""Waist breadth over waist depth."""

_HEIGHT_RANGE = (0.5, 2.5)
_CHEST_RANGE = (0.3, 2.0)
_HEIGHT_SCALE = 0.05
"""Height difference (m) that `for_subject` weighs like a `_CHEST_SCALE` chest difference."""
_CHEST_SCALE = 0.04


def _check_height(source: str, height: float) -> None:
    """`InputError` naming `source` unless `height` (m) is a plausible stature."""
    if not _HEIGHT_RANGE[0] <= height <= _HEIGHT_RANGE[1]:
        low, high = _HEIGHT_RANGE
        raise InputError(source, f"height {height} m is outside {low}..{high} m")


def checked_poses(poses: np.ndarray, source: str = "poses") -> np.ndarray:
    """Poses as a float64 (n, 13, 3) array in meters, checked.

    Raises `InputError` naming `source` when the shape is wrong or a pose holds NaN or
    infinity (naming the first such pose index).
    """
    array = np.asarray(poses, dtype=np.float64)
    if array.ndim != 3 or array.shape[1:] != (N_JOINTS, 3):
        raise InputError(source, f"poses must have shape (n, {N_JOINTS}, 3), got {array.shape}")
    finite = np.isfinite(array).all(axis=(1, 2))
    if not finite.all():
        bad = int(np.flatnonzero(~finite)[0])
        raise InputError(source, f"pose {bad} contains NaN or infinity")
    return array


def standing_heights(poses: np.ndarray) -> np.ndarray:
    """Stature (n,) in meters of the subject of each pose (n, 13, 3), from its segments.

    The ankle-to-head-joint chain (mean leg of both sides, hip midpoint to shoulder
    midpoint, shoulder midpoint to head) over `ANKLE_TO_HEAD_FRACTION`; independent of
    the posture, so a crouching pose gets its subject's standing height.
    """
    poses = checked_poses(poses)
    hip_mid = poses[:, [7, 8]].mean(axis=1)
    shoulder_mid = poses[:, [1, 2]].mean(axis=1)
    thighs = np.linalg.norm(poses[:, [9, 10]] - poses[:, [7, 8]], axis=-1).mean(axis=1)
    shins = np.linalg.norm(poses[:, [11, 12]] - poses[:, [9, 10]], axis=-1).mean(axis=1)
    spine = np.linalg.norm(shoulder_mid - hip_mid, axis=-1)
    neck = np.linalg.norm(poses[:, 0] - shoulder_mid, axis=-1)
    return (thighs + shins + spine + neck) / ANKLE_TO_HEAD_FRACTION


def scaled_to(poses: np.ndarray, height: float) -> np.ndarray:
    """Poses (n, 13, 3) in meters scaled so each subject's stature is `height` meters.

    Each pose is scaled about its hip midpoint on the floor (the hip midpoint's x and z,
    the lower ankle's y), so the lower ankle keeps its height and the body its place.
    """
    _check_height("height", height)
    poses = checked_poses(poses)
    heights = standing_heights(poses)
    if not heights.all():
        bad = int(np.flatnonzero(heights == 0.0)[0])
        raise InputError("poses", f"pose {bad} has no size: its legs, spine and neck are 0 m")
    factor = height / heights
    pivot = poses[:, [7, 8]].mean(axis=1)
    pivot[:, 1] = poses[:, [11, 12], 1].min(axis=1)
    return pivot[:, None] + factor[:, None, None] * (poses - pivot[:, None])


def _stadium_radius(girth: float, aspect: float) -> float:
    """Radius (m) of a stadium-shaped cross-section (two half circles joined by straight
    sides) of breadth over depth `aspect` and perimeter `girth` (m)."""
    return girth / (2.0 * aspect - 2.0 + np.pi) / 2.0


@dataclass(frozen=True)
class BodyModel:
    """One body size: stature, girths and the radius of every capsule, in meters.

    `kind` is one of `KINDS`; `chest`, `waist` and `hip` are girths (circumferences).
    Build one with `from_girths` (the radii follow from the girths) or take one from
    `catalog`, `named` or `for_subject`.
    """

    name: str
    kind: str
    height: float
    chest: float
    waist: float
    hip: float
    pelvis_radius: float
    abdomen_radius: float
    chest_radius: float
    shoulder_radius: float
    neck_radius: float
    head_radius: float
    upper_arm_radius: float
    forearm_radius: float
    thigh_radius: float
    shin_radius: float
    foot_radius: float

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise InputError(f"body model {self.name!r}", f"kind must be one of {KINDS}")
        _check_height(f"body model {self.name!r}", self.height)
        lengths = (self.chest, self.waist, self.hip, *self.capsule_radii)
        if not all(np.isfinite(v) and v > 0 for v in lengths):
            raise InputError(f"body model {self.name!r}", "girths and radii must be positive")

    @classmethod
    def from_girths(
        cls, name: str, kind: str, height: float, chest: float, waist: float, hip: float
    ) -> BodyModel:
        """A body of stature `height` with chest, waist and hip girths, all in meters.

        Trunk radii come from stadium-shaped cross-sections of the girths (breadth over
        depth `CHEST_ASPECT`, `WAIST_ASPECT`; the pelvis spans the hip joints of an
        average body of this height); limb, neck and head radii are typical fractions of
        the girths and the height, averaged along each limb (thigh to knee, calf to ankle).
        """
        chest_radius = _stadium_radius(chest, CHEST_ASPECT)
        abdomen_radius = _stadium_radius(waist, WAIST_ASPECT)
        hip_joints = Body.from_height(height).hip_width
        head_girth = min(0.57, 0.40 + 0.105 * height)
        return cls(
            name=name,
            kind=kind,
            height=height,
            chest=chest,
            waist=waist,
            hip=hip,
            pelvis_radius=(hip - 2.0 * hip_joints) / (2.0 * np.pi),
            abdomen_radius=abdomen_radius,
            chest_radius=chest_radius,
            shoulder_radius=0.032 * height,
            neck_radius=0.40 * chest / (2.0 * np.pi),
            head_radius=0.9 * head_girth / (2.0 * np.pi),
            upper_arm_radius=0.30 * chest / (2.0 * np.pi),
            forearm_radius=0.23 * chest / (2.0 * np.pi),
            thigh_radius=0.50 * hip / (2.0 * np.pi),
            shin_radius=0.32 * hip / (2.0 * np.pi),
            foot_radius=0.016 * height,
        )

    def scaled(self, factor: float) -> BodyModel:
        """This body `factor` (> 0) times as tall and as round: stature and girths scaled,
        the radii following from them (`from_girths`), named "NAME x FACTOR"."""
        girths = (self.height, self.chest, self.waist, self.hip)
        return BodyModel.from_girths(
            f"{self.name} x {factor:g}", self.kind, *(factor * v for v in girths)
        )

    @classmethod
    def catalog(cls) -> tuple[BodyModel, ...]:
        """Every body size: men's, then women's, then children's, each by rising height."""
        return _CATALOG

    @classmethod
    def named(cls, name: str) -> BodyModel:
        """The catalogue's body model called `name`; `InputError` listing the names if none."""
        for model in _CATALOG:
            if model.name == name:
                return model
        names = ", ".join(model.name for model in _CATALOG)
        raise InputError("body model", f"no body model named {name!r}; valid names: {names}")

    @classmethod
    def for_subject(
        cls, height: float, kind: str | None = None, chest: float | None = None
    ) -> BodyModel:
        """The catalogue's size nearest a subject of stature `height` m.

        `kind` (one of `KINDS`) restricts the choice; `chest` (girth, m) when known
        counts beside the height (5 cm of height weigh like 4 cm of chest). Ties go to
        the earlier entry of `catalog`.
        """
        _check_height("height", height)
        if kind is not None and kind not in KINDS:
            raise InputError("kind", f"unknown kind {kind!r}; valid kinds: {', '.join(KINDS)}")
        if chest is not None and not _CHEST_RANGE[0] <= chest <= _CHEST_RANGE[1]:
            raise InputError("chest", f"{chest} m is outside {_CHEST_RANGE[0]}..{_CHEST_RANGE[1]}")
        candidates = [m for m in _CATALOG if kind is None or m.kind == kind]
        cost = [((m.height - height) / _HEIGHT_SCALE) ** 2 for m in candidates]
        if chest is not None:
            cost = [
                c + ((m.chest - chest) / _CHEST_SCALE) ** 2
                for c, m in zip(cost, candidates, strict=True)
            ]
        return candidates[int(np.argmin(cost))]

    @property
    def capsule_radii(self) -> np.ndarray:
        """Radius (K,) in meters of each capsule of `CAPSULE_NAMES`."""
        return np.array([getattr(self, field) for _, _, field in _CAPSULES])

    @property
    def chest_spread(self) -> float:
        """Half the spacing (m) of the two chest capsules' axes, from the chest girth."""
        return max(0.0, (self.chest - 2.0 * np.pi * self.chest_radius) / 4.0)

    @property
    def abdomen_spread(self) -> float:
        """Half the spacing (m) of the two abdomen capsules' axes, from the waist girth."""
        return max(0.0, (self.waist - 2.0 * np.pi * self.abdomen_radius) / 4.0)

    def capsules(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The capsules of this body in poses (n, 13, 3), meters.

        Returns the axis starts (n, K, 3) and ends (n, K, 3) in meters, the radii (K,) in
        meters and the part (K,) int, an index in `PART_NAMES`, of each capsule of
        `CAPSULE_NAMES` (K = 18). Poses should have this model's stature (`scaled_to`).
        """
        j = checked_poses(poses)
        h = self.height
        hip_mid = j[:, [7, 8]].mean(axis=1)
        shoulder_mid = j[:, [1, 2]].mean(axis=1)
        spine = shoulder_mid - hip_mid
        across_shoulders = unit_vectors(j[:, 1] - j[:, 2])
        across_hips = unit_vectors(j[:, 7] - j[:, 8])
        up_neck = unit_vectors(j[:, 0] - shoulder_mid)
        crown = HEAD_TOP_FRACTION * h - self.head_radius
        chin = min(crown, self.head_radius - CHIN_FRACTION * h)
        axes = {
            "pelvis": (j[:, 7], j[:, 8]),
            "shoulders": (j[:, 1], j[:, 2]),
            "neck": (shoulder_mid, j[:, 0]),
            "head": (j[:, 0] + chin * up_neck, j[:, 0] + crown * up_neck),
        }
        for side, sign in (("l", 1.0), ("r", -1.0)):
            for trunk, span, across, spread in (
                ("abdomen", ABDOMEN_SPAN, across_hips, self.abdomen_spread),
                ("chest", CHEST_SPAN, across_shoulders, self.chest_spread),
            ):
                offset = sign * spread * across
                axes[f"{trunk}_{side}"] = tuple(hip_mid + f * spine + offset for f in span)
        for side, (shoulder, elbow, wrist, hip, knee, ankle) in (
            ("l", (1, 3, 5, 7, 9, 11)),
            ("r", (2, 4, 6, 8, 10, 12)),
        ):
            hand = (HAND_FRACTION * h - self.forearm_radius) * unit_vectors(
                j[:, wrist] - j[:, elbow]
            )
            up_shin = unit_vectors(j[:, knee] - j[:, ankle])
            forward = unit_vectors(np.cross(across_hips, up_shin))
            sole = j[:, ankle] - (ANKLE_HEIGHT_FRACTION * h - self.foot_radius) * up_shin
            axes[f"{side}_upper_arm"] = (j[:, shoulder], j[:, elbow])
            axes[f"{side}_forearm"] = (j[:, elbow], j[:, wrist] + hand)
            axes[f"{side}_thigh"] = (j[:, hip], j[:, knee])
            axes[f"{side}_shin"] = (j[:, knee], j[:, ankle])
            axes[f"{side}_foot"] = (
                sole - (HEEL_FRACTION * h - self.foot_radius) * forward,
                sole + (TOE_FRACTION * h - self.foot_radius) * forward,
            )
        starts = np.stack([axes[name][0] for name in CAPSULE_NAMES], axis=1)
        ends = np.stack([axes[name][1] for name in CAPSULE_NAMES], axis=1)
        return starts, ends, self.capsule_radii, CAPSULE_PARTS.copy()


_SIZES: tuple[tuple[str, str, float, float, float, float], ...] = (
    # name, kind, stature, chest, waist, hip (m): JIS L4004 men (A body type: the waist
    # 12 cm under the chest), L4005 women (A type, busts 80-96 cm), L4001 children.
    ("men-SS", "men", 1.60, 0.84, 0.72, 0.87),
    ("men-S", "men", 1.65, 0.88, 0.76, 0.90),
    ("men-M", "men", 1.70, 0.92, 0.80, 0.94),
    ("men-L", "men", 1.75, 0.96, 0.84, 0.97),
    ("men-LL", "men", 1.80, 1.00, 0.88, 1.00),
    ("men-3L", "men", 1.85, 1.04, 0.94, 1.04),
    ("women-P", "women", 1.50, 0.80, 0.61, 0.87),
    ("women-S", "women", 1.54, 0.80, 0.62, 0.88),
    ("women-M", "women", 1.58, 0.84, 0.65, 0.91),
    ("women-L", "women", 1.62, 0.90, 0.71, 0.95),
    ("women-T", "women", 1.66, 0.86, 0.67, 0.93),
    ("women-LL", "women", 1.70, 0.96, 0.78, 0.99),
    ("children-110", "children", 1.10, 0.56, 0.51, 0.59),
    ("children-120", "children", 1.20, 0.60, 0.53, 0.63),
    ("children-130", "children", 1.30, 0.64, 0.55, 0.68),
    ("children-140", "children", 1.40, 0.68, 0.57, 0.73),
    ("children-150", "children", 1.50, 0.74, 0.61, 0.80),
)

_CATALOG: tuple[BodyModel, ...] = tuple(BodyModel.from_girths(*size) for size in _SIZES)
