"""A user's humanoid avatar (glTF binary or JSON / VRM 0.x / VRM 1.0 / USD) as a
`HumanoidRig`.

Bones are found by the VRM humanoid table when the file has one (`VRMC_vrm` or `VRM`
extension), otherwise by node name (glTF) or the last path component of the joint
tokens (USD): Unity / VRM humanoid names ("LeftUpperArm", "leftUpperArm") or Mixamo
names ("mixamorig:LeftArm", "mixamorig_LeftArm"), compared without case, spaces,
underscores, a "namespace:" prefix and Mixamo's "mixamorig" prefix. Hips, Head and
both arms' and legs' three bones are required; Spine, Chest and Neck are placed on the
line from the hips to the middle of the shoulders where the avatar lacks them. The rest
pose is the file's node transforms (glTF) or the UsdSkel Skeleton's rest transforms,
else its bind transforms (USD: the first Skeleton that has every required bone), in
meters with +Y up; a model facing -Z (VRM 0.x) is turned to face +Z, as the
retargeting expects.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from samba.export.errors import ExportError
from samba.export.gltf_reader import node_rest_positions, read_gltf
from samba.export.humanoid import BONE_INDEX, BONE_NAMES, HumanoidRig

REQUIRED: tuple[str, ...] = tuple(
    name for name in BONE_NAMES if name not in ("Spine", "Chest", "Neck")
)

_ALIASES: dict[str, tuple[str, ...]] = {
    "Hips": ("hips", "pelvis"),
    "Spine": ("spine",),
    "Chest": ("chest", "spine1"),
    "Neck": ("neck",),
    "Head": ("head",),
    "LeftUpperArm": ("leftupperarm", "leftarm"),
    "LeftLowerArm": ("leftlowerarm", "leftforearm"),
    "LeftHand": ("lefthand",),
    "RightUpperArm": ("rightupperarm", "rightarm"),
    "RightLowerArm": ("rightlowerarm", "rightforearm"),
    "RightHand": ("righthand",),
    "LeftUpperLeg": ("leftupperleg", "leftupleg", "leftthigh"),
    "LeftLowerLeg": ("leftlowerleg", "leftleg", "leftshin"),
    "LeftFoot": ("leftfoot",),
    "RightUpperLeg": ("rightupperleg", "rightupleg", "rightthigh"),
    "RightLowerLeg": ("rightlowerleg", "rightleg", "rightshin"),
    "RightFoot": ("rightfoot",),
}
"""Humanoid bone -> node names that mean it, in the normalised form `_plain` gives."""


USD_SUFFIXES: tuple[str, ...] = (".usd", ".usda", ".usdc", ".usdz")
"""Suffixes (any letter case) of the avatars read as USD: `samba.export.usd_writer.SUFFIXES`,
spelt out so that reading a glTF avatar does not load usd-core."""

_MIXAMO_PREFIX = re.compile(r"^mixamorig\d*")
"""Mixamo's bone-name prefix, as `_plain` leaves it of an underscored name."""

MIN_BONE_M = 1e-3
"""Shortest bone (meters, rest pose) an avatar may have: a bone of zero length has no
direction to turn, and retargeting onto it divides by zero."""


def read_avatar_rig(path: str | Path) -> HumanoidRig:
    """The humanoid rig of the avatar file at `path`, rest pose (17, 3) in meters, +Y up,
    facing +Z. USD (.usd, .usda, .usdc, .usdz) by its suffix, any other file as glTF: binary
    (.glb, .vrm) or JSON (.gltf), told apart by content. Raises `ExportError` naming the
    file when it cannot be read or has no humanoid skeleton (listing the bones that are
    missing)."""
    is_usd = Path(path).suffix.lower() in USD_SUFFIXES
    return _rig(str(path), _usd_bones(path) if is_usd else _gltf_bones(path))


def _gltf_bones(path: str | Path) -> dict[str, np.ndarray]:
    """Humanoid bone name -> rest position (3,) in meters of a glTF / VRM avatar's bones."""
    file = read_gltf(path)
    try:
        nodes = _humanoid_nodes(file.doc)
        world = node_rest_positions(file)
    except (KeyError, IndexError, TypeError, ValueError, AttributeError) as exc:
        raise ExportError(file.source, f"malformed glTF: {type(exc).__name__}: {exc}") from exc
    return {name: world[node] for name, node in nodes.items()}


def _usd_bones(path: str | Path) -> dict[str, np.ndarray]:
    """Humanoid bone name -> rest position (3,) in meters, +Y up, of the first humanoid
    UsdSkel Skeleton of a USD avatar, its joints found by name; a Skeleton that cannot be
    posed is passed over when another one is humanoid."""
    from samba.export.usd_reader import read_usd_skeleton_rests  # pxr loads only for USD avatars

    skeletons = read_usd_skeleton_rests(path)
    reasons = []
    for skeleton in skeletons:
        if skeleton.problem is not None:
            reasons.append(skeleton.problem)
            continue
        bones = {name: skeleton.positions[i] for name, i in _named_bones(skeleton.names).items()}
        missing = _missing(bones)
        if not missing or len(skeletons) == 1:
            return bones  # `_rig` names the missing bones of a file's one skeleton
        reasons.append(f"{skeleton.path}: no {', '.join(missing)}")
    if len(skeletons) == 1:
        raise ExportError(str(path), reasons[0])
    raise ExportError(
        str(path),
        f"avatar has no humanoid skeleton: none of its {len(skeletons)} skeletons has every "
        f"bone ({'; '.join(reasons)})",
    )


def _rig(source: str, bones: dict[str, np.ndarray]) -> HumanoidRig:
    """The rig of an avatar's humanoid bones (name -> rest position (3,) in meters, +Y up):
    turned to face +Z, Spine, Chest and Neck filled in where absent, checked for missing,
    non-finite and zero-length bones (`ExportError` naming `source`)."""
    missing = _missing(bones)
    if missing:
        raise ExportError(
            source, f"avatar has no humanoid skeleton: no bone for {', '.join(missing)}"
        )
    rest = np.full((len(BONE_NAMES), 3), np.nan)
    for name, position in bones.items():
        rest[BONE_INDEX[name]] = position
    if rest[BONE_INDEX["LeftUpperArm"], 0] < rest[BONE_INDEX["RightUpperArm"], 0]:
        rest *= [-1.0, 1.0, -1.0]
    _fill_spine(rest)
    if not np.isfinite(rest).all():
        raise ExportError(source, "avatar skeleton has non-finite node transforms")
    rig = HumanoidRig(rest=rest, tips=_tips(rest), name=Path(source).stem)
    lengths = np.linalg.norm(rig.offsets[1:], axis=1)
    if (lengths < MIN_BONE_M).any():
        short = [BONE_NAMES[i + 1] for i in np.flatnonzero(lengths < MIN_BONE_M)]
        raise ExportError(
            source,
            f"avatar bones of (nearly) zero length: {', '.join(short)} (scaled to nothing?)",
        )
    return rig


def _missing(bones: dict[str, np.ndarray]) -> list[str]:
    """The required bones (`REQUIRED` order) that `bones` lacks."""
    return [name for name in REQUIRED if name not in bones]


def _humanoid_nodes(doc: dict[str, Any]) -> dict[str, int]:
    """Humanoid bone name -> node index, from the VRM table or the node names."""
    extensions = doc.get("extensions") or {}
    nodes = doc.get("nodes", [])
    by_vrm_name = {name[0].lower() + name[1:]: name for name in BONE_NAMES}
    if "VRMC_vrm" in extensions:
        bones = extensions["VRMC_vrm"].get("humanoid", {}).get("humanBones", {})
        pairs = [(key, value.get("node")) for key, value in bones.items()]
    elif "VRM" in extensions:
        bones = extensions["VRM"].get("humanoid", {}).get("humanBones", [])
        pairs = [(b.get("bone", ""), b.get("node")) for b in bones]
    else:
        return _named_bones([node.get("name", "") for node in nodes])
    wanted = [(key, node) for key, node in pairs if key in by_vrm_name]
    for key, node in wanted:
        if not (isinstance(node, int) and 0 <= node < len(nodes)):
            raise ValueError(f"the VRM humanoid table puts {key} on node {node!r} of {len(nodes)}")
    return {by_vrm_name[key]: node for key, node in wanted}


def _named_bones(names: Sequence[str]) -> dict[str, int]:
    """Humanoid bone name -> index of the first of `names` (node or joint names) that
    means it, by `_ALIASES`."""
    wanted = {alias: name for name, aliases in _ALIASES.items() for alias in aliases}
    found: dict[str, int] = {}
    for i, node_name in enumerate(names):
        name = wanted.get(_plain(node_name))
        if name and name not in found:
            found[name] = i
    return found


def _plain(name: str) -> str:
    """A node or joint name without a "namespace:" prefix, case, spaces, underscores and
    Mixamo's "mixamorig" prefix: Blender's USD export writes "mixamorig:Hips" as
    "mixamorig_Hips", and some Mixamo downloads number it ("mixamorig1:Hips")."""
    plain = name.rsplit(":", 1)[-1].replace("_", "").replace(" ", "").lower()
    return _MIXAMO_PREFIX.sub("", plain)


def _fill_spine(rest: np.ndarray) -> None:
    """Place missing Spine, Chest and Neck on the hips-to-shoulders line, in place."""
    hips = rest[BONE_INDEX["Hips"]]
    shoulders = (rest[BONE_INDEX["LeftUpperArm"]] + rest[BONE_INDEX["RightUpperArm"]]) / 2
    for name, share in (("Neck", 1.0), ("Spine", 0.25), ("Chest", 0.6)):
        if np.isnan(rest[BONE_INDEX[name]]).any():
            rest[BONE_INDEX[name]] = hips + share * (shoulders - hips)


def _tips(rest: np.ndarray) -> np.ndarray:
    """Leaf ends (head top, finger tips, toes) in proportion to the avatar's height."""
    height = (
        rest[BONE_INDEX["Head"], 1]
        - rest[[BONE_INDEX["LeftFoot"], BONE_INDEX["RightFoot"]], 1].mean()
    )
    height = max(height, 1e-3) / 0.86
    tips = [[0.0, 0.10 * height, 0.0]]
    for upper, hand in (("LeftLowerArm", "LeftHand"), ("RightLowerArm", "RightHand")):
        forearm = rest[BONE_INDEX[hand]] - rest[BONE_INDEX[upper]]
        tips.append(0.108 * height * forearm / max(np.linalg.norm(forearm), 1e-9))
    for foot in ("LeftFoot", "RightFoot"):
        ankle = max(rest[BONE_INDEX[foot], 1], 0.0)
        tips.append([0.0, -ankle, 0.11 * height])
    return np.array(tips)
