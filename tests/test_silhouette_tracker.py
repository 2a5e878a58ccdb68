"""Tests of `samba.silhouette.tracker`: tree-based filtering of one camera's silhouettes, on
the small tree of `silhouette_fixtures` and noise-free renders of its poses."""

from __future__ import annotations

import numpy as np
import pytest
from silhouette_fixtures import (
    SQUAT_TAKE,
    TAKE_FRAMES,
    SmallBuild,
    facing_angles,
    source_poses,
)

from samba.base.errors import InputError
from samba.body.body_model import PART_NAMES
from samba.silhouette.distance import SilhouetteWeights
from samba.silhouette.render import render_silhouettes
from samba.silhouette.shape_tree import PART_JOINTS, ShapeTree
from samba.silhouette.tracker import SilhouetteTracker, TrackerSettings

ARMS = (PART_NAMES.index("l_arm"), PART_NAMES.index("r_arm"))


def _render(tree: ShapeTree, poses: np.ndarray) -> np.ndarray:
    """Noise-free silhouettes (n, 240, 320) of the tree's body in world poses (n, 13, 3)."""
    return render_silhouettes(poses, tree.view.camera, tree.body)


def _relative(poses: np.ndarray) -> np.ndarray:
    """Poses (n, 13, 3) float64 with the hip midpoint at the origin."""
    poses = np.asarray(poses, dtype=np.float64)
    return poses - poses[:, [7, 8]].mean(axis=1, keepdims=True)


@pytest.fixture(scope="module")
def sources(small_build: SmallBuild) -> np.ndarray:
    """Index into the database poses of each leaf's pose."""
    return source_poses(small_build.tree.leaves.poses, small_build.poses)


def _facing_leaves_of_take(tree: ShapeTree, sources: np.ndarray, take: int) -> np.ndarray:
    """Leaves (ascending) of one take's poses that face the camera within 30 degrees: one
    per distinct pose of a take that stays in place, in the take's order."""
    angles = facing_angles(tree.leaves.poses)
    return np.flatnonzero((sources // TAKE_FRAMES == take) & (np.abs(angles) < 30.0))


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("distance", "hamming"),
        ("occlusion_factor", 0.5),
        ("occlusion_factor", float("nan")),
        ("part_sigma", (0.03, 0.03, 0.08, 0.08, 0.06)),
        ("part_sigma", (0.03, 0.0, 0.08, 0.08, 0.06, 0.06)),
        ("likelihood_sigma", 0.0),
        ("part_cap", (10.0,) * 5),
        ("relative_sigma", 0.0),
        ("keep", (40, 120)),
        ("keep", (40, 0, 400)),
        ("leaf_side_weight", 0.0),
        ("leaf_side_weight", float("inf")),
        ("top_sigma", -1.0),
        ("top_sigma", float("nan")),
    ],
)
def test_settings_reject_bad_values(field: str, value: object) -> None:
    with pytest.raises(InputError, match=field):
        TrackerSettings(**{field: value})


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("posterior_size", 0),  # crashes the second frame: max of an empty array
        ("mean_temperature", -1.0),
        ("mean_temperature", float("nan")),
        ("log_margin", -1.0),  # prunes every node: IndexError in step
        ("log_margin", float("nan")),
        ("upper_sigma_factor", 0.0),  # divides the upper levels' distances by zero
    ],
)
def test_settings_reject_values_that_break_tracking(field: str, value: object) -> None:
    with pytest.raises(InputError, match=field):
        TrackerSettings(**{field: value})


def test_a_sequence_of_tree_poses_is_tracked_exactly(
    small_tree: ShapeTree, sources: np.ndarray
) -> None:
    # The squat's leaves facing the camera, rendered without noise: every frame's
    # silhouette is exactly one leaf's, 5 to 10 cm of joint motion apart.
    truth = _facing_leaves_of_take(small_tree, sources, SQUAT_TAKE)
    assert len(truth) >= 6
    poses = small_tree.leaves.poses[truth].astype(np.float64)
    masks = _render(small_tree, poses)
    best_leaf = TrackerSettings(mean_temperature=0.0)
    estimates = SilhouetteTracker(small_tree, best_leaf).track(masks)
    found = np.array([e.leaf for e in estimates])
    # At the bottom of the squat two leaves 3 cm apart have almost one silhouette: the
    # motion model may keep the previous one for a frame.
    assert np.mean(found == truth) >= 0.75, f"tracked leaves {found}, rendered {truth}"
    errors = np.linalg.norm(np.array([e.pose for e in estimates]) - poses, axis=-1)
    assert errors.mean(axis=1).max() * 100 < 3.5  # cm
    assert errors[found == truth].max() * 1000 < 1.0  # mm
    # The default estimate, the posterior mean, stays as close.
    means = np.array([e.pose for e in SilhouetteTracker(small_tree).track(masks)])
    assert np.linalg.norm(means - poses, axis=-1).mean(axis=1).max() * 100 < 3.5  # cm
    for estimate, leaf in zip(estimates, truth, strict=True):
        if estimate.leaf != leaf:
            continue
        assert estimate.found and estimate.distance == pytest.approx(0.0, abs=1e-9)
        visible = small_tree.leaves.visibility[leaf]
        np.testing.assert_array_equal(estimate.occluded, visible < 0.3)
        # Every top-level node is evaluated, and pruning spares most of the rest.
        nodes = sum(len(level) for level in small_tree.levels)
        assert len(small_tree.levels[0]) <= estimate.evaluated < nodes


def test_the_first_frame_finds_each_camera_facing_leaf(
    small_tree: ShapeTree, sources: np.ndarray
) -> None:
    leaves = np.concatenate(
        [_facing_leaves_of_take(small_tree, sources, take)[:3] for take in range(10)]
    )
    masks = _render(small_tree, small_tree.leaves.poses[leaves])
    tracker = SilhouetteTracker(small_tree)
    found = []
    for mask in masks:
        tracker.reset()
        found.append(tracker.step(mask).leaf)
    np.testing.assert_array_equal(found, leaves)


@pytest.mark.parametrize("side", [0.4, -0.4])
def test_a_pose_beside_home_comes_back_in_world_coordinates(
    small_tree: ShapeTree, sources: np.ndarray, side: float
) -> None:
    # The first camera-facing pose of the wave and the pointing (they stand in place
    # and move their arms sideways, which one camera sees), 0.4 m to the side of home.
    leaves = [_facing_leaves_of_take(small_tree, sources, take)[0] for take in (6, 9)]
    truth = small_tree.leaves.poses[leaves].astype(np.float64) + np.array([side, 0.0, 0.0])
    tracker = SilhouetteTracker(small_tree)
    for pose, mask in zip(truth, _render(small_tree, truth), strict=True):
        tracker.reset()
        estimate = tracker.step(mask)
        hips = estimate.pose[[7, 8]].mean(axis=0) - pose[[7, 8]].mean(axis=0)
        assert np.linalg.norm(hips) < 0.05  # m
        assert np.linalg.norm(estimate.pose - pose, axis=-1).mean() < 0.05  # m


def test_a_taller_subject_comes_back_at_its_stature(
    small_tree: ShapeTree, sources: np.ndarray
) -> None:
    # The wave's first camera-facing pose, its subject 5% taller than the body model and
    # rendered so (the model scaled by 1.05): told the stature, the tracker finds the
    # leaf and returns it 5% taller, standing where the subject stands.
    leaf = _facing_leaves_of_take(small_tree, sources, 6)[0]
    taller = small_tree.body.scaled(1.05)
    pose = small_tree.leaves.poses[leaf].astype(np.float64)
    floor = pose[[7, 8]].mean(axis=0) * np.array([1.0, 0.0, 1.0])
    truth = floor + 1.05 * (pose - floor)
    mask = render_silhouettes(truth[None], small_tree.view.camera, taller)[0]
    estimate = SilhouetteTracker(small_tree, height=taller.height).step(mask)
    assert estimate.leaf == leaf
    assert np.linalg.norm(estimate.pose - truth, axis=-1).mean() < 0.03  # m
    unscaled = SilhouetteTracker(small_tree).step(mask)
    assert np.linalg.norm(unscaled.pose - truth, axis=-1).mean() > 0.05  # m


@pytest.mark.parametrize("height", [0.2, 3.0, float("nan")])
def test_an_implausible_stature_raises(small_tree: ShapeTree, height: float) -> None:
    with pytest.raises(InputError, match=r"height: the subject's stature must be 0\.5\.\.2\.5 m"):
        SilhouetteTracker(small_tree, height=height)


def test_the_first_frame_prefers_the_camera_facing_twin(
    small_tree: ShapeTree, sources: np.ndarray
) -> None:
    # A pose and itself turned by 180 degrees (back to the camera) have nearly the same
    # silhouette; render the back-facing one, whose silhouette it is exactly.
    leaves = small_tree.leaves
    silhouettes = leaves.silhouettes.to_masks()
    angles = facing_angles(leaves.poses)
    pairs = []
    for front in np.flatnonzero(np.abs(angles) < 30.0):
        turned = (angles - angles[front]) % 360.0
        for back in np.flatnonzero((sources == sources[front]) & (np.abs(turned - 180.0) < 1.0)):
            weights = SilhouetteWeights.from_mask(silhouettes[back], "normalised")
            pairs.append((weights.distances(silhouettes[front][None])[0], front, back))
    _, front, back = min(pairs)
    mask = _render(small_tree, leaves.poses[[back]])[0]
    estimate = SilhouetteTracker(small_tree).step(mask)
    assert estimate.leaf != back
    assert abs(angles[estimate.leaf]) <= TrackerSettings().start_tolerance
    uniform = SilhouetteTracker(small_tree, TrackerSettings(start_tolerance=180.0))
    assert uniform.step(mask).leaf == back


def _hidden_arm_pair(tree: ShapeTree) -> tuple[int, int, int]:
    """(leaf, other, arm): a leaf whose `arm` is occluded and another leaf whose pose
    differs from it in that arm by 8 to 25 cm RMS and in every other part by less."""
    relative = _relative(tree.leaves.poses)
    best = (np.inf, -1, -1, -1)
    for arm in ARMS:
        for leaf in np.flatnonzero(tree.leaves.visibility[:, arm] < 0.3):
            gaps = np.linalg.norm(relative - relative[leaf], axis=-1)
            rms = np.stack([np.sqrt((gaps[:, list(j)] ** 2).mean(1)) for j in PART_JOINTS], 1)
            others = np.delete(rms, arm, axis=1).max(axis=1)
            fits = (rms[:, arm] > 0.08) & (rms[:, arm] < 0.25) & (others < rms[:, arm] / 4)
            for other in np.flatnonzero(fits):
                best = min(best, (others[other], leaf, other, arm))
    assert best[1] >= 0, "no leaf pair differs in an occluded arm only"
    return best[1], best[2], best[3]


def test_the_occlusion_aware_model_lets_a_hidden_arm_move(small_tree: ShapeTree) -> None:
    leaf, other, arm = _hidden_arm_pair(small_tree)
    relative = _relative(small_tree.leaves.poses[[leaf, other]])
    sigma = np.array(TrackerSettings().part_sigma)
    hidden = small_tree.leaves.visibility[leaf] < 0.3
    assert hidden[arm]
    mask = _render(small_tree, small_tree.leaves.poses[[leaf]])[0]
    drops = {}
    for factor in (1.0, 5.0):
        settings = TrackerSettings(occlusion_factor=factor, posterior_size=1, start_tolerance=180.0)
        tracker = SilhouetteTracker(small_tree, settings)
        estimate = tracker.step(mask)
        assert estimate.leaf == leaf and estimate.occluded[arm]
        prior = tracker._log_prior(np.array([leaf, other]))
        drops[factor] = prior[0] - prior[1]
        # One Gaussian per part around the previous leaf; a hidden part's sigma is
        # `factor` times wider.
        squared = [((relative[1, j] - relative[0, j]) ** 2).sum() for j in PART_JOINTS]
        widened = sigma * np.where(hidden, factor, 1.0)
        penalties = 0.5 * np.array(squared) / widened**2
        expected = np.minimum(penalties, settings.part_cap).sum()
        assert drops[factor] == pytest.approx(expected, rel=1e-6)
    assert drops[5.0] < drops[1.0] / 4


def test_an_empty_frame_holds_the_previous_pose(small_tree: ShapeTree, sources: np.ndarray) -> None:
    leaves = _facing_leaves_of_take(small_tree, sources, SQUAT_TAKE)[:2]
    masks = _render(small_tree, small_tree.leaves.poses[leaves])
    tracker = SilhouetteTracker(small_tree)
    first = tracker.step(masks[0])
    held = tracker.step(np.zeros_like(masks[0]))
    assert not held.found and first.found
    np.testing.assert_array_equal(held.pose, first.pose)
    assert held.leaf == first.leaf and held.evaluated == 0 and np.isnan(held.distance)
    again = tracker.step(masks[1])
    assert again.found and again.leaf == leaves[1]


def test_an_empty_first_frame_raises(small_tree: ShapeTree, sources: np.ndarray) -> None:
    tracker = SilhouetteTracker(small_tree)
    empty = np.zeros((240, 320), dtype=bool)
    with pytest.raises(InputError, match="silhouette: the first frame has no silhouette"):
        tracker.step(empty)
    leaf = _facing_leaves_of_take(small_tree, sources, SQUAT_TAKE)[0]
    tracker.step(_render(small_tree, small_tree.leaves.poses[[leaf]])[0])
    tracker.reset()
    with pytest.raises(InputError, match="first frame"):
        tracker.step(empty)


def test_a_mask_of_the_wrong_size_or_type_raises(
    small_tree: ShapeTree, sources: np.ndarray
) -> None:
    leaf = _facing_leaves_of_take(small_tree, sources, SQUAT_TAKE)[0]
    mask = _render(small_tree, small_tree.leaves.poses[[leaf]])[0]
    tracker = SilhouetteTracker(small_tree)
    tracker.step(mask)
    with pytest.raises(InputError, match="silhouette"):
        tracker.step(mask[:120])
    with pytest.raises(InputError, match="silhouette"):
        tracker.step(mask.astype(np.uint8))
    # An empty mask of the wrong size or type is a wrong input too, not a frame without
    # a subject.
    with pytest.raises(InputError, match="silhouette"):
        tracker.step(np.zeros((120, 160), dtype=bool))
    with pytest.raises(InputError, match="silhouette"):
        tracker.step(np.zeros((240, 320), dtype=np.uint8))
