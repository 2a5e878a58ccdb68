"""Where an export's take comes from: a BVH file, a recorded .mcap take, or a pose store take."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from samba.body import N_JOINTS, Take
from samba.db import PoseStore, frame_count_problem
from samba.export.errors import ExportError
from samba.ingest import BvhImportOptions, RigMap, load_bvh_take, read_take


def load_take(
    ref: str, store: str | None = None, skip_tpose: bool = False, rig: RigMap | None = None
) -> Take:
    """The take named by `ref`: a take name or id of the pose store at `store`, or
    without a store a BVH file path (read at its own frame rate, its joints by `rig` or
    any rig detected; its leading T-pose frames dropped with `skip_tpose`) or an MCAP
    take recorded by the live service (`samba.ingest.mcap_take.read_take`).

    Store takes whose near-duplicate poses were dropped on import get the missing
    frames back by linear interpolation, so the take plays at its recorded speed.
    Raises an `InputError` subclass naming `ref` when it cannot be found or read.
    """
    if store is not None:
        return _store_take(PoseStore.open(store), ref)
    path = Path(ref)
    if path.suffix.lower() == ".mcap":
        return read_take(path)
    if path.suffix.lower() != ".bvh":
        raise ExportError(
            ref, "not a .bvh file or .mcap take; to export a take of a pose store, give --db STORE"
        )
    return load_bvh_take(path, BvhImportOptions(fps=None, skip_tpose=skip_tpose, rig=rig))


def _store_take(store: PoseStore, ref: str) -> Take:
    info = store.take(ref)
    poses = store.take_poses(info.id).astype(np.float64)  # StoreError when damaged
    rows = slice(info.first_row, info.first_row + info.frame_count)
    frames = np.asarray(store.frames[rows], dtype=np.int64)
    problem = frame_count_problem(int(frames[-1] - frames[0]) + 1)
    if problem:
        raise ExportError(ref, f"its frames {frames[0]}-{frames[-1]} played whole: {problem}")
    full = np.arange(frames[0], frames[-1] + 1)
    if len(full) != len(frames):
        flat = poses.reshape(len(poses), -1)
        poses = np.stack([np.interp(full, frames, c) for c in flat.T], axis=1)
        poses = poses.reshape(len(full), N_JOINTS, 3)
    return Take(name=info.name, poses=poses, fps=info.fps, source=info.source, rig=info.rig)
