"""Camera frames on disk: videos and image sequences that OpenCV writes and reads back.

`write_video` stores grey (F, H, W) or BGR (F, H, W, 3) uint8 frames as a lossless FFV1
video in an AVI container by default (what the synthetic rig writes; MJPG and others
work too but lose detail), `write_images` as numbered PNG files (8 or 16 bits, also
lossless), and `read_frames` reads either back. Files are written to a temporary name
and renamed into place, so a crash never leaves half a video under the final name.
Every problem with a file raises `InputError` naming it.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from samba.base import InputError
from samba.cameras.frame_source import open_video

IMAGE_EXTENSIONS = (".png", ".tif", ".tiff", ".bmp", ".jpg", ".jpeg", ".pgm", ".ppm")
"""File name extensions `read_frames` takes as images in a folder."""


def write_video(
    frames: np.ndarray, path: str | Path, fps: float = 30.0, fourcc: str = "FFV1"
) -> None:
    """Write uint8 frames (F, H, W) grey or (F, H, W, 3) BGR as a video at `fps`.

    `fourcc` is the OpenCV codec code; the container follows the extension of `path`
    (FFV1 needs .avi or .mkv). Raises `InputError` for bad frames or when OpenCV cannot
    write that codec to that file.
    """
    frames = _check_frames(frames, {np.dtype(np.uint8)})
    path = Path(path)
    if not fps > 0:
        raise InputError("fps", f"must be positive, got {fps}")
    height, width = frames.shape[1:3]
    temporary = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    writer = cv2.VideoWriter(
        str(temporary), cv2.VideoWriter_fourcc(*fourcc), fps, (width, height), frames.ndim == 4
    )
    try:
        if not writer.isOpened():
            raise InputError(str(path), f"OpenCV cannot write a {fourcc} video to this file")
        for frame in frames:
            writer.write(frame)
    finally:
        writer.release()
    if not temporary.exists() or temporary.stat().st_size == 0:
        temporary.unlink(missing_ok=True)
        raise InputError(str(path), f"OpenCV wrote no {fourcc} video to this file")
    os.replace(temporary, path)


def write_images(
    frames: np.ndarray, folder: str | Path, prefix: str = "frame", extension: str = ".png"
) -> list[Path]:
    """Write frames (F, H, W) or (F, H, W, 3), uint8 or uint16, as numbered images.

    Files are `folder/{prefix}_{index:06d}{extension}`, the folder is created if needed.
    Returns the paths in frame order.
    """
    frames = _check_frames(frames, {np.dtype(np.uint8), np.dtype(np.uint16)})
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for index, frame in enumerate(frames):
        path = folder / f"{prefix}_{index:06d}{extension}"
        temporary = folder / f".{path.stem}.{os.getpid()}.tmp{extension}"
        if not cv2.imwrite(str(temporary), frame):
            temporary.unlink(missing_ok=True)
            raise InputError(str(path), f"OpenCV cannot write a {extension} image here")
        os.replace(temporary, path)
        paths.append(path)
    return paths


def read_frames(path: str | Path, grey: bool = True) -> np.ndarray:
    """All frames of a video file or of a folder of images, (F, H, W) or (F, H, W, 3).

    Images in a folder are read in name order and keep their depth (uint8 or uint16);
    videos decode to uint8. With `grey`, colour frames are converted (a grey video read
    back gives its grey values exactly). Raises `InputError` naming the file for a
    missing or unreadable file or image, a video without a decodable frame, an empty
    folder or images of different sizes.
    """
    path = Path(path)
    if path.is_dir():
        frames = _read_images(path)
    elif path.is_file():
        frames = _read_video(path)
    else:
        raise InputError(str(path), "no such video file or image folder")
    if grey:
        frames = [cv2.cvtColor(f, cv2.COLOR_BGR2GRAY) if f.ndim == 3 else f for f in frames]
    return np.stack(frames)


def _read_video(path: Path) -> list[np.ndarray]:
    capture = open_video(path)
    try:
        frames = []
        while True:
            ok, frame = capture.read()
            if not ok:
                break
            frames.append(frame)
    finally:
        capture.release()
    if not frames:
        raise InputError(str(path), "no frame of this video could be decoded")
    return frames


def _read_images(folder: Path) -> list[np.ndarray]:
    files = sorted(f for f in folder.iterdir() if f.suffix.lower() in IMAGE_EXTENSIONS)
    if not files:
        raise InputError(str(folder), f"holds no images ({', '.join(IMAGE_EXTENSIONS)})")
    frames = []
    for file in files:
        image = cv2.imread(str(file), cv2.IMREAD_UNCHANGED)
        if image is None or image.size == 0:
            raise InputError(str(file), "not a readable image")
        if image.ndim == 3 and image.shape[2] == 4:
            image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
        if frames and image.shape[:2] != frames[0].shape[:2]:
            first = frames[0].shape
            raise InputError(
                str(file),
                f"image is {image.shape[1]}x{image.shape[0]} but {files[0].name} is "
                f"{first[1]}x{first[0]}",
            )
        frames.append(image)
    return frames


def _check_frames(frames: np.ndarray, dtypes: set[np.dtype]) -> np.ndarray:
    """Frames as a C-contiguous (F, H, W) or (F, H, W, 3) array of one of `dtypes`."""
    if not isinstance(frames, np.ndarray):
        raise InputError("frames", f"must be a numpy array, got {type(frames).__name__}")
    if frames.dtype not in dtypes:
        names = " or ".join(sorted(d.name for d in dtypes))
        raise InputError("frames", f"must be {names}, got {frames.dtype}")
    if frames.ndim not in (3, 4) or (frames.ndim == 4 and frames.shape[3] != 3):
        raise InputError("frames", f"must be (F, H, W) or (F, H, W, 3), got {frames.shape}")
    if 0 in frames.shape:
        raise InputError("frames", f"are empty, shape {frames.shape}")
    return np.ascontiguousarray(frames)
