"""Acceptance on the real CMU files in ../shared/data/cmu: every file imports as a plausible,
rigid, upright human standing on a level floor."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from samba.body.skeleton import bone_lengths
from samba.body.take import Take
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take
from samba.ingest.normalize import foot_contacts, leading_tpose_frames

EXPECTED_RIGS = {"cgspeed": "cmu-max", "iclone": "iclone", "daz": "daz"}


@pytest.fixture(scope="module")
def takes(cmu_files: list[Path]) -> dict[str, Take]:
    """Every shared file imported with default options."""
    return {f.name: load_bvh_take(f) for f in cmu_files}


def test_every_file_imports_with_its_rig(takes: dict[str, Take]) -> None:
    assert len(takes) == 49
    for name, take in takes.items():
        assert take.rig == EXPECTED_RIGS[name.split("_")[0]], name
        assert take.fps == 30.0
        assert take.poses.dtype == np.float32 and take.poses.shape[1:] == (13, 3)
        assert np.isfinite(take.poses).all()
        assert take.meta["up"] == "+y" and take.meta["handedness"] == "right", name
    units = {take.meta["units"] for name, take in takes.items() if name.startswith("cgspeed")}
    assert units == {"cmu"}
    assert {t.meta["units"] for n, t in takes.items() if not n.startswith("cgspeed")} == {"cm"}
    total = sum(len(t) for t in takes.values())
    assert 16_000 < total < 17_500  # the data README: about 16,700 poses at 30 fps


def test_bones_are_rigid_within_a_millimetre(takes: dict[str, Take]) -> None:
    for name, take in takes.items():
        lengths = bone_lengths(take.poses.astype(np.float64))
        assert np.ptp(lengths, axis=0).max() < 0.001, name


def test_limb_lengths_are_anatomically_plausible(takes: dict[str, Take]) -> None:
    for name, take in takes.items():
        upper_arm, _, _, _, femur, tibia, _, _ = np.median(
            bone_lengths(take.poses.astype(np.float64)), axis=0
        )
        assert 0.33 < femur < 0.55, (name, femur)
        assert 0.30 < tibia < 0.52, (name, tibia)
        assert 0.22 < upper_arm < 0.38, (name, upper_arm)
        height = np.percentile(take.poses[:, 0, 1], 90)
        assert 1.0 < height < 2.2, (name, height)


def test_head_is_above_the_feet(takes: dict[str, Take]) -> None:
    for name, take in takes.items():
        head = take.poses[:, 0, 1]
        feet = take.poses[:, 11:13, 1].max(axis=1)
        assert np.mean(head > feet) >= 0.99, name


@pytest.mark.parametrize("prefix", ["cgspeed_131", "iclone_007", "iclone_002_0"])
def test_feet_touch_the_floor_at_walk_contacts(takes: dict[str, Take], prefix: str) -> None:
    walks = [t for name, t in takes.items() if name.startswith(prefix)]
    assert walks
    for take in walks:
        contacts = foot_contacts(take.poses.astype(np.float64), take.fps)
        if len(contacts) < 10:
            continue  # a jump or a run with no slow foot: nothing to check
        assert np.abs(contacts[:, 1]).max() < 0.05, take.name


def test_leading_tpose_frames_can_be_dropped(cmu_dir: Path) -> None:
    path = cmu_dir / "daz_salsa_01.bvh"
    kept = load_bvh_take(path)
    dropped = load_bvh_take(path, BvhImportOptions(skip_tpose=True))
    assert any("T-pose" in w for w in kept.warnings)
    assert len(dropped) == len(kept) - 1
    assert dropped.frames[0] == 1
    assert leading_tpose_frames(kept.poses) == 1
    assert leading_tpose_frames(dropped.poses) == 0
