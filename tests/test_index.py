"""The k-d tree index returns exactly the brute-force nearest poses, with and without
missing markers, through the tree and through the scan of small tables, and survives a
save/load round trip."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from samba.body.alignment import align_markers
from samba.body.perturb import perturb_joint_angles
from samba.body.skeleton import Body, markers_of
from samba.db.errors import QueryError, StoreError
from samba.db.index import APPROXIMATE_EPS, PoseIndex
from samba.ingest.bvh_take import load_bvh_take


def _database(n: int, seed: int = 0) -> np.ndarray:
    """n varied poses (float32, meters): perturbed A-poses of random bodies, headings, places."""
    rng = np.random.default_rng(seed)
    base = np.stack(
        [
            Body.from_height(h).standard_pose(a)
            for h, a in zip(rng.uniform(1.5, 1.95, n), rng.uniform(5, 80, n), strict=True)
        ]
    )
    poses = perturb_joint_angles(base, 35.0, rng)
    yaw = rng.uniform(0, 2 * np.pi, n)
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.zeros((n, 3, 3))
    rot[:, 0, 0], rot[:, 0, 2], rot[:, 1, 1], rot[:, 2, 0], rot[:, 2, 2] = c, s, 1, -s, c
    poses = np.einsum("nij,nkj->nki", rot, poses) + rng.uniform(-2, 2, (n, 1, 3)) * [1, 0, 1]
    return poses.astype(np.float32)


def _observations(poses: np.ndarray, n: int, seed: int) -> np.ndarray:
    """Marker sets near (not equal to) database poses, with 1 cm noise."""
    rng = np.random.default_rng(seed)
    picked = poses[rng.choice(len(poses), n)].astype(np.float64)
    return markers_of(perturb_joint_angles(picked, 8.0, rng)) + rng.normal(0, 0.01, (n, 8, 3))


def brute_force(
    poses: np.ndarray, markers: np.ndarray, k: int, scale: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """The definition: distances over the observation's markers, database aligned likewise."""
    keep = ~np.isnan(markers).any(axis=1)
    db = markers_of(poses.astype(np.float64))
    db[:, ~keep] = np.nan
    db_aligned, _ = align_markers(db, scale_by_tibia=scale)
    obs_aligned, _ = align_markers(markers, scale_by_tibia=scale)
    d = np.linalg.norm((db_aligned[:, keep] - obs_aligned[keep]).reshape(len(poses), -1), axis=1)
    order = np.argsort(d, kind="stable")[:k]
    return d[order], order


def _assert_same(poses, markers, dist, idx, k, scale: bool = False) -> None:
    for m, d_row, i_row in zip(markers, dist, idx, strict=True):
        d_ref, i_ref = brute_force(poses, m, k, scale)
        np.testing.assert_allclose(d_row, d_ref, atol=2e-6)
        # the same poses, up to ties at equal distance
        assert set(i_row[d_row < d_ref[-1] - 1e-5]) <= set(i_ref)
        assert np.all(np.diff(d_row) >= -1e-9)


@pytest.fixture(scope="module")
def poses() -> np.ndarray:
    return _database(20_000)


def _tree_index(poses: np.ndarray) -> PoseIndex:
    """An index that searches its tree whatever the table's size."""
    index = PoseIndex.build(poses, generation="g1")
    index.scan_limit = 0
    return index


@pytest.fixture(scope="module", params=["tree", "scan"])
def index(poses: np.ndarray, request: pytest.FixtureRequest) -> PoseIndex:
    """The same table searched through the tree and by the scan (20,000 poses: scanned
    by default)."""
    if request.param == "tree":
        return _tree_index(poses)
    index = PoseIndex.build(poses, generation="g1")
    assert len(index) <= index.scan_limit
    return index


def test_complete_queries_equal_brute_force(poses, index) -> None:
    markers = _observations(poses, 60, seed=1)
    dist, idx = index.query(markers, k=10)
    assert dist.shape == idx.shape == (60, 10)
    _assert_same(poses, markers, dist, idx, 10)


def test_single_query_equals_batch(poses, index) -> None:
    markers = _observations(poses, 5, seed=2)
    _, idx = index.query(markers, k=7)
    for i in range(5):
        d1, i1 = index.query(markers[i], k=7)
        assert d1.shape == (7,)
        np.testing.assert_array_equal(i1, idx[i])


def test_a_stored_pose_finds_itself(poses, index) -> None:
    dist, idx = index.query(markers_of(poses[1234].astype(np.float64)), k=1)
    assert idx[0] == 1234 and dist[0] < 1e-5


@pytest.mark.parametrize("missing", [(0,), (3,), (6,), (0, 1), (2, 5), (4, 7), (1, 6)])
def test_queries_with_missing_markers_equal_brute_force(poses, index, missing) -> None:
    markers = _observations(poses, 12, seed=10 + sum(missing))
    markers[:, list(missing)] = np.nan
    dist, idx = index.query(markers, k=10)
    _assert_same(poses, markers, dist, idx, 10)


def test_mixed_missing_patterns_in_one_batch(poses, index) -> None:
    rng = np.random.default_rng(5)
    markers = _observations(poses, 40, seed=5)
    for row in markers:
        row[rng.choice(8, size=rng.integers(0, 3), replace=False)] = np.nan
    dist, idx = index.query(markers, k=5)
    _assert_same(poses, markers, dist, idx, 5)


def test_missing_marker_still_finds_the_true_pose(poses, index) -> None:
    markers = markers_of(poses[777].astype(np.float64))
    markers[[2, 5]] = np.nan  # left wrist and right knee lost
    dist, idx = index.query(markers, k=3)
    assert idx[0] == 777 and dist[0] < 1e-5


def test_tibia_scaled_index_finds_a_smaller_body_in_the_same_pose(poses) -> None:
    scaled = PoseIndex.build(poses, scale_by_tibia=True)
    small = markers_of(poses[:30].astype(np.float64)) * 0.8  # same poses, 80% size
    small[::2, 4] = np.nan
    dist, idx = scaled.query(small, k=5)
    _assert_same(poses, small, dist, idx, 5, scale=True)
    assert (idx[:, 0] == np.arange(30)).all() and dist[:, 0].max() < 1e-5
    _, unscaled = PoseIndex.build(poses).query(small, k=1)
    assert (unscaled[:, 0] != np.arange(30)).any()


def test_approximate_search_has_high_recall(poses) -> None:
    index = _tree_index(poses)
    markers = _observations(poses, 200, seed=3)
    _, exact = index.query(markers, k=10)
    _, approx = index.query(markers, k=10, eps=APPROXIMATE_EPS)
    recall = np.mean([len(set(a) & set(e)) / 10 for a, e in zip(approx, exact, strict=True)])
    assert recall >= 0.97


def test_scan_is_exact_among_poses_at_equal_distance() -> None:
    """Forty copies of one pose fill the scan's candidates with ties its float32 ranking
    cannot order; it must fall back to full precision and still agree with brute force."""
    others = _database(3_000, seed=7)
    poses = np.concatenate([others, np.repeat(others[:1], 40, axis=0), others[1:2] + 1e-6])
    index = PoseIndex.build(poses)
    markers = markers_of(others[0].astype(np.float64)) + 0.003
    dist, idx = index.query(markers[None], k=10)
    _assert_same(poses, markers[None], dist, idx, 10)
    for scanned in (index, _tree_index(poses)):
        d, _ = scanned.query(markers[None], k=45)
        d_ref, _ = brute_force(poses, markers, 45)
        np.testing.assert_allclose(d[0], d_ref, atol=2e-6)


def test_save_and_load_round_trip_without_pickle(poses, index, tmp_path: Path) -> None:
    path = tmp_path / "index.npz"
    index.save(path)
    with np.load(path, allow_pickle=False) as data:
        assert all(data[key].dtype != object for key in data.files)
    loaded = PoseIndex.load(path, poses)
    assert loaded is not None and loaded.generation == "g1" and not loaded.scale_by_tibia
    markers = _observations(poses, 20, seed=4)
    (d1, i1), (d2, i2) = index.query(markers, k=10), loaded.query(markers, k=10)
    np.testing.assert_allclose(d1, d2, rtol=1e-12)  # the compiled scan may reorder sums
    np.testing.assert_array_equal(i1, i2)


def test_load_rejects_stale_or_damaged_files(poses, index, tmp_path: Path) -> None:
    path = tmp_path / "index.npz"
    assert PoseIndex.load(path, poses) is None  # absent
    index.save(path)
    assert PoseIndex.load(path, poses[:-1]) is None  # built for another pose count
    path.write_bytes(path.read_bytes()[:1000])
    assert PoseIndex.load(path, poses) is None  # truncated


def test_bad_queries_raise_query_errors(index) -> None:
    with pytest.raises(QueryError, match="expected"):
        index.query(np.zeros((7, 3)))
    with pytest.raises(QueryError, match="k must be"):
        index.query(np.zeros((8, 3)), k=0)
    with pytest.raises(QueryError, match="no marker"):
        index.query(np.full((8, 3), np.nan))
    with pytest.raises(QueryError, match="eps"):
        index.query(np.zeros((8, 3)), eps=-1)
    with pytest.raises(StoreError):
        PoseIndex.build(np.empty((0, 13, 3), dtype=np.float32))


def test_real_data_queries_equal_brute_force(cmu_files: list[Path]) -> None:
    poses = np.concatenate([load_bvh_take(f).poses for f in cmu_files[::4]])
    held_out = load_bvh_take(cmu_files[1]).poses[::25].astype(np.float64)
    markers = markers_of(held_out)
    markers[::3, 3] = np.nan
    for index in (PoseIndex.build(poses), _tree_index(poses)):
        dist, idx = index.query(markers, k=10)
        _assert_same(poses, markers, dist, idx, 10)
