"""The paper's Figure 4 experiment as a test: arm swings seen from the side, where the
far arm passes behind the body, tracked with the three silhouette distances and the
plain and the occlusion-aware motion model."""

from __future__ import annotations

import numpy as np

from samba.body_model import BodyModel
from samba.camera import Camera
from samba.shape_tree import ShapeTree
from samba.silhouette_evaluation import arm_swing_experiment, staged
from samba.silhouette_view import SilhouetteView
from samba.synthetic import generate, library

CAMERA = Camera.look_at("front", (0.0, 1.2, 3.6), (0.0, 0.9, 0.0), (320, 240), 55.0)
BODY = BodyModel.for_subject(1.75)


def test_the_normalised_distance_with_the_occlusion_aware_model_fails_least() -> None:
    poses = np.concatenate([t.poses for t in library(3, 4.0, 15.0, seed=1)])
    tree = ShapeTree.build(poses.astype(np.float64), SilhouetteView(CAMERA), BODY)
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
