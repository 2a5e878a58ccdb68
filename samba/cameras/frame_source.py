"""The frames of one camera, from a folder of images or a video file.

A folder's images (by extension, see `IMAGE_SUFFIXES`) are its frames in file-name
order, numbers in names compared as numbers ("frame9" before "frame10"); frame n is the
n-th image (from 0). A video's frames are numbered as decoded. Several cameras'
sources are synchronised by frame number. Every problem a user can cause (a missing
path, an empty folder, an unreadable image or video, images of different sizes) is an
`InputError` naming the file.
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


def sized_frames(
    frames: Iterator[tuple[int, np.ndarray]], source: str, camera: Camera, calibration: str
) -> Iterator[tuple[int, np.ndarray]]:
    """`frames` of `source`, checked to be of the image size of `camera` (of the file
    `calibration`); InputError naming both otherwise."""
    width, height = camera.size
    for number, frame in frames:
        if frame.shape[:2] != (height, width):
            raise InputError(
                source,
                f"frames are {frame.shape[1]}x{frame.shape[0]} but camera {camera.name!r} "
                f"of {calibration} takes {width}x{height} images",
            )
        yield number, frame


def _natural_key(path: Path) -> list[object]:
    """Sort key of a file name with its runs of digits compared as numbers."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", path.name)]
