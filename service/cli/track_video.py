"""`samba track-video VIDEO --calib FILE --db STORE -o FILE.mcap`: markerless capture from
one ordinary camera (silhouette tracking over the store's shape tree), written as a take.

The empty stage comes from `--background` (a video or image folder of the stage without
the subject) or from the first `--empty-frames` frames of VIDEO; footage without one takes
`--segment` (a learnt person segmenter, `samba.silhouette.person_segmentation`). Each frame's
silhouette (`samba.silhouette.extraction`) is tracked with `samba.silhouette.tracker`;
the 13-joint poses go to an MCAP take like the live service's, which `samba export`
and `samba db import` read. The shape tree is read from the store
(`samba db tree`), and built and saved there first when it is missing. Frames cut by a
few pixels at the right or bottom of the calibrated image (an encoder's crop) are
taken, with a line saying so (`samba.cameras.camera_frames`).
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from samba.base import InputError, add_force_argument, check_outputs, natural, positive_float
from samba.cameras import Camera, camera_frames, open_frames, sized_frames
from samba.db import stored_tree
from samba.db.cli import add_camera_arguments, chosen_body, chosen_camera, chosen_home
from samba.service.video_capture import track_video
from samba.silhouette import (
    BACKGROUND_METHODS,
    PersonSegmenter,
    SilhouetteExtractor,
    SilhouetteTracker,
    SilhouetteView,
)


def register(parser: argparse.ArgumentParser) -> None:
    """Add the `track-video` arguments to `parser`."""
    parser.add_argument("video", help="video file or folder of images of one camera")
    parser.add_argument("--calib", required=True, metavar="FILE", help="camera calibration TOML")
    parser.add_argument("--db", required=True, metavar="STORE", help="pose store (its shape trees)")
    parser.add_argument(
        "-o", "--output", required=True, metavar="FILE.mcap", help="take to write (.mcap)"
    )
    add_force_argument(parser)
    add_camera_arguments(parser)
    parser.add_argument(
        "--tree", metavar="NAME", help="shape tree name in the store (default: CAMERA-BODY)"
    )
    stage = parser.add_mutually_exclusive_group(required=True)
    stage.add_argument(
        "--background", metavar="DIR_OR_VIDEO", help="video or image folder of the empty stage"
    )
    stage.add_argument(
        "--empty-frames",
        type=natural,
        metavar="N",
        help="the first N frames of VIDEO show the empty stage",
    )
    stage.add_argument(
        "--segment",
        action="store_true",
        help="no empty stage: find the person in every frame with a learnt person segmenter "
        "(MediaPipe Pose; set up once on first use, about 430 MB)",
    )
    parser.add_argument(
        "--method",
        choices=BACKGROUND_METHODS,
        default="colour",
        help="background model (default colour)",
    )
    parser.add_argument(
        "--fps",
        type=positive_float,
        default=30.0,
        metavar="N",
        help="frame rate of VIDEO (default 30)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Track VIDEO and write the take; print what was done. A run that fails leaves no
    take behind."""
    out = Path(args.output)
    if out.suffix.lower() != ".mcap":
        raise InputError(str(out), "the take is written as MCAP: give a .mcap file name")
    check_outputs([out], args.force, [args.video, args.calib])
    camera = chosen_camera(args.calib, args.camera)
    view = SilhouetteView(camera, chosen_home(args))
    frames, note = camera_frames(args.video, camera, args.calib)
    if note:
        print(note)
    with contextlib.ExitStack() as workers:
        if args.segment:
            segmenter = workers.enter_context(PersonSegmenter(args.video, camera.size))
            extractor = SilhouetteExtractor.tracking(segmenter, view.size[0])
            empty_stage = "--segment"
        else:
            extractor = _learnt(args, frames, camera, view)
            empty_stage = (
                "--background" if args.background else f"--empty-frames {args.empty_frames}"
            )
        tree = stored_tree(args.db, args.tree, view, chosen_body(args))
        tracker = SilhouetteTracker(tree, height=args.height)
        seconds, held = track_video(
            frames, extractor, tracker, out, args.fps, args.video, empty_stage
        )
    print(
        f"track-video: {len(seconds)} frames tracked ({held} held: no silhouette), "
        f"{np.median(seconds) * 1e3:.1f} ms per frame (p50: silhouette and tracking), "
        f"shape tree of {len(tree.leaves):,} poses -> {out}"
    )
    return 0


def _learnt(
    args: argparse.Namespace,
    frames: Iterator[tuple[int, np.ndarray]],
    camera: Camera,
    view: SilhouetteView,
) -> SilhouetteExtractor:
    """The extractor learnt from the empty stage: `--background`, or the first
    `--empty-frames` frames taken from `frames`; `InputError` naming where it came from."""
    if args.background:
        background = open_frames(args.background).frames()
        empty = list(sized_frames(background, args.background, camera, args.calib))
    else:
        empty = list(itertools.islice(frames, args.empty_frames))
    try:  # the empty stage is checked before the shape tree is built (up to a minute)
        return SilhouetteExtractor.for_tracking(
            [frame for _, frame in empty], view.size[0], method=args.method
        )
    except InputError as exc:
        stage = args.background or f"{args.video} (--empty-frames)"
        raise InputError(stage, exc.problem) from None
