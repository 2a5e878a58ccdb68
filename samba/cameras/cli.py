"""`samba calibrate`: cameras from their recordings of a board, one camera's lens alone
(`--intrinsics-only`), or another calibration converted (`--convert`). This module only
parses and checks the flags; the calibration is the rest of `samba.cameras`."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from tqdm import tqdm

from samba.base import InputError, add_force_argument, check_outputs, natural, positive
from samba.cameras.calibration import WORLDS
from samba.cameras.calibration_board import BOARD_SPEC_HELP, parse_board
from samba.cameras.calibration_file import convert_calibration, write_calibration
from samba.cameras.recordings import calibrate_lens_recording, calibrate_recordings, camera_table


def register(parser: argparse.ArgumentParser) -> None:
    """`samba calibrate`: cameras from their recordings of a board, one camera's lens
    alone (--intrinsics-only), or another calibration converted (--convert)
    (`samba.cameras`)."""
    parser.add_argument(
        "sources",
        nargs="*",
        metavar="IMAGES_OR_VIDEO",
        help="one per camera: a folder of images (frames in file-name order) or a video file",
    )
    parser.add_argument(
        "--board",
        metavar="SPEC",
        help=f"the board (required unless --convert; no default): {BOARD_SPEC_HELP}",
    )
    parser.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="FILE.toml",
        help="calibration file to write",
    )
    add_force_argument(parser)
    parser.add_argument(
        "--intrinsics-only",
        action="store_true",
        help="one camera's lens alone (focal lengths, principal point, distortion) from "
        "its photos or video, e.g. a phone or webcam; the camera is written at the origin",
    )
    parser.add_argument(
        "--convert",
        metavar="IN",
        help="write the calibration IN (our TOML, anipose / Pose2Sim / FreeMoCap TOML, "
        "Qualisys .qca / .qca.txt, an EasyMocap folder with intri.yml and extri.yml) as "
        "ours, meters and +Y up; takes no images and no --board (default: calibrate from "
        "images)",
    )
    parser.add_argument(
        "--world",
        choices=WORLDS,
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
        help="use every N-th frame only (frame numbers keep counting all frames; default 1)",
    )
    parser.add_argument(
        "--refine-intrinsics",
        action="store_true",
        help="also refine focal lengths, principal points and distortion in the joint "
        "adjustment (slower; helps when each camera saw the board in few images)",
    )
    parser.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="print per image which detector found the board, or why none did",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Calibrate, or convert, and write the calibration; print the cameras."""
    output = Path(args.output)
    _check_calibrate_flags(args)
    check_outputs([output], args.force, [args.convert] if args.convert else args.sources)
    if args.convert:
        cameras = convert_calibration(args.convert, output)
        print("\n".join(camera_table(cameras)))
        print(f"wrote {output} from {args.convert}")
        return 0
    board = parse_board(args.board)
    log = tqdm.write if args.verbose else None
    if args.intrinsics_only:
        calibration = calibrate_lens_recording(args.sources[0], board, args.every, log)
    else:
        calibration = calibrate_recordings(
            args.sources,
            board,
            world=args.world or "board",
            floor_frame=args.floor_frame,
            every=args.every,
            refine_intrinsics=args.refine_intrinsics,
            log=log,
        )
    print(calibration.report())
    result = calibration.result
    write_calibration(output, result.cameras, error_px=float(np.mean(result.rms_px)))
    print(f"wrote {output}")
    return 0


def _check_calibrate_flags(args: argparse.Namespace) -> None:
    """InputError naming the flag for a combination `samba calibrate` cannot run."""
    if args.convert:
        if args.sources:
            raise InputError(
                "--convert", f"takes no images or videos (got {' '.join(args.sources)})"
            )
        given = {
            "--board": args.board is not None,
            "--intrinsics-only": args.intrinsics_only,
            "--world": args.world is not None,
            "--floor-frame": args.floor_frame is not None,
            "--every": args.every != 1,
            "--refine-intrinsics": args.refine_intrinsics,
        }
        for flag, present in given.items():
            if present:
                raise InputError(flag, "does not apply to --convert")
        return
    if not args.sources:
        raise InputError(
            "IMAGES_OR_VIDEO", "give a folder of images or a video per camera, or --convert IN"
        )
    if args.board is None:
        raise InputError("--board", "required to calibrate from images or videos")
    if args.intrinsics_only:
        if len(args.sources) > 1:
            raise InputError(
                "--intrinsics-only",
                f"takes one camera's images or video, got {len(args.sources)}: "
                f"{' '.join(args.sources)}",
            )
        given = {
            "--world": args.world is not None,
            "--floor-frame": args.floor_frame is not None,
            "--refine-intrinsics": args.refine_intrinsics,
        }
        for flag, present in given.items():
            if present:
                raise InputError(flag, "does not apply to --intrinsics-only (no world, one camera)")
