"""The markerless camera node (`samba node --mode silhouette`): one ordinary camera, the
subject's silhouette tracked over the pose store's shape tree, one pose packet per frame.

`SilhouetteNode` turns colour frames into 13-joint poses: background subtraction
(`samba.silhouette.extraction`), the silhouette at the view's 320x240, and the
tree-based filter (`samba.silhouette.tracker`). The server takes its pose packets in a
session whose `input` is "poses" and streams the avatar like any other.

`SyntheticStageFeed` is the synthetic rig of this mode: the body model in a built-in
motion (staged in front of the camera, facing it when it starts) in colour on a
textured wall (`samba.silhouette.person_render`), on a wall-clock grid like
`samba.service.node.SyntheticFeed`.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from samba.body import BodyModel
from samba.cameras import Camera
from samba.service.node import Capture, grid_captures
from samba.silhouette import (
    ShapeTree,
    SilhouetteExtractor,
    SilhouetteTracker,
    downsampled,
    person_frames,
    stage_background,
    staged,
)
from samba.synthetic import generate


class SilhouetteNode:
    """Frames (H, W, 3) uint8 BGR of the tree's camera -> poses (13, 3) world meters.

    `extractor` was learnt from the empty stage seen by the same camera; `height` is the
    subject's stature in meters (default: the tree's body model's). `process` returns
    None until the subject is first seen; after that a frame without a silhouette holds
    the last pose.
    """

    MISSING = "frames without a pose"
    """What `NodeSummary.missing_rate` counts for this node: frames before the subject
    was first seen."""

    def __init__(
        self, tree: ShapeTree, extractor: SilhouetteExtractor, height: float | None = None
    ) -> None:
        self.tree = tree
        self.extractor = extractor
        self._tracker = SilhouetteTracker(tree, height=height)
        self._seen = False

    def restart(self) -> None:
        """Forget the past (a new take): the subject faces the camera again."""
        self._tracker.reset()
        self._seen = False

    def process(self, frame: np.ndarray, name: str = "frame") -> np.ndarray | None:
        """The pose (13, 3) m in this frame, or None while nobody has been seen.
        InputError naming `name` for a frame of the wrong size or type."""
        mask = self.extractor.silhouette(frame)
        if not self._seen and not mask.any():
            return None
        size = self.tree.view.size
        if mask.shape != size[::-1]:
            mask = downsampled(mask, size)
        self._seen = True
        return self._tracker.step(mask).pose

    def unlabelled(self) -> np.ndarray:
        """No blobs (0, 2): a markerless node sends poses, not markers."""
        return np.zeros((0, 2))


class SyntheticStageFeed:
    """The body model `body` doing `motion` (`samba.synthetic.motions.generate(motion, seconds,
    fps, seed)`), staged facing `camera` at the tree's home, filmed in colour at `fps` on
    a wall-clock grid from `start_at` (see `samba.service.node.SyntheticFeed`)."""

    def __init__(
        self,
        camera: Camera,
        tree: ShapeTree,
        body: BodyModel,
        motion: str,
        seconds: float,
        fps: float,
        seed: int,
        start_at: float | None,
        pace: bool = True,
        loop: bool = False,
    ) -> None:
        self.camera, self.body, self.fps = camera, body, fps
        self.start_at, self.pace, self.loop = start_at, pace, loop
        poses = generate(motion, seconds, fps, seed).poses.astype(np.float64)
        self.poses = staged(poses, tree.view, body.height, in_place=motion in ("walk", "run"))
        self._rng = np.random.default_rng(seed)
        self.background = stage_background(camera.size, self._rng)
        self.name = f"synthetic stage ({motion})"

    def empty_frames(self, count: int = 10) -> np.ndarray:
        """`count` frames (n, H, W, 3) uint8 of the empty stage, with sensor noise."""
        noise = self._rng.standard_normal((count, *self.background.shape), dtype=np.float32)
        return np.clip(self.background + 3.0 * noise, 0, 255).astype(np.uint8)

    def frames(self) -> Iterator[np.ndarray]:
        """One pass over the take's frames (H, W, 3) uint8 BGR, each rendered when it is
        due (a colour frame takes about 15 ms at 640x480)."""
        for pose in self.poses:
            yield person_frames(pose[None], self.camera, self.body, self.background, self._rng)[0]

    def captures(self) -> Iterator[Capture]:
        """The frames stamped with their grid times, in order (endless when looping)."""
        return grid_captures(self.frames, self.fps, self.start_at, self.pace, self.loop, self.name)
