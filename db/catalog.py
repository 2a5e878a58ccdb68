"""The store's catalog: one SQLite file with a row per take and the committed state.

The `state` table holds what a reader needs for a consistent snapshot: how many pose
rows are committed (`n_poses`), which data files hold them (`data_name`) and a
`generation` id that changes with every commit (the index is tagged with it).
"""

from __future__ import annotations

import json
import sqlite3
from dataclasses import dataclass
from pathlib import Path

FORMAT = "samba-pose-store/1"

SCHEMA = """
CREATE TABLE state (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE takes (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    name TEXT NOT NULL,
    source TEXT NOT NULL,
    content_hash TEXT NOT NULL,
    mirrored INTEGER NOT NULL DEFAULT 0,
    mirror_of INTEGER REFERENCES takes(id),
    rig TEXT NOT NULL,
    subject TEXT NOT NULL DEFAULT '',
    action TEXT NOT NULL DEFAULT '',
    tags TEXT NOT NULL DEFAULT '[]',
    fps REAL NOT NULL,
    frame_count INTEGER NOT NULL,
    source_frames INTEGER NOT NULL,
    first_row INTEGER NOT NULL,
    checksum TEXT NOT NULL,
    meta TEXT NOT NULL DEFAULT '{}',
    warnings TEXT NOT NULL DEFAULT '[]',
    added_at TEXT NOT NULL,
    UNIQUE (content_hash, mirrored)
);
"""


@dataclass(frozen=True)
class TakeInfo:
    """A catalog row: where a take came from and which pose rows hold it.

    Poses of the take are rows `first_row .. first_row + frame_count - 1` of the store;
    `fps` is their rate, `source_frames` the frame count of the source file.
    """

    id: int
    name: str
    source: str
    content_hash: str
    mirrored: bool
    mirror_of: int | None
    rig: str
    subject: str
    action: str
    tags: tuple[str, ...]
    fps: float
    frame_count: int
    source_frames: int
    first_row: int
    checksum: str
    meta: dict[str, str]
    warnings: tuple[str, ...]
    added_at: str

    @property
    def rows(self) -> range:
        """The take's row numbers in the store's pose array."""
        return range(self.first_row, self.first_row + self.frame_count)

    def to_dict(self) -> dict[str, object]:
        """The row as plain JSON-ready values."""
        return {
            "id": self.id,
            "name": self.name,
            "source": self.source,
            "content_hash": self.content_hash,
            "mirrored": self.mirrored,
            "mirror_of": self.mirror_of,
            "rig": self.rig,
            "subject": self.subject,
            "action": self.action,
            "tags": list(self.tags),
            "fps": self.fps,
            "frames": self.frame_count,
            "source_frames": self.source_frames,
            "first_row": self.first_row,
            "checksum": self.checksum,
            "meta": self.meta,
            "warnings": list(self.warnings),
            "added_at": self.added_at,
        }


TAKE_COLUMNS = (
    "id, name, source, content_hash, mirrored, mirror_of, rig, subject, action, tags, fps, "
    "frame_count, source_frames, first_row, checksum, meta, warnings, added_at"
)


def connect(path: Path) -> sqlite3.Connection:
    """A connection to the catalog at `path` with a generous busy timeout."""
    conn = sqlite3.connect(str(path), timeout=60.0, isolation_level=None)
    conn.execute("PRAGMA synchronous = FULL")
    return conn


def take_from_row(row: tuple) -> TakeInfo:
    """A `TakeInfo` from a SELECT of `TAKE_COLUMNS`."""
    (
        id_,
        name,
        source,
        digest,
        mirrored,
        mirror_of,
        rig,
        subject,
        action,
        tags,
        fps,
        frame_count,
        source_frames,
        first_row,
        checksum,
        meta,
        warnings,
        added_at,
    ) = row
    return TakeInfo(
        id=id_,
        name=name,
        source=source,
        content_hash=digest,
        mirrored=bool(mirrored),
        mirror_of=mirror_of,
        rig=rig,
        subject=subject,
        action=action,
        tags=tuple(json.loads(tags)),
        fps=fps,
        frame_count=frame_count,
        source_frames=source_frames,
        first_row=first_row,
        checksum=checksum,
        meta=json.loads(meta),
        warnings=tuple(json.loads(warnings)),
        added_at=added_at,
    )


def read_state(conn: sqlite3.Connection) -> dict[str, str]:
    """The committed state as a dict (format, n_poses, data_name, generation, created)."""
    return dict(conn.execute("SELECT key, value FROM state").fetchall())


def read_takes(conn: sqlite3.Connection, after_id: int = 0) -> list[TakeInfo]:
    """The catalog rows with an id above `after_id` (0: all), ordered by first row."""
    rows = conn.execute(
        f"SELECT {TAKE_COLUMNS} FROM takes WHERE id > ? ORDER BY first_row, id", (after_id,)
    ).fetchall()
    return [take_from_row(r) for r in rows]
