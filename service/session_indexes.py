"""`SessionIndexes`: the pose indexes that the sessions of one process search, shared.

Sessions that search the same snapshot of the same pose database (the same folder and
generation: an import in between makes a new snapshot) with the same kind of index
(the store's own, or one with the mirror images for methods with `mirrored_database`)
share one loaded index. It is read, and its masked tables made, once. The frames of
such sessions that arrive together are reconstructed in one batch
(`samba.service.frame_pipeline.process_together`). An index goes when the last session that
searches it closes.
"""

from __future__ import annotations

import threading
import weakref
from pathlib import Path

import numpy as np

from samba.body import mirror_poses
from samba.db import PoseIndex, PoseStore


class SessionIndexes:
    """The indexes of the sessions of one process; see the module docstring."""

    def __init__(self) -> None:
        self._indexes: weakref.WeakValueDictionary[tuple[str, str, bool], PoseIndex] = (
            weakref.WeakValueDictionary()
        )
        self._lock = threading.Lock()

    def index(self, database: str | Path, mirrored: bool) -> PoseIndex:
        """The index of the store at `database`, with the mirror images of its poses when
        `mirrored`; `StoreError` when the folder holds no store or no poses."""
        store = PoseStore.open(database)
        key = (str(store.path.resolve()), store.generation, mirrored)
        with self._lock:
            index = self._indexes.get(key)
            if index is None:
                index = store.index
                if mirrored:
                    poses = np.asarray(store.poses)
                    index = PoseIndex.build(
                        np.concatenate([poses, mirror_poses(poses)]),
                        scale_by_tibia=store.scale_by_tibia,
                    )
                self._indexes[key] = index
            return index
