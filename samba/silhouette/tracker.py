"""`SilhouetteTracker`: tree-based Bayesian filtering of a single camera's silhouettes over a
`ShapeTree` (Okada, Stenger, Kondoh, Section 2).

Each frame the observed silhouette is normalised (`samba.silhouette.view`) and the tree
is evaluated once, coarse to fine: every top-level node, then the children of the
nodes that survive on each level. A node's score is the log likelihood of Eq. 3 (a
Gaussian in the silhouette distance `distance`, one of
`samba.silhouette.distance.DISTANCES`, with a sigma per level); on the leaves it is the
log posterior, the likelihood plus the log prior of Eq. 2: the previous frame's
posterior (its best leaves and their weights) pushed through the first-order motion
model of Eq. 8, a Gaussian per body part on joint positions (the trunk's in the world's
axes, the limbs' and the head's in the body's own frame).
Each part's Gaussian is floored `part_cap` nats below its peak: a limb that was lost can
be found again wherever the silhouette shows it, while the trunk (whose cap is high)
keeps the side of the body that faces the camera — a silhouette seen from the back is
almost the one seen from the front, and only the motion model tells them apart.
Nodes more than `log_margin` below the best score of their level, or beyond the
`keep` best, are pruned with their subtrees, except the ancestors of the previous
frame's posterior leaves: on a badly spoilt frame their coarse silhouettes can lose to
others (a subject bent towards the camera to one standing, or to one bent away from it
with its back turned), and the prior, which only the leaves carry, must be able to keep
the track where it was.

Beyond the paper's distance, the best `symmetric_leaves` leaves by that score are
scored again with a symmetric one: the paper's distance, whose weights come from the
observed silhouette, plus `leaf_side_weight` times the XOR weighted by the leaf's own
core-weighted map (`samba.silhouette.distance.model_weighted_distances`; plain XOR for
"xor"), with sigma taken again from the best of them. The one-sided distance barely
charges what lies near the observed outline: legs together, inside the outline of a
walker's two legs, a leaf a tenth bigger than the subject, or a body turned the mirror
way past the side view, cost little, while a leaf one limb's width off costs a lot. The
leaf's own weights charge its structure missing from the frame (bench_silhouette:
turning 13.2 -> 5.6 cm, walking 12.8 -> 9.7 cm); weighing them three times (walking
8.5 -> 7.5 cm) lets a leaf whose thin legs lie a few pixels off the observed ones win
against a bigger one with the feet together that covers them; 45 leaves rather than 30
are scored so (walking on other held-out takes 8.2 -> 7.7 cm, 3-4 ms more a frame on a
61,144-leaf tree).

Beyond the paper's first-order model (Eq. 8), each part's Gaussian is centred
`velocity_gain` of the last step ahead: the change between the best leaves of the two
previous frames, so a limb that swings on keeps swinging rather than turning back (the
silhouette of a limb swinging towards the camera is that of one swinging away);
`velocity_gain` = 0 is the paper's model.

The motion model is occlusion-aware (Eq. 9): a body part that is hidden in a
previous leaf (its visible fraction below `occluded_below`) gets `occlusion_factor`
times its standard deviation (the paper's m = 5), so it is free to jump to where it
reappears. `occlusion_factor` = 1 is the plain model (the paper's DM1).

Beyond the paper's likelihood, a leaf's score also has a Gaussian term (sigma `top_sigma`
pixels) in the difference between its top row and the observed silhouette's in the
normalised image: how tall the subject looks above the floor point where it stands, once
scaled to the body model's stature (the subject's is given to the tracker). A frame whose
silhouette the view's top edge cuts (the head or a raised hand out of view) has no term. The core-
weighted distances charge little for an outline moved a few pixels, so a leaf with the
feet together, placed at the front foot of a stride (half a step too near the camera,
hence a tenth bigger after normalising), covered the observed silhouette at little cost:
its head stood 4-7 pixels above the observed one. The term took walking from 7.3 cm / 6.7%
failures to 6.1 cm / 1.4% and 7.7 cm / 7.2% to 6.2 cm / 1.4% on two sets of held-out
takes (bench_silhouette).

A silhouette looks the same from the front and from the back, so the first frame (and
the first after `reset`) needs a hint: it only considers poses whose front is within
`start_tolerance` degrees of facing the camera (the player faces the screen when the
game starts); from then on the motion model keeps the side.

The estimate is the posterior mean: the `posterior_size` best leaves, each moved from
the tree's home to where the silhouette stands on the floor, averaged with their
posterior weights raised to 1 / `mean_temperature` (one camera often leaves two leaves
equally likely — a hand in front of the body or behind it — and their mean is nearer the
truth than either guess; `mean_temperature` = 0 keeps only the best leaf, the paper's
estimate). Poses are (13, 3) meters in the world frame (+Y up).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import logsumexp

from samba.base import InputError
from samba.silhouette.distance import (
    DISTANCES,
    SilhouetteWeights,
    downsampled,
    model_weighted_distances,
)
from samba.silhouette.runs import RowSums
from samba.silhouette.shape_tree import LEVEL_SIZES, PART_JOINTS, ShapeTree


@dataclass(frozen=True)
class TrackerSettings:
    """The filter's parameters (see the module docstring).

    `part_sigma` (parts,) meters: frame-to-frame standard deviation of a joint of each
    body part (torso, head, arms, legs; `samba.body.body_model.PART_NAMES`), per coordinate.
    The legs' is wide (0.3 m): a leg striding towards the camera changes the silhouette
    little, so a narrower prior held a walk on a leaf with the feet together for half
    of each stride while the true stride paid 20-35 nats (bench_silhouette, walking:
    9.7 -> 8.5 cm and 11.5 -> 9.0 cm on two sets of held-out takes, 0.06 m before; the
    other motions within 0.4 cm).
    `likelihood_sigma`: the least sigma of Eq. 3 on the 320-pixel-wide level, in units
    of the distance (scaled with the image width for "core" and "normalised", whose
    distances are in pixels); a noisy silhouette matches no node well, so sigma grows to
    `relative_sigma` times the best distance of the level in the frame (a node 10 %
    worse than the best then costs about 2 nats, however noisy the frame; a sharper
    likelihood follows limbs better but, on badly spoilt silhouettes, can turn the
    body's back to the camera). On the upper
    levels sigma is `upper_sigma_factor` times wider, as a node's silhouette only
    stands for its leaves'. `keep` (per level): most nodes a level passes on;
    `log_margin` (nats): how far below a level's best score a node is still passed on.
    `occlusion_factor` (m of Eq. 9) widens parts visible below `occluded_below` (a
    fraction of their area); `part_cap` (nats, per part), `velocity_gain` and
    `start_tolerance` (degrees) are described in the module docstring. The arms' cap
    is low (5 nats): an arm swinging towards the camera or away from it changes the
    silhouette little, and with 10 a track holding an arm the wrong way paid the
    whole cap to put it right (bench_silhouette, the arm swing: 5.7 -> 5.2, 6.8 -> 5.9
    and 8.8 -> 7.8 cm on three sets of held-out takes; the golf swing on one of them
    5.6 -> 5.8 cm; at 3 the paper's models of Figure 4 lose their order);
    `posterior_size` leaves carry the posterior to the next frame; `mean_temperature`
    flattens their weights in the estimate (0: the best leaf alone).
    `symmetric_leaves`: the best this many leaves are scored again with the symmetric
    distance (module docstring); 0 keeps the paper's one-sided distance.
    `leaf_side_weight` (> 0): the weight of the leaf's side of the symmetric distance.
    `top_sigma` (pixels of the 320-pixel-wide level, >= 0): sigma of the leaves' top-row
    term (module docstring); 0 leaves it out (the paper's likelihood).
    """

    distance: str = "normalised"
    occlusion_factor: float = 5.0
    occluded_below: float = 0.3
    part_sigma: tuple[float, ...] = (0.05, 0.03, 0.08, 0.08, 0.3, 0.3)
    likelihood_sigma: float = 0.01
    relative_sigma: float = 0.25
    upper_sigma_factor: float = 4.0
    keep: tuple[int, ...] = (40, 120, 400)
    log_margin: float = 12.0
    part_cap: tuple[float, ...] = (40.0, 10.0, 5.0, 5.0, 10.0, 10.0)
    velocity_gain: float = 0.5
    start_tolerance: float = 60.0
    posterior_size: int = 30
    mean_temperature: float = 3.0
    symmetric_leaves: int = 45
    leaf_side_weight: float = 3.0
    top_sigma: float = 1.0

    def __post_init__(self) -> None:
        if self.distance not in DISTANCES:
            raise InputError(
                "distance", f"must be one of {', '.join(DISTANCES)}, got {self.distance!r}"
            )
        if not self.occlusion_factor >= 1.0:
            raise InputError("occlusion_factor", f"must be >= 1, got {self.occlusion_factor}")
        if len(self.part_sigma) != len(PART_JOINTS) or min(self.part_sigma) <= 0:
            raise InputError("part_sigma", f"need {len(PART_JOINTS)} positive values")
        if not self.likelihood_sigma > 0:
            raise InputError("likelihood_sigma", f"must be > 0, got {self.likelihood_sigma}")
        if len(self.part_cap) != len(PART_JOINTS) or not min(self.part_cap) > 0:
            raise InputError("part_cap", f"need {len(PART_JOINTS)} positive values")
        if len(self.keep) != len(LEVEL_SIZES) or min(self.keep) < 1:
            raise InputError("keep", f"need {len(LEVEL_SIZES)} counts >= 1")
        if not (self.posterior_size >= 1 and self.upper_sigma_factor >= 1):
            raise InputError("posterior_size", "posterior_size and upper_sigma_factor >= 1")
        if not 0.0 <= self.velocity_gain <= 1.0:
            raise InputError("velocity_gain", f"must be in 0..1, got {self.velocity_gain}")
        if not (np.isfinite(self.log_margin) and self.log_margin > 0):
            raise InputError("log_margin", f"must be finite and > 0, got {self.log_margin}")
        if not (np.isfinite(self.mean_temperature) and self.mean_temperature >= 0):
            raise InputError(
                "mean_temperature", f"must be finite and >= 0, got {self.mean_temperature}"
            )
        if not (isinstance(self.symmetric_leaves, int) and self.symmetric_leaves >= 0):
            raise InputError(
                "symmetric_leaves", f"must be an integer >= 0, got {self.symmetric_leaves!r}"
            )
        if not (np.isfinite(self.leaf_side_weight) and self.leaf_side_weight > 0):
            raise InputError(
                "leaf_side_weight", f"must be finite and > 0, got {self.leaf_side_weight}"
            )
        if not (np.isfinite(self.top_sigma) and self.top_sigma >= 0):
            raise InputError("top_sigma", f"must be finite and >= 0, got {self.top_sigma}")
        if not (self.relative_sigma > 0 and 0 <= self.start_tolerance <= 180):
            raise InputError("relative_sigma", "must be > 0 (start_tolerance in 0..180)")


@dataclass(frozen=True)
class SilhouetteEstimate:
    """One tracked frame: `pose` (13, 3) world meters, the `leaf` it came from, its
    silhouette `distance` (the symmetric one with the tracker's `symmetric_leaves`), the
    `occluded` (parts,) bool flags of the leaf, `evaluated` (tree nodes whose likelihood
    was computed) and `found` (False when the frame had no silhouette and the previous
    pose is held)."""

    pose: np.ndarray
    leaf: int
    distance: float
    occluded: np.ndarray
    evaluated: int
    found: bool


class SilhouetteTracker:
    """Tracks one subject through silhouettes of `tree.view` (see the module docstring).

    `height` is the subject's stature in meters (default: the tree's body model's): the
    observed silhouettes are scaled to the model's stature and the poses back to the
    subject's (`size`: the subject's stature over the model's). `InputError` for a
    stature outside 0.5..2.5 m.
    """

    def __init__(
        self,
        tree: ShapeTree,
        settings: TrackerSettings | None = None,
        height: float | None = None,
    ) -> None:
        self.tree = tree
        self.settings = settings or TrackerSettings()
        if height is None:
            height = tree.body.height
        if not 0.5 <= height <= 2.5:
            raise InputError("height", f"the subject's stature must be 0.5..2.5 m, got {height}")
        self.size = height / tree.body.height
        self._tops = tree.levels[-1].silhouettes.top_rows()
        self._features = _part_features(tree.leaves.poses)
        away = np.abs(_facing_angles(tree.leaves.poses, tree.view.camera.center))
        self._turned_away = [away > self.settings.start_tolerance]
        for level in range(len(tree.levels) - 2, -1, -1):  # away when all leaves below are
            below = self._turned_away[0]
            facing = np.zeros(len(tree.levels[level]), dtype=bool)
            facing[tree.levels[level + 1].parents[~below]] = True
            self._turned_away.insert(0, ~facing)
        self._sigma = np.asarray(self.settings.part_sigma, dtype=np.float64)
        self._dims = np.array([3 * len(j) for j in PART_JOINTS], dtype=np.float64)
        self.reset()

    def reset(self) -> None:
        """Forget the past: the next frame is searched with a uniform prior."""
        self._previous: np.ndarray | None = None  # leaf indices of the posterior
        self._weights = np.zeros(0)
        self._best: list[int] = []  # the best leaf of the last two frames, oldest first
        self._last: SilhouetteEstimate | None = None

    def step(self, mask: np.ndarray) -> SilhouetteEstimate:
        """Track one frame: `mask` (H, W) bool, the silhouette at the view's size. A frame
        with no silhouette holds the previous pose (`found` False)."""
        mask = np.asarray(mask)
        if mask.shape != self.tree.view.size[::-1] or mask.dtype != bool:
            raise InputError(
                "silhouette",
                f"expected a {self.tree.view.size[1]} x {self.tree.view.size[0]} bool mask, "
                f"got {mask.shape} {mask.dtype}",
            )
        if not mask.any():
            return self._hold(mask)
        normalised, placement = self.tree.view.normalise(mask, self.size)
        top = None if mask[0].any() else int(np.argmax(normalised.any(axis=1)))
        settings = self.settings
        held = self._held_ancestors()
        nodes = np.arange(len(self.tree.levels[0]))
        evaluated = 0
        for level, size in enumerate(LEVEL_SIZES):
            if level:
                nodes = self.tree.children(level - 1, nodes)
            tree_level = self.tree.levels[level]
            image = normalised if size == self.tree.view.size else downsampled(normalised, size)
            weights = SilhouetteWeights.from_mask(image, settings.distance)
            distances = tree_level.silhouettes.distances(RowSums.from_weights(weights), nodes)
            evaluated += len(nodes)
            leaves = level == len(LEVEL_SIZES) - 1
            prior = np.zeros(len(nodes))  # with the top-row term on the leaves
            if self._previous is None:
                prior[self._turned_away[level][nodes]] = -np.inf
            elif leaves:
                prior = self._log_prior(nodes)
            if leaves:
                prior = prior + self._log_top_term(nodes, top)
            scores = prior + self._log_likelihood(distances, size[0], leaves)
            if leaves and settings.symmetric_leaves:
                best = np.argsort(scores)[::-1][: settings.symmetric_leaves]
                nodes, prior = nodes[best], prior[best]
                masks = tree_level.silhouettes.subset(nodes).to_masks()
                distances = distances[best] + settings.leaf_side_weight * model_weighted_distances(
                    masks, image, "xor" if settings.distance == "xor" else "core"
                )
                scores = prior + self._log_likelihood(distances, size[0], leaves)
            order = np.argsort(scores)[::-1][: settings.keep[level]]
            order = order[scores[order] >= scores[order[0]] - settings.log_margin]
            nodes, scores, distances = nodes[order], scores[order], distances[order]
            if level < len(held):
                nodes = np.union1d(nodes, held[level])
        best = settings.posterior_size
        self._previous = nodes[:best]
        self._weights = np.exp(scores[:best] - logsumexp(scores[:best]))
        leaf = int(nodes[0])
        self._best = [*self._best[-1:], leaf]
        estimate = SilhouetteEstimate(
            pose=self._mean(self.tree.placed(self._previous, placement), scores[:best]),
            leaf=leaf,
            distance=float(distances[0]),
            occluded=self.tree.leaves.visibility[leaf] < settings.occluded_below,
            evaluated=evaluated,
            found=True,
        )
        self._last = estimate
        return estimate

    def _log_likelihood(self, distances: np.ndarray, width: int, leaves: bool) -> np.ndarray:
        """Eq. 3 for silhouette `distances` (k,) on a level `width` pixels wide: sigma is
        `likelihood_sigma` (scaled to the width but for "xor") or `relative_sigma` times
        the best distance, whichever is larger, `upper_sigma_factor` wider above the
        leaves."""
        settings = self.settings
        least = settings.likelihood_sigma
        if settings.distance != "xor":
            least *= width / LEVEL_SIZES[-1][0]
        sigma = max(least, settings.relative_sigma * float(distances.min()))
        if not leaves:
            sigma *= settings.upper_sigma_factor
        return -0.5 * (distances / sigma) ** 2

    def _log_top_term(self, leaves: np.ndarray, top: int | None) -> np.ndarray:
        """The top-row term (k,) of `leaves` (indices) against the observed normalised
        silhouette's top row `top`; zeros when `top_sigma` is 0 or `top` is None (the
        view's top edge cuts the subject, whose top is then not seen)."""
        sigma = self.settings.top_sigma
        if sigma == 0 or top is None:
            return np.zeros(len(leaves))
        return -0.5 * ((self._tops[leaves] - top) / sigma) ** 2

    def _held_ancestors(self) -> list[np.ndarray]:
        """Per upper level, the nodes (sorted indices) above the previous posterior's
        leaves, which pruning keeps; none before the first frame."""
        if self._previous is None:
            return []
        held, nodes = [], self._previous
        for level in range(len(self.tree.levels) - 1, 0, -1):
            nodes = np.unique(self.tree.levels[level].parents[nodes])
            held.insert(0, nodes)
        return held

    def _mean(self, placed: np.ndarray, scores: np.ndarray) -> np.ndarray:
        """The estimate (13, 3) m from the posterior's leaves `placed` (k, 13, 3) m, best
        first, and their log posterior `scores` (k,)."""
        temperature = self.settings.mean_temperature
        if temperature == 0:
            return placed[0]
        weights = np.exp((scores - scores[0]) / temperature)
        return np.tensordot(weights / weights.sum(), placed, axes=1)

    def track(self, masks: np.ndarray) -> list[SilhouetteEstimate]:
        """`step` over silhouettes (n, H, W) bool, in order."""
        return [self.step(mask) for mask in masks]

    def _hold(self, mask: np.ndarray) -> SilhouetteEstimate:
        if self._last is None:
            raise InputError("silhouette", "the first frame has no silhouette to start from")
        return SilhouetteEstimate(
            self._last.pose, self._last.leaf, float("nan"), self._last.occluded, 0, False
        )

    def _log_prior(self, leaves: np.ndarray) -> np.ndarray:
        """Log prior (k,) of `leaves` (indices): the motion model applied to the previous
        posterior, each part floored `part_cap` below its peak."""
        settings = self.settings
        occluded = self.tree.leaves.visibility[self._previous] < settings.occluded_below
        factor = np.where(occluded, settings.occlusion_factor, 1.0)
        variance = (self._sigma * factor) ** 2  # (previous, parts)
        peaks = np.log(self._weights) - 0.5 * (self._dims * np.log(2 * np.pi * variance)).sum(1)
        log_density = np.broadcast_to(peaks, (len(leaves), len(peaks)))
        for part, cap in enumerate(settings.part_cap):
            features = self._features[part]
            a = features[leaves]
            b = features[self._previous]
            if len(self._best) == 2:
                older, newer = features[self._best]
                b = b + settings.velocity_gain * (newer - older)
            squared = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T
            penalty = 0.5 * np.maximum(squared, 0.0) / variance[None, :, part]
            log_density = log_density - np.minimum(penalty, cap)
        return logsumexp(log_density, axis=1)


def _part_features(poses: np.ndarray) -> list[np.ndarray]:
    """Per body part, its joints (m, 3 * joints) in meters: the trunk's relative to the
    hip midpoint in the world's axes (they carry the body's heading), every other part's
    in the body's own frame (turned about the vertical so that the hip line lies along
    +X), so that turning the whole body moves the trunk only."""
    relative = poses.astype(np.float64) - poses[:, [7, 8]].mean(axis=1, keepdims=True)
    left = relative[:, 7] - relative[:, 8]
    heading = np.arctan2(left[:, 2], left[:, 0])
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]
    body = relative.copy()
    body[..., 0] = c * relative[..., 0] + s * relative[..., 2]
    body[..., 2] = -s * relative[..., 0] + c * relative[..., 2]
    frames = [relative] + [body] * (len(PART_JOINTS) - 1)
    return [f[:, list(j)].reshape(len(poses), -1) for f, j in zip(frames, PART_JOINTS, strict=True)]


def _facing_angles(poses: np.ndarray, camera: np.ndarray) -> np.ndarray:
    """Degrees (m,) between each pose's front (seen from above) and the direction from
    its hip midpoint to the `camera` centre (3,)."""
    left = poses[:, 7] - poses[:, 8]
    to_camera = camera - poses[:, [7, 8]].mean(axis=1)
    front = np.arctan2(-left[:, 2], left[:, 0])
    wanted = np.arctan2(to_camera[:, 0], to_camera[:, 2])
    return (np.degrees(front - wanted) + 180.0) % 360.0 - 180.0
