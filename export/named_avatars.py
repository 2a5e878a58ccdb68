"""Skeleton-only avatars named as other tools name their bones: the mannequin's skeleton
as a .glb whose joints carry Unity / VRM, Mixamo, Blender, Unreal or Character Creator
names, its Hips joint where asked. The avatar tests drive them, and `samba examples`
writes an Unreal one (`ue_avatar.glb`) for the export examples.
"""

from __future__ import annotations

import json
import os
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from samba.base import write_bytes_atomic
from samba.export.gltf_writer import write_glb
from samba.export.humanoid import BONE_INDEX, BONE_NAMES, N_BONES, HumanoidRig
from samba.export.motion import HumanoidMotion

_SIDED = ("UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot")
AVATAR_CONVENTIONS: dict[str, dict[str, str]] = {
    "unity": {name: name for name in BONE_NAMES},
    "mixamo": {
        "Hips": "mixamorig:Hips",
        "Spine": "mixamorig:Spine",
        "Chest": "mixamorig:Spine1",
        "Neck": "mixamorig:Neck",
        "Head": "mixamorig:Head",
    }
    | {
        f"{s}{b}": f"mixamorig:{s}{m}"
        for s in ("Left", "Right")
        for b, m in zip(_SIDED, ("Arm", "ForeArm", "Hand", "UpLeg", "Leg", "Foot"), strict=True)
    },
    "blender": {"Hips": "hips", "Spine": "spine", "Chest": "chest", "Neck": "neck", "Head": "head"}
    | {
        f"{s}{b}": f"{m}.{s[0]}"
        for s in ("Left", "Right")
        for b, m in zip(
            _SIDED, ("upper_arm", "forearm", "hand", "thigh", "shin", "foot"), strict=True
        )
    },
    "unreal": {
        "Hips": "pelvis",
        "Spine": "spine_01",
        "Chest": "spine_02",
        "Neck": "neck_01",
        "Head": "head",
    }
    | {
        f"{s}{b}": f"{m}_{s[0].lower()}"
        for s in ("Left", "Right")
        for b, m in zip(
            _SIDED, ("upperarm", "lowerarm", "hand", "thigh", "calf", "foot"), strict=True
        )
    },
    "character creator": {
        "Hips": "CC_Base_Pelvis",
        "Spine": "CC_Base_Waist",
        "Chest": "CC_Base_Spine01",
        "Neck": "CC_Base_NeckTwist01",
        "Head": "CC_Base_Head",
    }
    | {
        f"{s}{b}": f"CC_Base_{s[0]}_{m}"
        for s in ("Left", "Right")
        for b, m in zip(
            _SIDED, ("Upperarm", "Forearm", "Hand", "Thigh", "Calf", "Foot"), strict=True
        )
    },
}
"""Each convention's name of each humanoid bone."""


def glb_with_json(glb: bytes, edit: Callable[[dict[str, Any]], None]) -> bytes:
    """The .glb `glb` (its bytes) with its JSON chunk `edit`ed in place (the binary chunk
    kept as it is)."""
    size = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20 : 20 + size])
    edit(doc)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    rest = glb[20 + size :]
    head = struct.pack("<4sII", b"glTF", 2, 20 + len(text) + len(rest))
    return head + struct.pack("<I4s", len(text), b"JSON") + text + rest


def write_named_avatar(
    path: str | os.PathLike[str], convention: str, hips_above_legs: float = 0.0
) -> HumanoidRig:
    """Write a skeleton-only .glb of the mannequin at `path`, its joints named after
    `convention` (a key of `AVATAR_CONVENTIONS`) and its Hips joint `hips_above_legs`
    meters above the middle of its upper-leg joints; returns the rig written (rest
    positions in meters)."""
    mannequin = HumanoidRig.from_body()
    rest = mannequin.rest.copy()
    legs = rest[[BONE_INDEX["LeftUpperLeg"], BONE_INDEX["RightUpperLeg"]]].mean(axis=0)
    rest[BONE_INDEX["Hips"]] = legs + np.array([0.0, hips_above_legs, 0.0])
    rig = HumanoidRig(rest=rest, tips=mannequin.tips)
    still = np.tile([0.0, 0.0, 0.0, 1.0], (1, N_BONES, 1))
    write_glb(path, HumanoidMotion(rig, still, rest[:1], 30.0))
    names = AVATAR_CONVENTIONS[convention]

    def rename(doc: dict[str, Any]) -> None:
        for node in doc["nodes"]:
            node["name"] = names.get(node.get("name"), node.get("name"))

    write_bytes_atomic(path, glb_with_json(Path(path).read_bytes(), rename))
    return rig
