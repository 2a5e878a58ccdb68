"""Rigs recognised by their structure: the three shared CMU rigs under six naming
conventions and four structural changes other tools make import to the same 13 joints
(within 1 mm); skeletons that are not a humanoid's are refused with a clear message."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from samba.cli import main
from samba.ingest import (
    QUADRUPED,
    RIG_CONVENTIONS,
    RIG_STRUCTURES,
    rest_pose_bvh,
    rig_variant,
    unnamed_rig,
)
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


TAIL = [
    ("Tail", "Hips", (0, 0, -20)),
    ("Tail1", "Tail", (0, 0, -20)),
    ("Tail2", "Tail1", (0, 0, -20)),
]


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
        (unnamed_rig(QUADRUPED), "the left leg does not hang away from the chest"),
        (unnamed_rig(QUADRUPED + TAIL), "its tree has 6 long branches where a humanoid has 5"),
        (HAND, "no branch point carries the head and two arms"),
    ],
    ids=["quadruped", "quadruped-with-tail", "hand"],
)
def test_a_skeleton_that_is_not_a_humanoids_is_refused_saying_why(
    rig: list, problem: str, tmp_path: Path
) -> None:
    path = tmp_path / "rig.bvh"
    path.write_text(rest_pose_bvh(rig))
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
