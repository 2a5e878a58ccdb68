"""`samba examples DIR`: write the input files the README's and the manual's command
examples run on (`samba.service.examples`), then say what was written and what to try."""

from __future__ import annotations

import argparse
import time

from samba.base import add_force_argument
from samba.service.examples import NEXT_COMMANDS, write_examples


def register(parser: argparse.ArgumentParser) -> None:
    """Add the `examples` arguments to `parser`."""
    parser.add_argument(
        "dir",
        metavar="DIR",
        help="folder to write the example inputs into (made if missing); run the "
        "examples from inside it",
    )
    add_force_argument(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Write the example inputs into DIR and print each with what it is, then the next
    commands to try there."""
    began = time.perf_counter()
    written = write_examples(args.dir, args.force)
    width = max(len(str(path)) for path, _ in written)
    for path, what in written:
        print(f"wrote {path!s:<{width}}  {what}")
    print(f"in {time.perf_counter() - began:.1f} s. Next, in {args.dir}:")
    print(f"  cd {args.dir}")
    for command in NEXT_COMMANDS:
        print(f"  {command}")
    print("  and every example of the README and docs/ (they run as printed there)")
    return 0
