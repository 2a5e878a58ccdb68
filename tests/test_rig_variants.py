"""Rigs recognised by their structure: the three shared CMU rigs under six naming
conventions and four structural changes other tools make import to the same 13 joints
(within 1 mm); skeletons that are not a humanoid's are refused with a clear message."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from samba.cli import main
from samba.ingest import RIG_CONVENTIONS, RIG_STRUCTURES, rig_variant
from samba.ingest.bvh import read_bvh
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take
from samba.ingest.errors import RigError
from samba.ingest.rigs import RigMap

RIGS = ("cgspeed_131_01", "iclone_002_01", "daz_salsa_01")
VARIANTS = (
    [(name, ()) for name in RIG_CONVENTIONS]
    + [("game studio", (structure,)) for structure in RIG_STRUCTURES]
    + [("game studio", RIG_STRUCTURES)]
)


@pytest.mark.parametrize("rig", RIGS)
def test_every_variant_of_a_shared_rig_imports_to_the_same_joints(
    rig: str, cmu_dir: Path, tmp_path: Path
) -> None:
    bvh = read_bvh(cmu_dir / f"{rig}.bvh")
    original = tmp_path / "original.bvh"
    original.write_text(rig_variant(bvh, "original"))
    expected = load_bvh_take(original).poses
    for convention, structures in VARIANTS:
        path = tmp_path / f"{convention}-{len(structures)}.bvh".replace(" ", "_")
        path.write_text(rig_variant(bvh, convention, structures))
        take = load_bvh_take(path)  # a built-in table or the resolver ("detected")
        error = np.abs(take.poses - expected).max()
        assert error < 1e-3, (convention, structures, take.rig, error)


def _bvh(joints: list[tuple[str, str | None, tuple[float, float, float]]]) -> str:
    """BVH text of joints (name, parent name, offset in cm), every joint with three
    rotation channels, two frames in the rest pose."""
    children: dict[str | None, list[int]] = {}
    for i, (_, parent, _) in enumerate(joints):
        children.setdefault(parent, []).append(i)
    lines, count = ["HIERARCHY"], 0

    def write(i: int, depth: int) -> None:
        nonlocal count
        name, parent, (x, y, z) = joints[i]
        pad = "  " * depth
        channels = "6 Xposition Yposition Zposition" if parent is None else "3"
        lines.extend(
            [
                f"{pad}{'ROOT' if parent is None else 'JOINT'} {name}",
                f"{pad}{{",
                f"{pad}  OFFSET {x} {y} {z}",
                f"{pad}  CHANNELS {channels} Zrotation Xrotation Yrotation",
            ]
        )
        count += 6 if parent is None else 3
        for c in children.get(name, []):
            write(c, depth + 1)
        if name not in children:
            end = [f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET 0 -3 0", f"{pad}  }}"]
            lines.extend(end)
        lines.append(f"{pad}}}")

    write(children[None][0], 0)
    lines += ["MOTION", "Frames: 2", "Frame Time: 0.0333333"]
    lines += [" ".join(["0"] * count)] * 2
    return "\n".join(lines) + "\n"


QUADRUPED = [
    ("Hips", None, (0, 60, 0)),
    ("Spine", "Hips", (0, 0, 30)),
    ("Chest", "Spine", (0, 0, 30)),
    ("Neck", "Chest", (0, 10, 15)),
    ("Head", "Neck", (0, 5, 15)),
    ("LeftUpLeg", "Hips", (10, 0, 0)),
    ("LeftLeg", "LeftUpLeg", (0, -30, 0)),
    ("LeftFoot", "LeftLeg", (0, -28, 0)),
    ("RightUpLeg", "Hips", (-10, 0, 0)),
    ("RightLeg", "RightUpLeg", (0, -30, 0)),
    ("RightFoot", "RightLeg", (0, -28, 0)),
    ("LeftArm", "Chest", (10, 0, 0)),
    ("LeftForeArm", "LeftArm", (0, -30, 0)),
    ("LeftHand", "LeftForeArm", (0, -28, 0)),
    ("RightArm", "Chest", (-10, 0, 0)),
    ("RightForeArm", "RightArm", (0, -30, 0)),
    ("RightHand", "RightForeArm", (0, -28, 0)),
]
"""A four-legged rig, its legs named as a humanoid's arms and legs."""
TAIL = [
    ("Tail", "Hips", (0, 0, -20)),
    ("Tail1", "Tail", (0, 0, -20)),
    ("Tail2", "Tail1", (0, 0, -20)),
]


def _unnamed(rig: list[tuple[str, str | None, tuple[float, float, float]]]) -> list:
    """`rig` with every joint named "Bone<i>": nothing but the tree to go by."""
    names = {name: f"Bone{i}" for i, (name, _, _) in enumerate(rig)}
    return [(names[n], names.get(p), o) for n, p, o in rig]


HAND = [("hand_r", None, (0, 100, 0))] + [
    joint
    for k, finger in enumerate(("thumb", "index", "middle", "ring", "pinky"))
    for joint in (
        (f"{finger}_01_r", "hand_r", (-4 + 2 * k, 3, 0)),
        (f"{finger}_02_r", f"{finger}_01_r", (0, 3, 0)),
        (f"{finger}_03_r", f"{finger}_02_r", (0, 2.5, 0)),
    )
]
"""A hand-only rig: a wrist and five fingers."""


@pytest.mark.parametrize(
    ("rig", "problem"),
    [
        (_unnamed(QUADRUPED), "the left leg does not hang away from the chest"),
        (_unnamed(QUADRUPED + TAIL), "its tree has 6 long branches where a humanoid has 5"),
        (HAND, "no branch point carries the head and two arms"),
    ],
    ids=["quadruped", "quadruped-with-tail", "hand"],
)
def test_a_skeleton_that_is_not_a_humanoids_is_refused_saying_why(
    rig: list, problem: str, tmp_path: Path
) -> None:
    path = tmp_path / "rig.bvh"
    path.write_text(_bvh(rig))
    with pytest.raises(RigError) as err:
        load_bvh_take(path)
    assert str(err.value).startswith(f"{path}: unknown rig: not a humanoid skeleton: ")
    assert problem in str(err.value) and "--map" in str(err.value)


def test_db_rig_shows_the_mapping_and_writes_the_map_import_takes(
    cmu_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`samba db rig FILE --write-map OUT`: the game-studio rename of the Daz rig, its
    bones with their evidence; the written map imports the file as detection does."""
    path = tmp_path / "studio.bvh"
    path.write_text(rig_variant(read_bvh(cmu_dir / "daz_salsa_01.bvh"), "game studio"))
    mapping = tmp_path / "studio.toml"
    assert main(["db", "rig", str(path), "--write-map", str(mapping)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{path}: rig detected, 57 joints\n")
    assert "LeftUpperArm   UpperArm_L  name and structure" in out
    assert f"wrote {mapping}" in out
    mapped = load_bvh_take(path, BvhImportOptions(rig=RigMap.from_toml(mapping)))
    assert mapped.rig == "studio"
    np.testing.assert_array_equal(mapped.poses, load_bvh_take(path).poses)
    assert main(["db", "rig", str(path), "--write-map", str(mapping)]) == 1
    assert "already exists" in capsys.readouterr().err
