"""Hand-made take files (.mcap, as `samba serve` records them) for the tests of what an
import accepts: any frame rate, any message bytes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from mcap.writer import Writer

from samba.ingest import POSE_TOPIC, TAKE_METADATA
from samba.synthetic.motions import generate

T0 = 1_700_000_000_000_000_000
"""Capture time of the first frame, ns."""


def walk_poses(seconds: float = 1.0, seed: int = 0) -> np.ndarray:
    """A synthetic walk (n, 13, 3) meters at 30 fps."""
    return generate("walk", seconds=seconds, seed=seed).poses.astype(np.float64)


def pose_message(pose: np.ndarray) -> bytes:
    """The `/pose_raw` JSON of one pose (13, 3) meters."""
    return json.dumps({"joints": pose.tolist()}).encode()


def write_take_file(path: Path, messages: list[bytes], fps: str = "30.0") -> Path:
    """A take file at `path` whose take metadata says `fps` and whose `/pose_raw`
    messages are `messages` (one a frame, 1/30 s apart)."""
    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start(library="test")
        schema = writer.register_schema("samba.PoseRaw", "jsonschema", b"{}")
        channel = writer.register_channel(POSE_TOPIC, "json", schema)
        writer.add_metadata(TAKE_METADATA, {"name": path.stem, "fps": fps})
        for i, data in enumerate(messages):
            t = T0 + round(i * 1e9 / 30)
            writer.add_message(channel, log_time=t, data=data, publish_time=t)
        writer.finish()
    return path


def walk_take_file(path: Path, fps: str = "30.0", far: float | None = None) -> Path:
    """A take file of a 1-s walk; with `far`, joint 3 of frame 5 is at x = `far` meters."""
    poses = walk_poses()
    if far is not None:
        poses[5, 3, 0] = far
    return write_take_file(path, [pose_message(p) for p in poses], fps)
