"""A user's humanoid avatar (glTF binary / VRM 0.x / VRM 1.0) as a `HumanoidRig`.

Bones are found by the VRM humanoid table when the file has one (`VRMC_vrm` or `VRM`
extension), otherwise by node name: Unity / VRM humanoid names ("LeftUpperArm",
"leftUpperArm") or Mixamo names ("mixamorig:LeftArm"), compared without case, spaces,
underscores and a "namespace:" prefix. Hips, Head and both arms' and legs' three bones
are required; Spine, Chest and Neck are placed on the line from the hips to the middle of
the shoulders where the avatar lacks them. The rest pose is the file's node transforms;
a model facing -Z (VRM 0.x) is turned to face +Z, as the retargeting expects.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from export.errors import ExportError
from export.gltf_reader import node_rest_positions, read_glb
from export.humanoid import BONE_INDEX, BONE_NAMES, HumanoidRig

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


MIN_BONE_M = 1e-3
"""Shortest bone (meters, rest pose) an avatar may have: a bone of zero length has no
direction to turn, and retargeting onto it divides by zero."""


def read_avatar_rig(path: str | Path) -> HumanoidRig:
    """The humanoid rig of the avatar file at `path` (.glb or .vrm), rest pose in meters
    facing +Z. Raises `ExportError` naming the file when it cannot be read or has no
    humanoid skeleton (listing the bones that are missing)."""
    file = read_glb(path)
    try:
        nodes = _humanoid_nodes(file.doc)
        world = node_rest_positions(file)
    except (KeyError, IndexError, TypeError, ValueError, AttributeError) as exc:
        raise ExportError(file.source, f"malformed glTF: {type(exc).__name__}: {exc}") from exc
    missing = [name for name in REQUIRED if name not in nodes]
    if missing:
        raise ExportError(
            file.source, f"avatar has no humanoid skeleton: no bone for {', '.join(missing)}"
        )
    rest = np.full((len(BONE_NAMES), 3), np.nan)
    for name, node in nodes.items():
        rest[BONE_INDEX[name]] = world[node]
    if rest[BONE_INDEX["LeftUpperArm"], 0] < rest[BONE_INDEX["RightUpperArm"], 0]:
        rest *= [-1.0, 1.0, -1.0]
    _fill_spine(rest)
    if not np.isfinite(rest).all():
        raise ExportError(file.source, "avatar skeleton has non-finite node transforms")
    rig = HumanoidRig(rest=rest, tips=_tips(rest), name=Path(file.source).stem)
    lengths = np.linalg.norm(rig.offsets[1:], axis=1)
    if (lengths < MIN_BONE_M).any():
        short = [BONE_NAMES[i + 1] for i in np.flatnonzero(lengths < MIN_BONE_M)]
        raise ExportError(
            file.source,
            f"avatar bones of (nearly) zero length: {', '.join(short)} (scaled to nothing?)",
        )
    return rig


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
        wanted = {alias: name for name, aliases in _ALIASES.items() for alias in aliases}
        found: dict[str, int] = {}
        for i, node in enumerate(nodes):
            name = wanted.get(_plain(node.get("name", "")))
            if name and name not in found:
                found[name] = i
        return found
    wanted = [(key, node) for key, node in pairs if key in by_vrm_name]
    for key, node in wanted:
        if not (isinstance(node, int) and 0 <= node < len(nodes)):
            raise ValueError(f"the VRM humanoid table puts {key} on node {node!r} of {len(nodes)}")
    return {by_vrm_name[key]: node for key, node in wanted}


def _plain(name: str) -> str:
    return name.rsplit(":", 1)[-1].replace("_", "").replace(" ", "").lower()


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
