"""Users' avatars (glTF binary and JSON / VRM / USD) read as humanoid rigs, and takes
retargeted onto them."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from glb_edit import write_gltf
from pxr import Usd, UsdGeom, UsdSkel, Vt

from samba.body.skeleton import Body
from samba.export import glb_with_json, usd_writer
from samba.export.avatar_file import USD_SUFFIXES, read_avatar_rig
from samba.export.errors import ExportError
from samba.export.gltf_writer import write_glb
from samba.export.humanoid import BONE_INDEX, BONE_NAMES, N_BONES, HumanoidRig
from samba.export.motion import HumanoidMotion
from samba.export.retargeting import bone_direction_errors, retarget
from samba.export.usd_writer import joint_tokens, write_usd
from samba.synthetic.motions import generate

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


AVATAR_STILL = HumanoidMotion(
    AVATAR_RIG, np.tile([0.0, 0.0, 0.0, 1.0], (1, N_BONES, 1)), AVATAR_RIG.rest[None, 0], 30
)
"""`AVATAR_RIG` standing in its rest pose for one frame."""


@pytest.fixture
def avatar_glb(tmp_path: Path) -> bytes:
    """A skeleton-only .glb of `AVATAR_RIG` in its rest pose (node 0 is the Armature)."""
    path = tmp_path / "source.glb"
    write_glb(path, AVATAR_STILL)
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

    rig = read_avatar_rig(_saved(tmp_path, glb_with_json(avatar_glb, mixamo)))
    np.testing.assert_allclose(rig.rest, AVATAR_RIG.rest, atol=1e-5)


def test_an_avatar_scaled_to_nothing_is_refused(tmp_path: Path, avatar_glb: bytes) -> None:
    def flattened(doc: dict) -> None:
        doc["nodes"][0]["scale"] = [0.0, 0.0, 0.0]  # every bone of zero length

    path = _saved(tmp_path, glb_with_json(avatar_glb, flattened))
    with pytest.raises(ExportError, match="joints all stand at one point") as caught:
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

    rig = read_avatar_rig(_saved(tmp_path, glb_with_json(avatar_glb, vrm0), "avatar.vrm"))
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

    rig = read_avatar_rig(_saved(tmp_path, glb_with_json(avatar_glb, vrm1)))
    shoulders = (AVATAR_RIG.rest[BONE_INDEX["LeftUpperArm"]] + AVATAR_RIG.rest[8]) / 2
    np.testing.assert_allclose(rig.rest[BONE_INDEX["Neck"]], shoulders, atol=1e-6)
    hips = AVATAR_RIG.rest[0]
    np.testing.assert_allclose(rig.rest[BONE_INDEX["Chest"]], hips + 0.6 * (shoulders - hips))


def test_a_vrm_table_naming_a_missing_node_says_which(tmp_path: Path, avatar_glb: bytes) -> None:
    def bad_hips(doc: dict) -> None:
        doc["extensions"] = {"VRMC_vrm": {"humanoid": {"humanBones": {"hips": {"node": 9999}}}}}

    with pytest.raises(ExportError, match="puts hips on node 9999 of"):
        read_avatar_rig(_saved(tmp_path, glb_with_json(avatar_glb, bad_hips)))


def test_a_take_on_the_avatar_keeps_directions_and_the_avatars_proportions(
    tmp_path: Path, avatar_glb: bytes
) -> None:
    rig = read_avatar_rig(_saved(tmp_path, avatar_glb))
    take = generate("jumping_jacks", seed=2, seconds=2.0)
    positions = retarget(take.poses, rig, take.fps).world_positions()
    assert bone_direction_errors(positions, take.poses).max() < 1.0
    thigh = np.linalg.norm(positions[:, 12] - positions[:, 11], axis=-1)
    np.testing.assert_allclose(thigh, np.linalg.norm(rig.rest[12] - rig.rest[11]), atol=1e-9)


def test_an_avatar_whose_left_bones_no_name_says_is_read_by_its_structure(
    tmp_path: Path, avatar_glb: bytes
) -> None:
    """ "LeftUpperArm" renamed "bone_UpperArm" (no side in the name): the resolver places
    the left limbs by the tree, opposite the named right ones, and the rig is the same."""

    def rename(doc: dict) -> None:
        for node in doc["nodes"]:
            if node.get("name", "").startswith("Left"):
                node["name"] = "bone_" + node["name"][4:]

    path = _saved(tmp_path, glb_with_json(avatar_glb, rename))
    np.testing.assert_allclose(read_avatar_rig(path).rest, AVATAR_RIG.rest, atol=1e-6)


def test_an_avatar_that_is_no_humanoid_is_refused_saying_why(
    tmp_path: Path, avatar_glb: bytes
) -> None:
    def legs_forward(doc: dict) -> None:  # legs held out along the spine: no humanoid
        for node in doc["nodes"]:
            if node.get("name") in ("LeftUpperLeg", "RightUpperLeg"):
                node["rotation"] = [-0.9238795, 0.0, 0.0, 0.3826834]  # 135 degrees about -X

    path = _saved(tmp_path, glb_with_json(avatar_glb, legs_forward))
    with pytest.raises(ExportError) as e:
        read_avatar_rig(path)
    assert e.value.source == str(path)
    assert e.value.problem.startswith("avatar has no humanoid skeleton: the left leg does not")


@pytest.mark.parametrize(
    "content", [b"", b"solid cube\nendsolid\n", b"glTF\x02\x00\x00\x00garbage"]
)
def test_unreadable_avatars_are_named(tmp_path: Path, content: bytes) -> None:
    path = _saved(tmp_path, content)
    with pytest.raises(ExportError) as e:
        read_avatar_rig(path)
    assert e.value.source == str(path)
    if not content.startswith(b"glTF"):
        assert "avatars are read from .glb, .vrm, .gltf, .usd, .usda, .usdc or .usdz files" in str(
            e.value
        )
    with pytest.raises(ExportError, match="cannot read"):
        read_avatar_rig(tmp_path / "missing.vrm")


@pytest.mark.parametrize("bin_name", ["avatar.bin", "my avatar.bin", None])
def test_json_gltf_with_a_bin_file_or_a_data_uri_gives_the_glbs_rig(
    tmp_path: Path, avatar_glb: bytes, bin_name: str | None
) -> None:
    glb_rig = read_avatar_rig(_saved(tmp_path, avatar_glb))
    path = tmp_path / "avatar.gltf"
    write_gltf(avatar_glb, path, bin_name)
    if bin_name == "my avatar.bin":  # glTF URIs are percent-encoded
        path.write_text(path.read_text().replace('"my avatar.bin"', '"my%20avatar.bin"'))
    rig = read_avatar_rig(path)
    assert np.allclose(rig.rest, glb_rig.rest) and np.allclose(rig.tips, glb_rig.tips)
    np.testing.assert_allclose(rig.rest, AVATAR_RIG.rest, atol=1e-6)


def test_json_gltf_problems_name_the_file_and_the_buffer(tmp_path: Path, avatar_glb: bytes) -> None:
    gltf = tmp_path / "avatar.gltf"
    write_gltf(avatar_glb, gltf, "avatar.bin")
    doc = json.loads(gltf.read_text())
    length = doc["buffers"][0]["byteLength"]

    def variant(name: str, edit: Callable[[dict], None]) -> Path:
        changed = json.loads(gltf.read_text())
        edit(changed)
        path = tmp_path / name
        path.write_text(json.dumps(changed))
        return path

    (tmp_path / "short.bin").write_bytes((tmp_path / "avatar.bin").read_bytes()[: length // 2])
    (tmp_path / "broken.gltf").write_text(gltf.read_text()[:-40])
    problems = {
        variant("no_bin.gltf", lambda d: d["buffers"][0].update(uri="gone.bin")): (
            f"buffer 0: cannot read its file {tmp_path / 'gone.bin'}: No such file"
        ),
        variant("short.gltf", lambda d: d["buffers"][0].update(uri="short.bin")): (
            f"buffer 0 is too short: 'short.bin' holds {length // 2} bytes, "
            f"its byteLength says {length}"
        ),
        variant(
            "base64.gltf",
            lambda d: d["buffers"][0].update(uri="data:application/octet-stream;base64,AB*C"),
        ): "buffer 0: bad base64 in its data URI",
        variant("web.gltf", lambda d: d["buffers"][0].update(uri="https://example.com/a.bin")): (
            "only relative file names and data: URIs are supported"
        ),
        variant("no_uri.gltf", lambda d: d["buffers"][0].pop("uri")): (
            "buffer 0 has no uri and there is no binary chunk"
        ),
        tmp_path / "broken.gltf": "the file is not valid JSON",
    }
    for path, problem in problems.items():
        with pytest.raises(ExportError) as raised:
            read_avatar_rig(path)
        assert raised.value.source == str(path)
        assert problem in raised.value.problem


def test_a_usd_avatar_from_our_writer_gives_back_its_rig(tmp_path: Path) -> None:
    path = tmp_path / "avatar.usda"
    write_usd(path, AVATAR_STILL)
    rig = read_avatar_rig(path)
    np.testing.assert_allclose(rig.rest, AVATAR_RIG.rest, atol=1e-6)
    assert rig.name == "avatar"
    binary = tmp_path / "avatar.USDC"
    write_usd(tmp_path / "avatar.usdc", AVATAR_STILL)
    (tmp_path / "avatar.usdc").rename(binary)
    np.testing.assert_allclose(read_avatar_rig(binary).rest, rig.rest)


@pytest.mark.parametrize("transforms", ["rest", "bind"])
def test_a_z_up_centimetre_usd_stage_gives_the_rig_in_meters_y_up(
    tmp_path: Path, transforms: str
) -> None:
    """Blender's USD export: Z up, centimetres, the character facing -Y under a root joint
    (turned 180 degrees about the up axis here, so it faces +Y and is turned back)."""
    path = tmp_path / "blender.usda"
    _usd_avatar(path, [_turned_skeleton(AVATAR_RIG)], transforms, meters_per_unit=0.01, up="Z")
    rig = read_avatar_rig(path)
    np.testing.assert_allclose(rig.rest, AVATAR_RIG.rest, atol=1e-6)


@pytest.mark.parametrize("prefix", ["mixamorig_", "mixamorig1_"])
def test_a_blender_usd_of_a_mixamo_rig_is_read_by_its_names(tmp_path: Path, prefix: str) -> None:
    """Blender's USD export writes Mixamo's "mixamorig:LeftArm" as "mixamorig_LeftArm"
    (numbered in some downloads)."""
    tokens, positions = _turned_skeleton(AVATAR_RIG)
    renamed = {name: MIXAMO[name].replace("mixamorig:", prefix) for name in MIXAMO}
    tokens = ["/".join(renamed.get(part, part) for part in token.split("/")) for token in tokens]
    path = tmp_path / "mixamo.usda"
    _usd_avatar(path, [(tokens, positions)], "rest", meters_per_unit=0.01, up="Z")
    np.testing.assert_allclose(read_avatar_rig(path).rest, AVATAR_RIG.rest, atol=1e-6)


def test_of_several_usd_skeletons_the_humanoid_one_is_taken(tmp_path: Path) -> None:
    prop = (["Sword", "Sword/Blade"], np.array([[0.0, 1.0, 0.0], [0.0, 1.5, 0.0]]))
    tokens, positions = _turned_skeleton(AVATAR_RIG)
    path = tmp_path / "avatar.usda"
    _usd_avatar(path, [prop, (tokens, positions / 100.0)], "rest", meters_per_unit=1.0, up="Z")
    np.testing.assert_allclose(read_avatar_rig(path).rest, AVATAR_RIG.rest, atol=1e-6)


def test_usd_avatars_without_a_humanoid_skeleton_are_named(tmp_path: Path) -> None:
    plain = Usd.Stage.CreateNew(str(tmp_path / "plain.usda"))
    UsdGeom.Xform.Define(plain, "/World")
    plain.Save()
    tokens, positions = _turned_skeleton(AVATAR_RIG)
    no_arms = [t for t in tokens if "Arm" not in t and "Hand" not in t]
    kept = [i for i, t in enumerate(tokens) if t in no_arms]
    _usd_avatar(tmp_path / "armless.usda", [(no_arms, positions[kept])], "rest")
    prop = (["Sword", "Sword/Blade"], np.array([[0.0, 1.0, 0.0], [0.0, 1.5, 0.0]]))
    _usd_avatar(tmp_path / "two.usda", [prop, (no_arms, positions[kept])], "bind")
    _usd_avatar(tmp_path / "nothing.usda", [(tokens, positions)], "none")
    (tmp_path / "text.usda").write_text("Hips 0 0 0\n")
    problems = {
        "plain.usda": ["no UsdSkel Skeleton prim in the file"],
        "armless.usda": ["avatar has no humanoid skeleton: "],
        "two.usda": [
            "avatar has no humanoid skeleton: none of its 2 skeletons is a humanoid's "
            "(/Character/Skel0: 2 joints, too few for arms, legs and a head; "
            "/Character/Skel1: ",
        ],
        "nothing.usda": [
            "skeleton /Character/Skel0 has no restTransforms or bindTransforms for its 18 joints"
        ],
        "text.usda": ["cannot read the file as USD"],
        "missing.usd": ["cannot read the file: no such file"],
    }
    for name, parts in problems.items():
        path = tmp_path / name
        with pytest.raises(ExportError) as raised:
            read_avatar_rig(path)
        assert raised.value.source == str(path)
        assert all(part in raised.value.problem for part in parts), raised.value.problem


def test_a_usd_skeleton_that_cannot_be_posed_is_passed_over(tmp_path: Path) -> None:
    """A prop's Skeleton without rest or bind transforms beside a humanoid one: the
    humanoid is read; alone with another broken one, both are named."""
    path = tmp_path / "avatar.usda"
    _usd_avatar(path, [_turned_skeleton(AVATAR_RIG)], "rest", meters_per_unit=0.01, up="Z")
    stage = Usd.Stage.Open(str(path))
    prop = UsdSkel.Skeleton.Define(stage, "/Character/Prop")
    prop.CreateJointsAttr(Vt.TokenArray(["Sword", "Sword/Blade"]))
    stage.Save()
    np.testing.assert_allclose(read_avatar_rig(path).rest, AVATAR_RIG.rest, atol=1e-6)
    broken = tmp_path / "broken.usda"
    tokens, positions = _turned_skeleton(AVATAR_RIG)
    _usd_avatar(broken, [(tokens, positions), (tokens, positions)], "none")
    with pytest.raises(ExportError) as raised:
        read_avatar_rig(broken)
    assert "none of its 2 skeletons is a humanoid's" in raised.value.problem
    assert "skeleton /Character/Skel1 has no restTransforms" in raised.value.problem


def test_usd_suffixes_are_the_usd_writers() -> None:
    assert sorted(USD_SUFFIXES) == sorted(usd_writer.SUFFIXES)


def _turned_skeleton(rig: HumanoidRig) -> tuple[list[str], np.ndarray]:
    """The rig's joints under a "Root" joint as a Z-up, centimetre stage would hold them:
    joint tokens and world positions (n, 3), turned 180 degrees about the up axis (the
    rig then faces +Y; the root joint at the origin)."""
    tokens = ["Root", *(f"Root/{token}" for token in joint_tokens(rig))]
    y_up = np.vstack([np.zeros(3), rig.rest])
    z_up = 100.0 * np.stack([y_up[:, 0], -y_up[:, 2], y_up[:, 1]], axis=1)
    return tokens, z_up * [-1.0, -1.0, 1.0]


def _usd_avatar(
    path: Path,
    skeletons: list[tuple[list[str], np.ndarray]],
    transforms: str,
    meters_per_unit: float = 1.0,
    up: str = "Y",
) -> None:
    """A USD file with one Skeleton per (joint tokens, world positions (n, 3)) under the
    SkelRoot /Character, as `transforms` "rest" (local; a root joint is turned 180 degrees
    about the up axis, its children's translations given in its turned frame), "bind"
    (world) or "none"."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up == "Z" else UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    UsdSkel.Root.Define(stage, "/Character")
    for k, (tokens, positions) in enumerate(skeletons):
        skeleton = UsdSkel.Skeleton.Define(stage, f"/Character/Skel{k}")
        skeleton.CreateJointsAttr(Vt.TokenArray(tokens))
        world = np.tile(np.eye(4), (len(tokens), 1, 1))
        world[:, 3, :3] = positions
        if tokens[0] == "Root":  # turned about the up axis (row vectors: p' = p @ M)
            world[0, :3, :3] = np.diag([-1.0, -1.0, 1.0] if up == "Z" else [-1.0, 1.0, -1.0])
        parents = UsdSkel.Topology(Vt.TokenArray(tokens)).GetParentIndices()
        local = np.array(
            [
                w if p < 0 else w @ np.linalg.inv(world[p])
                for w, p in zip(world, parents, strict=True)
            ]
        )
        if transforms == "rest":
            skeleton.CreateRestTransformsAttr(Vt.Matrix4dArray.FromNumpy(local))
        elif transforms == "bind":
            skeleton.CreateBindTransformsAttr(Vt.Matrix4dArray.FromNumpy(world))
    stage.Save()
