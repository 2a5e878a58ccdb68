"""A take as a pose store appends it: near-duplicate poses dropped, its mirror image, its
catalog rows (`samba.db.store.PoseStore.add_many` runs these inside its transaction)."""

from __future__ import annotations

import json
import sqlite3
from dataclasses import dataclass

import numpy as np

from samba.body import Take, mirror_poses
from samba.db.pose_files import checksum


def drop_near_duplicates(poses: np.ndarray, min_change: float) -> np.ndarray:
    """Indices of the poses (n, 13, 3) to keep: a pose is kept when some joint moved more
    than `min_change` meters since the last kept pose. The first pose is always kept."""
    if min_change <= 0 or len(poses) == 0:
        return np.arange(len(poses))
    keep = [0]
    last = poses[0]
    for i in range(1, len(poses)):
        if np.max(np.linalg.norm(poses[i] - last, axis=-1)) > min_change:
            keep.append(i)
            last = poses[i]
    return np.array(keep)


@dataclass(frozen=True)
class PreparedTake:
    """A take as it is stored: `variants` the poses (f, 13, 3) float32 meters with
    whether they are the mirror image (the take first), `frames` (f,) their frame
    numbers (after near-duplicate poses are dropped)."""

    take: Take
    variants: list[tuple[np.ndarray, bool]]
    frames: np.ndarray

    @classmethod
    def of(cls, take: Take, mirror: bool, min_change: float) -> PreparedTake:
        """`take` with poses moving less than `min_change` meters dropped, and its mirror
        image when `mirror`."""
        keep = drop_near_duplicates(take.poses, min_change)
        poses = np.ascontiguousarray(take.poses[keep], dtype=np.float32)
        variants = [(poses, False)]
        if mirror:
            variants.append((np.ascontiguousarray(mirror_poses(poses), dtype=np.float32), True))
        return cls(take, variants, take.frames[keep])


def stored_copy(conn: sqlite3.Connection, content_hash: str) -> int | None:
    """The id of the (unmirrored) take holding content `content_hash` in the transaction
    of `conn` (committed, or inserted earlier in it), or None."""
    row = conn.execute(
        "SELECT id FROM takes WHERE content_hash = ? AND mirrored = 0", (content_hash,)
    ).fetchone()
    return None if row is None else int(row[0])


def insert_takes(
    conn: sqlite3.Connection, prepared: PreparedTake, first_row: int, now: str
) -> list[int]:
    """Insert the catalog rows of a take and its mirror, whose poses start at row
    `first_row`; returns their ids (the take's first)."""
    take = prepared.take
    ids: list[int] = []
    first = first_row
    for data, mirrored in prepared.variants:
        cur = conn.execute(
            "INSERT INTO takes (name, source, content_hash, mirrored, mirror_of, rig, "
            "subject, action, tags, fps, frame_count, source_frames, first_row, "
            "checksum, meta, warnings, added_at) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, '[]', ?, ?, ?, ?, ?, ?, ?, ?)",
            (
                take.name + (" (mirrored)" if mirrored else ""),
                take.source,
                take.content_hash,
                int(mirrored),
                ids[0] if mirrored else None,
                take.rig,
                take.subject,
                take.action,
                take.fps,
                len(data),
                take.source_frames,
                first,
                checksum(data),
                json.dumps(take.meta),
                json.dumps(take.warnings),
                now,
            ),
        )
        ids.append(int(cur.lastrowid))
        first += len(data)
    return ids
