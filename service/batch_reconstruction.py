"""Offline reconstruction of many marker takes (`samba reconstruct TAKE... --out-dir`), in
this process or on a Dask cluster (`--workers N | --cluster ADDRESS`): one task per take,
or per part of a take longer than `TASK_FRAMES`, each read, put on the reconstruction's
frame rate and reconstructed (`reconstruct_marker_take`) where it runs.

A part reconstructs the `SETTLE_FRAMES` frames before its first and throws them away, so
that the reconstruction's state (the previous estimates the smoothness term predicts
from, the markers held) has settled to that of the whole take's reconstruction; the
parts are joined in order and lowered to the floor of the whole take (`joined`). Measured
on the CMU take 85_12 (1,125 frames at 30 fps) in 3 parts, reconstructed by `samba`
against the 49 shared CMU files with their mirrors, the joints of the joined parts are at
most 7e-9 mm from those of the take reconstructed whole (0 against the tests' store of 6
takes, and with `calibrated` and `smoothed` there); with no frame to settle, 17 mm (40 mm,
164 mm) at the first frames of a part.

The pose store travels as its path, which every worker must be able to read (shared
storage); each process loads its index once per store snapshot and keeps it for the
takes that follow (`store_index`), so the database reaches a worker once, not once per
take. The reconstructions come back to the caller, which writes them.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import lru_cache, partial
from operator import attrgetter
from pathlib import Path
from typing import Any

from samba.base import outcomes_in_order
from samba.db import PoseIndex, PoseStore
from samba.ingest import MarkerSet, MarkerTake, read_marker_take
from samba.reconstruct import method
from samba.service.marker_reconstruction import (
    CHUNK_FRAMES,
    MarkerReconstruction,
    joined,
    reconstruct_marker_take,
)
from samba.service.session_indexes import SessionIndexes

INDEXES_KEPT = 4
"""Store indexes (store, snapshot, mirrored or not) a process keeps loaded."""
TASK_FRAMES = 1800
"""Most frames of a take one cluster task reconstructs (1 minute at 30 fps, a few
seconds of a worker): a longer take is split into parts of about equal length, each a
task, whose bounds are multiples of `CHUNK_FRAMES` (the batches of a whole take's
reconstruction)."""
SETTLE_FRAMES = CHUNK_FRAMES
"""Frames before a part's first that its task reconstructs and throws away (module
docstring): one batch of the whole take's reconstruction (64). 16 were enough on 85_12,
none left parts 1.7 cm off at their first frames."""


@dataclass(frozen=True)
class ReconstructionSettings:
    """How every take of a batch is reconstructed: the pose store at `database` (a
    path every worker reads), the method's name, the `marker_set` name (None: detected),
    the frame rate `fps` and the skin-offset `calibration` stretch (start, stop) in
    seconds (None: markers taken as joint centres)."""

    database: str
    method_name: str
    marker_set: str | None
    fps: float
    calibration: tuple[float, float] | None


@dataclass(frozen=True)
class TakePart:
    """Frames `first` to `stop` of the marker take at `path`, the `take`-th of a batch;
    `whole` when they are all of its frames (0 to 0: a take that could not be read)."""

    take: int
    path: str
    first: int
    stop: int
    whole: bool


def reconstruct_takes(
    paths: Sequence[str],
    settings: ReconstructionSettings,
    client: Any = None,
    progress: bool | None = None,
) -> Iterator[tuple[str, MarkerReconstruction | Exception]]:
    """Each marker take file of `paths` with its reconstruction, or the error that
    stopped it, in the order of `paths`: here one after the other (a bar per take's
    frames; `progress` None: on a terminal only), or with a Dask `client` one task per
    take, or per part of a long take (`take_parts`), on its workers (a bar counting the
    parts; the longest first in each window of tasks: `outcomes_in_order`)."""
    if client is None:
        for path in paths:
            try:
                outcome: MarkerReconstruction | Exception = reconstruct_file(
                    path, settings, progress
                )
            except Exception as exc:
                outcome = exc
            yield path, outcome
        return
    outcomes = outcomes_in_order(
        client,
        partial(_reconstruct_part, settings=settings),
        take_parts(paths, settings),
        progress=progress,
        unit="part",
        name=attrgetter("path"),
        cost=_part_frames,
    )
    for _, group in itertools.groupby(outcomes, key=lambda outcome: outcome[0].take):
        parts = list(group)
        failed = [o for _, o in parts if isinstance(o, Exception)]
        if failed or len(parts) == 1:
            yield parts[0][0].path, failed[0] if failed else parts[0][1]
        else:
            yield parts[0][0].path, joined([o for _, o in parts])


def take_parts(paths: Sequence[str], settings: ReconstructionSettings) -> list[TakePart]:
    """The parts of the takes of `paths` for a cluster's tasks, in order: a take of up
    to `TASK_FRAMES` frames (at `settings.fps`) whole, a longer one in parts of about
    equal length whose bounds are multiples of `CHUNK_FRAMES`. The takes are read here
    to count their frames; one that cannot be read is one part, whose task reports why."""
    parts = []
    for i, path in enumerate(paths):
        try:
            frames = len(_marker_take(path, settings))
        except Exception:
            frames = 0
        count = -(-frames // TASK_FRAMES)
        if count <= 1:
            parts.append(TakePart(i, path, 0, frames, whole=True))
            continue
        bounds = [round(frames * k / count / CHUNK_FRAMES) * CHUNK_FRAMES for k in range(count)]
        for first, stop in itertools.pairwise([*bounds, frames]):
            parts.append(TakePart(i, path, first, stop, whole=False))
    return parts


def reconstruct_file(
    path: str,
    settings: ReconstructionSettings,
    progress: bool | None = False,
    frames: tuple[int, int] | None = None,
) -> MarkerReconstruction:
    """The marker take at `path` (C3D or a recorded take) reconstructed as `settings`
    say, its markers (n, 8, 3) m put on `settings.fps` first; with `frames` (first,
    stop), those frames only, after `SETTLE_FRAMES` (a part for `joined`:
    `reconstruct_marker_take`)."""
    take = _marker_take(path, settings)
    chosen = method(settings.method_name)
    reconstructor = chosen.build(store_index(settings.database, chosen.mirrored_database))
    return reconstruct_marker_take(
        take, reconstructor, settings.calibration, progress, frames, SETTLE_FRAMES
    )


def store_index(database: str, mirrored: bool) -> PoseIndex:
    """The index of the store at `database` (with its poses' mirror images when
    `mirrored`), loaded once per snapshot of the store in this process."""
    store = PoseStore.open(database)
    return _loaded_index(str(store.path.resolve()), store.generation, mirrored)


@lru_cache(maxsize=INDEXES_KEPT)
def _loaded_index(path: str, generation: str, mirrored: bool) -> PoseIndex:
    """The index `SessionIndexes` loads for the store at `path`; `generation` keys the
    cache, so a store changed since gets its index loaded again."""
    return SessionIndexes().index(Path(path), mirrored)


def _marker_take(path: str, settings: ReconstructionSettings) -> MarkerTake:
    """The marker take at `path`, read with `settings.marker_set`, at `settings.fps`."""
    return read_marker_take(path, MarkerSet.named(settings.marker_set)).resampled(settings.fps)


def _reconstruct_part(part: TakePart, settings: ReconstructionSettings) -> MarkerReconstruction:
    """The task of `part`: its take whole, or its frames (`reconstruct_file`)."""
    frames = None if part.whole else (part.first, part.stop)
    return reconstruct_file(part.path, settings, frames=frames)


def _part_frames(part: TakePart) -> float:
    """The frames of `part`: the cost of its task."""
    return float(part.stop - part.first)
