"""The local pose space and its energy (`samba.reconstruct.local_space`).

The exact fast solver and the paper's Levenberg-Marquardt from its initial value must
find the same pose (within 1e-6 m) with all markers or some missing, with or without
the smoothness term, with or without PCA truncation, and through the reconstructor;
weights all alike must give the paper's unweighted space; truncation must keep the
pose in the principal subspace it keeps.
"""

from __future__ import annotations

import numpy as np
import pytest

from samba.body.skeleton import markers_of
from samba.db.index import PoseIndex
from samba.reconstruct.local_space import (
    EnergyTerms,
    LocalPoseSpace,
    initial_weights,
    solve,
    solve_lm,
)
from samba.reconstruct.methods import method
from samba.reconstruct.pseudo_poses import AngleNoise, pseudo_poses
from samba.reconstruct.reconstruction import Reconstructor
from samba.synthetic.motions import generate, library

K, N = 10, 10
ALPHA = 1.0 / 0.01**2
BETA = 1.0 / 0.02**2
TRUTH = 21
"""Frame of the take observed; the neighbours are other frames around it."""


@pytest.fixture(scope="module")
def walk() -> np.ndarray:
    return generate("walk", seconds=2.0, seed=3).poses.astype(np.float64)


@pytest.fixture(scope="module")
def samples(walk: np.ndarray) -> np.ndarray:
    """K * N pseudo-poses (1, 100, 13, 3) of the frames 10, 12, .., 28 of the take."""
    noise = AngleNoise.draw(K, N, 5.0, seed=0)
    return pseudo_poses(walk[10:30:2], noise).reshape(1, K * N, 13, 3)


@pytest.fixture(scope="module")
def observation(walk: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Noisy markers (1, 8, 3) of frame TRUTH and a smoothness target (1, 13, 3) near it."""
    rng = np.random.default_rng(0)
    markers = markers_of(walk[TRUTH])[None] + rng.normal(0.0, 0.003, (1, 8, 3))
    target = walk[TRUTH][None] + rng.normal(0.0, 0.01, (1, 13, 3))
    return markers, target


@pytest.mark.parametrize("variance_kept", [1.0, 0.95])
@pytest.mark.parametrize("missing", [(), (2, 6)])
@pytest.mark.parametrize("has_target", [False, True])
def test_lm_and_fast_solver_agree(
    samples: np.ndarray,
    observation: tuple[np.ndarray, np.ndarray],
    variance_kept: float,
    missing: tuple[int, ...],
    has_target: bool,
) -> None:
    markers, target = observation
    markers = markers.copy()
    markers[:, list(missing)] = np.nan
    space = LocalPoseSpace.from_samples(samples, variance_kept, 1e-6)
    terms = EnergyTerms(markers, target, np.array([has_target]), ALPHA, BETA)
    fast = solve(space, terms)
    assert fast.shape == (1, 13, 3)
    lm = solve_lm(space, terms, initial_weights(space, samples[0], markers[0]))
    assert np.abs(lm - fast[0]).max() < 1e-6
    # Not a trivial agreement: the pose is a compromise, away from the mean and markers.
    assert np.abs(fast[0] - space.mean[0].reshape(13, 3)).max() > 1e-3


@pytest.fixture(scope="module")
def samba_reconstructor() -> Reconstructor:
    poses = np.concatenate([take.poses for take in library(takes_per_motion=2, seconds=4.0)])
    return method("samba").build(PoseIndex.build(poses))


@pytest.mark.parametrize("missing", [(), (3, 7)])
def test_reconstructor_lm_matches_the_live_path(
    samba_reconstructor: Reconstructor, missing: tuple[int, ...]
) -> None:
    # `samba` has no part refinement, so step() returns the energy solution itself.
    rng = np.random.default_rng(1)
    take = generate("kick", seconds=1.0, seed=4242).poses.astype(np.float64)
    markers = markers_of(take[:3]) + rng.normal(0.0, 0.003, (3, 8, 3))
    markers[2, list(missing)] = np.nan
    r = samba_reconstructor
    r.reset()
    first, second, third = (r.step(m).pose for m in markers)
    held = np.where(np.isnan(markers[2]), markers[1], markers[2])  # the missing markers held
    assert np.abs(r.solve_lm(markers[0]) - first).max() < 1e-6
    assert np.abs(r.solve_lm(held, 2.0 * second - first) - third).max() < 1e-6


@pytest.mark.parametrize("variance_kept", [1.0, 0.95])
def test_equal_weights_give_the_unweighted_space(samples: np.ndarray, variance_kept: float) -> None:
    plain = LocalPoseSpace.from_samples(samples, variance_kept, 1e-6)
    weighted = LocalPoseSpace.from_samples(
        samples, variance_kept, 1e-6, weights=np.full(samples.shape[:2], 3.0)
    )
    assert np.abs(weighted.mean - plain.mean).max() < 1e-12
    assert np.abs(weighted.covariance - plain.covariance).max() < 1e-12


def test_zero_weight_samples_do_not_count(samples: np.ndarray) -> None:
    weights = np.zeros(samples.shape[:2])
    weights[:, ::3] = 1.0
    weighted = LocalPoseSpace.from_samples(samples, 1.0, 1e-6, weights=weights)
    subset = LocalPoseSpace.from_samples(samples[:, ::3], 1.0, 1e-6)
    assert np.abs(weighted.mean - subset.mean).max() < 1e-12
    assert np.abs(weighted.covariance - subset.covariance).max() < 1e-12


def test_truncation_keeps_the_pose_in_the_kept_subspace(
    samples: np.ndarray, observation: tuple[np.ndarray, np.ndarray]
) -> None:
    flat = samples[0].reshape(K * N, 39)
    variances, vectors = np.linalg.eigh(np.cov(flat, rowvar=False, bias=True))
    variances, vectors = variances[::-1], vectors[:, ::-1]
    # The fewest largest components explaining 95% of the variance.
    kept = int(np.searchsorted(np.cumsum(variances) / variances.sum(), 0.95)) + 1
    assert kept < 20
    markers, target = observation
    space = LocalPoseSpace.from_samples(samples, 0.95, 1e-6)
    terms = EnergyTerms(markers, target, np.array([True]), ALPHA, BETA)
    offset = solve(space, terms)[0].reshape(39) - flat.mean(axis=0)
    inside = vectors[:, :kept] @ (vectors[:, :kept].T @ offset)
    assert np.linalg.norm(inside) > 1e-2
    assert np.linalg.norm(offset - inside) < 1e-9
