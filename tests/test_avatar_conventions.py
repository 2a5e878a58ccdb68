"""Any humanoid avatar drives: avatars named after Unity / VRM, Mixamo, Blender, Unreal
and Character Creator are read by the humanoid resolver, and on each a planted foot of
the source walk stays on the floor wherever the avatar's Hips joint sits."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from glb_edit import with_json

from samba.export.avatar_file import read_avatar_rig
from samba.export.gltf_writer import write_glb
from samba.export.humanoid import BONE_INDEX, BONE_NAMES, N_BONES, HumanoidRig
from samba.export.live_retarget import LiveRetarget
from samba.export.motion import HumanoidMotion
from samba.export.retargeting import leg_length, retarget
from samba.synthetic.motions import generate

_SIDED = ("UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot")
NAMES: dict[str, dict[str, str]] = {
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
HIPS_ABOVE_LEGS = (-0.07, 0.0, 0.08, 0.25)


def _avatar(tmp_path: Path, convention: str, hips_dy: float) -> tuple[Path, HumanoidRig]:
    """A skeleton-only .glb of the mannequin with its Hips joint `hips_dy` meters above
    its leg joints, its nodes named after `convention`."""
    mannequin = HumanoidRig.from_body()
    rest = mannequin.rest.copy()
    legs = rest[[BONE_INDEX["LeftUpperLeg"], BONE_INDEX["RightUpperLeg"]]].mean(axis=0)
    rest[BONE_INDEX["Hips"]] = legs + np.array([0.0, hips_dy, 0.0])
    rig = HumanoidRig(rest=rest, tips=mannequin.tips)
    source = tmp_path / "unity.glb"
    write_glb(
        source, HumanoidMotion(rig, np.tile([0.0, 0.0, 0.0, 1.0], (1, N_BONES, 1)), rest[:1], 30.0)
    )

    def rename(doc: dict) -> None:
        for node in doc["nodes"]:
            node["name"] = NAMES[convention].get(node.get("name"), node.get("name"))

    path = tmp_path / f"{convention.replace(' ', '_')}.glb"
    path.write_bytes(with_json(source.read_bytes(), rename))
    return path, rig


@pytest.mark.parametrize("convention", list(NAMES))
def test_every_convention_drives_with_its_feet_on_the_floor(
    convention: str, tmp_path: Path
) -> None:
    take = generate("walk", seed=2, seconds=4.0)
    planted = take.poses[:, [11, 12], 1] < 0.001  # the synthetic walk plants at y = 0
    for hips_dy in HIPS_ABOVE_LEGS:
        path, built = _avatar(tmp_path, convention, hips_dy)
        rig = read_avatar_rig(path)
        np.testing.assert_allclose(rig.rest, built.rest, atol=1e-6)
        offline = retarget(take.poses, rig, take.fps)
        live = LiveRetarget(rig, leg_length=leg_length(take.poses))
        roots = np.stack([live.step(pose)[1] for pose in take.poses])
        for root in (offline.root, roots):
            motion = HumanoidMotion(rig, offline.rotations, root, take.fps)
            feet = motion.world_positions()[:, [BONE_INDEX["LeftFoot"], BONE_INDEX["RightFoot"]]]
            assert np.abs(feet[..., 1][planted] - rig.ankle_height).max() < 0.01, hips_dy
