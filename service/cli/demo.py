"""`samba demo`: a whole live capture on this machine, start to finish, in one command
(`samba.service.demo`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from samba.base import InputError, add_force_argument, address, positive_float
from samba.ingest import RigMap
from samba.ingest.cli import add_marker_set_argument
from samba.service.demo import DEFAULT_FOLDER, DemoSettings, run_demo
from samba.service.marker_motion import is_marker_file
from samba.service.vmc import MARIONETTE_PORT
from samba.synthetic import MOTIONS


def register(parser: argparse.ArgumentParser) -> None:
    """Add the demo's flags to `parser`."""
    parser.add_argument(
        "--out-dir",
        default=DEFAULT_FOLDER,
        metavar="DIR",
        help="folder the demo keeps its database, calibration, take and exports in "
        f"(default ./{DEFAULT_FOLDER})",
    )
    add_force_argument(parser)
    parser.add_argument(
        "--db",
        metavar="STORE",
        help="use this pose store instead of building one (default: build one in DIR/store)",
    )
    parser.add_argument(
        "--motion",
        type=_motion,
        default="walk",
        metavar="MOTION",
        help=f"built-in motion ({', '.join(MOTIONS)}), a BVH file, or a C3D file whose real "
        "markers the cameras film (default: walk)",
    )
    add_marker_set_argument(parser)
    parser.add_argument(
        "--map",
        metavar="FILE.toml",
        help="joint mapping file for a BVH --motion of a rig not recognised (samba db rig "
        "--write-map writes one; default: detected)",
    )
    parser.add_argument(
        "--seconds",
        type=positive_float,
        default=8.0,
        metavar="S",
        help="capture length, seconds (default 8)",
    )
    parser.add_argument(
        "--fps",
        type=positive_float,
        default=60.0,
        metavar="N",
        help="camera frame rate (default 60)",
    )
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
    parser.add_argument(
        "--open",
        action="store_true",
        help="open the viewer in a browser (default: print its address only)",
    )
    parser.add_argument("--seed", type=int, default=0, metavar="N", help="random seed (default 0)")
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
    """Run the demo in `--out-dir`; prints what it did."""
    if args.marker_set is not None and not is_marker_file(args.motion):
        raise InputError("--marker-set", "applies to a C3D file (--motion FILE.c3d) only")
    if args.map is not None and not args.motion.lower().endswith(".bvh"):
        raise InputError("--map", "applies to a BVH file (--motion FILE.bvh) only")
    settings = DemoSettings(
        motion=args.motion,
        seconds=args.seconds,
        fps=args.fps,
        db=args.db,
        vmc=args.vmc,
        out_dir=args.out_dir,
        force=args.force,
        open_viewer=args.open,
        seed=args.seed,
        avatar=args.avatar,
        marker_set=args.marker_set,
        rig_map=RigMap.from_toml(args.map) if args.map else None,
    )
    return run_demo(settings)
