"""`samba calibrate`: calibrate a group of cameras from synchronised images of a board.

Each positional argument is one camera: a folder of images or a video file
(`samba.cameras.frame_source`); frame n of every camera is the same instant. The board is found
in every frame (`samba.cameras.calibration_board`), the cameras are calibrated jointly
(`samba.cameras.calibration`) and written as a calibration file (`samba.cameras.calibration_file`).
A camera is named after its folder or video file (without the extension).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from tqdm import tqdm

from samba.base.arguments import natural, positive
from samba.base.errors import InputError
from samba.cameras.calibration import MIN_VIEWS, WORLDS, CalibrationResult, calibrate
from samba.cameras.calibration_board import BOARD_SPEC_HELP, Board, BoardView, parse_board
from samba.cameras.calibration_file import write_calibration
from samba.cameras.frame_source import FrameSource, open_frames


def register(parser: argparse.ArgumentParser) -> None:
    """Add the `calibrate` arguments to `parser`."""
    parser.add_argument(
        "sources",
        nargs="+",
        metavar="IMAGES_OR_VIDEO",
        help="one per camera: a folder of images (frames in file-name order) or a video file",
    )
    parser.add_argument("--board", required=True, metavar="SPEC", help=BOARD_SPEC_HELP)
    parser.add_argument(
        "-o", "--output", required=True, metavar="CALIB.toml", help="calibration file to write"
    )
    parser.add_argument(
        "--world",
        choices=WORLDS,
        default="board",
        help="board: the board lies face up on the floor in --floor-frame, which becomes "
        "y = 0 with the origin at its first corner; camera0: the first camera at the "
        "origin looking along -Z (default board)",
    )
    parser.add_argument(
        "--floor-frame",
        type=natural,
        metavar="N",
        help="frame in which the board lies on the floor (default: the first frame in "
        "which any camera sees the board)",
    )
    parser.add_argument(
        "--every",
        type=positive,
        default=1,
        metavar="N",
        help="use every N-th frame only (frame numbers keep counting all frames)",
    )
    parser.add_argument(
        "--refine-intrinsics",
        action="store_true",
        help="also refine focal lengths, principal points and distortion in the joint "
        "adjustment (slower; helps when each camera saw the board in few images)",
    )
    parser.set_defaults(run=_run)


def _run(args: argparse.Namespace) -> int:
    board = parse_board(args.board)
    output = Path(args.output)
    if not output.resolve().parent.is_dir():
        raise InputError("--output", f"folder of {output} does not exist")
    sources = [open_frames(path) for path in args.sources]
    names = _camera_names(sources)
    if args.floor_frame is not None and args.world != "board":
        raise InputError("--floor-frame", "applies to --world board only")
    if args.floor_frame is not None and args.floor_frame % args.every:
        raise InputError("--floor-frame", f"frame {args.floor_frame} is skipped by --every")
    detections, sizes, frames = [], [], []
    for source in sources:
        found, size, count = _detect(board, source, args.every)
        detections.append(found)
        sizes.append(size)
        frames.append(count)
    result = calibrate(
        board,
        detections,
        sizes,
        names,
        world=args.world,
        floor_frame=args.floor_frame,
        refine_intrinsics=args.refine_intrinsics,
    )
    _print_report(result, frames, detections)
    write_calibration(output, result.cameras, error_px=float(np.mean(result.rms_px)))
    print(f"wrote {output}")
    return 0


def _camera_names(sources: Sequence[FrameSource]) -> list[str]:
    """Each source's folder name or video file stem; cam0, cam1, ... if they repeat."""
    names = [source.path.stem if source.is_video else source.path.name for source in sources]
    if len(set(names)) < len(names):
        return [f"cam{i}" for i in range(len(sources))]
    return names


def _detect(
    board: Board, source: FrameSource, every: int
) -> tuple[dict[int, BoardView], tuple[int, int], int]:
    """The board's views in a camera's frames (frame number -> view), the image size
    (width, height) and the number of frames examined. InputError when the board is found
    in fewer than `MIN_VIEWS` frames."""
    found: dict[int, BoardView] = {}
    size, count = (0, 0), 0
    frames = tqdm(source.frames(every), desc=str(source.path), unit="frame", disable=None)
    for number, image in frames:
        size, count = (image.shape[1], image.shape[0]), count + 1
        view = board.detect(image)
        if view is not None:
            found[number] = view
    if not found:
        raise InputError(
            str(source.path), f"the board ({board.spec}) was not found in any of its {count} frames"
        )
    if len(found) < MIN_VIEWS:
        raise InputError(
            str(source.path),
            f"the board was found in only {len(found)} of its {count} frames; calibration "
            f"needs at least {MIN_VIEWS}",
        )
    return found, size, count


def _print_report(
    result: CalibrationResult,
    frames: Sequence[int],
    detections: Sequence[dict[int, BoardView]],
) -> None:
    header = (
        f"{'camera':<12} {'frames':>6} {'board':>6} {'used':>5} {'rms px':>7} {'fx':>8} "
        f"{'fy':>8} {'cx':>7} {'cy':>7}  position (m)"
    )
    print(header)
    print("-" * len(header))
    for i, camera in enumerate(result.cameras):
        k = camera.matrix
        x, y, z = camera.center
        print(
            f"{camera.name:<12} {frames[i]:>6} {len(detections[i]):>6} {result.views[i]:>5} "
            f"{result.rms_px[i]:>7.3f} {k[0, 0]:>8.1f} {k[1, 1]:>8.1f} {k[0, 2]:>7.1f} "
            f"{k[1, 2]:>7.1f}  ({x:6.3f}, {y:6.3f}, {z:6.3f})"
        )
    print("frames: examined; board: frames in which the board was found; used: of those, in")
    print("the joint adjustment; rms px: reprojection error there")
    if result.world == "board":
        print(
            f"world: the board on the floor in frame {result.floor_frame} is y = 0, "
            "+Y up, origin at its first corner, meters"
        )
    else:
        print(f"world: camera {result.cameras[0].name} at the origin looking along -Z, +Y up")
