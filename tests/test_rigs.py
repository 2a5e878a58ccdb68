"""Rig maps (`samba.ingest.rigs`): detection of the built-in rigs, prefixes, user TOML maps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from bvh_fixtures import MAPPED_KEYS, RIG_NAMES, make_humanoid, rig_names

from samba.body.skeleton import JOINT_NAMES
from samba.ingest.bvh import parse_bvh
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take
from samba.ingest.errors import RigError
from samba.ingest.resolver import SkeletonTree
from samba.ingest.rigs import BUILTIN_RIGS, RigMap, detect_rig, map_rig, rig_by_name

CUSTOM = {
    "hips": "Bone_Pelvis",
    "spine": "Bone_Spine",
    "chest": "Bone_Chest",
    "neck": "Bone_Neck",
    "head": "Bone_Skull",
    "l_collar": "Bone_L_Clav",
    "l_shoulder": "Bone_L_Arm1",
    "l_elbow": "Bone_L_Arm2",
    "l_wrist": "Bone_L_Palm",
    "l_hip": "Bone_L_Leg1",
    "l_knee": "Bone_L_Leg2",
    "l_ankle": "Bone_L_Heel",
    "l_toe": "Bone_L_Toes",
    "r_collar": "Bone_R_Clav",
    "r_shoulder": "Bone_R_Arm1",
    "r_elbow": "Bone_R_Arm2",
    "r_wrist": "Bone_R_Palm",
    "r_hip": "Bone_R_Leg1",
    "r_knee": "Bone_R_Leg2",
    "r_ankle": "Bone_R_Heel",
    "r_toe": "Bone_R_Toes",
}
"""A rig no built-in map knows."""


def _write(tmp_path: Path, name: str, text: str) -> Path:
    """Write `text` to tmp_path/name and return the path."""
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def _toml(names: dict[str, str], **extra: str) -> str:
    """A mapping file [joints] table from skeleton keys (ankle = our foot) to names."""
    lines = [f'{k} = "{v}"' for k, v in extra.items()] + ["[joints]"]
    for ours, key in zip(JOINT_NAMES, MAPPED_KEYS, strict=True):
        lines.append(f'{ours} = "{names[key]}"')
    return "\n".join(lines) + "\n"


def _tree(names: tuple[str, ...]) -> SkeletonTree:
    """The test subject's tree with these joint names (in the fixture's joint order)."""
    skeleton = parse_bvh(make_humanoid("cmu-max", frames=2).text).skeleton()
    return SkeletonTree(tuple(names), skeleton.parents, skeleton.positions)


def _rig_error(call, *args, **kwargs) -> RigError:
    """The `RigError` raised by call(*args, **kwargs)."""
    with pytest.raises(RigError) as info:
        call(*args, **kwargs)
    return info.value


def test_every_builtin_rig_has_a_fixture() -> None:
    assert {r.name for r in BUILTIN_RIGS} == set(RIG_NAMES)


@pytest.mark.parametrize("rig", [r.name for r in BUILTIN_RIGS])
def test_builtin_rig_is_detected_and_imported(tmp_path: Path, rig: str) -> None:
    fixture = make_humanoid(rig, frames=20, seed=5)
    path = _write(tmp_path, f"{rig}.bvh", fixture.text)
    take = load_bvh_take(path)
    assert take.rig == rig
    np.testing.assert_allclose(take.poses, fixture.positions, atol=2e-5)


@pytest.mark.parametrize("rig", [r.name for r in BUILTIN_RIGS])
def test_detect_rig_finds_the_13_joints_by_name(rig: str) -> None:
    fixture = make_humanoid(rig, frames=2)
    names = parse_bvh(fixture.text).names
    found_rig, joints = detect_rig(names, "x.bvh", lambda: _tree(names))
    assert found_rig.name == rig
    wanted = [rig_names(rig)[k] for k in MAPPED_KEYS]
    assert [names[j] for j in joints] == wanted


@pytest.mark.parametrize("prefix", ["mixamorig:", "mixamorig1:", "mixamorig12:", "MIXAMORIG:"])
def test_mixamo_namespace_variants(tmp_path: Path, prefix: str) -> None:
    names = {k: prefix + v.split(":")[1] for k, v in RIG_NAMES["mixamo"].items()}
    fixture = make_humanoid(names, frames=10)
    take = load_bvh_take(_write(tmp_path, "mixamo.bvh", fixture.text))
    assert take.rig == "mixamo"
    np.testing.assert_allclose(take.poses, fixture.positions, atol=2e-5)


def test_motionbuilder_names_without_prefix_are_not_mixamo() -> None:
    names = parse_bvh(make_humanoid("motionbuilder", frames=2).text).names
    assert detect_rig(names, "x.bvh", lambda: _tree(names))[0].name == "motionbuilder"


def test_daz_genesis_bend_joints(tmp_path: Path) -> None:
    names = rig_names("daz") | {
        "l_shoulder": "lShldrBend",
        "r_shoulder": "rShldrBend",
        "l_elbow": "lForearmBend",
        "r_elbow": "rForearmBend",
        "l_hip": "lThighBend",
        "r_hip": "rThighBend",
    }
    fixture = make_humanoid(names, frames=10)
    take = load_bvh_take(_write(tmp_path, "genesis.bvh", fixture.text))
    assert take.rig == "daz"
    np.testing.assert_allclose(take.poses, fixture.positions, atol=2e-5)


@pytest.mark.parametrize(
    "spell", [str.upper, str.lower, lambda n: n.replace("Left", "Left_").replace("Right", "Right ")]
)
def test_names_match_ignoring_case_underscores_and_spaces(spell) -> None:
    names = tuple(spell(n) for n in parse_bvh(make_humanoid("cmu-max", frames=2).text).names)
    rig, joints = detect_rig(names, "x.bvh", lambda: _tree(names))
    assert rig.name == "cmu-max"
    assert names[joints[JOINT_NAMES.index("l_elbow")]] == spell("LeftElbow")


def test_a_rig_of_unknown_names_is_mapped_by_its_structure(tmp_path: Path) -> None:
    """No built-in table knows "Bone_L_Arm1" or "Bone_L_Heel": the resolver places them
    by the tree (the sides from the "L"/"R" in the names) and the take imports exactly."""
    fixture = make_humanoid(CUSTOM, frames=15)
    take = load_bvh_take(_write(tmp_path, "custom.bvh", fixture.text))
    assert take.rig == "detected"
    np.testing.assert_allclose(take.poses, fixture.positions, atol=2e-5)


def test_names_that_contradict_the_structure_are_refused_naming_the_joint(
    tmp_path: Path,
) -> None:
    names = {"l_elbow": "LeftArmBend", "r_elbow": "RightArmBend"}
    path = _write(tmp_path, "odd.bvh", make_humanoid(names, frames=5).text)
    err = _rig_error(load_bvh_take, path)
    assert err.source == str(path)
    assert str(err).startswith(f"{path}: unknown rig: not a humanoid skeleton: ")
    problem = "'LeftArmBend' is named for the upper arm but stands where the left lower arm is"
    assert problem in err.problem
    assert "--map" in err.problem


def test_user_mapping_file_imports_an_unknown_rig(tmp_path: Path) -> None:
    fixture = make_humanoid(CUSTOM, frames=15)
    path = _write(tmp_path, "custom.bvh", fixture.text)
    mapping = _write(tmp_path, "my-rig.toml", _toml(CUSTOM, name="studio"))
    take = load_bvh_take(path, BvhImportOptions(rig=RigMap.from_toml(mapping)))
    assert take.rig == "studio"
    np.testing.assert_allclose(take.poses, fixture.positions, atol=2e-5)


def test_mapping_file_name_defaults_to_its_stem_and_accepts_lists(tmp_path: Path) -> None:
    text = _toml(CUSTOM).replace('head = "Bone_Skull"', 'head = ["Kopf", "Bone_Skull"]')
    rig = RigMap.from_toml(_write(tmp_path, "studio-b.toml", text))
    assert rig.name == "studio-b"
    assert rig.joints[0] == ("Kopf", "Bone_Skull")
    names = parse_bvh(make_humanoid(CUSTOM, frames=2).text).names
    _, joints = map_rig(names, "x.bvh", lambda: _tree(names), rig)
    assert names[joints[0]] == "Bone_Skull"


def test_mapping_that_does_not_fit_the_file_names_the_file(tmp_path: Path) -> None:
    path = _write(tmp_path, "walk.bvh", make_humanoid("daz", frames=5).text)
    mapping = _write(tmp_path, "m.toml", _toml(CUSTOM))
    err = _rig_error(load_bvh_take, path, BvhImportOptions(rig=RigMap.from_toml(mapping)))
    assert str(err).startswith(f"{path}: rig 'm' cannot map")
    assert "head (looked for Bone_Skull)" in err.problem


def test_builtin_rig_forced_on_another_rig_fails_clearly(tmp_path: Path) -> None:
    path = _write(tmp_path, "walk.bvh", make_humanoid("cmu-max", frames=5).text)
    err = _rig_error(load_bvh_take, path, BvhImportOptions(rig=rig_by_name("daz")))
    assert str(err).startswith(f"{path}: rig 'daz' cannot map")


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("[joints\nhead = 'Head'\n", "not valid TOML"),
        ("name = 'x'\n", "needs a [joints] table"),
        ("joints = 3\n", "needs a [joints] table"),
        ("[joints]\nhead = 'Head'\n", "does not map l_shoulder, r_shoulder"),
        ("[joints]\nhead = 'Head'\npelvis = 'Hips'\n", "unknown joints ['pelvis']"),
        ("\xff\xfe", "not valid TOML"),
    ],
)
def test_invalid_mapping_files(tmp_path: Path, text: str, problem: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_bytes(text.encode("latin-1"))
    err = _rig_error(RigMap.from_toml, path)
    assert err.source == str(path)
    assert str(err).startswith(f"{path}: ")
    assert problem in err.problem


@pytest.mark.parametrize("value", ["5", "''", "[]", "[1, 2]", "{ a = 'x' }", "true"])
def test_mapping_values_must_be_names(tmp_path: Path, value: str) -> None:
    text = _toml(CUSTOM).replace('head = "Bone_Skull"', f"head = {value}")
    path = _write(tmp_path, "bad.toml", text)
    err = _rig_error(RigMap.from_toml, path)
    assert str(err).startswith(f"{path}: joint head must map to a name or a list of names")


def test_unreadable_mapping_file(tmp_path: Path) -> None:
    for path in (tmp_path / "missing.toml", tmp_path):
        err = _rig_error(RigMap.from_toml, path)
        assert str(err).startswith(f"{path}: cannot read mapping file")


def test_rig_by_name() -> None:
    assert rig_by_name("iclone").name == "iclone"
    err = _rig_error(rig_by_name, "blender")
    assert "unknown rig 'blender'" in str(err)
    for rig in BUILTIN_RIGS:
        assert rig.name in err.problem
