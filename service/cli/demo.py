"""`samba demo`: a whole live capture on this machine, start to finish, in one command
(`samba.service.demo`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from samba.base import InputError, address, positive_float
from samba.ingest.cli import add_marker_set_argument
from samba.service.demo import DemoSettings, run_demo
from samba.service.marker_motion import is_marker_file
from samba.service.vmc import MARIONETTE_PORT
from samba.synthetic import MOTIONS


def register(parser: argparse.ArgumentParser) -> None:
    """Add the demo's flags to `parser`."""
    parser.add_argument("--out", help="folder for the database, take and exports (default: temp)")
    parser.add_argument("--db", help="use this pose store instead of building one")
    parser.add_argument(
        "--motion",
        type=_motion,
        default="walk",
        help=f"built-in motion ({', '.join(MOTIONS)}), a BVH file, or a C3D file whose real "
        "markers the cameras film (default: walk)",
    )
    add_marker_set_argument(parser)
    parser.add_argument("--seconds", type=positive_float, default=8.0, help="capture length")
    parser.add_argument("--fps", type=positive_float, default=60.0, help="camera frame rate")
    parser.add_argument(
        "--vmc",
        type=address,
        default=("127.0.0.1", MARIONETTE_PORT),
        metavar="HOST:PORT",
        help=f"also stream VMC here (default 127.0.0.1:{MARIONETTE_PORT})",
    )
    parser.add_argument(
        "--avatar",
        metavar="FILE",
        help="stream and export onto this humanoid avatar (glTF, VRM or USD; default: the "
        "built-in mannequin)",
    )
    parser.add_argument("--open", action="store_true", help="open the viewer in a browser")
    parser.add_argument("--seed", type=int, default=0, help="random seed")
    parser.set_defaults(run=run)


def _motion(value: str) -> str:
    """`--motion`: a built-in motion's name or an existing file, checked before the demo
    builds anything."""
    if value in MOTIONS or Path(value).is_file():
        return value
    raise argparse.ArgumentTypeError(
        f"{value!r} is neither a built-in motion ({', '.join(MOTIONS)}) nor a BVH or C3D file"
    )


def run(args: argparse.Namespace) -> int:
    """Run the demo in `--out` or a temporary folder; prints what it did."""
    if args.marker_set is not None and not is_marker_file(args.motion):
        raise InputError("--marker-set", "applies to a C3D file (--motion FILE.c3d) only")
    settings = DemoSettings(
        motion=args.motion,
        seconds=args.seconds,
        fps=args.fps,
        db=args.db,
        vmc=args.vmc,
        out=args.out,
        open_viewer=args.open,
        seed=args.seed,
        avatar=args.avatar,
        marker_set=args.marker_set,
    )
    return run_demo(settings)
