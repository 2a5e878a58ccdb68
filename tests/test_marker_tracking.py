"""Tests of the 8-label tracker `samba.markers.tracking`: crossing, merging, occlusion."""

from __future__ import annotations

import numpy as np
import pytest

from samba.base.errors import InputError
from samba.body.skeleton import markers_of, standard_pose
from samba.cameras.camera import Camera
from samba.markers.tracking import (
    REFERENCE_DISTANCE_M,
    REFERENCE_FOCAL_PX,
    MarkerTracker,
    TrackerSettings,
    pixel_scale,
)

# a subject facing a 160x120 camera: shoulders, wrists, knees, feet (pixels)
BASE = np.array(
    [[70, 40], [90, 40], [55, 62], [105, 62], [74, 82], [86, 82], [74, 104], [86, 104]],
    dtype=np.float64,
)
L_WRIST, R_WRIST, L_KNEE = 2, 3, 4


def _sway(frames: int) -> np.ndarray:
    """Every marker swaying gently around `BASE`: (frames, 8, 2) pixels."""
    t = np.arange(frames)[:, None, None]
    phase = np.arange(8)[None, :, None] * 0.7
    return BASE + 1.5 * np.sin(0.15 * t + phase) * np.array([1.0, 0.5])


def _blobs(truth: np.ndarray, hidden: np.ndarray | None = None, merge_px: float = 1.5):
    """Per-frame centroid lists from truth (F, 8, 2): hidden markers left out, markers
    closer than `merge_px` merged into one blob at their mean, order shuffled."""
    rng = np.random.default_rng(0)
    frames = []
    for f, points in enumerate(truth):
        shown = points[~hidden[f]] if hidden is not None else points
        merged, used = [], np.zeros(len(shown), bool)
        for i in range(len(shown)):
            if used[i]:
                continue
            near = ~used & (np.linalg.norm(shown - shown[i], axis=-1) < merge_px)
            used |= near
            merged.append(shown[near].mean(axis=0))
        frames.append(rng.permutation(np.array(merged).reshape(-1, 2)))
    return frames


def _wrong(tracked: np.ndarray, truth: np.ndarray) -> int:
    """Labels reported anywhere but on their own marker (frames x labels)."""
    reported = ~np.isnan(tracked[..., 0])
    return int((reported & (np.linalg.norm(tracked - truth, axis=-1) > 1e-6)).sum())


def _crossing(frames: int = 40, bounce: bool = False) -> np.ndarray:
    """The wrists move towards each other at 2 px/frame each and cross (or, with
    `bounce`, meet, stay together three frames and go back)."""
    truth = _sway(frames)
    t = np.arange(frames, dtype=np.float64)
    travel = np.minimum(t, 12.0) - np.clip(t - 15.0, 0.0, None) if bounce else t
    truth[:, L_WRIST] = np.stack([55 + 2 * travel, np.full(frames, 62.0)], axis=-1)
    truth[:, R_WRIST] = np.stack([105 - 2 * travel, np.full(frames, 62.4)], axis=-1)
    return truth


def test_labels_follow_moving_markers_exactly() -> None:
    truth = _sway(60)
    tracked = MarkerTracker(BASE).track(_blobs(truth))
    assert tracked.shape == (60, 8, 2)
    assert np.allclose(tracked, truth)


def test_crossing_markers_are_dropped_never_swapped() -> None:
    truth = _crossing()
    tracked = MarkerTracker(BASE).track(_blobs(truth, merge_px=2.5))
    assert _wrong(tracked, truth) == 0
    wrists = tracked[:, [L_WRIST, R_WRIST], 0]
    assert np.isnan(wrists[12:14]).all()  # dropped while they cross (frame 12.5)
    assert not np.isnan(wrists[:8]).any() and not np.isnan(wrists[-8:]).any()  # and back
    assert not np.isnan(np.delete(tracked, [L_WRIST, R_WRIST], axis=1)).any()


def test_markers_that_meet_and_go_back_are_not_swapped() -> None:
    truth = _crossing(bounce=True)
    guarded = MarkerTracker(BASE).track(_blobs(truth))
    assert _wrong(guarded, truth) == 0
    assert np.isnan(guarded[13:18, [L_WRIST, R_WRIST]]).all()  # they stop 2 px apart
    # the paper's plain nearest-neighbour filter carries the labels on across each other
    plain = MarkerTracker(BASE, TrackerSettings(guard_swaps=False)).track(_blobs(truth))
    assert _wrong(plain, truth) > 0


def test_a_marker_that_passes_behind_another_is_not_taken_for_it() -> None:
    truth = _sway(30)
    truth[:, L_KNEE] = truth[:, L_KNEE + 1] + np.linspace([-8, 0], [8, 0], 30)
    hidden = np.zeros((30, 8), bool)
    hidden[13:17, L_KNEE + 1] = True  # the right knee hides behind the left one
    tracked = MarkerTracker(BASE).track(_blobs(truth, hidden))
    assert _wrong(tracked, truth) == 0


def test_a_blob_of_a_marker_that_jumped_while_hidden_is_not_taken_by_another() -> None:
    # Both feet hidden a frame; the right foot comes back 11 px from where its label looks
    # for it (a kick), just where the left foot was, which stays hidden. The left foot's
    # label must not take it: the right foot's label found nothing in its gate, so the
    # new blob may be the right foot's.
    l_foot, r_foot = 6, 7
    truth = _sway(16)
    hidden = np.zeros((16, 8), bool)
    hidden[10:, l_foot] = True
    hidden[10, r_foot] = True
    truth[11:, r_foot] = truth[11:, l_foot] + [1.0, 0.0]
    tracked = MarkerTracker(BASE).track(_blobs(truth, hidden))
    assert _wrong(tracked, truth) == 0
    assert np.isnan(tracked[11:, [l_foot, r_foot]]).all()


def test_a_label_on_a_blob_of_two_merged_markers_is_not_reported() -> None:
    # The right knee, hidden behind the left one for 11 frames (its label searching where
    # it was last seen), comes out 1 px from it: one blob, whose centroid is neither
    # knee's. Flagged (`Blobs.merged`), the left knee's label is not reported on it;
    # unflagged, it is, 0.5 px off.
    truth = _sway(14)
    truth[:, L_KNEE + 1] = truth[:, L_KNEE] + np.linspace([-8, 0], [1, 0], 14)
    hidden = np.zeros((14, 8), bool)
    hidden[2:13, L_KNEE + 1] = True
    blobs = _blobs(truth, hidden, merge_px=3.0)
    for flag in (True, False):
        tracker = MarkerTracker(BASE + truth[0] - _sway(1)[0])
        tracked = []
        for f, centroids in enumerate(blobs):
            merged = np.zeros(len(centroids), dtype=bool)
            if flag and f == 13:
                merged[np.argmin(np.linalg.norm(centroids - truth[f, L_KNEE], axis=-1))] = True
            tracked.append(tracker.step(centroids, merged))
        tracked = np.stack(tracked)
        assert not np.isnan(tracked[:13, L_KNEE]).any()  # through the occlusion
        assert _wrong(tracked[:13], truth[:13]) == 0
        assert np.isnan(tracked[13, L_KNEE]).all() == flag


def test_unlabelled_blobs_come_with_their_motion() -> None:
    # the left wrist's label is abandoned; its blob, unlabelled, moves 1 px a frame
    start = BASE.copy()
    start[L_WRIST] = np.nan
    tracker = MarkerTracker(start)
    frames = [BASE + [[f, 0.0]] * np.eye(8)[L_WRIST][:, None] for f in range(3)]
    tracker.step(frames[0])
    np.testing.assert_array_equal(tracker.anonymous_blobs, frames[0][[L_WRIST]])
    assert np.isnan(tracker.anonymous_motion).all()  # a new track: its motion unknown
    for frame in frames[1:]:
        tracker.step(frame)
        np.testing.assert_allclose(tracker.anonymous_motion, [[1.0, 0.0]])


def test_a_marker_is_reacquired_after_an_occlusion() -> None:
    truth = _sway(50)
    hidden = np.zeros((50, 8), bool)
    hidden[10:12, 0] = True  # two frames: the label coasts
    hidden[20:35, L_WRIST] = True  # fifteen frames: the label searches
    tracked = MarkerTracker(BASE).track(_blobs(truth, hidden))
    assert _wrong(tracked, truth) == 0
    assert np.isnan(tracked[10:12, 0]).all() and not np.isnan(tracked[12:, 0]).any()
    assert np.isnan(tracked[20:35, L_WRIST]).all() and not np.isnan(tracked[35:, L_WRIST]).any()


def test_a_dropped_frame_loses_every_label_for_that_frame_only() -> None:
    truth = _sway(20)
    blobs = _blobs(truth)
    blobs[8] = np.zeros((0, 2))
    tracked = MarkerTracker(BASE).track(blobs)
    assert np.isnan(tracked[8]).all()
    assert np.allclose(np.delete(tracked, 8, axis=0), np.delete(truth, 8, axis=0))


def test_an_abandoned_label_comes_back_only_through_reacquire() -> None:
    truth = _sway(60)
    hidden = np.zeros((60, 8), bool)
    hidden[5:45, [L_KNEE, L_KNEE + 1]] = True  # both knees: no elimination possible
    tracker = MarkerTracker(BASE)
    blobs = _blobs(truth, hidden)
    tracked = tracker.track(blobs[:50])
    assert np.isnan(tracked[45:, [L_KNEE, L_KNEE + 1]]).all()
    assert tracker.lost_frames[L_KNEE] > tracker.settings.max_lost_frames
    assert len(tracker.anonymous_blobs) == 2
    tracker.reacquire(L_KNEE, truth[49, L_KNEE])
    rest = tracker.track(blobs[50:])
    assert np.allclose(rest[:, L_KNEE], truth[50:, L_KNEE])
    assert _wrong(rest, truth[50:]) == 0


def test_a_released_label_lets_go_of_its_blob_until_reacquired() -> None:
    truth = _sway(30)
    hidden = np.zeros((30, 8), bool)
    hidden[10:, L_KNEE + 1] = True  # the right knee is gone: no finding by elimination
    blobs = _blobs(truth, hidden)
    tracker = MarkerTracker(BASE)
    tracker.track(blobs[:10])
    tracker.release(L_KNEE)  # another camera's views say this blob is not the left knee
    after = tracker.track(blobs[10:20])
    assert np.isnan(after[:, L_KNEE]).all()
    assert tracker.lost_frames[L_KNEE] > tracker.settings.coast_frames
    assert any(np.allclose(b, truth[19, L_KNEE]) for b in tracker.anonymous_blobs)
    tracker.reacquire(L_KNEE, truth[19, L_KNEE])
    rest = tracker.track(blobs[20:])
    assert np.allclose(rest[:, L_KNEE], truth[20:, L_KNEE])
    assert _wrong(np.concatenate([after, rest]), truth[10:]) == 0


def test_the_start_may_be_off_by_a_few_pixels() -> None:
    truth = _sway(10)
    start = BASE + np.random.default_rng(1).uniform(-2.5, 2.5, BASE.shape)
    tracked = MarkerTracker(start).track(_blobs(truth))
    assert np.allclose(tracked, truth)


def test_initial_labels_from_the_standard_pose() -> None:
    camera = Camera.look_at("front", (1.0, 1.2, 4.0), (1.0, 0.9, 0.0), (160, 120), 60.0)
    pose = standard_pose(1.8)
    pose[:, 0] += 1.0
    expected = camera.project(markers_of(pose))
    tracker = MarkerTracker.from_standard_pose(camera, (1.0, 0.0), 0.0, 1.8)
    assert np.allclose(tracker.step(expected[::-1].copy()), expected)
    assert tracker.settings == TrackerSettings()  # 160 px wide, 60 degrees: the reference
    turned = MarkerTracker.from_standard_pose(camera, (1.0, 0.0), 180.0, 1.8)
    assert np.allclose(turned.step(expected), expected[[1, 0, 3, 2, 5, 4, 7, 6]])


def test_settings_scale_with_the_focal_length() -> None:
    camera = Camera.look_at("hd", (0, 1.5, 4), (0, 1, 0), (640, 480), 60.0)
    settings = TrackerSettings.for_camera(camera, ambiguity_px=2.0)
    assert camera.matrix[0, 0] / REFERENCE_FOCAL_PX == pytest.approx(4.0)
    assert settings.gate_px == pytest.approx(4 * TrackerSettings().gate_px)
    assert settings.ambiguity_px == pytest.approx(8.0)
    assert settings.coast_frames == TrackerSettings().coast_frames
    with pytest.raises(ValueError, match="unknown tracker settings: gate"):
        TrackerSettings.for_camera(camera, gate=3.0)


def test_settings_shrink_for_a_subject_far_away() -> None:
    # 640 px wide: 4 pixels per reference pixel for a subject within 6 m; one 24 m away
    # looks four times smaller, as at 160x120 from 6 m, and 48 m away no smaller than that
    camera = Camera.look_at("hd", (0, 1.5, 4), (0, 1, 0), (640, 480), 60.0)
    assert REFERENCE_DISTANCE_M == 6.0
    assert pixel_scale(camera) == pytest.approx(4.0)
    assert pixel_scale(camera, 6.0) == pytest.approx(4.0)
    assert pixel_scale(camera, 24.0) == pytest.approx(1.0)
    assert pixel_scale(camera, 48.0) == pytest.approx(1.0)
    far = TrackerSettings.for_camera(camera, 12.0)
    assert far.gate_px == pytest.approx(2 * TrackerSettings().gate_px)
    tracker = MarkerTracker.from_standard_pose(camera, (0.0, -8.0))  # about 12 m away
    assert tracker.settings.gate_px == pytest.approx(far.gate_px, rel=0.01)


def test_bad_inputs_raise_input_errors() -> None:
    with pytest.raises(InputError, match="initial"):
        MarkerTracker(np.zeros((7, 2)))
    tracker = MarkerTracker(BASE)
    with pytest.raises(InputError, match="centroids"):
        tracker.step(np.zeros((3, 3)))
    with pytest.raises(InputError, match="centroids"):
        tracker.step(np.array([[np.nan, 1.0]]))
    with pytest.raises(InputError, match="merged"):
        tracker.step(BASE, np.zeros(7, dtype=bool))
    with pytest.raises(InputError, match="label"):
        tracker.reacquire(8, (1.0, 2.0))
    with pytest.raises(InputError, match="label"):
        tracker.release(-1)
    with pytest.raises(InputError, match="l_wrist"):
        tracker.reacquire(L_WRIST, (np.inf, 2.0))
