"""`samba capture-volume VIDEO... --calib FILE -o TAKE.bvh`: model-free capture from several
calibrated cameras (Chu, Jenkins, Matarić): visual hull, derived skeleton, BVH.

One video or image folder per camera, in the order of the cameras in the calibration,
is read in lockstep (the take ends with the shortest); frames cut by a few pixels at the
right or bottom of the calibrated image (an encoder's crop) are taken, with a line
saying so (`samba.cameras.camera_frames`). The capture volume is `--bounds`, by default the
box over the floor that the cameras carving a voxel all see, 2.2 m high
(`samba.volume.floor_coverage`). Each camera's empty stage comes
from `--background` (one video or folder per camera) or from the first
`--empty-frames` frames of its video; footage without an empty stage takes `--segment`
(a learnt person segmenter, `samba.silhouette.person_segmentation`). Every frame's silhouettes
(`samba.silhouette.extraction`) are carved into a voxel volume (`samba.volume.visual_hull`);
the take runs from the first to the last frame with somebody in the volume. The
volumes give a kinematic model common to the take and its joint angles
(`samba.volume.capture`), written as BVH; with `--joints`, a human model's 13 capture
joints (`samba.volume.humanoid`) go to a NumPy archive too, left and right taken from
`--facing` or, by default, from the direction the subject walks.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from samba.base import (
    InputError,
    add_force_argument,
    check_outputs,
    finite_float,
    natural,
    positive,
    positive_float,
)
from samba.cameras import Camera, CameraGroup, camera_frames, read_calibration
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
    capture_region,
    capture_volumes,
    carve_streams,
    humanoid_joints,
    learn_extractors,
    walked_direction,
)

FACING = (0.0, 1.0)
"""The subject's forward direction (x, z) when neither `--facing` nor the path gives it."""


def register(parser: argparse.ArgumentParser) -> None:
    """Add the `capture-volume` arguments to `parser`."""
    parser.add_argument(
        "videos",
        nargs="+",
        metavar="VIDEO",
        help="video file or image folder of each camera, in the order of the cameras in --calib",
    )
    parser.add_argument("--calib", required=True, metavar="FILE", help="camera calibration TOML")
    parser.add_argument(
        "-o", "--output", required=True, metavar="FILE.bvh", help="motion to write (.bvh)"
    )
    add_force_argument(parser)
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
        "--method",
        choices=BACKGROUND_METHODS,
        default="colour",
        help="background model (default colour)",
    )
    parser.add_argument(
        "--bounds",
        nargs=6,
        type=finite_float,
        metavar=("X0", "Y0", "Z0", "X1", "Y1", "Z1"),
        help="capture volume corners, meters (default: the floor all cameras carving a voxel "
        "see, up to 2.2 m)",
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
        "--tolerance",
        type=natural,
        default=0,
        metavar="PX",
        help="keep voxels within PX pixels of a silhouette: a calibration a few pixels off "
        "carves thin parts (the feet) away (default: 0)",
    )
    parser.add_argument(
        "--fps",
        type=positive_float,
        default=30.0,
        metavar="N",
        help="frame rate of the videos (default: 30)",
    )
    parser.add_argument(
        "--lowpass",
        type=positive_float,
        metavar="HZ",
        help="low-pass the joint angles at HZ (default: as captured)",
    )
    parser.add_argument("--unit", choices=UNITS, default="m", help="BVH length unit (default: m)")
    parser.add_argument(
        "--joints",
        metavar="FILE.npz",
        help="also write the 13 capture joints of a human model (default: none)",
    )
    parser.add_argument(
        "--facing",
        nargs=2,
        type=finite_float,
        metavar=("X", "Z"),
        help="the subject's forward direction in the first frame (default: the direction "
        "walked, else +Z)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Capture the videos and write the BVH (and the joints); print what was done. A run
    that fails leaves no output file behind."""
    out = Path(args.output)
    _check_suffix(out, ".bvh", "the motion is written as BVH: give a .bvh file name")
    joints_out = Path(args.joints) if args.joints else None
    if joints_out is not None:
        _check_suffix(joints_out, ".npz", "the joints are written as a NumPy .npz archive")
    inputs = [*args.videos, *(args.background or []), args.calib]
    check_outputs([out, *([joints_out] if joints_out else [])], args.force, inputs)
    cameras = read_calibration(args.calib)
    if len(cameras) < 2:
        raise InputError(
            args.calib, f"has {len(cameras)} camera; a visual hull needs at least 2 cameras"
        )
    _check_per_camera(args.videos, "videos", cameras, args.calib)
    if args.min_views is not None and args.min_views > len(cameras):
        raise InputError(
            "--min-views",
            f"{args.min_views} is more than the {len(cameras)} cameras of {args.calib}",
        )
    if args.bounds is None:
        bounds = capture_region(cameras, args.min_views)
        print(_region_line(bounds, args.min_views or len(cameras), len(cameras)))
    else:
        bounds = np.reshape(args.bounds, (2, 3))
    try:
        grid = VoxelGrid.from_bounds(bounds[0], bounds[1], args.voxel)
    except InputError as exc:
        raise InputError("--bounds", exc.problem) from None
    streams = [
        _camera_frames(video, camera, args.calib)
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
        first, volumes, counts = carve_streams(
            streams, extractors, hull, args.min_views, args.tolerance
        )
    if not volumes:
        raise InputError(
            ", ".join(args.videos),
            f"nobody was seen in the volume in any frame (none carves {MIN_VOXELS} voxels)",
        )
    capture = capture_volumes(np.stack(volumes), grid, args.fps)
    motion = capture.motion if args.lowpass is None else capture.motion.lowpassed(args.lowpass)
    joints, facing = None, ""
    if joints_out is not None and capture.fit.model.branch_count == HUMAN_END_BRANCHES:
        forward, facing = _facing(args.facing, capture.fit.root)
        joints = humanoid_joints(capture.fit, forward)
    write_volume_capture(out, motion, args.unit, joints_out, joints)
    note = ""
    if joints_out is not None and joints is None:
        note = (
            f"; not humanoid ({capture.fit.model.branch_count} end branches, not "
            f"{HUMAN_END_BRANCHES}): {joints_out} not written"
        )
    elif joints_out is not None:
        note = f", 13 joints -> {joints_out} ({facing})"
    print(_summary(capture, counts, first, out) + note)
    return 0


def _camera_frames(source: str, camera: Camera, calibration: str) -> Frames:
    """The frames of the video or folder `source` of `camera` (of the file
    `calibration`) at its image size; a line says so when they are its image cut."""
    frames, note = camera_frames(source, camera, calibration)
    if note:
        print(note)
    return frames


def _region_line(bounds: np.ndarray, views: int, cameras: int) -> str:
    """The line telling the capture volume `bounds` (2, 3) m derived from the
    calibration: the floor `views` of the `cameras` see."""
    (x0, y0, z0), (x1, y1, z1) = bounds
    seen = "all" if views == cameras else f"{views} of the"
    return (
        f"capture volume x {x0:.2f}..{x1:.2f}, y {y0:.2f}..{y1:.2f}, z {z0:.2f}..{z1:.2f} m: "
        f"the floor {seen} {cameras} cameras see (--bounds to set it)"
    )


def _facing(given: Sequence[float] | None, root: np.ndarray) -> tuple[np.ndarray, str]:
    """The subject's forward direction (3,) and where it came from, in words: `given`
    (x, z) by --facing, else the direction the root (n, 3) m walked, else `FACING`."""
    if given is not None:
        return np.array([given[0], 0.0, given[1]]), "facing from --facing"
    walked = walked_direction(root)
    if walked is not None:
        return walked, f"facing ({walked[0]:.2f}, {walked[2]:.2f}): the direction walked"
    return np.array([FACING[0], 0.0, FACING[1]]), "facing +Z: --facing to set it"


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


def _check_suffix(path: Path, suffix: str, problem: str) -> None:
    """`InputError` naming `path` unless it ends in `suffix` (`problem` says what the
    suffix is for)."""
    if path.suffix.lower() != suffix:
        raise InputError(str(path), problem)


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
            (source, _camera_frames(source, camera, args.calib))
            for source, camera in zip(args.background, cameras, strict=True)
        ]
    else:
        stages = [
            (video, itertools.islice(stream, args.empty_frames))
            for video, stream in zip(args.videos, streams, strict=True)
        ]
    return learn_extractors(stages, args.method)
