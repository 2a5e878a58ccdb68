"""Lost marker labels found again across cameras (`samba.markers.cross_view_labels`)."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from samba.base.errors import InputError
from samba.body.skeleton import markers_of, standing_pose
from samba.cameras.camera import Camera, CameraGroup
from samba.cameras.synthetic_cameras import with_size
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take
from samba.markers.camera_chain import ChainSettings, run_chain
from samba.markers.cross_view_labels import FRESH_FRAMES, CrossViewLabeller, Reacquisition
from samba.markers.observation import spread_cameras
from samba.markers.tracking import TrackerSettings
from samba.synthetic.motions import generate

L_WRIST, R_WRIST, L_KNEE, L_FOOT = 2, 3, 4, 6


@pytest.fixture
def markers() -> np.ndarray:
    """The 8 markers (8, 3) m of the standard pose at the origin."""
    return markers_of(standing_pose())


def _group(markers: np.ndarray, count: int) -> CameraGroup:
    """`count` 640x480 cameras spread around a subject standing at the markers."""
    poses = np.repeat(standing_pose()[None], 2, axis=0)
    return CameraGroup(tuple(with_size(c, (640, 480)) for c in spread_cameras(poses, count)))


def _behind(markers: np.ndarray, camera: Camera) -> np.ndarray:
    """The markers with the right wrist 10 cm right behind the left one as `camera`
    sees them: one blob there for both."""
    hidden = markers.copy()
    ray = hidden[L_WRIST] - camera.center
    hidden[R_WRIST] = hidden[L_WRIST] + 0.1 * ray / np.linalg.norm(ray)
    return hidden


def _unlabelled(pixels: np.ndarray, lost: dict[int, list[int]]) -> list[np.ndarray]:
    """Per camera, the true pixels of the labels lost there (the blobs left unlabelled)."""
    return [pixels[c, lost.get(c, [])] for c in range(len(pixels))]


def test_a_label_lost_in_one_camera_is_found_from_the_others(markers: np.ndarray) -> None:
    cameras = _group(markers, 2)
    labeller = CrossViewLabeller(cameras, markers)
    pixels = cameras.project(markers)
    labelled = pixels.copy()
    labelled[1, L_WRIST] = np.nan
    out, found = labeller.step(labelled, _unlabelled(pixels, {1: [L_WRIST]}))
    np.testing.assert_allclose(out, pixels)
    assert found == [Reacquisition(1, L_WRIST, tuple(pixels[1, L_WRIST]))]


def test_a_blob_moving_unlike_the_label_is_not_taken(markers: np.ndarray) -> None:
    # camera 1's blob lies where the left wrist projects, but it moved 3 px (0.75
    # reference pixels) since the frame before while the wrist stood still: another
    # marker's blob that the wrist hides behind
    cameras = _group(markers, 2)
    pixels = cameras.project(markers)
    labelled = pixels.copy()
    labelled[1, L_WRIST] = np.nan
    blobs = _unlabelled(pixels, {1: [L_WRIST]})
    for move, taken in (([3.0, 0.0], False), ([1.0, 0.5], True), ([np.nan, np.nan], True)):
        labeller = CrossViewLabeller(cameras, markers)
        motion = [np.zeros((0, 2)), np.array([move])]
        out, found = labeller.step(labelled, blobs, motion)
        assert (found == [Reacquisition(1, L_WRIST, tuple(pixels[1, L_WRIST]))]) == taken
        assert np.isnan(out[1, L_WRIST]).all() != taken


def test_a_label_lost_everywhere_is_found_near_its_prediction(markers: np.ndarray) -> None:
    cameras = _group(markers, 3)
    labeller = CrossViewLabeller(cameras, markers)
    moved = markers.copy()
    moved[R_WRIST] += [0.03, 0.02, 0.0]  # 3.6 cm from where it was: inside the gate
    pixels = cameras.project(moved)
    labelled = pixels.copy()
    labelled[:, R_WRIST] = np.nan
    out, found = labeller.step(labelled, _unlabelled(pixels, {0: [R_WRIST], 1: [R_WRIST]}))
    np.testing.assert_allclose(out[:2, R_WRIST], pixels[:2, R_WRIST])
    assert np.isnan(out[2, R_WRIST]).all()  # its blob there was not sent
    assert {(f.camera, f.label) for f in found} == {(0, R_WRIST), (1, R_WRIST)}


def test_two_blobs_on_the_epipolar_line_leave_the_label_lost(markers: np.ndarray) -> None:
    cameras = _group(markers, 2)
    labeller = CrossViewLabeller(cameras, markers)
    pixels = cameras.project(markers)
    # a second blob in camera 1 where a point 5 cm farther along camera 0's ray shows
    ray = markers[L_WRIST] - cameras[0].center
    decoy = cameras[1].project(markers[L_WRIST] + 0.05 * ray / np.linalg.norm(ray))
    labelled = pixels.copy()
    labelled[1, L_WRIST] = np.nan
    unlabelled = [np.zeros((0, 2)), np.stack([pixels[1, L_WRIST], decoy])]
    out, found = labeller.step(labelled, unlabelled)
    assert found == []
    assert np.isnan(out[1, L_WRIST]).all()


def _wrist_on_blob_of(
    markers: np.ndarray, count: int, other: int
) -> tuple[CrossViewLabeller, np.ndarray]:
    """A labeller of `count` cameras after one frame in which camera 0's tracker put the
    left wrist's label on marker `other`'s blob (and lost `other`); the others are right.
    Returns the labeller and the frame's output labels (c, 8, 2)."""
    cameras = _group(markers, count)
    labeller = CrossViewLabeller(cameras, markers)
    pixels = cameras.project(markers)
    labelled = pixels.copy()
    labelled[0, L_WRIST] = pixels[0, other]
    labelled[0, other] = np.nan
    out, _ = labeller.step(labelled, [np.zeros((0, 2))] * count)
    return labeller, out


def test_a_view_the_other_two_outvote_is_dropped_and_named(markers: np.ndarray) -> None:
    labeller, out = _wrist_on_blob_of(markers, 3, L_FOOT)
    assert np.isnan(out[0, L_WRIST]).all()
    expected = np.zeros((3, 8), dtype=bool)
    expected[0, L_WRIST] = True
    np.testing.assert_array_equal(labeller.outvoted, expected)


def test_a_view_meeting_one_other_is_not_outvoted(markers: np.ndarray) -> None:
    # camera 0's wrong view meets camera 2's within the tolerance (a near ghost): the
    # right views of cameras 1 and 2 do not outvote it, lest a right view be released
    labeller, _ = _wrist_on_blob_of(markers, 3, L_KNEE)
    assert not labeller.outvoted.any()


def test_a_view_newer_than_two_that_meet_is_outvoted_though_it_meets_one(
    markers: np.ndarray,
) -> None:
    # as above, but camera 0 has just put the label on the knee's blob, after a frame
    # without it, while cameras 1 and 2 have held theirs for two frames
    cameras = _group(markers, 3)
    labeller = CrossViewLabeller(cameras, markers)
    pixels = cameras.project(markers)
    lost = pixels.copy()
    lost[0, L_WRIST] = np.nan
    labeller.step(lost, [np.zeros((0, 2))] * 3)
    assert not labeller.outvoted.any()
    wrong = pixels.copy()
    wrong[0, L_WRIST], wrong[0, L_KNEE] = pixels[0, L_KNEE], np.nan
    out, _ = labeller.step(wrong, [np.zeros((0, 2))] * 3)
    expected = np.zeros((3, 8), dtype=bool)
    expected[0, L_WRIST] = True
    np.testing.assert_array_equal(labeller.outvoted, expected)
    np.testing.assert_allclose(out[1:, L_WRIST], pixels[1:, L_WRIST])


def test_two_disagreeing_views_are_dropped_but_neither_is_outvoted(markers: np.ndarray) -> None:
    labeller, out = _wrist_on_blob_of(markers, 2, L_KNEE)
    assert np.isnan(out[:, L_WRIST]).all()  # one of the two is wrong: which, no view says
    assert not labeller.outvoted.any()


def _lost_for_a_while(labeller: CrossViewLabeller, pixels: np.ndarray, labels: list[int]) -> None:
    """Step the labeller through FRESH_FRAMES + 1 frames with `labels` lost everywhere and
    no blob of theirs in sight."""
    labelled = pixels.copy()
    labelled[:, labels] = np.nan
    for _ in range(FRESH_FRAMES + 1):
        labeller.step(labelled, [np.zeros((0, 2))] * len(pixels))


def test_a_label_lost_long_is_found_again_within_reach_of_its_neighbour(
    markers: np.ndarray,
) -> None:
    # Two cameras: the wrist comes back 25 cm from where it was lost (beyond the gate of
    # a fresh prediction), within arm's reach of its shoulder, the one blob pair in sight.
    cameras = _group(markers, 2)
    labeller = CrossViewLabeller(cameras, markers)
    _lost_for_a_while(labeller, cameras.project(markers), [R_WRIST])
    moved = markers.copy()
    moved[R_WRIST] += [0.0, 0.15, 0.2]
    pixels = cameras.project(moved)
    labelled = pixels.copy()
    labelled[:, R_WRIST] = np.nan
    out, found = labeller.step(labelled, _unlabelled(pixels, {0: [R_WRIST], 1: [R_WRIST]}))
    np.testing.assert_allclose(out[:, R_WRIST], pixels[:, R_WRIST])
    assert {(f.camera, f.label) for f in found} == {(0, R_WRIST), (1, R_WRIST)}


def test_two_labels_lost_long_that_could_take_the_same_blobs_stay_lost(
    markers: np.ndarray,
) -> None:
    cameras = _group(markers, 2)
    labeller = CrossViewLabeller(cameras, markers)
    _lost_for_a_while(labeller, cameras.project(markers), [L_WRIST, R_WRIST])
    moved = markers.copy()
    moved[[L_WRIST, R_WRIST]] = (markers[L_WRIST] + markers[R_WRIST]) / 2 + [
        [0.05, 0.3, 0.3],
        [-0.05, 0.3, 0.3],
    ]
    pixels = cameras.project(moved)
    labelled = pixels.copy()
    labelled[:, [L_WRIST, R_WRIST]] = np.nan
    unlabelled = _unlabelled(pixels, {0: [L_WRIST, R_WRIST], 1: [L_WRIST, R_WRIST]})
    out, found = labeller.step(labelled, unlabelled)
    assert found == []  # hands together in front: either wrist could be either blob
    assert np.isnan(out[:, [L_WRIST, R_WRIST]]).all()


def test_a_blob_far_from_the_prediction_is_not_taken(markers: np.ndarray) -> None:
    cameras = _group(markers, 2)
    labeller = CrossViewLabeller(cameras, markers)
    moved = markers.copy()
    moved[R_WRIST] += [0.0, 0.5, 0.0]  # half a meter up in one frame: not this marker
    pixels = cameras.project(moved)
    labelled = pixels.copy()
    labelled[:, R_WRIST] = np.nan
    _, found = labeller.step(labelled, _unlabelled(pixels, {0: [R_WRIST], 1: [R_WRIST]}))
    assert found == []


def test_a_blob_another_lost_marker_projects_onto_is_left_alone(markers: np.ndarray) -> None:
    cameras = _group(markers, 3)
    labeller = CrossViewLabeller(cameras, markers)
    # camera 1's one blob of both wrists lies on the left wrist's epipolar lines
    pixels = cameras.project(_behind(markers, cameras[1]))
    labelled = pixels.copy()
    labelled[1, [L_WRIST, R_WRIST]] = np.nan
    out, found = labeller.step(labelled, _unlabelled(pixels, {1: [L_WRIST]}))
    assert found == []
    assert np.isnan(out[1, [L_WRIST, R_WRIST]]).all()


def test_a_label_on_two_merged_markers_is_dropped(markers: np.ndarray) -> None:
    cameras = _group(markers, 3)
    labeller = CrossViewLabeller(cameras, markers)
    pixels = cameras.project(_behind(markers, cameras[2]))
    labelled = pixels.copy()
    labelled[2, R_WRIST] = np.nan  # camera 2's tracker kept the left wrist on the blob
    out, found = labeller.step(labelled, [np.zeros((0, 2))] * 3)
    assert found == []
    assert np.isnan(out[2, [L_WRIST, R_WRIST]]).all()
    np.testing.assert_allclose(out[:2], pixels[:2])


def test_bad_input_names_the_argument(markers: np.ndarray) -> None:
    cameras = _group(markers, 2)
    with pytest.raises(InputError, match="initial"):
        CrossViewLabeller(cameras, markers[:5])
    with pytest.raises(InputError, match="cameras"):
        CrossViewLabeller(CameraGroup((cameras[0],)), markers)
    labeller = CrossViewLabeller(cameras, markers)
    with pytest.raises(InputError, match="labelled"):
        labeller.step(np.zeros((3, 8, 2)), [np.zeros((0, 2))] * 3)
    with pytest.raises(InputError, match="unlabelled"):
        labeller.step(np.zeros((2, 8, 2)), [np.zeros((0, 2))])
    with pytest.raises(InputError, match="motion"):
        labeller.step(np.zeros((2, 8, 2)), [np.zeros((1, 2))] * 2, [np.zeros((0, 2))] * 2)


def test_cross_view_labelling_recovers_markers_without_swaps() -> None:
    poses = generate("kick", seconds=4, fps=30, seed=5).poses
    cameras = [with_size(c, (320, 240)) for c in spread_cameras(poses, 3)]
    alone = run_chain(poses, cameras, 30.0, ChainSettings(cross_view=None))
    together = run_chain(poses, cameras, 30.0, ChainSettings())
    assert together.swaps() == 0
    assert together.phantoms() == 0
    assert together.lost_rate() < alone.lost_rate()
    assert together.rms_error() < 0.015


def test_a_subject_turning_side_on_gets_no_marker_on_the_other_shoulder() -> None:
    # Three cameras at shoulder height around a subject turning on the spot: the right
    # shoulder hides behind the left one in camera 2, whose label goes on the left
    # shoulder's blob; every pair of shoulder views meets (both at one height), and once
    # camera 0 lost sight of it the wrong view and camera 1's put the right shoulder
    # 59 cm off for 15 frames, until the newer wrong view was taken off its blob.
    take = generate("turn", seed=1)
    cameras = [with_size(c, (160, 120)) for c in spread_cameras(take.poses, 3)]
    result = run_chain(take.poses, cameras, take.fps, seed=1)
    error = np.linalg.norm(result.markers - result.truth, axis=-1)
    assert np.nanmax(error) < 0.05


@pytest.mark.slow
def test_four_cameras_keep_a_salsas_feet_apart(cmu_files: list[Path]) -> None:
    # Four 640x480 cameras round a salsa (8 s of daz_salsa_01), the trackers' distances
    # 8% tighter (as for a subject 6.5 m away): a camera's tracker put the left foot's
    # label on the right foot's blob as the left one hid behind it. That view was dropped
    # (its views disagreed) but, counted as held since long before, it outvoted the two
    # newer right views: 28 label views were swaps.
    path = next(f for f in cmu_files if f.name == "daz_salsa_01.bvh")
    take = load_bvh_take(path, BvhImportOptions(skip_tpose=True))
    cameras = [with_size(c, (640, 480)) for c in spread_cameras(take.poses[:360], 4)]
    tighter = asdict(TrackerSettings().scaled(0.92))
    result = run_chain(take.poses[:240], cameras, take.fps, ChainSettings(tracker=tighter))
    assert result.swaps() == 0
    assert result.rms_error() < 0.005
