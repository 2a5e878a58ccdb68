"""Rig maps: which joint of a foreign skeleton is each of Samba's 13 joints.

Built-in maps cover the three rigs of the shared CMU data (cgspeed "3ds Max" names,
Character Creator / iClone `CC_Base_*`, Daz/Poser `hip/abdomen/lThigh`) and the other
rigs users commonly bring (cgspeed "MotionBuilder" names, Mixamo `mixamorig:*`,
Unity / VRM humanoid names). Names match case-insensitively after dropping a namespace
prefix such as `mixamorig:`. Any other rig is mapped by the humanoid resolver
(`samba.ingest.resolver`: names and tree together), recorded as rig "detected"; where
that fails, or to override it, by a TOML file:

    name = "my-rig"            # optional
    [joints]
    head = "Head"
    l_shoulder = "L_UpperArm"
    ...                        # all 13 joints of samba.body.skeleton.JOINT_NAMES
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import tomli_w

from samba.body import JOINT_NAMES
from samba.ingest.errors import RigError
from samba.ingest.name_maps import read_name_map
from samba.ingest.resolver import SkeletonTree, resolve_humanoid

DETECTED = "detected"
"""The rig name of a skeleton the resolver mapped."""


@dataclass(frozen=True)
class RigMap:
    """A named map from the 13 joints (in skeleton order) to accepted foreign joint names.

    `joints[i]` lists the names accepted for joint i, best first.
    """

    name: str
    joints: tuple[tuple[str, ...], ...]

    def resolve(self, names: tuple[str, ...]) -> tuple[list[int], list[str]]:
        """Indices into `names` of the 13 joints, and the joints that could not be found."""
        lookup: dict[str, int] = {}
        for i, n in enumerate(names):
            lookup.setdefault(_plain(n), i)
        found, missing = [], []
        for ours, candidates in zip(JOINT_NAMES, self.joints, strict=True):
            hit = next((lookup[_plain(c)] for c in candidates if _plain(c) in lookup), None)
            if hit is None:
                missing.append(f"{ours} (looked for {' / '.join(candidates)})")
            else:
                found.append(hit)
        return found, missing

    def toml(self) -> str:
        """The map as the TOML mapping file `from_toml` reads (and `--map` takes)."""
        joints = {
            ours: names[0] if len(names) == 1 else list(names)
            for ours, names in zip(JOINT_NAMES, self.joints, strict=True)
        }
        return tomli_w.dumps({"name": self.name, "joints": joints})

    @classmethod
    def from_toml(cls, path: str | Path) -> RigMap:
        """Read a user mapping file; raises `RigError` naming the file and the problem."""
        name, joints = read_name_map(path, "joints", JOINT_NAMES, "name", RigError)
        return cls(name=name, joints=joints)


def _plain(name: str) -> str:
    return name.rsplit(":", 1)[-1].replace(" ", "").replace("_", "").lower()


def _rig(name: str, head: str, pairs: list[tuple[str, str]]) -> RigMap:
    """A rig from the head name and (left, right) names, shoulder to foot; '|' separates options."""
    joints: list[tuple[str, ...]] = [tuple(head.split("|"))]
    for left, right in pairs:
        joints.append(tuple(left.split("|")))
        joints.append(tuple(right.split("|")))
    return RigMap(name=name, joints=tuple(joints))


BUILTIN_RIGS: tuple[RigMap, ...] = (
    _rig(
        "cmu-max",
        "Head",
        [
            ("LeftShoulder", "RightShoulder"),
            ("LeftElbow", "RightElbow"),
            ("LeftWrist", "RightWrist"),
            ("LeftHip", "RightHip"),
            ("LeftKnee", "RightKnee"),
            ("LeftAnkle", "RightAnkle"),
        ],
    ),
    _rig(
        "iclone",
        "CC_Base_Head",
        [
            ("CC_Base_L_Upperarm", "CC_Base_R_Upperarm"),
            ("CC_Base_L_Forearm", "CC_Base_R_Forearm"),
            ("CC_Base_L_Hand", "CC_Base_R_Hand"),
            ("CC_Base_L_Thigh", "CC_Base_R_Thigh"),
            ("CC_Base_L_Calf", "CC_Base_R_Calf"),
            ("CC_Base_L_Foot", "CC_Base_R_Foot"),
        ],
    ),
    _rig(
        "daz",
        "head",
        [
            ("lShldr|lShldrBend", "rShldr|rShldrBend"),
            ("lForeArm|lForearmBend", "rForeArm|rForearmBend"),
            ("lHand", "rHand"),
            ("lThigh|lThighBend", "rThigh|rThighBend"),
            ("lShin", "rShin"),
            ("lFoot", "rFoot"),
        ],
    ),
    _rig(
        "mixamo",
        "mixamorig:Head",
        [
            ("mixamorig:LeftArm", "mixamorig:RightArm"),
            ("mixamorig:LeftForeArm", "mixamorig:RightForeArm"),
            ("mixamorig:LeftHand", "mixamorig:RightHand"),
            ("mixamorig:LeftUpLeg", "mixamorig:RightUpLeg"),
            ("mixamorig:LeftLeg", "mixamorig:RightLeg"),
            ("mixamorig:LeftFoot", "mixamorig:RightFoot"),
        ],
    ),
    _rig(
        "motionbuilder",
        "Head",
        [
            ("LeftArm", "RightArm"),
            ("LeftForeArm", "RightForeArm"),
            ("LeftHand", "RightHand"),
            ("LeftUpLeg", "RightUpLeg"),
            ("LeftLeg", "RightLeg"),
            ("LeftFoot", "RightFoot"),
        ],
    ),
    _rig(
        "humanoid",
        "Head",
        [
            ("LeftUpperArm", "RightUpperArm"),
            ("LeftLowerArm", "RightLowerArm"),
            ("LeftHand", "RightHand"),
            ("LeftUpperLeg", "RightUpperLeg"),
            ("LeftLowerLeg", "RightLowerLeg"),
            ("LeftFoot", "RightFoot"),
        ],
    ),
)
"""Built-in rigs, tried in this order by `detect_rig`."""


def rig_by_name(name: str) -> RigMap:
    """A built-in rig by its name; raises `RigError` listing the known names."""
    for rig in BUILTIN_RIGS:
        if rig.name == name:
            return rig
    known = ", ".join(r.name for r in BUILTIN_RIGS)
    raise RigError("--rig", f"unknown rig {name!r}; built-in rigs are {known}")


def detect_rig(
    names: tuple[str, ...], source: str, skeleton: Callable[[], SkeletonTree]
) -> tuple[RigMap, list[int]]:
    """The rig of a skeleton with joint `names` and the indices of its 13 joints: the first
    built-in rig that maps all 13 by name, else the humanoid resolver's mapping of the
    tree `skeleton()` gives (rig `DETECTED`; the tree is only built then).

    Mixamo is only chosen when the names carry the `mixamorig` prefix, since after the
    prefix its names equal MotionBuilder's. Raises `RigError` naming `source` and what
    the resolver could not place.
    """
    mixamo = any(n.lower().startswith("mixamorig") for n in names)
    for rig in BUILTIN_RIGS:
        if (rig.name == "mixamo") != mixamo and rig.name in ("mixamo", "motionbuilder"):
            continue
        found, missing = rig.resolve(names)
        if not missing:
            return rig, found
    tree = skeleton()
    try:
        joints = resolve_humanoid(tree, source).capture_joints
    except RigError as exc:
        raise RigError(
            source, f"unknown rig: {exc.problem}; pass a mapping file with --map"
        ) from None
    return rig_of(tree, joints, DETECTED), joints


def rig_of(tree: SkeletonTree, joints: list[int], name: str) -> RigMap:
    """The `RigMap` named `name` that maps the 13 joints to `tree`'s joints `joints`."""
    return RigMap(name=name, joints=tuple((tree.names[j],) for j in joints))


def map_rig(
    names: tuple[str, ...],
    source: str,
    skeleton: Callable[[], SkeletonTree],
    rig: RigMap | None = None,
) -> tuple[RigMap, list[int]]:
    """Indices into `names` of the 13 joints, by `rig` when given (a user's map wins over
    detection), else by `detect_rig`."""
    if rig is None:
        return detect_rig(names, source, skeleton)
    found, missing = rig.resolve(names)
    if missing:
        raise RigError(source, f"rig {rig.name!r} cannot map: {'; '.join(missing)}")
    return rig, found
