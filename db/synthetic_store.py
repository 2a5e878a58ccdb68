"""A pose store filled with the built-in synthetic motions: the database of the demo and
of tests and benchmarks that must run without real motion capture."""

from __future__ import annotations

from pathlib import Path

from samba.db.store import PoseStore
from samba.synthetic import library


def build_synthetic_store(
    path: str | Path,
    takes_per_motion: int = 3,
    seconds: float = 6.0,
    seed: int = 0,
    mirror: bool = True,
) -> PoseStore:
    """Create a store at `path` (must not exist) holding `takes_per_motion` takes of
    `seconds` of every built-in motion at 30 fps (`samba.synthetic.motions.library`, random bodies
    from `seed`), with their mirror images when `mirror`, and its saved index."""
    store = PoseStore.create(path)
    for take in library(takes_per_motion=takes_per_motion, seconds=seconds, seed=seed):
        store.add(take, mirror=mirror, build_index=False)
    store.build_index()
    return store
