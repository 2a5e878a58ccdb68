"""The labels of every camera of a stage at once (`samba.markers.stage_tracking.StageTracker`)."""

from __future__ import annotations

import numpy as np
import pytest

from samba.body.skeleton import markers_of, standing_pose
from samba.cameras.camera import Camera, CameraGroup
from samba.cameras.synthetic_cameras import with_size
from samba.markers.cross_view_labels import CrossViewSettings
from samba.markers.observation import spread_cameras
from samba.markers.stage_tracking import StageTracker
from samba.markers.tracking import TrackerSettings, subject_distance

L_WRIST, L_FOOT = 2, 6


def test_a_tracker_on_a_wrong_blob_is_taken_off_it_and_given_the_right_one() -> None:
    # Camera 0's tracker holds the left wrist's label on the left foot's blob (it kept
    # following a blob after its own marker was hidden); cameras 1 and 2 see the wrist
    # where it is. The stage takes camera 0's tracker off the foot, and the cross-view
    # labelling gives it the wrist's own blob.
    poses = np.repeat(standing_pose()[None], 2, axis=0)
    cameras = CameraGroup(tuple(with_size(c, (640, 480)) for c in spread_cameras(poses, 3)))
    pixels = cameras.project(markers_of(standing_pose()))  # (3, 8, 2)
    start = pixels.copy()
    start[0, L_WRIST] = pixels[0, L_FOOT]
    start[0, L_FOOT] = np.nan
    stage = StageTracker.from_labels(cameras, start, cross_view=CrossViewSettings())
    blobs = list(pixels)
    first = stage.step(blobs)
    assert np.isnan(first[0, L_WRIST]).all()
    assert stage.trackers[0].lost_frames[L_WRIST] > stage.trackers[0].settings.coast_frames
    later = [stage.step(blobs) for _ in range(3)][-1]
    np.testing.assert_allclose(later[0, L_WRIST], pixels[0, L_WRIST])
    assert not np.isnan(later[1:]).any()


def test_trackers_started_from_labels_fit_the_subjects_distance() -> None:
    # Three 640x480 cameras 12 m from a subject standing still: from the nodes' labels
    # the stage cannot know the distance, so its trackers start at 4 pixels per reference
    # pixel; once the markers triangulate, at about 2 (as `TrackerSettings.for_camera`).
    pose = standing_pose()
    far = np.repeat(pose[None], 2, axis=0)
    cameras = [with_size(c, (640, 480)) for c in spread_cameras(far, 3)]
    hips = pose[[7, 8]].mean(axis=0)
    moved = tuple(
        Camera.look_at(c.name, hips + 12.0 * _unit(c.center - hips), hips, c.size, 60.0)
        for c in cameras
    )
    group = CameraGroup(moved)
    pixels = group.project(markers_of(pose))
    stage = StageTracker.from_labels(group, pixels, cross_view=CrossViewSettings())
    assert [t.settings.gate_px for t in stage.trackers] == pytest.approx([12.0] * 3)
    stage.step(list(pixels))
    expected = [TrackerSettings.for_camera(c, subject_distance(c, markers_of(pose))) for c in moved]
    assert [t.settings for t in stage.trackers] == expected
    assert all(5.5 < t.settings.gate_px < 6.5 for t in stage.trackers)


def _unit(vector: np.ndarray) -> np.ndarray:
    """`vector` (3,) scaled to length 1."""
    return vector / np.linalg.norm(vector)
