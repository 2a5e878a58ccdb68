"""Tests of the capsule body model `samba.body.body_model`."""

from __future__ import annotations

import numpy as np
import pytest

from samba.base.errors import InputError
from samba.body.body_model import (
    CAPSULE_NAMES,
    KINDS,
    PART_NAMES,
    BodyModel,
    checked_poses,
    scaled_to,
    standing_heights,
)
from samba.body.skeleton import Body, standard_pose
from samba.synthetic.motions import generate


def _extent(starts: np.ndarray, ends: np.ndarray, radii: np.ndarray, axis: int) -> np.ndarray:
    """Lowest and highest coordinate (2,) along `axis` of the capsules of one pose."""
    low = np.minimum(starts[:, axis], ends[:, axis]) - radii
    high = np.maximum(starts[:, axis], ends[:, axis]) + radii
    return np.array([low.min(), high.max()])


def _turned(poses: np.ndarray, degrees: float) -> np.ndarray:
    """Poses turned about the vertical axis through the origin."""
    a = np.radians(degrees)
    turn = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    return poses @ turn.T


def test_the_catalogue_holds_plausible_sizes_of_every_kind() -> None:
    catalog = BodyModel.catalog()
    counts = {kind: sum(m.kind == kind for m in catalog) for kind in KINDS}
    assert counts["men"] >= 4 and counts["women"] >= 4 and counts["children"] >= 3
    assert len({m.name for m in catalog}) == len(catalog)
    for m in catalog:
        assert m.name.startswith(m.kind)
        assert (1.45 <= m.height <= 1.95) if m.kind != "children" else (1.0 <= m.height <= 1.6)
        assert 0.5 <= m.chest <= 1.2 and 0.45 <= m.waist <= m.chest and 0.55 <= m.hip <= 1.2
        assert (m.capsule_radii > 0.01).all() and (m.capsule_radii < 0.15).all()
        assert m.chest_radius > m.upper_arm_radius > m.forearm_radius
        assert m.thigh_radius > m.shin_radius
    men = [m for m in catalog if m.kind == "men"]
    assert [m.chest for m in men] == sorted(m.chest for m in men)  # bigger men, bigger chests


def test_radii_follow_the_girths() -> None:
    slim = BodyModel.from_girths("slim", "men", 1.75, chest=0.86, waist=0.72, hip=0.88)
    broad = BodyModel.from_girths("broad", "men", 1.75, chest=1.08, waist=0.98, hip=1.06)
    for name in ("chest_radius", "abdomen_radius", "pelvis_radius", "thigh_radius"):
        assert getattr(broad, name) > getattr(slim, name)
    # the trunk's stadium cross-section has the girth as its perimeter
    m = BodyModel.named("men-M")
    perimeter = 4 * m.chest_spread + 2 * np.pi * m.chest_radius
    assert perimeter == pytest.approx(m.chest, rel=1e-9)


def test_every_capsule_belongs_to_a_part() -> None:
    starts, ends, radii, part = BodyModel.named("women-M").capsules(standard_pose(1.58)[None])
    k = len(CAPSULE_NAMES)
    assert starts.shape == ends.shape == (1, k, 3) and radii.shape == part.shape == (k,)
    assert set(part.tolist()) == set(range(len(PART_NAMES)))
    names = dict(zip(CAPSULE_NAMES, (PART_NAMES[p] for p in part), strict=True))
    assert names["l_forearm"] == names["l_upper_arm"] == "l_arm"
    assert names["r_foot"] == names["r_shin"] == "r_leg"
    assert names["head"] == "head" and names["chest_l"] == names["pelvis"] == "torso"


@pytest.mark.parametrize("name", ["men-L", "women-S", "children-120"])
def test_a_standing_body_spans_its_height_from_sole_to_crown(name: str) -> None:
    model = BodyModel.named(name)
    pose = standard_pose(model.height)[None]
    starts, ends, radii, _ = model.capsules(pose)
    bottom, top = _extent(starts[0], ends[0], radii, axis=1)
    assert top - bottom == pytest.approx(model.height, abs=0.005)
    assert bottom == pytest.approx(-0.039 * model.height, abs=0.005)  # sole under the ankle
    head = CAPSULE_NAMES.index("head")
    assert min(starts[0, head, 1], ends[0, head, 1]) > pose[0, 0, 1] - 0.02  # head on top


def test_the_trunk_is_wider_than_deep() -> None:
    model = BodyModel.named("men-M")
    starts, ends, radii, _ = model.capsules(standard_pose(model.height)[None])
    trunk = [CAPSULE_NAMES.index(n) for n in ("chest_l", "chest_r", "abdomen_l", "abdomen_r")]
    width = np.diff(_extent(starts[0, trunk], ends[0, trunk], radii[trunk], axis=0))[0]
    depth = np.diff(_extent(starts[0, trunk], ends[0, trunk], radii[trunk], axis=2))[0]
    assert 0.28 < width < 0.36 and 0.19 < depth < 0.25
    assert width > 1.3 * depth


def test_hands_and_feet_reach_past_the_joints_and_feet_point_forward() -> None:
    model = BodyModel.named("men-M")
    pose = standard_pose(model.height, arm_angle_deg=0.0)[None]
    for turn in (0.0, 90.0):
        turned = _turned(pose, turn)
        _, ends, radii, _ = model.capsules(turned)
        forearm, foot = CAPSULE_NAMES.index("l_forearm"), CAPSULE_NAMES.index("l_foot")
        hand_tip = ends[0, forearm, 1] - radii[forearm]
        assert turned[0, 5, 1] - hand_tip == pytest.approx(0.09 * model.height, abs=0.01)
        toe = ends[0, foot] - turned[0, 11]
        facing = _turned(np.array([[0.0, 0.0, 1.0]]), turn)[0]
        assert toe @ facing > 0.1 and abs(toe[1]) < 0.06  # forward, along the floor


def test_standing_height_is_independent_of_the_posture() -> None:
    body = Body.from_height(1.80)
    take = generate("squat", seconds=2.0, fps=10.0, seed=4, body=body)
    heights = standing_heights(take.poses)
    assert np.allclose(heights, 1.80, atol=1e-4)
    assert standing_heights(standard_pose(1.62)[None])[0] == pytest.approx(1.62)


def test_scaled_poses_have_the_model_height_and_keep_their_place() -> None:
    poses = generate("walk", seconds=1.0, fps=10.0, seed=2).poses.astype(np.float64)
    scaled = scaled_to(poses, 1.50)
    assert np.allclose(standing_heights(scaled), 1.50)
    hips, hips_scaled = poses[:, [7, 8]].mean(axis=1), scaled[:, [7, 8]].mean(axis=1)
    assert np.allclose(hips_scaled[:, [0, 2]], hips[:, [0, 2]])  # same place on the floor
    assert np.allclose(scaled[:, [11, 12], 1].min(axis=1), poses[:, [11, 12], 1].min(axis=1))
    ratio = np.linalg.norm(scaled[:, 3] - scaled[:, 1], axis=-1) / np.linalg.norm(
        poses[:, 3] - poses[:, 1], axis=-1
    )
    assert np.allclose(ratio, 1.50 / standing_heights(poses))  # uniformly scaled


def test_named_and_for_subject_pick_sizes() -> None:
    assert BodyModel.named("men-M").height == 1.70
    assert BodyModel.for_subject(1.71).name == "men-M"  # ties go to the catalogue's order
    assert BodyModel.for_subject(1.58, kind="women").name == "women-M"
    assert BodyModel.for_subject(1.70, kind="women", chest=0.86).name == "women-T"
    assert BodyModel.for_subject(1.70, kind="women", chest=0.97).name == "women-LL"
    assert BodyModel.for_subject(1.22, kind="children").name == "children-120"
    assert BodyModel.for_subject(2.05).name == "men-3L"


def test_bad_input_names_the_problem() -> None:
    with pytest.raises(InputError, match="valid names: men-SS, men-S, men-M"):
        BodyModel.named("men-XXL")
    with pytest.raises(InputError, match=r"height 3\.1 m is outside"):
        BodyModel.for_subject(3.1)
    with pytest.raises(InputError, match="unknown kind 'aliens'"):
        BodyModel.for_subject(1.7, kind="aliens")
    with pytest.raises(InputError, match="chest"):
        BodyModel.for_subject(1.7, chest=92.0)  # centimetres instead of meters
    with pytest.raises(InputError, match="kind must be one of"):
        BodyModel.from_girths("x", "giants", 1.7, 0.9, 0.8, 0.9)
    with pytest.raises(InputError, match="girths and radii must be positive"):
        BodyModel.from_girths("x", "men", 1.7, 0.9, 0.8, 0.2)  # hips narrower than the joints
    poses = np.zeros((4, 13, 3))
    poses[2, 5, 0] = np.nan
    with pytest.raises(InputError, match="pose 2 contains NaN"):
        checked_poses(poses)
    with pytest.raises(InputError, match=r"shape \(n, 13, 3\), got \(13, 3\)"):
        BodyModel.named("men-M").capsules(standard_pose())
    with pytest.raises(InputError, match="height"):
        scaled_to(standard_pose()[None], 0.0)
    with pytest.raises(InputError, match="pose 1 has no size"):
        scaled_to(np.stack([standard_pose(), np.zeros((13, 3))]), 1.7)


def test_a_scaled_body_is_that_much_taller_and_rounder() -> None:
    model = BodyModel.named("men-L")
    big = model.scaled(1.04)
    assert big.name == "men-L x 1.04" and big.kind == model.kind
    for field in ("height", "chest", "waist", "hip"):
        assert getattr(big, field) == pytest.approx(1.04 * getattr(model, field))
    assert big.thigh_radius == pytest.approx(1.04 * model.thigh_radius)
