"""Reference joint centres from a full marker set (`samba.ingest.reference_joints`): the
chord function's geometry, and on the shared CMU takes bones that keep their length, a
left that matches the right, adult sizes and joints on the anatomical side of markers."""

from __future__ import annotations

from dataclasses import replace
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from samba.body import JOINT_INDEX
from samba.ingest import C3dError, JointWidths, MarkerTake, read_c3d, reference_joints
from samba.ingest.joint_centres import LANDMARKS, chord

TAKES = ("85_02", "85_12")
BONES = {
    "upper arm": ("shoulder", "elbow"),
    "forearm": ("elbow", "wrist"),
    "thigh": ("hip", "knee"),
    "shank": ("knee", "foot"),
}


@cache
def _reference(path: Path) -> tuple[MarkerTake, np.ndarray]:
    take = read_c3d(path)
    return take, reference_joints(take)


def _joint(joints: np.ndarray, name: str) -> np.ndarray:
    return joints[:, JOINT_INDEX[name]]


def _length(joints: np.ndarray, side: str, bone: str) -> np.ndarray:
    a, b = BONES[bone]
    return np.linalg.norm(_joint(joints, f"{side}_{a}") - _joint(joints, f"{side}_{b}"), axis=-1)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_the_chord_function_puts_the_centre_at_the_offset_at_a_right_angle_medially() -> None:
    hip, thigh, knee_marker = np.array([[0.0, 0.4, 0.0], [0.06, 0.2, 0.0], [0.05, 0.0, 0.0]])
    np.testing.assert_allclose(chord(hip, thigh, knee_marker, 0.05), [0.0, 0.0, 0.0], atol=1e-12)

    rng = np.random.default_rng(7)
    joint, plane, marker = rng.normal(size=(3, 500, 3))
    offset = 0.2 * np.linalg.norm(joint - marker, axis=-1).min()
    centre = chord(joint, plane, marker, offset)
    np.testing.assert_allclose(np.linalg.norm(centre - marker, axis=-1), offset)
    right_angle = np.sum(_unit(joint - centre) * _unit(marker - centre), axis=-1)
    np.testing.assert_allclose(right_angle, 0.0, atol=1e-9)
    normal = _unit(np.cross(plane - marker, joint - marker))
    np.testing.assert_allclose(np.sum((centre - marker) * normal, axis=-1), 0.0, atol=1e-12)
    line = _unit(joint - marker)

    def across(p: np.ndarray) -> np.ndarray:  # the part of p - marker across the line
        w = p - marker
        return w - np.sum(w * line, axis=-1, keepdims=True) * line

    assert (np.sum(across(centre) * across(plane), axis=-1) < 0).all()  # away from `plane`
    too_far = np.linalg.norm(joint[0] - marker[0]) * 1.01
    assert np.isnan(chord(joint[0], plane[0], marker[0], too_far)).all()


def test_a_take_lacking_the_pelvis_markers_is_refused_naming_them() -> None:
    labels = tuple(label for label in LANDMARKS.values() if label[1:] not in ("FWT", "BWT"))
    take = MarkerTake(
        name="lab",
        points=np.zeros((3, len(labels), 3)),
        labels=labels,
        markers=np.zeros((3, 8, 3)),
        fps=120.0,
        source="/data/lab.c3d",
        marker_set="plug-in-gait",
    )
    with pytest.raises(C3dError) as err:
        reference_joints(take)
    assert str(err.value) == (
        "/data/lab.c3d: the reference joint centres need the labels LFWT, RFWT, LBWT, RBWT, "
        "which the take lacks"
    )


@pytest.mark.parametrize("name", TAKES)
def test_every_joint_is_found_in_every_frame_and_a_missing_marker_blanks_its_joints(
    c3d_dir: Path, name: str
) -> None:
    take, joints = _reference(c3d_dir / f"{name}.c3d")
    assert joints.shape == (len(take), 13, 3) and np.isfinite(joints).all()  # gap-filled
    points = take.points.copy()
    points[5, take.labels.index("LKNE")] = np.nan
    blanked = reference_joints(replace(take, points=points))
    lost = {name for name, j in JOINT_INDEX.items() if np.isnan(blanked[5, j]).any()}
    assert lost == {"l_knee", "l_foot"}  # the ankle is found from the knee


@pytest.mark.parametrize("name", TAKES)
def test_bones_keep_their_length_and_left_matches_right(c3d_dir: Path, name: str) -> None:
    _, joints = _reference(c3d_dir / f"{name}.c3d")
    lengths = {(side, bone): _length(joints, side, bone) for side in "lr" for bone in BONES}
    for length in lengths.values():
        assert length.std() < 0.03  # meters, soft tissue moving the markers
    for bone in ("upper arm", "forearm"):
        assert abs(lengths["l", bone].mean() - lengths["r", bone].mean()) < 0.02
    legs = [lengths[side, "thigh"] + lengths[side, "shank"] for side in "lr"]
    assert abs(legs[0].mean() - legs[1].mean()) < 0.02
    # CMU's LKNE sits 4-5 cm further from LANK than RKNE from RANK (raw markers), so the
    # left knee is higher: thigh and shank differ by 3-4 cm each side while legs match
    for bone in ("thigh", "shank"):
        assert abs(lengths["l", bone].mean() - lengths["r", bone].mean()) < 0.045


@pytest.mark.parametrize("name", TAKES)
def test_sizes_are_an_adults(c3d_dir: Path, name: str) -> None:
    _, joints = _reference(c3d_dir / f"{name}.c3d")
    for side in "lr":
        assert 0.35 < np.median(_length(joints, side, "thigh")) < 0.50
        assert 0.33 < np.median(_length(joints, side, "shank")) < 0.48
    hips = np.linalg.norm(_joint(joints, "l_hip") - _joint(joints, "r_hip"), axis=-1)
    # Harrington's 2 (0.33 PW + 7.3 mm) is 0.15 m here: CMU's waist markers are 21 cm apart
    assert 0.14 < np.median(hips) < 0.30


@pytest.mark.parametrize("name", TAKES)
def test_hips_lie_below_behind_and_inside_the_asis_and_knees_inside_the_knee_marker(
    c3d_dir: Path, name: str
) -> None:
    take, joints = _reference(c3d_dir / f"{name}.c3d")
    left, right = take.point("LFWT"), take.point("RFWT")
    lateral = _unit(right - left)  # to the subject's right
    front = (left + right - take.point("LBWT") - take.point("RBWT")) / 2
    front = _unit(front - np.sum(front * lateral, axis=-1, keepdims=True) * lateral)
    upright = np.cross(lateral, front)[:, 1] > np.cos(np.radians(30.0))
    assert upright.mean() > 0.5
    for side, sign, asis in (("l", -1.0, left), ("r", 1.0, right)):
        offset = _joint(joints, f"{side}_hip") - asis
        assert (offset[upright, 1] < -0.02).all()  # below, in the frames standing upright
        assert (np.sum(offset * front, axis=-1) < -0.04).all()  # behind
        assert (sign * np.sum(offset * lateral, axis=-1) < 0).all()  # medial

        marker = take.point(f"{side.upper()}KNE")
        knee = _joint(joints, f"{side}_knee") - marker
        offset = (JointWidths().knee + JointWidths().marker) / 2
        np.testing.assert_allclose(np.linalg.norm(knee, axis=-1), offset)
        medial = -sign * np.sum(knee * lateral, axis=-1)
        assert (medial > 0.01).all() and 0.04 < np.median(medial) < 0.07


@pytest.mark.parametrize("name", TAKES)
def test_elbows_lie_inside_the_elbow_marker_and_survive_a_straight_arm(
    c3d_dir: Path, name: str
) -> None:
    take, joints = _reference(c3d_dir / f"{name}.c3d")
    offset = (JointWidths().elbow + JointWidths().marker) / 2
    down = _unit(take.point("T10") + take.point("STRN") - take.point("C7") - take.point("CLAV"))
    points = take.points.copy()
    for side, sign in (("l", -1.0), ("r", 1.0)):
        shoulder, elbow = _joint(joints, f"{side}_shoulder"), _joint(joints, f"{side}_elbow")
        marker = take.point(f"{side.upper()}ELB")
        np.testing.assert_allclose(np.linalg.norm(elbow - marker, axis=-1), offset)
        hanging = np.sum(_unit(elbow - shoulder) * down, axis=-1) > np.cos(np.radians(30.0))
        lateral = sign * _unit(take.point("RSHO") - take.point("LSHO"))
        assert (np.sum((elbow - marker) * lateral, axis=-1)[hanging] < -0.02).all()  # medial
        for label in ("WRA", "WRB"):  # frame 7: the arm held dead straight
            points[7, take.labels.index(side.upper() + label)] = 2 * marker[7] - shoulder[7]
    straight = reference_joints(replace(take, points=points))
    for side in "lr":
        np.testing.assert_allclose(
            _joint(straight, f"{side}_elbow")[7], _joint(joints, f"{side}_elbow")[7], atol=1e-3
        )
