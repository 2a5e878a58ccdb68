"""Knees and feet lost in every camera found again by the legs' shape (`samba.markers.leg_labels`
through `samba.markers.cross_view_labels.CrossViewLabeller`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from samba.body.skeleton import markers_of, standing_pose
from samba.cameras.camera import CameraGroup
from samba.cameras.synthetic_cameras import with_size
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take
from samba.markers.camera_chain import ChainSettings, run_chain
from samba.markers.cross_view_labels import FRESH_FRAMES, CrossViewLabeller, CrossViewSettings
from samba.markers.leg_labels import KNOWN, LegBody, ShinMeter, assign_legs
from samba.markers.observation import evaluation_cameras, spread_cameras

LEGS = [4, 5, 6, 7]  # left knee, right knee, left foot, right foot


@pytest.fixture
def markers() -> np.ndarray:
    """The 8 markers (8, 3) m of the standard pose at the origin."""
    return markers_of(standing_pose())


def _cameras(count: int = 2) -> CameraGroup:
    """`count` 640x480 cameras spread around a subject standing at the origin."""
    poses = np.repeat(standing_pose()[None], 2, axis=0)
    return CameraGroup(tuple(with_size(c, (640, 480)) for c in spread_cameras(poses, count)))


def _legs_lost(labeller: CrossViewLabeller, pixels: np.ndarray) -> None:
    """Step through FRESH_FRAMES + 1 frames with the leg labels lost everywhere and no
    blob of theirs in sight."""
    labelled = pixels.copy()
    labelled[:, LEGS] = np.nan
    for _ in range(FRESH_FRAMES + 1):
        labeller.step(labelled, [np.zeros((0, 2))] * len(pixels))


def _stride(markers: np.ndarray, step_m: float, apart_m: float = 0.1) -> np.ndarray:
    """The markers with the left leg `step_m` forward (+Z) and the right one as far back,
    each `apart_m` farther out to its side: each knee and foot moved together, so the
    shins keep their length."""
    moved = markers.copy()
    moved[[4, 6]] += [apart_m, 0.0, step_m]
    moved[[5, 7]] -= [apart_m, 0.0, step_m]
    return moved


def _find_legs(
    markers: np.ndarray, moved: np.ndarray, settings: CrossViewSettings | None = None
) -> tuple[np.ndarray, np.ndarray, set[tuple[int, int]]]:
    """Lose the legs, then show them at `moved` in both cameras as unlabelled blobs for
    two frames: the labels out of the second (2, 8, 2), the true pixels (2, 8, 2) and
    the (camera, label) found there. The first frame finds nothing: an assignment must
    be seen twice (`LEG_CONFIRM_M`)."""
    cameras = _cameras()
    labeller = CrossViewLabeller(cameras, markers, settings)
    _legs_lost(labeller, cameras.project(markers))
    pixels = cameras.project(moved)
    labelled = pixels.copy()
    labelled[:, LEGS] = np.nan
    _, first = labeller.step(labelled, [pixels[c, LEGS] for c in range(2)])
    assert first == []
    out, found = labeller.step(labelled, [pixels[c, LEGS] for c in range(2)])
    return out, pixels, {(f.camera, f.label) for f in found}


def test_legs_lost_in_both_cameras_are_found_by_their_shape(markers: np.ndarray) -> None:
    # Two cameras: each knee's blob lies on both knees' epipolar lines, so one label at a
    # time has a rival for every blob; the shins and the left-right order settle it.
    out, pixels, found = _find_legs(markers, _stride(markers, 0.15))
    np.testing.assert_allclose(out[:, LEGS], pixels[:, LEGS])
    assert found == {(c, label) for c in range(2) for label in LEGS}


def test_knees_close_in_one_camera_are_found_on_their_own_blobs(markers: np.ndarray) -> None:
    # the knees 11.6 px (2.9 reference pixels) apart in camera 0: near enough to merge
    # as they cross, but two blobs now, each given to one knee of the same assignment
    out, pixels, found = _find_legs(markers, _stride(markers, 0.1, apart_m=0.0))
    np.testing.assert_allclose(out[:, LEGS], pixels[:, LEGS])
    assert found == {(c, label) for c in range(2) for label in LEGS}


def test_a_leg_blob_near_another_markers_view_is_not_given(markers: np.ndarray) -> None:
    # the left wrist, labelled in both cameras, 4 cm from the left knee: the knee's blob
    # may be both merged, so the knee is not labelled; the rest of the legs are
    moved = _stride(markers, 0.15)
    moved[2] = moved[4] + [0.04, 0.0, 0.0]
    out, pixels, found = _find_legs(markers, moved)
    assert not any(label == 4 for _, label in found)
    assert found >= {(c, label) for c in range(2) for label in (5, 7)}
    np.testing.assert_allclose(out[:, [5, 7]], pixels[:, [5, 7]])


def test_legs_that_jump_between_frames_are_not_labelled(markers: np.ndarray) -> None:
    # Two frames that each fit, 30 cm apart: a coincidence (a ghost that fits the shins
    # in one frame), not legs that moved.
    cameras = _cameras()
    labeller = CrossViewLabeller(cameras, markers)
    _legs_lost(labeller, cameras.project(markers))
    for step_m in (0.0, 0.15):
        pixels = cameras.project(_stride(markers, step_m))
        labelled = pixels.copy()
        labelled[:, LEGS] = np.nan
        _, found = labeller.step(labelled, [pixels[c, LEGS] for c in range(2)])
        assert found == []


def test_without_the_legs_rule_they_stay_lost(markers: np.ndarray) -> None:
    out, _, found = _find_legs(markers, _stride(markers, 0.15), CrossViewSettings(legs=None))
    assert found == set()
    assert np.isnan(out[:, LEGS]).all()


def test_legs_side_by_side_in_depth_stay_lost(markers: np.ndarray) -> None:
    # Knees and feet 4 cm apart sideways (less than `side_margin_m`), one leg 40 cm
    # forward: nothing tells which is which.
    together = _stride(markers, 0.2, apart_m=0.0)
    together[[4, 6], 0] = 0.02
    together[[5, 7], 0] = -0.02
    out, _, found = _find_legs(markers, together)
    assert found == set()
    assert np.isnan(out[:, LEGS]).all()


def test_legs_with_a_wrong_shin_stay_lost(markers: np.ndarray) -> None:
    # A foot 10 cm off its knee's standing distance (a blob of something else there).
    moved = _stride(markers, 0.15)
    moved[6, 1] += 0.10
    _, _, found = _find_legs(markers, moved)
    assert found == set()


def test_assign_legs_refuses_two_fitting_answers_that_disagree(markers: np.ndarray) -> None:
    body = LegBody.from_markers(markers)
    current = markers.copy()
    current[LEGS] = np.nan
    # two copies of the legs 20 cm apart: either set fits, each blob its own
    points = np.concatenate([markers[LEGS], markers[LEGS] + [0.0, 0.0, 0.2]])
    blobs = np.arange(8)[None, :].repeat(2, axis=0)
    allowed = np.zeros((8, 8), dtype=bool)
    allowed[LEGS] = True
    assert (assign_legs(current, points, blobs, allowed, body) == KNOWN).all()
    chosen = assign_legs(current, points[:4], blobs[:, :4], allowed[:, :4], body)
    np.testing.assert_array_equal(chosen[LEGS], [0, 1, 2, 3])


def test_assign_legs_needs_the_shoulders_and_candidates(markers: np.ndarray) -> None:
    body = LegBody.from_markers(markers)
    current = markers.copy()
    current[LEGS] = np.nan
    points = markers[LEGS]
    blobs = np.arange(4)[None, :].repeat(2, axis=0)
    allowed = np.zeros((8, 4), dtype=bool)
    allowed[LEGS] = True
    assert (assign_legs(current, points, blobs, allowed, body)[LEGS] >= 0).all()
    no_shoulder = current.copy()
    no_shoulder[1] = np.nan
    assert (assign_legs(no_shoulder, points, blobs, allowed, body) == KNOWN).all()
    none = np.zeros((0, 3))
    assert (assign_legs(current, none, blobs[:, :0], allowed[:, :0], body) == KNOWN).all()
    one_short = allowed.copy()
    one_short[6] = False  # the left foot may take no candidate: nothing is placed
    assert (assign_legs(current, points, blobs, one_short, body) == KNOWN).all()


def test_shin_meter_measures_the_subject(markers: np.ndarray) -> None:
    meter = ShinMeter()
    assert np.isnan(meter.shins).all()
    longer = markers.copy()
    longer[[6, 7], 1] -= 0.04  # feet 4 cm lower: shins 4 cm longer
    meter.add(longer)
    half = longer.copy()
    half[4] = np.nan  # the left knee not triangulated: only the right shin counts
    meter.add(half)
    standing = LegBody.from_markers(markers).shins
    np.testing.assert_allclose(meter.shins, standing + 0.04)
    scaled = LegBody.from_markers(markers).scaled(np.array([np.nan, standing[1] + 0.04]))
    np.testing.assert_allclose(scaled.shins, [standing[0], standing[1] + 0.04])


def test_two_cameras_keep_more_leg_markers_of_held_out_motion(cmu_files: list[Path]) -> None:
    # The camera issue's held-out take, two evaluation cameras at 160x120: without the
    # legs' labelling its knees and feet are lost for good after the lead-in.
    path = next(f for f in cmu_files if f.name == "iclone_007_05.bvh")
    poses = load_bvh_take(path, BvhImportOptions(skip_tpose=True)).poses
    cameras = evaluation_cameras(poses)
    without = run_chain(
        poses, cameras, 30.0, ChainSettings(cross_view=CrossViewSettings(legs=None))
    )
    with_legs = run_chain(poses, cameras, 30.0, ChainSettings())
    assert with_legs.swaps() == 0
    assert with_legs.phantoms() == 0
    legs = slice(4, 8)
    assert without.reconstructed[:, legs].mean() < 0.05
    assert with_legs.reconstructed[:, legs].mean() > 0.1
    assert with_legs.rms_error() < 0.015
