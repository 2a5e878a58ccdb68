"""`PoseStore`: a directory holding a pose database that survives crashes.

Layout of a store directory:

* `catalog.sqlite`: the catalog (`samba.db.catalog`): a row per take and the committed state.
* `poses-<name>.f32`, `rows-<name>.i32`: the pose data files (`samba.db.pose_files`):
  every pose as float32 rows of 13 x 3 meters, memory-mapped, and per row its take id
  and frame number.
* `index.npz`: the prebuilt k-d tree index (`samba.db.index`), tagged with the generation.

Writers hold an exclusive `flock` on `lock`. An import (of one take, or of a group of
takes at once: `add_many`) appends pose rows past the committed count, fsyncs, then
commits the catalog rows and the new count in one SQLite transaction; rows past the
committed count are garbage from an interrupted import and are cut off by the next
writer. Deleting takes writes compacted data files under a new name and switches to them
in one transaction. So a kill at any moment leaves the previous or the new state. A
reader takes a snapshot when it opens (catalog rows in memory, the committed prefix of
the data files mapped) and keeps it while writers go on.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shlex
import sqlite3
import time
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from samba.body import Take
from samba.db.catalog import (
    FORMAT,
    SCHEMA,
    TakeInfo,
    connect,
    read_state,
    read_takes,
)
from samba.db.errors import StoreCorruptedError, StoreError
from samba.db.index import PoseIndex
from samba.db.pose_files import (
    DATA_PREFIXES,
    PoseBlock,
    append_rows,
    checksum,
    data_files,
    fsync_dir,
    fsync_file,
    map_committed,
    write_compacted,
)
from samba.db.take_checks import MAX_COORDINATE_M, check_addable, take_problems
from samba.db.take_refs import command_ref, find_take
from samba.db.take_rows import PreparedTake, insert_takes, stored_copy
from samba.db.take_rows import drop_near_duplicates as drop_near_duplicates

CATALOG = "catalog.sqlite"
INDEX = "index.npz"


@dataclass(frozen=True)
class AddResult:
    """What `PoseStore.add` did: the new take ids (original, then mirror), or the id of
    the take that already held the same content (`duplicate_of`)."""

    take_ids: tuple[int, ...] = ()
    frames_in: int = 0
    frames_kept: int = 0
    duplicate_of: int | None = None


@dataclass
class VerifyReport:
    """Problems found by `PoseStore.verify` (empty when the store is sound) and notes."""

    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when no problem was found."""
        return not self.problems


class PoseStore:
    """A snapshot of a pose store directory, with the operations that change it.

    `poses` (n, 13, 3) float32 meters, `take_ids` (n,) and `frames` (n,) int32 are the
    snapshot taken when the store was opened (or last refreshed); `takes` lists the
    catalog rows. Changing operations (`add`, `remove`, `label`) lock the store, refresh
    this object's snapshot (so they build on the latest committed state, whichever object
    or process committed it), commit, and refresh it again.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self._index: PoseIndex | None = None
        self.takes: list[TakeInfo] = []
        self._revision: str | None = None
        self.refresh()

    # -- opening -------------------------------------------------------------------------

    @classmethod
    def create(cls, path: str | Path, scale_by_tibia: bool = False) -> PoseStore:
        """Create an empty store at `path` (a new or empty directory) and open it.

        `scale_by_tibia` makes its index compare poses scaled to a common tibia length
        (see `PoseIndex.build`); it is fixed for the life of the store.
        """
        path = Path(path)
        if (path / CATALOG).exists():
            raise StoreError(str(path), "a pose store already exists here")
        if path.exists() and (not path.is_dir() or any(path.iterdir())):
            raise StoreError(str(path), "exists and is not an empty directory")
        path.mkdir(parents=True, exist_ok=True)
        tmp = path / f".{CATALOG}.{uuid.uuid4().hex}"
        conn = connect(tmp)
        try:
            conn.executescript(SCHEMA)
            now = datetime.now(UTC).isoformat(timespec="seconds")
            state = {
                "format": FORMAT,
                "n_poses": "0",
                "data_name": "0",
                "generation": uuid.uuid4().hex,
                "created": now,
                "scale_by_tibia": "1" if scale_by_tibia else "0",
            }
            conn.executemany("INSERT INTO state VALUES (?, ?)", state.items())
        finally:
            conn.close()
        for file in data_files(path, "0"):
            file.touch()
        fsync_file(tmp)
        os.replace(tmp, path / CATALOG)
        fsync_dir(path)
        return cls(path)

    @classmethod
    def open(cls, path: str | Path) -> PoseStore:
        """Open an existing store; raises `StoreError` when `path` holds none."""
        path = Path(path)
        if not (path / CATALOG).is_file():
            raise StoreError(str(path), "no pose store here (create one with `samba db init`)")
        return cls(path)

    def refresh(self) -> None:
        """Take a new snapshot of the committed state."""
        for _ in range(20):
            try:
                self._load_snapshot()
                return
            except FileNotFoundError as exc:
                missing = exc.filename
                time.sleep(0.05)  # a writer switched data files between our reads
        raise StoreError(
            str(missing), "missing: the store's data file is gone (or a writer keeps replacing it)"
        )

    def _load_snapshot(self) -> None:
        conn = self._connect()
        try:
            conn.execute("BEGIN")
            state = read_state(conn)
            revision = state.get("revision")
            # Catalog rows are read again only when another commit changed them: a loop of
            # imports would otherwise read every row after each file (quadratic time).
            same = revision is not None and revision == self._revision
            takes = self.takes if same else read_takes(conn)
            conn.execute("COMMIT")
        except (sqlite3.DatabaseError, ValueError) as exc:  # ValueError: bad text or JSON
            raise StoreError(str(self.path / CATALOG), f"catalog unreadable: {exc}") from exc
        finally:
            conn.close()
        if state.get("format") != FORMAT:
            raise StoreError(str(self.path), f"unknown store format {state.get('format')!r}")
        name = state["data_name"]
        self.poses, rows = map_committed(self.path, name, int(state["n_poses"]))
        self.take_ids = rows[:, 0]
        self.frames = rows[:, 1]
        self.takes = takes
        self._revision = revision
        self.generation = state["generation"]
        self.data_name = name
        self.scale_by_tibia = state.get("scale_by_tibia") == "1"
        if self._index is not None and self._index.generation != self.generation:
            self._index = None

    def _connect(self) -> sqlite3.Connection:
        try:
            return connect(self.path / CATALOG)
        except (sqlite3.Error, UnicodeDecodeError) as exc:  # a damaged schema can give either
            raise StoreError(str(self.path / CATALOG), f"cannot open catalog: {exc}") from exc

    def __len__(self) -> int:
        return len(self.poses)

    # -- reading -------------------------------------------------------------------------

    def take(self, ref: int | str) -> TakeInfo:
        """A take by id (an int, or text such as `#3`) or by name (any other text, digits
        too: `samba.db.take_refs`); raises `StoreError` if there is none (or several)."""
        return find_take(self.takes, ref, str(self.path))

    def removal_hint(self, take_ids: Sequence[int]) -> str:
        """The command that removes the takes `take_ids` (each by name where the name
        says which, a mirror through its original), e.g. `samba db rm STORE walk`."""
        by_id = {t.id: t for t in self.takes}
        refs: list[str] = []
        for take_id in take_ids:
            info = by_id[int(take_id)]
            info = by_id.get(info.mirror_of, info) if info.mirror_of is not None else info
            ref = command_ref(info, self.takes)
            if ref not in refs:
                refs.append(ref)
        return f"samba db rm {shlex.quote(str(self.path))} {' '.join(refs)}"

    def take_poses(self, ref: int | str) -> np.ndarray:
        """The poses (frame_count, 13, 3) float32 of one take, meters; StoreError naming
        the data file when they are damaged (`check_poses`)."""
        info = self.take(ref)
        poses = np.asarray(self.poses[info.first_row : info.first_row + info.frame_count])
        self._check_sound(
            poses,
            f"take {info.id} ({info.name!r})",
            self.take_ids[info.first_row : info.first_row + info.frame_count],
        )
        return poses

    def check_poses(self) -> None:
        """StoreError naming the data file, the takes whose poses hold NaN, infinity or a
        coordinate beyond `MAX_COORDINATE_M` (damage that `verify` details) and the
        command that removes them: searching, indexing or importing into such a store
        would fail or mislead."""
        self._check_sound(np.asarray(self.poses), "pose data", self.take_ids)

    def _check_sound(self, poses: np.ndarray, what: str, take_ids: np.ndarray) -> None:
        with np.errstate(invalid="ignore"):
            sound = np.abs(poses) <= MAX_COORDINATE_M  # False for NaN
        if sound.all():
            return
        bad_rows = ~sound.all(axis=(1, 2))
        known = {t.id for t in self.takes}
        causes = [int(i) for i in np.unique(take_ids[bad_rows]) if int(i) in known]
        names = ", ".join(f"{t.id} ({t.name!r})" for t in self.takes if t.id in causes)
        remedy = f"remove with `{self.removal_hint(causes)}`, then " if causes else ""
        raise StoreError(
            str(data_files(self.path, self.data_name)[0]),
            f"{what} damaged: {np.count_nonzero(~sound)} values NaN, infinite or beyond "
            f"{MAX_COORDINATE_M:g} m"
            + (f" in take {names}" if names else "")
            + f"; {remedy}run `samba db verify {shlex.quote(str(self.path))}`",
        )

    @property
    def index(self) -> PoseIndex:
        """The k-d tree index of this snapshot: loaded from disk, or rebuilt when stale."""
        if self._index is None:
            if len(self) == 0:
                raise StoreError(str(self.path), "the store holds no poses to search")
            index = self._load_saved_index()
            if index is None:
                self.check_poses()
                index = PoseIndex.build(
                    self.poses, generation=self.generation, scale_by_tibia=self.scale_by_tibia
                )
                self._save_index_if_current(index)
            self._index = index
        return self._index

    def index_is_fresh(self) -> bool:
        """True when `index.npz` is the index of this snapshot (a query loads, not rebuilds)."""
        return len(self) > 0 and self._load_saved_index() is not None

    def _load_saved_index(self) -> PoseIndex | None:
        """`index.npz` if it is readable and tagged with this snapshot's generation."""
        index = PoseIndex.load(self.path / INDEX, self.poses)
        if index is None or index.generation != self.generation:
            return None
        return index if index.scale_by_tibia == self.scale_by_tibia else None

    def _save_index_if_current(self, index: PoseIndex) -> None:
        with self._lock(blocking=False) as locked:
            if locked and self._committed_generation() == index.generation:
                index.save(self.path / INDEX)

    def _committed_generation(self) -> str:
        conn = self._connect()
        try:
            return read_state(conn)["generation"]
        finally:
            conn.close()

    def query(
        self, markers: np.ndarray, k: int = 10, eps: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """k nearest poses to markers (b, 8, 3) or (8, 3); see `PoseIndex.query`."""
        return self.index.query(markers, k=k, eps=eps)

    def stats(self) -> dict[str, object]:
        """Counts and sizes: takes, poses, per-rig counts, bytes on disk."""
        files = [p for p in self.path.iterdir() if p.is_file()]
        by_rig: dict[str, int] = {}
        for t in self.takes:
            by_rig[t.rig] = by_rig.get(t.rig, 0) + t.frame_count
        return {
            "path": str(self.path),
            "takes": len(self.takes),
            "mirrored_takes": sum(t.mirrored for t in self.takes),
            "poses": len(self),
            "poses_by_rig": by_rig,
            "seconds": round(sum(t.frame_count / t.fps for t in self.takes), 1),
            "bytes_on_disk": sum(p.stat().st_size for p in files),
            "index_fresh": self.index_is_fresh(),
            "scale_by_tibia": self.scale_by_tibia,
            "generation": self.generation,
        }

    # -- writing -------------------------------------------------------------------------

    @contextlib.contextmanager
    def _lock(self, blocking: bool = True) -> Iterator[bool]:
        with open(self.path / "lock", "a+b") as fh:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | (0 if blocking else fcntl.LOCK_NB))
            except BlockingIOError:
                yield False
                return
            try:
                yield True
            finally:
                fcntl.flock(fh, fcntl.LOCK_UN)

    @contextlib.contextmanager
    def _writing(
        self, poses_change: bool = True, appends_only: bool = False
    ) -> Iterator[sqlite3.Connection]:
        """Lock the store, open a write transaction; commit and refresh on success.

        Inside, this object's snapshot is the committed state the transaction starts
        from (another object or process may have committed since it was taken). Data
        files of other states are deleted before and after, under the lock. With
        `poses_change` the commit gets a new generation, which makes the saved index
        stale. Every commit gets a new catalog revision; with `appends_only` (the body
        only inserts takes) this object's take list is extended by the new rows rather
        than read again. Raising inside rolls everything back.
        """
        with self._lock():
            conn = self._connect()
            try:
                conn.execute("BEGIN IMMEDIATE")
                self._remove_orphans(read_state(conn))
                self.refresh()
                yield conn
                if poses_change:
                    conn.execute(
                        "UPDATE state SET value = ? WHERE key = 'generation'",
                        (uuid.uuid4().hex,),
                    )
                revision = uuid.uuid4().hex
                conn.execute(
                    "INSERT OR REPLACE INTO state (key, value) VALUES ('revision', ?)", (revision,)
                )
                takes = self._takes_after(conn) if appends_only else read_takes(conn)
                conn.execute("COMMIT")
            except BaseException:
                if conn.in_transaction:
                    conn.execute("ROLLBACK")
                raise
            finally:
                conn.close()
            self.takes, self._revision = takes, revision
            self.refresh()
            self._remove_orphans({"data_name": self.data_name})

    def _takes_after(self, conn: sqlite3.Connection) -> list[TakeInfo]:
        """This snapshot's takes followed by the rows a transaction inserted after them
        (ids above every id of the snapshot; they hold the rows after the snapshot's)."""
        last = max((t.id for t in self.takes), default=0)
        return self.takes + read_takes(conn, after_id=last)

    def _remove_orphans(self, state: dict[str, str]) -> None:
        current = {p.name for p in data_files(self.path, state["data_name"])}
        for p in self.path.iterdir():
            stale_data = p.name.startswith(DATA_PREFIXES) and p.name not in current
            if stale_data or p.name.startswith((".index-", f".{CATALOG}.")):
                p.unlink(missing_ok=True)

    def add(
        self,
        take: Take,
        mirror: bool = False,
        min_change: float = 0.0,
        build_index: bool = True,
    ) -> AddResult:
        """Import a take (and its left/right mirror when `mirror`); a no-op returning
        `duplicate_of` when a take with the same content hash is already stored.

        `min_change` (meters) drops near-duplicate consecutive poses. With
        `build_index` the index is rebuilt and saved after the commit. A take without
        poses raises `StoreError` before anything is written.
        """
        return self.add_many([take], mirror, min_change, build_index)[0]

    def add_many(
        self,
        takes: Sequence[Take],
        mirror: bool = False,
        min_change: float = 0.0,
        build_index: bool = True,
    ) -> list[AddResult]:
        """Import `takes` in one commit (one fsync of the data files, one catalog
        transaction): after a crash the store holds all of them or none. Each take is
        added as by `add`, in order; a take whose content is already stored, or comes
        earlier in `takes`, is a duplicate of it. Returns one result per take. A take
        without poses raises `StoreError` before anything is written.
        """
        for take in takes:
            check_addable(take)
        batch = [PreparedTake.of(take, mirror, min_change) for take in takes]
        try:
            results = self._add_prepared(batch)
        except _NothingAddedError as nothing:
            return nothing.results
        if build_index:
            self.build_index()
        return results

    def _add_prepared(self, batch: list[PreparedTake]) -> list[AddResult]:
        """Insert the catalog rows of every take of `batch` that is not a duplicate,
        append their poses and commit; `_NothingAddedError` (a rollback) when all are."""
        with self._writing(appends_only=True) as conn:
            n = int(read_state(conn)["n_poses"])
            now = datetime.now(UTC).isoformat(timespec="seconds")
            results: list[AddResult] = []
            blocks: list[PoseBlock] = []
            first = n
            for prepared in batch:
                duplicate = stored_copy(conn, prepared.take.content_hash)
                if duplicate is not None:
                    results.append(AddResult(frames_in=len(prepared.take), duplicate_of=duplicate))
                    continue
                ids = insert_takes(conn, prepared, first, now)
                for (data, _), take_id in zip(prepared.variants, ids, strict=True):
                    blocks.append(PoseBlock(data, take_id, prepared.frames))
                    first += len(data)
                results.append(
                    AddResult(
                        take_ids=tuple(ids),
                        frames_in=len(prepared.take),
                        frames_kept=len(prepared.frames),
                    )
                )
            if not blocks:
                raise _NothingAddedError(results)
            append_rows(self.path, self.data_name, n, blocks)
            conn.execute("UPDATE state SET value = ? WHERE key = 'n_poses'", (str(first),))
        return results

    def remove(self, refs: Sequence[int | str]) -> list[int]:
        """Delete takes by id or name (a take's mirror goes with it); returns the ids
        removed. Data files are compacted under a new name in the same commit."""
        targets = {self.take(r).id for r in refs}
        targets |= {t.id for t in self.takes if t.mirror_of in targets}
        with self._writing() as conn:
            takes = read_takes(conn)
            missing = targets - {t.id for t in takes}
            if missing:
                raise StoreError(str(self.path), f"takes {sorted(missing)} were removed meanwhile")
            keep = [t for t in takes if t.id not in targets]
            name = str(int(read_state(conn)["data_name"]) + 1)
            rows = np.stack([self.take_ids, self.frames], axis=1)
            total = write_compacted(self.path, name, self.poses, rows, [t.rows for t in keep])
            first = 0
            for t in keep:
                conn.execute("UPDATE takes SET first_row = ? WHERE id = ?", (first, t.id))
                first += t.frame_count
            conn.executemany("DELETE FROM takes WHERE id = ?", [(i,) for i in sorted(targets)])
            conn.execute("UPDATE state SET value = ? WHERE key = 'n_poses'", (str(total),))
            conn.execute("UPDATE state SET value = ? WHERE key = 'data_name'", (name,))
            if total == 0:
                (self.path / INDEX).unlink(missing_ok=True)
        if len(self):
            self.build_index()
        return sorted(targets)

    def label(
        self,
        ref: int | str,
        subject: str | None = None,
        action: str | None = None,
        tags: Sequence[str] | None = None,
    ) -> TakeInfo:
        """Set a take's subject, action and/or tags; returns the updated row."""
        take_id = self.take(ref).id
        with self._writing(poses_change=False) as conn:
            for column, value in (("subject", subject), ("action", action)):
                if value is not None:
                    conn.execute(f"UPDATE takes SET {column} = ? WHERE id = ?", (value, take_id))
            if tags is not None:
                conn.execute(
                    "UPDATE takes SET tags = ? WHERE id = ?",
                    (json.dumps(sorted(set(tags))), take_id),
                )
        return self.take(take_id)

    def build_index(self) -> PoseIndex:
        """Build the index for the current snapshot and save it (under the lock);
        StoreError when the pose data is damaged (`check_poses`)."""
        self.check_poses()
        index = PoseIndex.build(
            self.poses, generation=self.generation, scale_by_tibia=self.scale_by_tibia
        )
        with self._lock():
            if self._committed_generation() == self.generation:
                index.save(self.path / INDEX)
        self._index = index
        return index

    # -- checking ------------------------------------------------------------------------

    def verify(self) -> VerifyReport:
        """Check the catalog, the data files and the index against each other."""
        report = VerifyReport()
        result = self._catalog_check()
        if result != "ok":
            report.problems.append(f"catalog integrity check: {result}")
        expected = 0
        for t in sorted(self.takes, key=lambda t: t.first_row):
            if t.first_row != expected:
                report.problems.append(
                    f"take {t.id} starts at row {t.first_row}, expected {expected}"
                )
            expected = t.first_row + t.frame_count
            data = np.ascontiguousarray(self.poses[t.first_row : expected])
            if len(data) != t.frame_count:
                report.problems.append(f"take {t.id}: rows beyond the end of the data file")
                continue
            if checksum(data) != t.checksum:
                report.problems.append(f"take {t.id} ({t.name}): pose data checksum mismatch")
            if not (self.take_ids[t.first_row : expected] == t.id).all():
                report.problems.append(f"take {t.id} ({t.name}): pose rows name another take")
            refused = take_problems(data, t.fps)
            if refused:
                report.problems.append(
                    f"take {t.id} ({t.name}): import refuses it: {'; '.join(refused)}; "
                    f"`{self.removal_hint([t.id])}` removes it"
                )
        if expected != len(self):
            report.problems.append(f"takes cover {expected} rows but {len(self)} are committed")
        if len(self) and not self.index_is_fresh():
            report.notes.append("index is stale or missing; it is rebuilt on first query")
        return report

    def check_catalog(self) -> None:
        """StoreError naming the catalog when SQLite's integrity check fails on it (a
        few milliseconds: the catalog holds one row per take)."""
        result = self._catalog_check()
        if result != "ok":
            raise StoreError(
                str(self.path / CATALOG),
                f"damaged ({result.splitlines()[0]}); run `samba db verify {self.path}`",
            )

    def _catalog_check(self) -> str:
        """SQLite's integrity check of the catalog: "ok", or what it found."""
        conn = self._connect()
        try:
            return str(conn.execute("PRAGMA integrity_check").fetchone()[0])
        except sqlite3.DatabaseError as exc:
            return str(exc)
        finally:
            conn.close()

    def verify_or_raise(self) -> None:
        """Raise `StoreCorruptedError` listing every problem `verify` finds."""
        report = self.verify()
        if not report.ok:
            raise StoreCorruptedError(f"{self.path}: " + "; ".join(report.problems))


class _NothingAddedError(Exception):
    """Every take of a batch is a duplicate: the transaction rolls back (a commit would
    make the saved index stale for nothing); `results` says what each take duplicates."""

    def __init__(self, results: list[AddResult]) -> None:
        super().__init__(len(results))
        self.results = results
