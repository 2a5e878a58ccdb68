"""Users' avatars (glTF / VRM) read as humanoid rigs, and takes retargeted onto them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from glb_edit import with_json

from export.avatar_file import read_avatar_rig
from export.errors import ExportError
from export.gltf_writer import write_glb
from export.humanoid import BONE_INDEX, BONE_NAMES, N_BONES, HumanoidRig
from export.motion import HumanoidMotion
from export.retarget import bone_direction_errors, retarget
from samba.skeleton import Body
from samba.synthetic import generate

AVATAR_RIG = HumanoidRig.from_body(Body.from_height(1.58).scaled({"thigh": 1.08}), 35.0)
MIXAMO = {
    "Hips": "mixamorig:Hips",
    "Spine": "mixamorig:Spine",
    "Chest": "mixamorig:Spine1",
    "Neck": "mixamorig:Neck",
    "Head": "mixamorig:Head",
    "LeftUpperArm": "mixamorig:LeftArm",
    "LeftLowerArm": "mixamorig:LeftForeArm",
    "LeftHand": "mixamorig:LeftHand",
    "RightUpperArm": "mixamorig:RightArm",
    "RightLowerArm": "mixamorig:RightForeArm",
    "RightHand": "mixamorig:RightHand",
    "LeftUpperLeg": "mixamorig:LeftUpLeg",
    "LeftLowerLeg": "mixamorig:LeftLeg",
    "LeftFoot": "mixamorig:LeftFoot",
    "RightUpperLeg": "mixamorig:RightUpLeg",
    "RightLowerLeg": "mixamorig:RightLeg",
    "RightFoot": "mixamorig:RightFoot",
}


@pytest.fixture
def avatar_glb(tmp_path: Path) -> bytes:
    """A skeleton-only .glb of `AVATAR_RIG` in its rest pose (node 0 is the Armature)."""
    still = HumanoidMotion(
        AVATAR_RIG, np.tile([0.0, 0.0, 0.0, 1.0], (1, N_BONES, 1)), AVATAR_RIG.rest[None, 0], 30
    )
    path = tmp_path / "source.glb"
    write_glb(path, still)
    return path.read_bytes()


def _saved(tmp_path: Path, data: bytes, name: str = "avatar.glb") -> Path:
    path = tmp_path / name
    path.write_bytes(data)
    return path


def test_humanoid_named_glb_gives_back_its_rest_pose(tmp_path: Path, avatar_glb: bytes) -> None:
    rig = read_avatar_rig(_saved(tmp_path, avatar_glb))
    np.testing.assert_allclose(rig.rest, AVATAR_RIG.rest, atol=1e-6)
    assert rig.name == "avatar"


def test_mixamo_names_in_centimetres_under_a_scaled_root(tmp_path: Path, avatar_glb: bytes) -> None:
    def mixamo(doc: dict) -> None:
        for node in doc["nodes"][1 : N_BONES + 1]:
            node["name"] = MIXAMO[node["name"]]
            node["translation"] = [100.0 * c for c in node["translation"]]
        doc["nodes"][0]["scale"] = [0.01, 0.01, 0.01]

    rig = read_avatar_rig(_saved(tmp_path, with_json(avatar_glb, mixamo)))
    np.testing.assert_allclose(rig.rest, AVATAR_RIG.rest, atol=1e-5)


def test_an_avatar_scaled_to_nothing_is_refused(tmp_path: Path, avatar_glb: bytes) -> None:
    def flattened(doc: dict) -> None:
        doc["nodes"][0]["scale"] = [0.0, 0.0, 0.0]  # every bone of zero length

    path = _saved(tmp_path, with_json(avatar_glb, flattened))
    with pytest.raises(ExportError, match="bones of \\(nearly\\) zero length: Spine") as caught:
        read_avatar_rig(path)
    assert str(path) in str(caught.value)


def test_vrm0_facing_minus_z_is_turned_to_face_plus_z(tmp_path: Path, avatar_glb: bytes) -> None:
    def vrm0(doc: dict) -> None:
        doc["nodes"][0]["rotation"] = [0.0, 1.0, 0.0, 0.0]  # 180 degrees about Y
        for i, node in enumerate(doc["nodes"][1 : N_BONES + 1], start=1):
            node["name"] = f"J_Bip_{i}"
        human = [
            {"bone": name[0].lower() + name[1:], "node": BONE_INDEX[name] + 1}
            for name in BONE_NAMES
        ]
        doc["extensions"] = {"VRM": {"humanoid": {"humanBones": human}}}

    rig = read_avatar_rig(_saved(tmp_path, with_json(avatar_glb, vrm0), "avatar.vrm"))
    np.testing.assert_allclose(rig.rest, AVATAR_RIG.rest, atol=1e-6)


def test_vrm1_table_and_optional_bones_filled_in(tmp_path: Path, avatar_glb: bytes) -> None:
    def vrm1(doc: dict) -> None:
        for i, node in enumerate(doc["nodes"][1 : N_BONES + 1], start=1):
            node["name"] = f"bone{i}"
        human = {
            name[0].lower() + name[1:]: {"node": BONE_INDEX[name] + 1}
            for name in BONE_NAMES
            if name not in ("Chest", "Neck")
        }
        doc["extensions"] = {"VRMC_vrm": {"humanoid": {"humanBones": human}}}

    rig = read_avatar_rig(_saved(tmp_path, with_json(avatar_glb, vrm1)))
    shoulders = (AVATAR_RIG.rest[BONE_INDEX["LeftUpperArm"]] + AVATAR_RIG.rest[8]) / 2
    np.testing.assert_allclose(rig.rest[BONE_INDEX["Neck"]], shoulders, atol=1e-6)
    hips = AVATAR_RIG.rest[0]
    np.testing.assert_allclose(rig.rest[BONE_INDEX["Chest"]], hips + 0.6 * (shoulders - hips))


def test_a_vrm_table_naming_a_missing_node_says_which(tmp_path: Path, avatar_glb: bytes) -> None:
    def bad_hips(doc: dict) -> None:
        doc["extensions"] = {"VRMC_vrm": {"humanoid": {"humanBones": {"hips": {"node": 9999}}}}}

    with pytest.raises(ExportError, match="puts hips on node 9999 of"):
        read_avatar_rig(_saved(tmp_path, with_json(avatar_glb, bad_hips)))


def test_a_take_on_the_avatar_keeps_directions_and_the_avatars_proportions(
    tmp_path: Path, avatar_glb: bytes
) -> None:
    rig = read_avatar_rig(_saved(tmp_path, avatar_glb))
    take = generate("jumping_jacks", seed=2, seconds=2.0)
    positions = retarget(take.poses, rig, take.fps).world_positions()
    assert bone_direction_errors(positions, take.poses).max() < 1.0
    thigh = np.linalg.norm(positions[:, 12] - positions[:, 11], axis=-1)
    np.testing.assert_allclose(thigh, np.linalg.norm(rig.rest[12] - rig.rest[11]), atol=1e-9)


def test_an_avatar_without_a_humanoid_skeleton_names_the_missing_bones(
    tmp_path: Path, avatar_glb: bytes
) -> None:
    def rename(doc: dict) -> None:
        for node in doc["nodes"]:
            if node.get("name", "").startswith("Left"):
                node["name"] = "bone_" + node["name"][4:]

    path = _saved(tmp_path, with_json(avatar_glb, rename))
    with pytest.raises(ExportError, match="no humanoid skeleton: no bone for LeftUpperArm") as e:
        read_avatar_rig(path)
    assert e.value.source == str(path)


@pytest.mark.parametrize(
    "content", [b"", b"solid cube\nendsolid\n", b"glTF\x02\x00\x00\x00garbage"]
)
def test_unreadable_avatars_are_named(tmp_path: Path, content: bytes) -> None:
    path = _saved(tmp_path, content)
    with pytest.raises(ExportError) as e:
        read_avatar_rig(path)
    assert e.value.source == str(path)
    if not content.startswith(b"glTF"):
        assert "avatars are read from .glb or .vrm files" in e.value.problem
    with pytest.raises(ExportError, match="cannot read"):
        read_avatar_rig(tmp_path / "missing.vrm")
