"""The reconstruction's parameters (`ReconstructionConfig`), whose defaults are the paper's
configuration; the named methods (`samba.reconstruct.methods`) are variations of it."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ReconstructionConfig:
    """Parameters of the reconstruction; the defaults are the paper's configuration
    (`samba.reconstruct.methods.PAPER`, which says how the values the paper leaves open
    were chosen).

    `k` neighbours and `n` pseudo-poses each (n = 1: none, the neighbours alone), joint
    noise `noise_deg` (standard deviation, degrees), PCA truncation `variance_kept`
    (fraction of variance, 1 = none) with variances floored at `variance_floor` (m^2).
    The energy weighs markers by alpha = 1 / marker_sigma^2 and smoothness by
    beta = 1 / smooth_sigma^2 (sigmas in meters); `min_markers` markers with a complete
    left/right pair are needed to reconstruct; a frame is confident when its marker RMS
    residual is at most `confident_residual` meters with at least 6 markers. `seed` fixes
    the pseudo-pose noise table; `eps` is passed to the index query (0 = exact).
    `part_k` > 0 re-estimates elbows, hips and head from their own `part_k` nearest poses
    (`samba.reconstruct.part_retrieval`); 0 keeps the paper's single retrieval. `part_ridge`
    > 0 (m^2) makes each part's estimate a locally weighted linear regression on its
    markers with that ridge on the slopes (`samba.reconstruct.local_regression`); 0 the
    neighbours' kernel-weighted mean. `missing_sigma` > 0
    (meters) holds the joint of a missing marker to its motion prediction with weight
    1 / missing_sigma^2 on top of the smoothness term; 0 leaves it to the pose space.
    `shoulder_origin` places the observation and its neighbours by their shoulder
    midpoint (False: by their marker centroid; `samba.body.Alignment`). `hold_frames` > 0
    holds a missing marker at its last observation for up to that many frames
    (`samba.reconstruct.marker_hold`) in frames that the markers seen make usable;
    markers held count for the solve but not for `markers_used`, the residual or the
    confidence; with `hold_follows` a held marker moves with the markers seen.
    `calibration_frames` > 0 calibrates the thighs and the neck over that many first
    reconstructed frames of a take and holds them to it
    (`samba.reconstruct.bone_calibration`). `joint_smoothing` < 1 smooths the head, elbows
    and hips over the frames with that weight on the newest
    (`samba.reconstruct.joint_smoothing`); 1 leaves them as estimated.
    """

    k: int = 10
    n: int = 10
    noise_deg: float = 12.0
    variance_kept: float = 0.9999
    variance_floor: float = 1e-6
    marker_sigma: float = 0.005
    smooth_sigma: float = 0.08
    min_markers: int = 3
    confident_residual: float = 0.03
    seed: int = 0
    eps: float = 0.0
    part_k: int = 0
    part_ridge: float = 0.0
    missing_sigma: float = 0.0
    bandwidth: float = 0.0
    min_bandwidth: float = 0.005
    shoulder_origin: bool = True
    hold_frames: int = 10
    hold_follows: bool = False
    calibration_frames: int = 0
    joint_smoothing: float = 1.0

    def __post_init__(self) -> None:
        if self.k < 1 or self.n < 1:
            raise ValueError(f"K and N must be >= 1, got K={self.k}, N={self.n}")
        if not 0.0 < self.variance_kept <= 1.0:
            raise ValueError(f"variance_kept must be in (0, 1], got {self.variance_kept}")
        if self.marker_sigma <= 0 or self.smooth_sigma <= 0:
            raise ValueError("marker_sigma and smooth_sigma must be positive")
        if self.part_ridge < 0:
            raise ValueError(f"part_ridge must be >= 0, got {self.part_ridge}")
        if self.hold_frames < 0:
            raise ValueError(f"hold_frames must be >= 0, got {self.hold_frames}")
        if self.calibration_frames < 0:
            raise ValueError(f"calibration_frames must be >= 0, got {self.calibration_frames}")
        if not 0.0 < self.joint_smoothing <= 1.0:
            raise ValueError(f"joint_smoothing must be in (0, 1], got {self.joint_smoothing}")

    @property
    def alpha(self) -> float:
        """Marker-term weight, 1/m^2."""
        return 1.0 / self.marker_sigma**2

    @property
    def beta(self) -> float:
        """Smoothness-term weight, 1/m^2."""
        return 1.0 / self.smooth_sigma**2

    @property
    def beta_missing(self) -> float:
        """Extra smoothness weight on the joints of missing markers, 1/m^2 (0: none)."""
        return 1.0 / self.missing_sigma**2 if self.missing_sigma > 0 else 0.0
