"""`Take`: one motion on the 13-joint skeleton, the unit the pose store imports.

A take comes from a BVH file (`ingest`), from a recording of the live service, or from
the synthetic motion generator. It carries the poses and what the catalog records
about their origin.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from samba.body.skeleton import N_JOINTS


@dataclass
class Take:
    """A motion: `poses` (n, 13, 3) float32 in meters, world frame +Y up, at `fps`.

    `frames` (n,) int holds each pose's frame number at `fps` counted from the start of
    the take (gaps appear where near-duplicate poses were dropped). `source` is the path
    or URI the take came from, `content_hash` a hex digest identifying that source's
    content (by default the SHA-256 of the poses), `rig` the skeleton it was mapped from
    ("synthetic", "cmu-max", ...).
    `warnings` lists what the importer noticed but did not treat as an error; `meta` holds
    free-form facts about the source (detected units, up axis, recording session ...).
    """

    name: str
    poses: np.ndarray
    fps: float
    source: str = ""
    content_hash: str = ""
    rig: str = ""
    subject: str = ""
    action: str = ""
    frames: np.ndarray | None = None
    source_frames: int = 0
    warnings: list[str] = field(default_factory=list)
    meta: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        poses = np.ascontiguousarray(self.poses, dtype=np.float32)
        if poses.ndim != 3 or poses.shape[1:] != (N_JOINTS, 3):
            raise ValueError(f"take {self.name!r}: poses must be (n, 13, 3), got {poses.shape}")
        if not np.isfinite(poses).all():
            raise ValueError(f"take {self.name!r}: poses contain NaN or infinity")
        if not self.fps > 0:
            raise ValueError(f"take {self.name!r}: fps must be positive, got {self.fps}")
        self.poses = poses
        if self.frames is None:
            self.frames = np.arange(len(poses), dtype=np.int32)
        self.frames = np.asarray(self.frames, dtype=np.int32)
        if self.frames.shape != (len(poses),):
            raise ValueError(f"take {self.name!r}: frames must be ({len(poses)},)")
        if not self.source_frames:
            self.source_frames = len(poses)
        if not self.content_hash:
            self.content_hash = hashlib.sha256(poses.tobytes()).hexdigest()

    def __len__(self) -> int:
        return len(self.poses)
