"""Batch import of motion files into a pose store, continuing past bad files."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

from tqdm import tqdm

from samba.base import SambaError, outcomes_in_order
from samba.body import Take
from samba.db import AddResult, PoseStore, check_addable
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take
from samba.ingest.input_files import clipped
from samba.ingest.mcap_take import read_take

SUFFIXES = (".bvh", ".mcap")
"""Files picked up in named folders: BVH and takes recorded by the live service."""
FileReader = Callable[[Path, BvhImportOptions | None], Take]
"""Reads one motion file as a checked take, raising what is wrong (`read_file`)."""
FILES_PER_TASK = 8
"""Most files one Dask task reads: a file takes tens of milliseconds to read, about ten
times what the scheduler spends on a task. The files of a task are chosen by size (the
reading time grows with it), so that the tasks have similar work."""
READERS = 2
"""Threads that read files ahead of the commits in an import without a cluster: the BVH
reader's kernels, the file reads and the hashing run outside the GIL (the 49 shared CMU
files read in 0.15-0.20 s rather than 0.26-0.29 s one by one on two cores, 2026-12-06)."""
COMMIT_FILES = 64
"""Most files whose takes `import_paths` commits together."""
COMMIT_SECONDS = 1.0
"""Longest time (seconds) a file read by `import_paths` waits for its commit."""


@dataclass
class FileResult:
    """The outcome of importing one file.

    `status` is 'added', 'duplicate' (same content already stored) or 'failed' ('waiting'
    while its commit is pending).
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


class ImportInterrupted(KeyboardInterrupt):
    """Ctrl-C during `import_paths`: `done` holds the results of the files read and
    committed before it, of `total` files."""

    def __init__(self, done: list[FileResult], total: int) -> None:
        super().__init__()
        self.done = done
        self.total = total


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


def read_file(path: Path, options: BvhImportOptions | None) -> Take:
    """The take of the motion file at `path` (BVH, or .mcap: `_load_take`), checked as a
    store checks it before a commit (`samba.db.check_addable`); raises what is wrong."""
    take = _load_take(path, options)
    check_addable(take)
    return take


def import_paths(
    store: PoseStore,
    paths: Iterable[str | Path],
    options: BvhImportOptions | None = None,
    mirror: bool = False,
    min_change: float = 0.0,
    progress: bool | None = None,
    commit_files: int = COMMIT_FILES,
    commit_seconds: float = COMMIT_SECONDS,
    client: Any = None,
    read: FileReader = read_file,
) -> list[FileResult]:
    """Import every file (folders are searched for .bvh files) into `store`; one result
    per file, in order.

    Files are read ahead by `READERS` threads, and their takes committed in file order, in
    groups (`PoseStore.add_many`): once `commit_files` are waiting or the first of them has
    waited `commit_seconds`. A bad file fails alone, whatever its error (one line:
    `FileResult.error`); an interruption (or a crash) loses at most the files not yet
    committed, and the store always holds whole files. A file whose content is
    already stored, or comes in an earlier file, is a duplicate. The index is rebuilt
    once at the end. A store whose catalog or pose data is damaged
    (`PoseStore.check_catalog`, `check_poses`) raises StoreError before anything is
    written. `progress` None shows a bar on a terminal only. Ctrl-C raises
    `ImportInterrupted` with the results of the files committed before it.

    With a Dask `client` (`samba.base.cluster_client`) the files are read (`read`) on its
    workers, in tasks of up to `FILES_PER_TASK` files of similar total size, and
    committed here in the same order, so the store ends as a serial import leaves it; a
    file whose worker died each time it was tried fails with `WorkerDeathError`. The bar
    then counts the files read, in any order.
    """
    files = expand_paths(paths)
    store.check_catalog()  # nothing goes into a damaged store
    store.check_poses()
    results: list[FileResult] = []
    group = _CommitGroup(store, mirror, min_change, results)
    try:
        for path, take in _readings(files, options, read, progress, client):
            if isinstance(take, BaseException):  # a bad file fails alone, whatever its error
                results.append(FileResult(str(path), "failed", error=_failure(path, take)))
                continue
            group.hold(path, take)
            if len(group) >= commit_files or group.waited() >= commit_seconds:
                group.commit()
        group.commit()
    except KeyboardInterrupt:
        raise ImportInterrupted([r for r in results if r.status != "waiting"], len(files)) from None
    if any(r.status == "added" for r in results):
        store.build_index()
    return results


class _CommitGroup:
    """Takes read from files, waiting to be committed together; each has its place in
    `results`, filled in by `commit`."""

    def __init__(
        self, store: PoseStore, mirror: bool, min_change: float, results: list[FileResult]
    ) -> None:
        self.store = store
        self.mirror = mirror
        self.min_change = min_change
        self.results = results
        self.waiting: list[tuple[int, Take]] = []
        self.since = 0.0

    def __len__(self) -> int:
        return len(self.waiting)

    def hold(self, path: Path, take: Take) -> None:
        """Queue `take`, read from `path`, with a place in the results."""
        if not self.waiting:
            self.since = time.monotonic()
        self.waiting.append((len(self.results), take))
        self.results.append(FileResult(str(path), "waiting"))

    def waited(self) -> float:
        """Seconds since the first waiting take was queued (0 when none waits)."""
        return time.monotonic() - self.since if self.waiting else 0.0

    def commit(self) -> None:
        """Add the waiting takes in one commit and fill in their results; a store error
        fails each of them with it."""
        if not self.waiting:
            return
        takes = [take for _, take in self.waiting]
        try:
            added = self.store.add_many(
                takes, mirror=self.mirror, min_change=self.min_change, build_index=False
            )
        except SambaError as exc:
            for place, _ in self.waiting:
                self.results[place] = FileResult(self.results[place].path, "failed", error=str(exc))
        else:
            for (place, take), result in zip(self.waiting, added, strict=True):
                self.results[place] = _file_result(self.results[place].path, take, result)
        self.waiting = []


def _file_result(path: str, take: Take, added: AddResult) -> FileResult:
    """What became of the file at `path`, read as `take`, that the store added (or found
    a duplicate of) as `added`."""
    duplicate = added.duplicate_of is not None
    return FileResult(
        path,
        "duplicate" if duplicate else "added",
        frames_in=take.source_frames,
        frames_kept=added.frames_kept,
        rig=take.rig,
        take_ids=(added.duplicate_of,) if duplicate else added.take_ids,
        warnings=list(take.warnings),
    )


def _failure(path: Path, exc: BaseException) -> str:
    """The one line telling why the file `path` failed with `exc`: a `SambaError`'s own
    message, else the error's type and at most `QUOTE_CHARS` characters of its text."""
    if isinstance(exc, SambaError):
        return str(exc)
    return f"{path}: cannot import: {type(exc).__name__}: {clipped(str(exc))}"


def _readings(
    files: Sequence[Path],
    options: BvhImportOptions | None,
    read: FileReader,
    progress: bool | None,
    client: Any,
) -> Iterator[tuple[Path, Take | BaseException]]:
    """Each file with its take, or the error reading it raised, in file order: read here
    (`_read_ahead`), or with a Dask `client` on its workers."""
    if client is not None:
        task = partial(read, options=options)
        yield from outcomes_in_order(
            client,
            task,
            files,
            progress=progress,
            unit="file",
            most_per_task=FILES_PER_TASK,
            cost=_file_bytes,
        )
        return
    bar = tqdm(files, unit="file", disable=None if progress is None else not progress)
    outcomes = _read_ahead(files, partial(read, options=options))
    for path, outcome in zip(bar, outcomes, strict=True):
        bar.set_postfix_str(path.name, refresh=False)
        yield path, outcome


def _read_ahead(
    files: Sequence[Path], task: Callable[[Path], Take]
) -> Iterator[Take | BaseException]:
    """Each file's take `task(file)`, or the exception it raised, in file order: read by
    `READERS` threads at most `2 * READERS` files ahead. A KeyboardInterrupt (the user's
    Ctrl-C) propagates; on leaving, files not yet started are dropped and the ones being
    read are waited for."""
    pool = ThreadPoolExecutor(READERS, thread_name_prefix="samba-import")
    queue = iter(files)
    ahead: deque[Future[Take]] = deque()
    try:
        for path in queue:
            ahead.append(pool.submit(task, path))
            if len(ahead) == 2 * READERS:
                break
        while ahead:
            future = ahead.popleft()
            following = next(queue, None)
            if following is not None:
                ahead.append(pool.submit(task, following))
            try:
                outcome: Take | BaseException = future.result()
            except Exception as exc:  # a bad file fails alone, whatever its error
                outcome = exc
            yield outcome
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _file_bytes(path: Path) -> float:
    """The size of the file at `path` in bytes (0 when it cannot be read): what reading it
    costs, for balancing the cluster's tasks."""
    try:
        return float(path.stat().st_size)
    except OSError:
        return 0.0


def _load_take(path: Path, options: BvhImportOptions | None) -> Take:
    """A BVH file read with `options`, or a take the live service recorded (.mcap), which
    keeps its own frame rate and gets only the subject / action labels and the file size
    limit of `options`."""
    if path.suffix.lower() != ".mcap":
        return load_bvh_take(path, options)
    take = read_take(path, (options or BvhImportOptions()).max_file_bytes)
    if options is not None:
        take.subject, take.action = options.subject, options.action
    return take
