"""`samba capture-volume VIDEO... --calib FILE -o TAKE.bvh`: model-free capture from several
calibrated cameras (Chu, Jenkins, Matarić): visual hull, derived skeleton, BVH.

One video or image folder per camera, in the order of the cameras in the calibration,
is read in lockstep (the take ends with the shortest). Each camera's empty stage comes
from `--background` (one video or folder per camera) or from the first
`--empty-frames` frames of its video; footage without an empty stage takes `--segment`
(a learnt person segmenter, `samba.silhouette.person_segmentation`). Every frame's silhouettes
(`samba.silhouette.extraction`) are carved into a voxel volume (`samba.volume.visual_hull`);
the take runs from the first to the last frame with somebody in the volume. The
volumes give a kinematic model common to the take and its joint angles
(`samba.volume.capture`), written as BVH; with `--joints`, a human model's 13 capture
joints (`samba.volume.humanoid`) go to a NumPy archive too.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from samba.base import InputError, finite_float, natural, positive, positive_float
from samba.cameras import CameraGroup, open_frames, read_calibration, sized_frames
from samba.export import UNITS
from samba.service.video_capture import write_volume_capture
from samba.silhouette import BACKGROUND_METHODS, PersonSegmenter, SilhouetteExtractor
from samba.volume import (
    HUMAN_END_BRANCHES,
    MIN_VOXELS,
    Frames,
    VisualHull,
    VolumeCapture,
    VoxelGrid,
    capture_volumes,
    carve_streams,
    humanoid_joints,
    learn_extractors,
)

DEFAULT_BOUNDS = (-1.0, 0.0, -1.0, 1.0, 2.1, 1.0)
"""Capture volume (x0, y0, z0, x1, y1, z1) m: 2 x 2 m of floor, 2.1 m high."""


def register(parser: argparse.ArgumentParser) -> None:
    """Add the `capture-volume` arguments to `parser`."""
    parser.add_argument(
        "videos",
        nargs="+",
        metavar="VIDEO",
        help="video file or image folder of each camera, in the order of the cameras in --calib",
    )
    parser.add_argument("--calib", required=True, help="camera calibration TOML")
    parser.add_argument("-o", "--out", required=True, help="motion to write (.bvh)")
    stage = parser.add_mutually_exclusive_group(required=True)
    stage.add_argument(
        "--background",
        nargs="+",
        metavar="DIR_OR_VIDEO",
        help="video or image folder of the empty stage, one per camera in camera order",
    )
    stage.add_argument(
        "--empty-frames",
        type=natural,
        metavar="N",
        help="the first N frames of each VIDEO show the empty stage",
    )
    stage.add_argument(
        "--segment",
        action="store_true",
        help="no empty stage: find the person in every frame with a learnt person segmenter "
        "(MediaPipe Pose; set up once on first use, about 430 MB)",
    )
    parser.add_argument(
        "--method", choices=BACKGROUND_METHODS, default="colour", help="background model"
    )
    parser.add_argument(
        "--bounds",
        nargs=6,
        type=finite_float,
        default=DEFAULT_BOUNDS,
        metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"),
        help="capture volume corners, meters (default: %(default)s)",
    )
    parser.add_argument(
        "--voxel",
        type=positive_float,
        default=0.03,
        metavar="M",
        help="voxel edge, meters (default: 0.03)",
    )
    parser.add_argument(
        "--min-views",
        type=positive,
        metavar="N",
        help="cameras whose silhouette must hold a voxel to keep it (default: all)",
    )
    parser.add_argument(
        "--fps", type=positive_float, default=30.0, help="frame rate of the videos (default: 30)"
    )
    parser.add_argument(
        "--lowpass", type=positive_float, metavar="HZ", help="low-pass the joint angles at HZ"
    )
    parser.add_argument("--unit", choices=UNITS, default="m", help="BVH length unit (default: m)")
    parser.add_argument(
        "--joints", metavar="FILE.npz", help="also write the 13 capture joints of a human model"
    )
    parser.add_argument(
        "--facing",
        nargs=2,
        type=finite_float,
        default=(0.0, 1.0),
        metavar=("X", "Z"),
        help="the subject's forward direction in the first frame (default: +Z)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Capture the videos and write the BVH (and the joints); print what was done. A run
    that fails leaves no output file behind."""
    out = Path(args.out)
    _check_output(out, ".bvh", "the motion is written as BVH: give a .bvh file name")
    joints_out = Path(args.joints) if args.joints else None
    if joints_out is not None:
        _check_output(joints_out, ".npz", "the joints are written as a NumPy .npz archive")
    cameras = read_calibration(args.calib)
    _check_per_camera(args.videos, "videos", cameras, args.calib)
    if args.min_views is not None and args.min_views > len(cameras):
        raise InputError(
            "--min-views",
            f"{args.min_views} is more than the {len(cameras)} cameras of {args.calib}",
        )
    bounds = np.reshape(args.bounds, (2, 3))
    try:
        grid = VoxelGrid.from_bounds(bounds[0], bounds[1], args.voxel)
    except InputError as exc:
        raise InputError("--bounds", exc.problem) from None
    streams = [
        sized_frames(open_frames(video).frames(), video, camera, args.calib)
        for video, camera in zip(args.videos, cameras, strict=True)
    ]
    hull = VisualHull(grid, cameras)
    with contextlib.ExitStack() as workers:
        if args.segment:
            extractors = [
                SilhouetteExtractor(workers.enter_context(PersonSegmenter(video, camera.size)))
                for video, camera in zip(args.videos, cameras, strict=True)
            ]
        else:
            extractors = _extractors(args, streams, cameras)
        first, volumes, counts = carve_streams(streams, extractors, hull, args.min_views)
    if not volumes:
        raise InputError(
            ", ".join(args.videos),
            f"nobody was seen in the volume in any frame (none carves {MIN_VOXELS} voxels)",
        )
    capture = capture_volumes(np.stack(volumes), grid, args.fps)
    motion = capture.motion if args.lowpass is None else capture.motion.lowpassed(args.lowpass)
    joints = None
    if joints_out is not None and capture.fit.model.branch_count == HUMAN_END_BRANCHES:
        facing = np.array([args.facing[0], 0.0, args.facing[1]])
        joints = humanoid_joints(capture.fit, facing)
    write_volume_capture(out, motion, args.unit, joints_out, joints)
    note = ""
    if joints_out is not None and joints is None:
        note = (
            f"; not humanoid ({capture.fit.model.branch_count} end branches, not "
            f"{HUMAN_END_BRANCHES}): {joints_out} not written"
        )
    elif joints_out is not None:
        note = f", 13 joints -> {joints_out}"
    print(_summary(capture, counts, first, out) + note)
    return 0


def _summary(capture: VolumeCapture, counts: list[int], first: int, out: Path) -> str:
    """The line telling what was captured from volumes of `counts` voxels each, the
    first from video frame `first`, and written to `out`."""
    model, times = capture.fit.model, capture.times
    return (
        f"capture-volume: {len(counts)} frames (video frames {first}.."
        f"{first + len(counts) - 1}), {np.median(counts):,.0f} voxels per frame (median), model of "
        f"{model.branch_count} branches, {model.link_count} links {model.signature}, "
        f"humanoid in {capture.humanoid_rate:.0%} of frames, {np.median(times.total):.2f} s "
        f"per frame (median; Isomap {times.isomap.sum() / times.total.sum():.0%}) -> {out}"
    )


def _check_output(path: Path, suffix: str, problem: str) -> None:
    """`InputError` naming `path` unless it is a new file with `suffix` in an existing
    folder (`problem` says what the suffix is for)."""
    if path.suffix.lower() != suffix:
        raise InputError(str(path), problem)
    if path.exists():
        raise InputError(str(path), "already exists; captures are never overwritten")
    if not path.resolve().parent.is_dir():
        raise InputError(str(path), "its folder does not exist")


def _check_per_camera(
    sources: Sequence[str], what: str, cameras: CameraGroup, calibration: str
) -> None:
    """`InputError` naming `calibration` unless there is one of `sources` (`what` they
    are, plural) per camera of `cameras`."""
    if len(sources) != len(cameras):
        raise InputError(
            calibration,
            f"has {len(cameras)} cameras ({', '.join(cameras.names)}) but got {len(sources)} "
            f"{what}; give one per camera, in camera order",
        )


def _extractors(
    args: argparse.Namespace, streams: list[Frames], cameras: CameraGroup
) -> list[SilhouetteExtractor]:
    """Each camera's silhouette extractor (`--method`), learnt from its empty stage: its
    `--background` (checked against the camera's image size) or the first
    `--empty-frames` frames taken from its stream. An `InputError` names the video or
    background it comes from."""
    if args.background:
        _check_per_camera(args.background, "--background videos", cameras, args.calib)
        stages = [
            (source, sized_frames(open_frames(source).frames(), source, camera, args.calib))
            for source, camera in zip(args.background, cameras, strict=True)
        ]
    else:
        stages = [
            (video, itertools.islice(stream, args.empty_frames))
            for video, stream in zip(args.videos, streams, strict=True)
        ]
    return learn_extractors(stages, args.method)
