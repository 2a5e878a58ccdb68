"""Silhouettes without an empty stage: the learnt person segmenter (MediaPipe Pose in an
environment of its own) on the real lab videos, and its failures as one line."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import shared_data_dir

from samba.silhouette import PersonSegmenter, SegmenterError, SilhouetteExtractor


@pytest.fixture(scope="module")
def cam01() -> np.ndarray:
    """Frames 0-59 of the shared lab's first camera (1080 x 1920, BGR)."""
    data = shared_data_dir()
    video = None if data is None else data / "pose2sim" / "videos" / "cam01.mp4"
    if video is None or not video.is_file():
        pytest.skip("the shared lab videos are not here: set SAMBA_DATA or put ../shared/data")
    capture = cv2.VideoCapture(str(video))
    frames = []
    while len(frames) < 60:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame)
    return np.stack(frames)


@pytest.mark.slow
def test_the_subject_is_found_in_real_footage_without_an_empty_stage(cam01: np.ndarray) -> None:
    height, width = cam01.shape[1:3]
    with PersonSegmenter("cam01.mp4", (width, height)) as segmenter:
        extractor = SilhouetteExtractor(segmenter)
        masks = [extractor.silhouette(frame) for frame in cam01]
    for mask in masks:
        rows = np.flatnonzero(mask.any(axis=1))
        assert 0.03 < mask.mean() < 0.15  # one person, about a third of the image's height
        assert 600 < rows.max() - rows.min() < 1100  # head to feet, pixels
        assert not mask[140:380, :80].any()  # the second person, at the left edge, is left out
    first = masks[0]  # frame 0: standing, arms down, at the walkway's near end
    assert first[330:1160, 240:570].mean() > 0.3 and not first[:300].any()


def test_a_frame_of_another_size_is_refused_and_the_worker_stops(cam01: np.ndarray) -> None:
    height, width = cam01.shape[1:3]
    segmenter = PersonSegmenter("cam01.mp4", (width, height))
    with pytest.raises(SegmenterError, match="frame of 540x960 in a video of 1080x1920"):
        segmenter.foreground(cam01[0, ::2, ::2])
    segmenter.close()
    segmenter.close()  # again: nothing


def test_a_segmenter_that_cannot_be_set_up_says_why(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("a file, not a folder")
    monkeypatch.setenv("SAMBA_TOOLS", str(blocker / "tools"))
    with pytest.raises(SegmenterError, match="cannot set up the person segmenter") as caught:
        PersonSegmenter("video.mp4")
    assert str(blocker) in str(caught.value) and "\n" not in str(caught.value)
