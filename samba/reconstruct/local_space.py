"""The local pose space (Samba paper, Section 4.1) and its energy (Eq. 6).

A frame's local pose space is the Gaussian of its M = K * N pseudo-poses, as 39-vectors
(13 joints x 3, meters, the canonical frame of `samba.body.alignment`): mean p, covariance
Lambda, and its PCA basis U with variances lambda_j. A pose in the space is
q = p + U w (Eq. 1), and the energy of w is, with squared terms,

    E(w) = sum_j w_j^2 / lambda_j                      prior, Mahalanobis (Eq. 3)
         + alpha * |S (p + U w) - x|^2                 markers present (Eq. 4)
         + beta  * |p + U w - (2 q_{i-1} - q_{i-2})|^2   smoothness (Eq. 5)
         + beta_missing * (the same over the joints of missing markers)

where x holds the observed markers and S selects the coordinates of the markers present.
The energy is linear least squares in w, so `solve` finds the exact minimiser with one
LAPACK call per batch (written in pose coordinates, where it needs no eigenvectors);
`solve_lm` minimises the same energy over w with Levenberg-Marquardt from the paper's
initial value (Section 4.3), for comparison.

PCA truncation (the paper's n largest eigenvalues) keeps the components that explain a
fraction `variance_kept` of the variance; the others get a variance so small that the
pose stays out of them. Variances are floored at `variance_floor` (m^2) so that a space
with fewer samples than dimensions (K = 10, N = 1) still has a finite prior.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from samba.body import MARKER_JOINTS, N_JOINTS

POSE_DIMS = 3 * N_JOINTS
MARKER_COORDS = np.array([3 * j + c for j in MARKER_JOINTS for c in range(3)])
"""Positions of the 24 marker coordinates inside a 39-vector."""
TRUNCATED = 1e-12
"""Factor that shrinks the variance of components dropped by truncation to nearly zero."""
ROUNDING_VARIANCE = 1e-12
"""Variance (m^2; a micrometre's spread) below which a component of a local pose space is
rounding noise of the float32 database poses, not motion: truncation counts it as zero."""


@dataclass(frozen=True)
class LocalPoseSpace:
    """Batched local pose spaces: `mean` (b, 39) meters and `covariance` (b, 39, 39) m^2,
    regularised (and truncated) as described in the module docstring; the prior of a
    pose q is (q - p)^T covariance^-1 (q - p)."""

    mean: np.ndarray
    covariance: np.ndarray

    @classmethod
    def from_samples(
        cls,
        samples: np.ndarray,
        variance_kept: float = 1.0,
        variance_floor: float = 1e-6,
        weights: np.ndarray | None = None,
    ) -> LocalPoseSpace:
        """The spaces of sample poses (b, M, 13, 3) or (b, M, 39), meters.

        `weights` (b, M) >= 0, when given, make mean and covariance weighted ones (a
        sample of weight 0 does not count); None weighs every sample alike (the paper).

        `variance_kept` in (0, 1]: fraction of the total variance the kept principal
        components explain (1 keeps all 39 and needs no eigendecomposition: the sample
        covariance plus `variance_floor` * I); below 1 the kept components' variances
        are floored at `variance_floor` (m^2) and the others shrunk to nearly zero.
        """
        samples = np.asarray(samples, dtype=np.float64)
        samples = samples.reshape(*samples.shape[:2], POSE_DIMS)
        if weights is None:
            weights = np.full(samples.shape[:2], 1.0 / samples.shape[1])
        else:
            weights = weights / weights.sum(axis=1, keepdims=True)
        weighted = samples * weights[:, :, None]
        mean = weighted.sum(axis=1)
        cov = np.matmul(weighted.transpose(0, 2, 1), samples)
        cov -= mean[:, :, None] * mean[:, None, :]
        if variance_kept >= 1.0:
            diag = np.arange(POSE_DIMS)
            cov[:, diag, diag] += variance_floor
            return cls(mean, cov)
        variances, vectors = np.linalg.eigh(cov)
        # Variances under ROUNDING_VARIANCE are rounding noise: counted as zero, so that
        # identical samples keep no component.
        clipped = np.where(variances > ROUNDING_VARIANCE, variances, 0.0)
        total = np.maximum(clipped.sum(axis=1, keepdims=True), 1e-30)
        # eigh sorts ascending: a component is dropped when the larger ones already
        # explain variance_kept of the total.
        larger = total - np.cumsum(clipped, axis=1)
        kept = larger < variance_kept * total
        shrunk = np.where(kept, np.maximum(variances, variance_floor), variance_floor * TRUNCATED)
        cov = np.matmul(vectors * shrunk[:, None, :], vectors.transpose(0, 2, 1))
        return cls(mean, cov)

    def __len__(self) -> int:
        return len(self.mean)

    def principal_components(self) -> tuple[np.ndarray, np.ndarray]:
        """(variances (b, 39) descending, basis (b, 39, 39) columns), m^2 and unit."""
        variances, vectors = np.linalg.eigh(self.covariance)
        return variances[:, ::-1], vectors[:, :, ::-1]


@dataclass(frozen=True)
class EnergyTerms:
    """What the energy compares a space against, batched like the spaces.

    `markers` (b, 8, 3) observed markers in the canonical frame (NaN = missing),
    `target` (b, 13, 3) the smoothness target 2 q_{i-1} - q_{i-2} (any values where
    `has_target` is False), `has_target` (b,) bool, `alpha` marker weight in 1/m^2,
    `beta` smoothness weight in 1/m^2, `beta_missing` extra smoothness weight (1/m^2) on
    the joints whose markers are missing: there the motion predicts the marker.
    """

    markers: np.ndarray
    target: np.ndarray
    has_target: np.ndarray
    alpha: float
    beta: float
    beta_missing: float = 0.0

    def marker_mask(self) -> np.ndarray:
        """(b, 39) 1.0 at the coordinates of the markers present, else 0.0."""
        mask = np.zeros((len(self.markers), POSE_DIMS))
        present = ~np.isnan(self.markers).any(axis=-1)
        mask[:, MARKER_COORDS] = np.repeat(present, 3, axis=1)
        return mask

    def observed(self) -> np.ndarray:
        """(b, 39) the observed markers at their coordinates, 0.0 elsewhere."""
        x = np.zeros((len(self.markers), POSE_DIMS))
        flat = self.markers.reshape(len(self.markers), -1)
        x[:, MARKER_COORDS] = np.where(np.isnan(flat), 0.0, flat)
        return x

    def betas(self) -> np.ndarray:
        """(b, 39) the smoothness weight of every coordinate: beta, plus `beta_missing`
        on the joints of missing markers; 0 in frames without a target."""
        missing = np.repeat(np.isnan(self.markers).any(axis=-1), 3, axis=1)
        weights = np.full((len(self.markers), POSE_DIMS), self.beta)
        weights[:, MARKER_COORDS] += self.beta_missing * missing
        return np.where(self.has_target[:, None], weights, 0.0)


def affine_solution(space: LocalPoseSpace, terms: EnergyTerms) -> tuple[np.ndarray, np.ndarray]:
    """The exact minimiser as an affine function of the smoothness target t (b, 39):
    q = offset + gain @ t, with offset (b, 39) and gain (b, 39, 39), canonical frame.

    Setting the gradient to zero gives (C^-1 + alpha D + B) q = C^-1 p + alpha D x + B t
    for covariance C, marker selection D and smoothness weights B (diagonal); multiplied
    by C it needs no inverse: (I + C (alpha D + B)) q = p + alpha C D x + C B t, one solve
    for the offset and the gain together.
    """
    mask = terms.marker_mask()
    beta = terms.betas()
    cov = space.covariance
    system = cov * (terms.alpha * mask + beta)[:, None, :]
    diag = np.arange(POSE_DIMS)
    system[:, diag, diag] += 1.0
    observed = np.matmul(cov, (mask * terms.observed())[:, :, None])[:, :, 0]
    offset_rhs = space.mean + terms.alpha * observed
    rhs = np.concatenate([offset_rhs[:, :, None], cov * beta[:, None, :]], axis=2)
    x = np.linalg.solve(system, rhs)
    return x[:, :, 0], x[:, :, 1:]


def solve(space: LocalPoseSpace, terms: EnergyTerms) -> np.ndarray:
    """Exact minimiser of the energy: poses (b, 13, 3) in the canonical frame, meters."""
    offset, gain = affine_solution(space, terms)
    q = offset + np.einsum("bij,bj->bi", gain, terms.target.reshape(len(space), POSE_DIMS))
    return q.reshape(len(space), N_JOINTS, 3)


def initial_weights(space: LocalPoseSpace, samples: np.ndarray, markers: np.ndarray) -> np.ndarray:
    """The paper's initial value (Section 4.3) for one frame: w0 (39,).

    The least-squares combination gamma of the samples' (M, 13, 3) markers that best
    matches the observed markers (8, 3) (canonical frame, NaN = missing), applied to the
    samples' poses and projected onto the principal components of `space` (a batch of
    one), largest first.
    """
    present = ~np.isnan(markers).any(axis=-1)
    flat = samples.reshape(len(samples), N_JOINTS, 3)
    r = flat[:, list(np.array(MARKER_JOINTS)[present])].reshape(len(samples), -1).T
    gamma, *_ = np.linalg.lstsq(r, markers[present].reshape(-1), rcond=None)
    q0 = gamma @ flat.reshape(len(samples), POSE_DIMS)
    _, basis = space.principal_components()
    return basis[0].T @ (q0 - space.mean[0])


def solve_lm(
    space: LocalPoseSpace, terms: EnergyTerms, w0: np.ndarray, tolerance: float = 1e-15
) -> np.ndarray:
    """The same energy minimised over the PCA weights w (Eq. 6) by Levenberg-Marquardt
    (scipy, MINPACK) from w0 (39,), for a batch of one frame; components shrunk by
    truncation are left out (w = 0 there). Returns the pose (13, 3), canonical frame."""
    variances, basis = space.principal_components()
    kept = variances[0] > _truncation_threshold(variances[0])
    u = basis[0][:, kept]
    p = space.mean[0]
    mask = terms.marker_mask()[0] > 0
    x = terms.observed()[0]
    target = terms.target.reshape(-1)
    sqrt_prior = 1.0 / np.sqrt(variances[0][kept])
    sqrt_alpha = np.sqrt(terms.alpha)
    sqrt_beta = np.sqrt(terms.betas()[0])

    def residuals(w: np.ndarray) -> np.ndarray:
        q = p + u @ w
        return np.concatenate(
            [sqrt_prior * w, sqrt_alpha * (q - x)[mask], sqrt_beta * (q - target)]
        )

    jacobian = np.concatenate([np.diag(sqrt_prior), sqrt_alpha * u[mask], sqrt_beta[:, None] * u])
    result = least_squares(
        residuals,
        w0[kept],
        jac=lambda _w: jacobian,
        method="lm",
        xtol=tolerance,
        ftol=tolerance,
        gtol=tolerance,
    )
    return (p + u @ result.x).reshape(N_JOINTS, 3)


def _truncation_threshold(variances: np.ndarray) -> float:
    """Variance below which a component counts as removed by truncation, m^2."""
    return float(np.max(variances)) * TRUNCATED
