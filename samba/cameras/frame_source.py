"""The frames of one camera, from a folder of images or a video file.

A folder's images (by extension, see `IMAGE_SUFFIXES`) are its frames in file-name
order, numbers in names compared as numbers ("frame9" before "frame10"); frame n is the
n-th image (from 0). A video's frames are numbered as decoded. Several cameras'
sources are synchronised by frame number. Every problem a user can cause (a missing
path, an empty folder, an unreadable image or video, images of different sizes) is an
`InputError` naming the file.

A video's frames may be the calibrated image cut by a few pixels at the right or the
bottom: encoders crop to a multiple of 8 or 16 (the shared lab's 1088 x 1920 sensor
window encoded 1080 wide). The pixels left keep their coordinates, so such frames are
taken (`image_cut`: at most `MAX_CUT_PX` pixels or `MAX_CUT_FRACTION` of the side) and
`sized_frames` brings them back to the camera's size, the cut columns and rows
repeating the last ones; `cut_note` is the line that tells the user.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from samba.base import InputError
from samba.cameras.camera import Camera

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
"""File extensions (any case) read as images from a folder."""
MAX_CUT_PX = 16
"""Most pixels by which a frame may fall short of the calibrated image, at the right or
the bottom, and still be taken for it (an encoder's crop to a multiple of 16)..."""
MAX_CUT_FRACTION = 0.01
"""... or, for large images, most fraction of the side."""


@dataclass(frozen=True)
class FrameSource:
    """One camera's frames: `path` is the folder or video, `images` the folder's image
    files in frame order (empty for a video)."""

    path: Path
    images: tuple[Path, ...]

    @property
    def is_video(self) -> bool:
        """Whether the frames come from a video file."""
        return not self.images

    def label(self, number: int) -> str:
        """Frame `number` as a user knows it: the image's file name, or "frame N"."""
        return f"frame {number}" if self.is_video else self.images[number].name

    def frames(self, every: int = 1) -> Iterator[tuple[int, np.ndarray]]:
        """(frame number, BGR uint8 image (h, w, 3)) of frames 0, every,
        2 every, ...; InputError for an unreadable image or video, or an image whose size
        differs from the first frame's."""
        if every < 1:
            raise ValueError(f"every must be >= 1, got {every}")
        size = None
        for number, image, source in self._decoded(every):
            if size is None:
                size = image.shape[:2]
            elif image.shape[:2] != size:
                raise InputError(
                    str(source),
                    f"image is {image.shape[1]}x{image.shape[0]} but the first frame of "
                    f"{self.path} is {size[1]}x{size[0]}",
                )
            yield number, image

    def size(self) -> tuple[int, int]:
        """(width, height) of the frames, pixels: the first frame's (decoded for it)."""
        frames = self.frames()
        try:
            _, image = next(frames)
        finally:
            frames.close()
        return image.shape[1], image.shape[0]

    def _decoded(self, every: int) -> Iterator[tuple[int, np.ndarray, Path]]:
        """(frame number, image, file it came from) of every `every`-th frame."""
        if not self.is_video:
            for number in range(0, len(self.images), every):
                image = cv2.imread(str(self.images[number]), cv2.IMREAD_COLOR)
                if image is None or image.size == 0:
                    raise InputError(str(self.images[number]), "cannot be read as an image")
                yield number, image, self.images[number]
            return
        capture = open_video(self.path)
        try:
            number = 0
            while capture.grab():
                if number % every == 0:
                    ok, image = capture.retrieve()
                    if not ok:
                        raise InputError(str(self.path), f"frame {number} cannot be decoded")
                    yield number, image, self.path
                number += 1
            if number == 0:
                raise InputError(str(self.path), "no frame of the video can be read")
        finally:
            capture.release()


def open_video(path: str | Path) -> cv2.VideoCapture:
    """An opened OpenCV capture of the video file `path` (the caller releases it);
    InputError naming the file when OpenCV cannot open it. FFmpeg's own messages
    ("moov atom not found" ...) are silenced (`OPENCV_FFMPEG_LOGLEVEL`, unless set
    already): the error says it once."""
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET
    capture = cv2.VideoCapture(str(path))
    if not capture.isOpened():
        capture.release()
        raise InputError(str(path), "cannot be opened as a video")
    return capture


def open_frames(path: str | Path) -> FrameSource:
    """The frame source at `path`: a folder of images or a video file. InputError when the
    path does not exist or a folder holds no images."""
    path = Path(path)
    if path.is_dir():
        images = sorted(
            (p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()),
            key=_natural_key,
        )
        if not images:
            raise InputError(str(path), f"folder holds no images ({', '.join(IMAGE_SUFFIXES)})")
        return FrameSource(path, tuple(images))
    if not path.is_file():
        raise InputError(str(path), "no such file or folder")
    return FrameSource(path, ())


def image_cut(
    size: tuple[int, int], source: str, camera: Camera, calibration: str
) -> tuple[int, int]:
    """(columns, rows) by which frames of `size` (width, height) pixels of `source` fall
    short of the image of `camera` (of the file `calibration`), cut at the right and the
    bottom: (0, 0) for frames of its size. InputError naming `source` and
    `calibration` when a frame is larger, or cut by more than `MAX_CUT_PX` pixels and
    `MAX_CUT_FRACTION` of the side."""
    cut = (camera.size[0] - size[0], camera.size[1] - size[1])
    small = all(
        0 <= short <= max(MAX_CUT_PX, MAX_CUT_FRACTION * side)
        for short, side in zip(cut, camera.size, strict=True)
    )
    if not small:
        raise InputError(
            source,
            f"frames are {size[0]}x{size[1]} but camera {camera.name!r} of {calibration} takes "
            f"{camera.size[0]}x{camera.size[1]} images (a cut at the right or bottom of at "
            f"most {MAX_CUT_PX} px or {MAX_CUT_FRACTION:.0%} is taken)",
        )
    return cut


def cut_note(size: tuple[int, int], source: str, camera: Camera, calibration: str) -> str:
    """The line telling that frames of `size` (width, height) pixels of `source` are the
    image of `camera` (of the file `calibration`) cut at the right or bottom, and taken
    so; "" for frames of its size. InputError as `image_cut` for any other size."""
    columns, rows = image_cut(size, source, camera, calibration)
    cuts = [
        f"{count} {what} at the {side}"
        for count, what, side in ((columns, "columns", "right"), (rows, "rows", "bottom"))
        if count
    ]
    if not cuts:
        return ""
    return (
        f"{source}: frames are {size[0]}x{size[1]}, camera {camera.name!r} of {calibration} "
        f"takes {camera.size[0]}x{camera.size[1]}: taken as its image cut by "
        f"{' and '.join(cuts)} (pixels keep their coordinates; the cut repeats the last ones)"
    )


def sized_frames(
    frames: Iterator[tuple[int, np.ndarray]], source: str, camera: Camera, calibration: str
) -> Iterator[tuple[int, np.ndarray]]:
    """`frames` of `source` at the image size of `camera` (of the file `calibration`):
    a frame cut at the right or bottom by a little (`image_cut`) is padded back to it,
    repeating its last columns and rows; InputError naming both for any other size."""
    for number, frame in frames:
        columns, rows = image_cut((frame.shape[1], frame.shape[0]), source, camera, calibration)
        if columns or rows:
            frame = cv2.copyMakeBorder(frame, 0, rows, 0, columns, cv2.BORDER_REPLICATE)
        yield number, frame


def camera_frames(
    source: str, camera: Camera, calibration: str
) -> tuple[Iterator[tuple[int, np.ndarray]], str]:
    """The frames (number, (H, W, 3) uint8 BGR) of the video or image folder `source` of
    `camera` (of the file `calibration`) at its image size (`sized_frames`), and the
    `cut_note` line telling they are its image cut ("" for frames of its size).
    InputError naming `source` when it cannot be read or its frames are of another size."""
    frames = open_frames(source)
    note = cut_note(frames.size(), source, camera, calibration)
    return sized_frames(frames.frames(), source, camera, calibration), note


def _natural_key(path: Path) -> list[object]:
    """Sort key of a file name with its runs of digits compared as numbers."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", path.name)]
