"""Opening a camera node on its source: the frames of a video, an image folder, a webcam or
one camera of the synthetic rig, and the node that turns them into packets (markers, or
with a shape tree a markerless pose), for `samba node`.

A synthetic source films a built-in motion, or the real markers of a C3D file
(`samba.service.marker_motion`), after its standing lead-in on a wall-clock grid starting
at `start_at` (default: `samba.service.node.START_DELAY_SECONDS` after the node is ready),
so that nodes of one rig started separately film the same instants.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass

from samba.base import InputError
from samba.body import BodyModel
from samba.cameras import Camera, open_frames
from samba.ingest import PLUG_IN_GAIT, MarkerSet
from samba.markers import LeadIn, RenderOptions
from samba.service.marker_motion import MARKER_TAKE_RENDER, MarkerMotion, is_marker_file
from samba.service.node import (
    DEFAULT_FPS,
    CameraNode,
    Capture,
    FileFeed,
    SubjectStart,
    SyntheticFeed,
    WebcamFeed,
    synthetic_lead_in,
)
from samba.service.silhouette_node import SilhouetteNode, SyntheticStageFeed
from samba.silhouette import ShapeTree, SilhouetteExtractor

DEFAULT_SYNTHETIC_SECONDS = 10.0
"""Length of the synthetic motion (after the 1-s standing lead-in) by default; a marker
file plays whole by default."""
EMPTY_STAGE_FRAMES = 10
"""Frames of the synthetic stage the silhouette node learns the background from."""
SOURCES = ("video", "images", "webcam", "synthetic")
"""The kinds of source a node reads."""


@dataclass(frozen=True)
class NodeSource:
    """Where a node's frames come from: `kind` (one of `SOURCES`) and `where` (the video
    file, the image folder, the webcam index, or the built-in motion or C3D marker file
    of the synthetic rig). `fps`: the frame rate (None: the video's own or the default);
    `pace` takes frames of files and the synthetic rig at their frame rate on the clock,
    `loop` starts them over at the end. `seconds`, `seed` and `start_at` (UNIX seconds)
    set a synthetic capture, `marker_set` the labels of a C3D file's 8 markers."""

    kind: str
    where: str | int
    fps: float | None = None
    pace: bool = True
    loop: bool = False
    seconds: float | None = None
    seed: int | None = None
    start_at: float | None = None
    marker_set: MarkerSet = PLUG_IN_GAIT

    @property
    def synthetic_fps(self) -> float:
        """The synthetic rig's frame rate."""
        return self.fps or DEFAULT_FPS

    def file_captures(self, checked: bool = True) -> Iterator[Capture]:
        """The captures of a webcam, a video or an image folder; when `checked`,
        `InputError` naming the path when a video is a folder or an image folder a file."""
        if self.kind == "webcam":
            return WebcamFeed(int(self.where), self.fps).captures()
        frames = open_frames(str(self.where))
        if checked and self.kind == "video" and not frames.is_video:
            raise InputError(str(self.where), "is a folder: use --images")
        if checked and self.kind == "images" and frames.is_video:
            raise InputError(str(self.where), "is a file: use --video")
        return FileFeed(frames, self.fps, self.pace, self.loop).captures()


def open_marker_node(
    source: NodeSource,
    camera: Camera,
    camera_id: int,
    threshold: float | str = "auto",
    start: SubjectStart | None = None,
) -> tuple[CameraNode, Iterator[Capture]]:
    """The marker node of `camera` (the `camera_id`-th of its calibration) and its
    captures from `source`. `threshold`: the blob threshold (or "auto"); `start`: where
    the subject stands at first (a synthetic source knows its own)."""
    if source.kind == "synthetic":
        seed, fps = source.seed or 0, source.synthetic_fps
        lead_in, options = _synthetic_take(source)
        feed = SyntheticFeed(
            camera,
            camera_id,
            lead_in,
            fps,
            seed,
            source.start_at,
            source.pace,
            source.loop,
            options,
        )
        return CameraNode(camera, SubjectStart.of(lead_in), feed.mask, threshold), feed.captures()
    node = CameraNode(camera, start or SubjectStart(), threshold=threshold)
    return node, source.file_captures()


def _synthetic_take(source: NodeSource) -> tuple[LeadIn, RenderOptions | None]:
    """What the synthetic rig of `source` films, after its lead-in, and how (None: the
    default `RenderOptions`): a C3D file's real markers (`MarkerMotion`, its first
    `seconds` or all of it) or `seconds` of a built-in motion. `C3dError` for a bad
    marker file, `InputError` naming `--seconds` when it gives no frame."""
    where, fps = str(source.where), source.synthetic_fps
    if is_marker_file(where):
        motion = MarkerMotion.read(where, fps, source.seconds, source.marker_set)
        return motion.lead_in(), MARKER_TAKE_RENDER
    seconds = source.seconds or DEFAULT_SYNTHETIC_SECONDS
    try:
        return synthetic_lead_in(where, seconds, fps, source.seed or 0), None
    except ValueError as exc:
        raise InputError("--seconds", str(exc)) from None


def open_silhouette_node(
    source: NodeSource,
    camera: Camera,
    tree: ShapeTree,
    body: BodyModel,
    height: float | None = None,
    background: str | None = None,
    empty_frames: int | None = None,
) -> tuple[SilhouetteNode, Iterator[Capture]]:
    """The markerless node tracking `camera`'s silhouettes over `tree` (built for `body`;
    `height` m the subject's) and its captures from `source`. The empty stage is the
    `background` video or folder, or the first `empty_frames` frames of the source; a
    synthetic source films its own."""
    view = tree.view
    if source.kind == "synthetic":
        feed = SyntheticStageFeed(
            camera,
            tree,
            body,
            str(source.where),
            source.seconds or DEFAULT_SYNTHETIC_SECONDS,
            source.synthetic_fps,
            source.seed or 0,
            source.start_at,
            source.pace,
            source.loop,
        )
        extractor = SilhouetteExtractor.for_tracking(
            feed.empty_frames(EMPTY_STAGE_FRAMES), view.size[0]
        )
        return SilhouetteNode(tree, extractor), feed.captures()
    captures = source.file_captures(checked=False)
    if background is not None:
        empty = [frame for _, frame in open_frames(background).frames()]
    else:
        empty = [capture.frame for capture in itertools.islice(captures, empty_frames)]
    extractor = SilhouetteExtractor.for_tracking(empty, view.size[0])
    return SilhouetteNode(tree, extractor, height), captures
