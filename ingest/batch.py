"""Batch import of motion files into a pose store, continuing past bad files."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

from tqdm import tqdm

from samba.base import SambaError
from samba.body import Take
from samba.db import PoseStore
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take
from samba.ingest.mcap_take import read_take

SUFFIXES = (".bvh", ".mcap")
"""Files picked up in named folders: BVH and takes recorded by the live service."""


@dataclass
class FileResult:
    """The outcome of importing one file.

    `status` is 'added', 'duplicate' (same content already stored) or 'failed'.
    `frames_in` counts the source file's frames, `frames_kept` the poses stored (per take,
    mirror not counted).
    """

    path: str
    status: str
    frames_in: int = 0
    frames_kept: int = 0
    rig: str = ""
    take_ids: tuple[int, ...] = ()
    warnings: list[str] = field(default_factory=list)
    error: str = ""


def expand_paths(paths: Iterable[str | Path]) -> list[Path]:
    """Files named directly, plus every motion file found (recursively) in named folders.

    A named path that does not exist is kept, so that its import fails with a clear error.
    """
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out.extend(sorted(f for f in p.rglob("*") if f.suffix.lower() in SUFFIXES))
        else:
            out.append(p)
    return out


def import_paths(
    store: PoseStore,
    paths: Iterable[str | Path],
    options: BvhImportOptions | None = None,
    mirror: bool = False,
    min_change: float = 0.0,
    progress: bool | None = None,
) -> list[FileResult]:
    """Import every file (folders are searched for .bvh files) into `store`.

    Each file commits on its own, so a bad file or an interruption loses nothing already
    imported; the index is rebuilt once at the end. A store whose catalog or pose data is
    damaged (`PoseStore.check_catalog`, `check_poses`) raises StoreError before anything
    is written. `progress` None shows a bar on a terminal only.
    """
    results: list[FileResult] = []
    files = expand_paths(paths)
    store.check_catalog()  # nothing goes into a damaged store
    store.check_poses()
    bar = tqdm(files, unit="file", disable=None if progress is None else not progress)
    for path in bar:
        bar.set_postfix_str(path.name, refresh=False)
        try:
            take = _load_take(path, options)
            added = store.add(take, mirror=mirror, min_change=min_change, build_index=False)
        except SambaError as exc:
            results.append(FileResult(str(path), "failed", error=str(exc)))
            continue
        status = "duplicate" if added.duplicate_of is not None else "added"
        ids = (added.duplicate_of,) if added.duplicate_of is not None else added.take_ids
        results.append(
            FileResult(
                str(path),
                status,
                frames_in=take.source_frames,
                frames_kept=added.frames_kept,
                rig=take.rig,
                take_ids=ids,
                warnings=list(take.warnings),
            )
        )
    if any(r.status == "added" for r in results):
        store.build_index()
    return results


def _load_take(path: Path, options: BvhImportOptions | None) -> Take:
    """A BVH file read with `options`, or a take the live service recorded (.mcap), which
    keeps its own frame rate and gets only the subject / action labels of `options`."""
    if path.suffix.lower() != ".mcap":
        return load_bvh_take(path, options)
    take = read_take(path)
    if options is not None:
        take.subject, take.action = options.subject, options.action
    return take
