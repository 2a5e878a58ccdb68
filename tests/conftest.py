"""Shared fixtures: the real CMU data (skipped with a reason where absent)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def shared_data_dir() -> Path | None:
    """`$SAMBA_DATA` or `../shared/data` beside the project, if it holds cmu/*.bvh."""
    candidates = [Path(os.environ["SAMBA_DATA"])] if os.environ.get("SAMBA_DATA") else []
    candidates.append(ROOT.parent / "shared" / "data")
    for c in candidates:
        if any((c / "cmu").glob("*.bvh")):
            return c
    return None


@pytest.fixture(scope="session")
def cmu_dir() -> Path:
    """The folder of real CMU BVH files; skips the test when the shared data is absent."""
    data = shared_data_dir()
    if data is None:
        pytest.skip(
            "real CMU data not found: set SAMBA_DATA or put ../shared/data/cmu beside the project"
        )
    return data / "cmu"


@pytest.fixture(scope="session")
def cmu_files(cmu_dir: Path) -> list[Path]:
    """Every BVH file of the shared CMU data, sorted."""
    return sorted(cmu_dir.glob("*.bvh"))
