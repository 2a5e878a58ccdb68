"""The reconstruction's compiled kernel (`samba.reconstruct.kernels`) agrees with its numpy
reference: on neighbours whose limbs take the pseudo-poses' fallback axes, on the local
regression of a part with lost markers, and on whole takes of every method, live and
batched, with missing markers, to 1e-9 m."""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import numpy as np
import pytest

from samba.base import kernels_enabled
from samba.body.skeleton import markers_of, mirror_poses, standard_pose
from samba.db.index import PoseIndex
from samba.evaluation.protocol import capture_take
from samba.reconstruct.local_regression import local_regression
from samba.reconstruct.methods import METHODS
from samba.synthetic.motions import generate, library

pytestmark = pytest.mark.skipif(
    not kernels_enabled(), reason="numba kernels are off (SAMBA_KERNELS=numpy or no numba)"
)
TOLERANCE_M = 1e-9


def degenerate_poses() -> np.ndarray:
    """Standard poses (3, 13, 3) with a straight arm, an upper arm along the shoulder line
    and a leg bone along +Y: the pseudo-poses' fallback axes."""
    poses = np.repeat(standard_pose()[None], 3, axis=0)
    shoulder, elbow, wrist = poses[0, 1], poses[0, 3], poses[0, 5]
    poses[0, 5] = elbow + (elbow - shoulder)  # straight left arm
    line = poses[1, 1] - poses[1, 2]
    poses[1, 3] = poses[1, 1] + 0.3 * line / np.linalg.norm(line)  # along the shoulders
    poses[1, 5] = poses[1, 3] + (wrist - elbow)
    poses[2, 9] = poses[2, 7] + np.array([0.0, 0.4, 0.0])  # thigh straight up
    return poses


class FixedNeighbours:
    """A neighbour source that answers every query with the same poses (K, 13, 3)."""

    scale_by_tibia = False

    def __init__(self, poses: np.ndarray) -> None:
        self.poses = poses

    def query(self, markers: np.ndarray, k: int = 10, eps: float = 0.0):
        rows = np.tile(np.arange(len(self.poses))[:k], (len(markers), 1))
        return np.zeros(rows.shape), rows


@pytest.mark.parametrize("by_shoulders", [True, False])
@pytest.mark.parametrize("name", ["chai", "samba", "best"])
def test_degenerate_limbs_agree_with_numpy(
    name: str, by_shoulders: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Neighbours with a straight arm, an upper arm along the shoulder line and a thigh
    # straight up take the pseudo-poses' fallback axes; one observation lacks two markers
    # (a shoulder among them: placed by its centroid even with `shoulder_origin`).
    poses = np.concatenate([degenerate_poses(), library(1, 1.0)[0].poses[:27]])
    chosen = METHODS[name]
    chosen = replace(chosen, config=replace(chosen.config, shoulder_origin=by_shoulders))
    reconstructor = chosen.build(FixedNeighbours(poses.astype(np.float64)))
    markers = np.repeat(markers_of(poses[3])[None], 2, axis=0) + 0.01
    markers[1, [1, 5]] = np.nan
    has_target = np.array([False, True])
    compiled = reconstructor._solve_batch(markers, has_target)
    monkeypatch.setenv("SAMBA_KERNELS", "numpy")
    reference = reconstructor._solve_batch(markers, has_target)
    for field in ("offset", "gain", "anchor"):
        np.testing.assert_allclose(
            getattr(compiled, field), getattr(reference, field), atol=1e-9, rtol=1e-7
        )


@pytest.fixture(scope="module")
def database() -> np.ndarray:
    """(960, 13, 3) poses of the synthetic motions."""
    return np.concatenate([t.poses for t in library(takes_per_motion=1, seconds=4.0)])


@pytest.mark.parametrize("name", ["chai", "samba", "best", "lwr", "smoothed"])
def test_whole_takes_agree_with_the_numpy_path(
    name: str, database: np.ndarray, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Exact retrieval (eps 0), so both paths start from the same neighbours: the compiled
    # index's approximate search visits other poses than the numpy path's k-d tree.
    method = dataclasses.replace(METHODS[name], config=replace(METHODS[name].config, eps=0.0))
    poses = (
        np.concatenate([database, mirror_poses(database)]) if method.mirrored_database else database
    )
    index = PoseIndex.build(poses)
    markers = capture_take("kick", generate("kick", seconds=2.0, fps=30, seed=4).poses, 0).markers
    markers[10:14, 2] = np.nan  # a wrist lost for four frames
    markers[20, [0, 5]] = np.nan
    compiled = method.build(index).reconstruct(markers)
    live = method.build(index)
    stepped = np.stack([live.step(frame).pose for frame in markers])
    monkeypatch.setenv("SAMBA_KERNELS", "numpy")
    reference = method.build(index).reconstruct(markers)
    np.testing.assert_allclose(compiled.poses, reference.poses, atol=TOLERANCE_M, rtol=0)
    np.testing.assert_allclose(stepped, reference.poses, atol=TOLERANCE_M, rtol=0)
    np.testing.assert_array_equal(compiled.confident, reference.confident)


@pytest.mark.parametrize("scale_by_tibia", [False, True])
def test_local_regression_agrees_with_numpy(
    scale_by_tibia: bool, database: np.ndarray, monkeypatch: pytest.MonkeyPatch
) -> None:
    # 40 neighbours of three observations, one without its right wrist and a knee; the
    # second asks for two joints only.
    rng = np.random.default_rng(3)
    neighbours = database[rng.integers(0, len(database), size=(3, 40))].astype(np.float64)
    markers = markers_of(database[[5, 300, 700]]) + rng.normal(0.0, 0.01, (3, 8, 3))
    markers[2, [3, 4]] = np.nan
    distances = np.sort(rng.uniform(0.01, 0.2, size=(3, 40)), axis=1)
    joints = np.array([[3, 4, 7], [0, 8, -1], [7, 8, 0]])
    compiled = local_regression(markers, neighbours, distances, joints, scale_by_tibia, 3e-5)
    monkeypatch.setenv("SAMBA_KERNELS", "numpy")
    reference = local_regression(markers, neighbours, distances, joints, scale_by_tibia, 3e-5)
    assert compiled.shape == (3, 3, 3)
    assert np.isnan(compiled[1, 2]).all() and not np.isnan(compiled[[0, 2]]).any()
    np.testing.assert_allclose(compiled, reference, atol=TOLERANCE_M, rtol=0)
