"""Shared fixtures: the real CMU data (skipped with a reason where absent), the
synthetic stage of the live service tests, the small shape tree of the silhouette
tests, and the pose-store tests' store of three takes."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from silhouette_fixtures import SmallBuild, build_small_tree
from store_fixtures import make_take

from samba.cameras.calibration_file import write_calibration
from samba.db.store import PoseStore
from samba.db.synthetic_store import build_synthetic_store
from samba.ingest import import_paths
from samba.service.synthetic_capture import SyntheticCapture
from samba.silhouette.shape_tree import ShapeTree

ROOT = Path(__file__).resolve().parents[1]
REAL_DATABASE = (
    "cgspeed_131_01",
    "cgspeed_131_02",
    "iclone_002_01",
    "iclone_007_01",
    "daz_martial_04",
    "daz_salsa_10",
)
"""The CMU takes (three rigs) of `cmu_store`."""


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


@pytest.fixture(scope="session")
def c3d_dir() -> Path:
    """The folder of the real C3D marker takes; skips the test when it is absent."""
    data = shared_data_dir()
    if data is None or not (data / "c3d" / "85_02.c3d").is_file():
        pytest.skip(
            "real C3D data not found: set SAMBA_DATA or put ../shared/data/c3d beside the project"
        )
    return data / "c3d"


@pytest.fixture(scope="session")
def cmu_store(cmu_files: list[Path], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A pose store of six real CMU takes of three rigs, with their mirror images."""
    path = tmp_path_factory.mktemp("reconstruct") / "db"
    store = PoseStore.create(path)
    import_paths(store, [f for f in cmu_files if f.stem in REAL_DATABASE], mirror=True)
    return path


@pytest.fixture(scope="session")
def live_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A pose store of the built-in synthetic motions (the live service tests' database)."""
    path = tmp_path_factory.mktemp("serve") / "db"
    build_synthetic_store(path, takes_per_motion=2, seconds=4.0, seed=5)
    return path


@pytest.fixture(scope="session")
def live_capture() -> SyntheticCapture:
    """2 s of a held-out synthetic walk at 60 fps filmed by two 640x480 cameras."""
    return SyntheticCapture.film("walk", seconds=2.0, fps=60.0, size=(640, 480), seed=11)


@pytest.fixture(scope="session")
def live_calibration(
    live_capture: SyntheticCapture, tmp_path_factory: pytest.TempPathFactory
) -> Path:
    """The calibration file of `live_capture`'s cameras."""
    path = tmp_path_factory.mktemp("calib") / "stage.toml"
    write_calibration(path, live_capture.cameras)
    return path


@pytest.fixture(scope="session")
def small_build() -> SmallBuild:
    """The small tree of `silhouette_fixtures` with its inputs."""
    return build_small_tree()


@pytest.fixture(scope="session")
def small_tree() -> ShapeTree:
    """The small tree of `silhouette_fixtures`."""
    return build_small_tree().tree


@pytest.fixture
def path(tmp_path: Path) -> Path:
    """Where the test's store lives (not created yet)."""
    return tmp_path / "store"


@pytest.fixture
def store(path: Path) -> PoseStore:
    """A store with three takes: a (30 poses), b (20), c (25)."""
    s = PoseStore.create(path)
    s.add(make_take("a", 30, seed=1))
    s.add(make_take("b", 20, seed=2))
    s.add(make_take("c", 25, seed=3))
    return s
