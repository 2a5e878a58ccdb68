"""The pose data files of a store, and writing them durably.

* `poses-<name>.f32`: every pose as float32 rows of 13 x 3 meters, memory-mapped.
* `rows-<name>.i32`: per pose row, int32 (take id, frame number).

`<name>` is the catalog's `data_name`; deleting takes writes compacted files under a new
name (`write_compacted`), an import appends rows past the committed count
(`append_rows`). Both fsync what they write before the catalog commits it; the catalog
(`samba.db.store`) says which name and how many rows are committed.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from samba.body import N_JOINTS
from samba.db.errors import StoreError

POSE_BYTES = N_JOINTS * 3 * 4
"""Bytes of one pose row: 13 joints x 3 float32 meters."""
ROW_BYTES = 2 * 4
"""Bytes of one row of `rows-<name>.i32`: int32 take id and frame number."""
DATA_PREFIXES = ("poses-", "rows-")
"""Name prefixes of the data files (of every name, committed or stale)."""


def data_files(store: Path, name: str) -> tuple[Path, Path]:
    """The pose file and the row file of data name `name` in the store at `store`."""
    return store / f"poses-{name}.f32", store / f"rows-{name}.i32"


def map_committed(store: Path, name: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The first `n` rows of the data files `name`, memory-mapped read-only: poses
    (n, 13, 3) float32 meters and rows (n, 2) int32 (take id, frame number).
    `StoreError` naming a file shorter than `n` rows."""
    poses_file, rows_file = data_files(store, name)
    for file, size in ((poses_file, POSE_BYTES), (rows_file, ROW_BYTES)):
        if file.stat().st_size < n * size:
            raise StoreError(str(file), f"shorter than the {n} committed poses: damaged")
    if not n:
        return np.empty((0, N_JOINTS, 3), dtype=np.float32), np.empty((0, 2), dtype=np.int32)
    poses = np.memmap(poses_file, dtype=np.float32, mode="r", shape=(n, N_JOINTS, 3))
    return poses, np.memmap(rows_file, dtype=np.int32, mode="r", shape=(n, 2))


@dataclass(frozen=True)
class PoseBlock:
    """The poses of one take as appended: `poses` (f, 13, 3) meters, its catalog id
    `take_id`, and the frame number (f,) of each pose."""

    poses: np.ndarray
    take_id: int
    frames: np.ndarray


def append_rows(store: Path, name: str, n: int, blocks: Sequence[PoseBlock]) -> None:
    """Write `blocks`, in order, after the first `n` committed rows of the data files
    `name` (cutting off any rows an interrupted import left there), and fsync them once."""
    poses_file, rows_file = data_files(store, name)
    with open(poses_file, "r+b") as pf, open(rows_file, "r+b") as rf:
        pf.truncate(n * POSE_BYTES)
        rf.truncate(n * ROW_BYTES)
        pf.seek(n * POSE_BYTES)
        rf.seek(n * ROW_BYTES)
        for block in blocks:
            pf.write(np.ascontiguousarray(block.poses, dtype=np.float32).tobytes())
            rows = np.stack([np.full(len(block.poses), block.take_id), block.frames], axis=1)
            rf.write(rows.astype(np.int32).tobytes())
        for fh in (pf, rf):
            fh.flush()
            os.fsync(fh.fileno())


def write_compacted(
    store: Path, name: str, poses: np.ndarray, rows: np.ndarray, keep: Sequence[range]
) -> int:
    """Write the row ranges `keep` of `poses` (n, 13, 3) and `rows` (n, 2), in order, as
    new data files `name`, fsynced with their folder; returns the rows written."""
    poses_file, rows_file = data_files(store, name)
    total = 0
    with open(poses_file, "wb") as pf, open(rows_file, "wb") as rf:
        for span in keep:
            pf.write(np.ascontiguousarray(poses[span.start : span.stop]).tobytes())
            rf.write(np.ascontiguousarray(rows[span.start : span.stop]).tobytes())
            total += len(span)
        for fh in (pf, rf):
            fh.flush()
            os.fsync(fh.fileno())
    fsync_dir(store)
    return total


def checksum(data: np.ndarray) -> str:
    """SHA-256 (hex) of poses as contiguous float32, the catalog's per-take checksum."""
    return hashlib.sha256(np.ascontiguousarray(data, dtype=np.float32).tobytes()).hexdigest()


def fsync_file(path: Path) -> None:
    """Flush `path` (a file or folder) to disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def fsync_dir(path: Path) -> None:
    """Flush the folder `path`'s entries (new and renamed files) to disk."""
    fsync_file(path)
