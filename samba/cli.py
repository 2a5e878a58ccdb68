"""The `samba` console command: one entry point, a subcommand per area.

Each area registers its subcommands from its own package; the table below names the
module that does so, imported only when needed. A `SambaError` (or an operating
system error such as a full disk) is printed as one line on stderr with exit status 1;
wrong flags exit with status 2 (argparse).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence

from samba.base.errors import SambaError

AREAS: dict[str, tuple[str, str]] = {
    "db": (
        "samba.ingest.cli",
        "pose database: init, import, ls, show, label, rm, verify, stats, tree, query",
    ),
    "eval": (
        "samba.evaluation.experiment",
        "accuracy and speed of every reconstruction method on BVH takes",
    ),
    "calibrate": ("samba.cameras.recordings", "calibrate cameras from images or videos of a board"),
    "export": (
        "samba.export.cli",
        "retarget takes to a humanoid avatar and write USD, glTF or BVH",
    ),
    "serve": ("samba.service.serve_cli", "live capture server: packets in; VMC, viewer, takes out"),
    "demo": (
        "samba.service.demo",
        "a live capture end to end: server, two camera nodes, take, export",
    ),
    "node": (
        "samba.service.node_cli",
        "camera node: track the 8 markers (or, markerless, the body) in frames, send them by UDP",
    ),
    "track-video": (
        "samba.service.track_video_cli",
        "markerless capture from one camera: silhouettes tracked over the shape tree, as a take",
    ),
    "capture-volume": (
        "samba.service.capture_volume_cli",
        "model-free capture from several cameras: visual hull, derived skeleton, BVH",
    ),
}
"""Subcommand -> (module with `register(parser)`, one-line help)."""


class _CommandParser(argparse.ArgumentParser):
    """A subcommand's parser: arguments it does not know are its error, printed with its
    own usage (`samba db import: error: unrecognized arguments: ...`), not the top-level
    parser's."""

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        """Parse `args`; exit 2 with this parser's usage on any it does not know."""
        parsed, extras = super().parse_known_args(args, namespace)
        if extras:
            self.error(f"unrecognized arguments: {' '.join(extras)}")
        return parsed, extras


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser with every area's subcommands."""
    parser = argparse.ArgumentParser(
        prog="samba",
        description="Samba: low-cost real-time motion capture from eight markers.",
    )
    sub = parser.add_subparsers(
        dest="area", required=True, metavar="COMMAND", parser_class=_CommandParser
    )
    for name, (module, help_text) in AREAS.items():
        area = sub.add_parser(name, help=help_text, description=help_text)
        importlib.import_module(module).register(area)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        status = int(args.run(args) or 0)
        sys.stdout.flush()  # a reader that left (`| head`) shows here, not at exit
        return status
    except BrokenPipeError:  # before OSError, its base class: output piped into `head`
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # for the exit flush
        return 0
    except SambaError as exc:
        print(f"samba: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # disk full, permissions, ... on a path the user gave
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"samba: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("samba: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
