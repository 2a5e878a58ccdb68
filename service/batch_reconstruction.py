"""Offline reconstruction of many marker takes (`samba reconstruct TAKE... --out-dir`), in
this process or on a Dask cluster (`--workers N | --cluster ADDRESS`): one task per take,
each read, put on the reconstruction's frame rate and reconstructed
(`reconstruct_marker_take`) where it runs.

The pose store travels as its path, which every worker must be able to read (shared
storage); each process loads its index once per store snapshot and keeps it for the
takes that follow (`store_index`), so the database reaches a worker once, not once per
take. The reconstructions come back to the caller, which writes them.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import lru_cache, partial
from pathlib import Path
from typing import Any

from samba.base import outcomes_in_order
from samba.db import PoseIndex, PoseStore
from samba.ingest import MarkerSet, read_marker_take
from samba.reconstruct import method
from samba.service.marker_reconstruction import MarkerReconstruction, reconstruct_marker_take
from samba.service.session_indexes import SessionIndexes

INDEXES_KEPT = 4
"""Store indexes (store, snapshot, mirrored or not) a process keeps loaded."""


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


def reconstruct_takes(
    paths: Sequence[str],
    settings: ReconstructionSettings,
    client: Any = None,
    progress: bool | None = None,
) -> Iterator[tuple[str, MarkerReconstruction | Exception]]:
    """Each marker take file of `paths` with its reconstruction, or the error that
    stopped it, in the order of `paths`: here one after the other (a bar per take's
    frames; `progress` None: on a terminal only), or with a Dask `client` one task per
    take on its workers (a bar counting takes)."""
    task = partial(reconstruct_file, settings=settings)
    if client is not None:
        yield from outcomes_in_order(client, task, list(paths), progress=progress, unit="take")
        return
    for path in paths:
        try:
            outcome: MarkerReconstruction | Exception = task(path, progress=progress)
        except Exception as exc:
            outcome = exc
        yield path, outcome


def reconstruct_file(
    path: str, settings: ReconstructionSettings, progress: bool | None = False
) -> MarkerReconstruction:
    """The marker take at `path` (C3D or a recorded take) reconstructed as `settings`
    say, its markers (n, 8, 3) m put on `settings.fps` first."""
    take = read_marker_take(path, MarkerSet.named(settings.marker_set)).resampled(settings.fps)
    chosen = method(settings.method_name)
    reconstructor = chosen.build(store_index(settings.database, chosen.mirrored_database))
    return reconstruct_marker_take(take, reconstructor, settings.calibration, progress)


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
