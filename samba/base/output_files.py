"""The one rule every `samba` command writes its outputs by: an existing file is never
overwritten without `--force`, and a command's own input never, even with `--force`.

Checked before any work is done, so a refused run costs nothing and leaves nothing."""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterable
from pathlib import Path

from samba.base.errors import InputError

FORCE_HINT = "--force overwrites"
"""How a refusal tells the way round it; every command with outputs has `--force`."""


def add_force_argument(parser: argparse.ArgumentParser) -> None:
    """Add `--force` to a command that writes files."""
    parser.add_argument(
        "--force",
        action="store_true",
        help="overwrite output files that exist (never the command's own inputs; default: refuse)",
    )


def check_outputs(
    outputs: Iterable[str | os.PathLike[str]],
    force: bool,
    inputs: Iterable[str | os.PathLike[str]] = (),
) -> None:
    """`InputError` naming the first of `outputs` (file paths, as typed) that is one of
    `inputs` (also with `force`: a command never writes over what it reads), whose folder
    does not exist, or that exists while `force` is False (the count of the others that
    exist too is in the same line)."""
    paths = [Path(p) for p in outputs]
    read = [Path(p) for p in inputs]
    for path in paths:
        source = next((p for p in read if _same_file(path, p)), None)
        if source is not None:
            raise InputError(
                str(path), f"is an input of this command ({source}); write the output elsewhere"
            )
        if path.is_dir():
            raise InputError(str(path), "is a folder; give a file name")
        if not path.parent.is_dir():
            raise InputError(str(path), f"its folder {path.parent} does not exist")
    existing = [p for p in paths if p.exists()]
    if existing and not force:
        more = f" (and {len(existing) - 1} more of the {len(paths)} outputs)"
        raise InputError(
            str(existing[0]),
            f"already exists{more if len(existing) > 1 else ''}; {FORCE_HINT}",
        )


def _same_file(a: Path, b: Path) -> bool:
    """Whether `a` and `b` name one file: the same path once links are followed, or (both
    existing) the same inode, which also catches hard links."""
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False
