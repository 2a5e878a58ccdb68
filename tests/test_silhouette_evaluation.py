"""The paper's Figure 4 experiment as a test: arm swings seen from the side, where the
far arm passes behind the body, tracked with the three silhouette distances and the
plain and the occlusion-aware motion model; and the accuracy target of frontal motions."""

from __future__ import annotations

import numpy as np
import pytest

from samba.body.body_model import BodyModel
from samba.body.skeleton import mirror_poses
from samba.cameras.camera import Camera
from samba.silhouette.evaluation import (
    arm_swing_experiment,
    observed_silhouettes,
    staged,
    track_take,
)
from samba.silhouette.shape_tree import ShapeTree
from samba.silhouette.tracker import SilhouetteTracker, TrackerSettings
from samba.silhouette.view import SilhouetteView
from samba.synthetic.motions import generate, library

pytestmark = pytest.mark.slow  # benchmark-like or end to end: CI runs it

CAMERA = Camera.look_at("front", (0.0, 1.2, 3.6), (0.0, 0.9, 0.0), (320, 240), 55.0)
BODY = BodyModel.for_subject(1.75)


@pytest.fixture(scope="module")
def tree() -> ShapeTree:
    """The tree of bench_silhouette's accuracy table: 3 takes per built-in motion and
    their mirror images."""
    poses = np.concatenate([t.poses for t in library(3, 4.0, 15.0, seed=1)])
    poses = np.concatenate([poses, mirror_poses(poses)])
    return ShapeTree.build(poses.astype(np.float64), SilhouetteView(CAMERA), BODY)


def test_the_normalised_distance_with_the_occlusion_aware_model_fails_least(
    tree: ShapeTree,
) -> None:
    outcomes = arm_swing_experiment(tree, sequences=12, seconds=3.0)
    assert all(o.failed + o.error + o.succeeded == 12 for o in outcomes)
    paper = {(o.distance, o.occlusion_factor): o for o in outcomes if o.velocity_gain == 0}
    assert len(paper) == 6  # three distances x the paper's two motion models
    best = paper["normalised", 5.0]
    others = [o for key, o in paper.items() if key != ("normalised", 5.0)]
    assert all(best.failed < o.failed for o in others), outcomes
    assert all(best.arm_error_cm < o.arm_error_cm for o in others), outcomes
    assert paper["xor", 1.0].failed == 12  # the plain XOR loses every side-on arm swing
    assert [o.velocity_gain > 0 for o in outcomes] == [False] * 6 + [True]  # then ours


def test_staged_takes_face_the_camera_from_home_at_the_body_height() -> None:
    view = SilhouetteView(CAMERA)
    take = generate("walk", 2.0, 15.0, seed=5).poses.astype(np.float64)
    poses = staged(take, view, BODY.height, in_place=True)
    hips = poses[:, [7, 8]].mean(axis=1)
    np.testing.assert_allclose(hips[:, [0, 2]], np.zeros((len(poses), 2)), atol=1e-9)
    left = poses[0, 7] - poses[0, 8]
    front = np.array([-left[2], 0.0, left[0]])
    to_camera = CAMERA.center - hips[0]
    to_camera[1] = 0.0
    cosine = front @ to_camera / np.linalg.norm(front) / np.linalg.norm(to_camera)
    assert cosine > 0.999
    side = staged(take, view, BODY.height, turn_deg=90.0)  # the camera sees its right side
    left = side[0, 7] - side[0, 8]
    assert left @ to_camera / np.linalg.norm(left) / np.linalg.norm(to_camera) < -0.99


@pytest.mark.parametrize(
    ("motion", "seed"),
    [("walk", 900), ("golf_swing", 912), ("point", 918), ("wave", 924), ("jumping_jacks", 936)],
)
def test_frontal_motions_are_tracked_within_8_cm_by_the_posterior_mean(
    tree: ShapeTree, motion: str, seed: int
) -> None:
    # The bench's first held-out take of the motion, facing the camera (walking on the
    # spot), silhouettes spoilt at level 0.5.
    take = generate(motion, 4.0, 15.0, seed).poses.astype(np.float64)
    poses = staged(take, tree.view, 1.75, in_place=motion == "walk")
    mean = track_take(motion, poses, tree, noise=0.5)
    best_leaf = track_take(motion, poses, tree, TrackerSettings(mean_temperature=0.0), 0.5)
    assert mean.mpjpe <= 8.0 and mean.failure_rate <= 0.05, (mean.mpjpe, mean.failure_rate)
    assert mean.mpjpe < best_leaf.mpjpe  # a hand in front of the body or behind it: both


def test_a_badly_spoilt_frame_does_not_lose_the_track(
    tree: ShapeTree, monkeypatch: pytest.MonkeyPatch
) -> None:
    # A golfer bent towards the camera at address; in frame 2 the spoilt silhouette
    # closes the gap between the legs, and on the tree's upper levels a subject standing,
    # or bent away with the back turned, matches it better. Pruning keeps the subtrees of
    # the last posterior, so the prior holds the track; without that, frame 2 is lost
    # (21 cm; three of frames 2-5 before the top-row term, which finds it again).
    poses = staged(
        generate("golf_swing", 4.0, 15.0, 2012).poses.astype(np.float64), tree.view, 1.75
    )
    held = track_take("golf_swing", poses[:6], tree, noise=0.5, seed=12)
    assert held.errors.mean(axis=1).max() < 8.0, held.errors.mean(axis=1)
    monkeypatch.setattr(SilhouetteTracker, "_held_ancestors", lambda self: [])
    lost = track_take("golf_swing", poses[:6], tree, noise=0.5, seed=12)
    assert lost.errors.mean(axis=1)[2] > 15.0, lost.errors.mean(axis=1)


def test_a_subject_turning_all_round_is_followed_past_the_side_view(tree: ShapeTree) -> None:
    # The bench's first held-out turn: 360 degrees in 4 s. With the paper's one-sided
    # distance the tracker turns back the mirror way at the side view; the symmetric one
    # on the best leaves follows the subject round.
    poses = staged(generate("turn", 4.0, 15.0, 906).poses.astype(np.float64), tree.view, 1.75)
    followed = track_take("turn", poses, tree, noise=0.5, seed=6)
    assert followed.mpjpe <= 8.0 and followed.failure_rate <= 0.05, followed.mpjpe
    one_sided = track_take("turn", poses, tree, TrackerSettings(symmetric_leaves=0), 0.5, 6)
    assert one_sided.mpjpe > 12.0 and one_sided.failure_rate > 0.2, one_sided.mpjpe


def test_a_walker_is_placed_in_depth_by_how_tall_the_silhouette_looks(tree: ShapeTree) -> None:
    # The bench's first held-out walk on the spot. A leaf with the feet together, placed
    # at the front foot of a stride, stands half a step too near the camera and looks a
    # tenth too big once normalised; the distances barely charge it, the top-row term
    # does (0% failures against 18% without it).
    take = generate("walk", 4.0, 15.0, 900).poses.astype(np.float64)
    poses = staged(take, tree.view, 1.75, in_place=True)
    tracked = track_take("walk", poses, tree, noise=0.5)
    assert tracked.mpjpe <= 7.0 and tracked.failure_rate <= 0.05, tracked.mpjpe
    without = track_take("walk", poses, tree, TrackerSettings(top_sigma=0.0), noise=0.5)
    assert without.mpjpe > 8.0 and without.failure_rate > 0.1, without.mpjpe


@pytest.mark.parametrize(
    ("motion", "seed", "factor"), [("golf_swing", 912, 1.04), ("walk", 900, 0.96)]
)
def test_a_subject_taller_or_shorter_than_the_body_model_is_tracked_at_its_stature(
    tree: ShapeTree, motion: str, seed: int, factor: float
) -> None:
    # A subject 4% taller (or shorter) than the nearest body model, the catalogue's step:
    # told the subject's stature, the tracker scales the silhouettes to the model and the
    # poses back (5.5 / 5.7 cm); not told, the size difference reads as depth and pose
    # (11.0 cm, 13% failures / 16.9 cm, 62%).
    subject = tree.body.scaled(factor)
    take = generate(motion, 4.0, 15.0, seed).poses.astype(np.float64)
    poses = staged(take, tree.view, subject.height, in_place=motion == "walk")
    told = track_take(motion, poses, tree, noise=0.5, subject=subject, height=subject.height)
    assert told.mpjpe <= 7.0 and told.failure_rate <= 0.05, told.mpjpe
    not_told = track_take(motion, poses, tree, noise=0.5, subject=subject)
    assert not_told.mpjpe > 9.0 and not_told.failure_rate > 0.1, not_told.mpjpe


def test_frames_whose_top_is_out_of_view_are_tracked_without_the_top_row(
    tree: ShapeTree,
) -> None:
    # The first 20 frames of the bench's first walk, the walker holding a pole straight
    # up to the view's top edge: the subject's top is out of view, so the top-row term is
    # left out and the poses are those of the tracker without it; without the pole the
    # term changes them.
    take = generate("walk", 4.0, 15.0, 900).poses.astype(np.float64)
    poses = staged(take, tree.view, 1.75, in_place=True)[:20]
    masks = observed_silhouettes(poses, tree, 0.5, np.random.default_rng(0))
    poled = masks.copy()
    for mask in poled:
        column = int(np.flatnonzero(mask.any(axis=0)).mean())
        mask[: np.flatnonzero(mask.any(axis=1))[0] + 1, column - 1 : column + 1] = True

    def tracked(settings: TrackerSettings, frames: np.ndarray) -> np.ndarray:
        tracker = SilhouetteTracker(tree, settings)
        return np.array([tracker.step(frame).pose for frame in frames])

    without = TrackerSettings(top_sigma=0.0)
    np.testing.assert_array_equal(tracked(TrackerSettings(), poled), tracked(without, poled))
    assert np.abs(tracked(TrackerSettings(), masks) - tracked(without, masks)).max() > 0.01  # m
