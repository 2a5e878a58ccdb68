"""What the Dask cluster tests share: a reader of motion files that kills the worker
process running it for chosen files (a worker dying mid-import)."""

from __future__ import annotations

import os
from pathlib import Path

from samba.body import Take
from samba.ingest import BvhImportOptions, read_file


def read_or_die(
    path: Path, options: BvhImportOptions | None, always: str, once: str, marks: Path
) -> Take:
    """`samba.ingest.read_file`, except that the worker process dies at once when it
    reads the file named `always`, and the first time any worker reads the file named
    `once` (a file in the folder `marks` remembers that time)."""
    if path.name == always:
        os._exit(1)
    if path.name == once and not (marks / once).exists():
        (marks / once).touch()
        os._exit(1)
    return read_file(path, options)
