"""Silhouettes without an empty stage: a learnt person segmenter (MediaPipe Pose's
segmentation, BlazePose) for footage that never shows the stage without the subject.

Background subtraction needs frames of the empty stage. Real footage often has none,
and a background taken as the per-pixel median of the clip keeps the subject wherever
it stays more than half the time (the shared lab videos: the subject turns and kicks
on one spot, and the median image shows its ghost). A person segmenter finds the person
in each frame by itself; MediaPipe Pose's also picks the most prominent person, so a
second person standing at the edge of the view is left out.

MediaPipe 0.10.21, the last release that carries its models in its wheel (later ones
download them, which closed networks cannot), needs numpy < 2, and Samba needs numpy 2.
So the segmenter runs in an environment of its own, a virtual environment made once on
first use (`tool_python`: `python -m venv` and `pip install mediapipe==0.10.21` with
what its pose solution needs, about 430 MB) in `$SAMBA_TOOLS` or `~/.cache/samba/tools`,
and each video gets a worker process there (`segmenter_worker.py`) that frames go to and
masks come back from over pipes. `PersonSegmenter` offers the `BackgroundModel` interface, so a
`SilhouetteExtractor` cleans its masks as it cleans any foreground.
"""

from __future__ import annotations

import os
import struct
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import IO

import numpy as np

from samba.base import InputError

SEGMENTER_PACKAGE = "mediapipe==0.10.21"
"""The segmenter, installed without its declared dependencies (jax, sounddevice, ...:
some 600 MB that its pose solution never loads) ..."""
SEGMENTER_NEEDS = (
    "absl-py",
    "attrs",
    "flatbuffers",
    "matplotlib",
    "numpy<2",
    "opencv-contrib-python-headless",
    "protobuf>=4.25.3,<5",
)
"""... and with what its pose solution imports: about 430 MB in all."""
WORKER = Path(__file__).with_name("segmenter_worker.py")
"""The worker script, run by the segmenter environment's Python."""


class SegmenterError(InputError):
    """The person segmenter could not be set up or stopped working."""


def tools_folder() -> Path:
    """Where Samba keeps the environments of its tools: `$SAMBA_TOOLS`, else
    `$XDG_CACHE_HOME/samba/tools`, else `~/.cache/samba/tools`."""
    if os.environ.get("SAMBA_TOOLS"):
        return Path(os.environ["SAMBA_TOOLS"])
    cache = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(cache) / "samba" / "tools"


def tool_python(announce: IO[str] | None = sys.stderr) -> Path:
    """The Python of the segmenter's environment, made first if it is not there yet
    (saying so on `announce`). `SegmenterError` with pip's last words when it cannot
    be made."""
    home = tools_folder() / SEGMENTER_PACKAGE.replace("==", "-")
    python = home / "bin" / "python"
    if (home / "ready").is_file() and python.is_file():
        return python
    if announce is not None:
        print(
            f"samba: setting up the person segmenter ({SEGMENTER_PACKAGE}) in {home}, "
            "once (about 430 MB)",
            file=announce,
            flush=True,
        )
    steps = [
        [sys.executable, "-m", "venv", "--clear", str(home)],
        [str(python), "-m", "pip", "install", "--quiet", "--no-deps", SEGMENTER_PACKAGE],
        [str(python), "-m", "pip", "install", "--quiet", *SEGMENTER_NEEDS],
    ]
    for step in steps:
        done = subprocess.run(step, capture_output=True, text=True)
        if done.returncode != 0:
            said = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
            raise SegmenterError(str(home), f"cannot set up the person segmenter: {said[0]}")
    (home / "ready").write_text(SEGMENTER_PACKAGE + "\n")
    return python


class PersonSegmenter:
    """The person's raw mask in each frame of one video, from a worker process of the
    segmenter's environment (module docstring). Frames must come in the video's order
    (the segmenter tracks the person from frame to frame) and share one size; `close`
    (or the end of a `with`) stops the worker. `source` names the video in errors."""

    def __init__(self, source: str, size: tuple[int, int] | None = None) -> None:
        self.source = source
        self._size = size
        self._log = tempfile.TemporaryFile()  # noqa: SIM115 - lives as long as the worker
        self._worker = subprocess.Popen(
            [str(tool_python()), str(WORKER)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._log,
        )
        if self._read_line() != b"READY\n":
            self._fail("the person segmenter did not start")

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the frames, pixels (known after the first frame)."""
        if self._size is None:
            raise SegmenterError(self.source, "no frame has been segmented yet")
        return self._size

    def foreground(self, frame: np.ndarray) -> np.ndarray:
        """The person (H, W) bool in one frame (H, W, 3) uint8 BGR."""
        frame = np.ascontiguousarray(frame, dtype=np.uint8)
        height, width = frame.shape[:2]
        if frame.ndim != 3 or frame.shape[2] != 3:
            raise SegmenterError(self.source, f"frames must be (H, W, 3), got {frame.shape}")
        if self._size is None:
            self._size = (width, height)
        elif self._size != (width, height):
            raise SegmenterError(
                self.source,
                f"frame of {width}x{height} in a video of {self._size[0]}x{self._size[1]}",
            )
        try:
            assert self._worker.stdin is not None and self._worker.stdout is not None
            self._worker.stdin.write(struct.pack("<II", height, width) + frame.tobytes())
            self._worker.stdin.flush()
            mask = self._worker.stdout.read(height * width)
        except (BrokenPipeError, OSError):
            mask = b""
        if len(mask) != height * width:
            self._fail("the person segmenter stopped")
        return np.frombuffer(mask, dtype=np.uint8).reshape(height, width) > 0

    def close(self) -> None:
        """Stop the worker (calling it again does nothing)."""
        if self._worker.poll() is None:
            try:
                assert self._worker.stdin is not None
                self._worker.stdin.close()
                self._worker.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self._worker.kill()
                self._worker.wait()
        self._log.close()

    def __enter__(self) -> PersonSegmenter:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def _read_line(self) -> bytes:
        assert self._worker.stdout is not None
        return self._worker.stdout.readline()

    def _fail(self, problem: str) -> None:
        """Stop the worker and raise `SegmenterError` with the worker's last words."""
        self._worker.kill()
        self._worker.wait()
        self._log.seek(0)
        said = [
            line
            for line in self._log.read().decode(errors="replace").splitlines()
            if line.strip() and not line.startswith(("W0", "I0", "INFO:", "WARNING:"))
        ]
        self._log.close()
        raise SegmenterError(self.source, problem + (f": {said[-1]}" if said else ""))
