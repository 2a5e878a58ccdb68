"""Frames a little smaller than the calibrated image: an encoder crops to a multiple of 8
or 16 at the right or bottom (the shared lab's 1088 x 1920 sensor window encoded 1080
wide). They are taken as that image, with a line saying so; frames cut by more, or
larger, are refused with one line naming the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from markerless_fixtures import write_image_folder

from samba.base import InputError
from samba.cameras import Camera, camera_frames, cut_note, sized_frames

CAMERA = Camera.look_at("front", (0.0, 1.0, 5.0), (0.0, 1.0, 0.0), (320, 240), 60.0)
CALIBRATION = "stage.toml"


def _folder(tmp_path: Path, width: int, height: int) -> tuple[Path, np.ndarray]:
    """An image folder of three random frames (3, height, width, 3) uint8, and them."""
    frames = np.random.default_rng(3).integers(0, 256, (3, height, width, 3), dtype=np.uint8)
    return write_image_folder(tmp_path / f"{width}x{height}", frames), frames


def test_a_frame_8_px_narrower_is_taken_as_the_image_cut_at_the_right(tmp_path: Path) -> None:
    folder, given = _folder(tmp_path, 312, 240)
    frames, note = camera_frames(str(folder), CAMERA, CALIBRATION)
    assert str(folder) in note and CALIBRATION in note and "'front'" in note
    assert "312x240" in note and "320x240" in note and "8 columns at the right" in note
    assert "\n" not in note
    taken = np.stack([frame for _, frame in frames])
    assert taken.shape == (3, 240, 320, 3)
    np.testing.assert_array_equal(taken[:, :, :312], given)  # pixels keep their coordinates
    np.testing.assert_array_equal(taken[:, :, 312:], np.repeat(given[:, :, 311:], 8, axis=2))


def test_a_frame_cut_at_the_bottom_is_taken_too(tmp_path: Path) -> None:
    folder, given = _folder(tmp_path, 320, 232)
    frames, note = camera_frames(str(folder), CAMERA, CALIBRATION)
    assert "8 rows at the bottom" in note and "columns" not in note
    taken = np.stack([frame for _, frame in frames])
    np.testing.assert_array_equal(taken[:, :232], given)
    np.testing.assert_array_equal(taken[:, 232:], np.repeat(given[:, 231:], 8, axis=1))


def test_frames_of_the_cameras_size_are_taken_as_they_are_without_a_note(tmp_path: Path) -> None:
    folder, given = _folder(tmp_path, 320, 240)
    frames, note = camera_frames(str(folder), CAMERA, CALIBRATION)
    assert note == ""
    np.testing.assert_array_equal(np.stack([frame for _, frame in frames]), given)


@pytest.mark.parametrize(("width", "height"), [(280, 240), (320, 200), (328, 240), (160, 120)])
def test_frames_cut_by_more_or_larger_are_refused_naming_the_file(
    tmp_path: Path, width: int, height: int
) -> None:
    folder, _ = _folder(tmp_path, width, height)
    with pytest.raises(InputError) as error:
        camera_frames(str(folder), CAMERA, CALIBRATION)
    message = str(error.value)
    assert "\n" not in message
    assert str(folder) in message and f"{width}x{height}" in message and "320x240" in message
    assert CALIBRATION in message
    frame = np.zeros((height, width, 3), dtype=np.uint8)
    with pytest.raises(InputError, match=f"{width}x{height}"):
        list(sized_frames(iter([(0, frame)]), str(folder), CAMERA, CALIBRATION))
    with pytest.raises(InputError, match=str(folder)):
        cut_note((width, height), str(folder), CAMERA, CALIBRATION)
