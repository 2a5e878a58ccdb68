"""Tests of the silhouette renderer `samba.silhouette.render`."""

from __future__ import annotations

import numpy as np
import pytest

from samba.base.errors import InputError
from samba.body.body_model import (
    ANKLE_HEIGHT_FRACTION,
    CAPSULE_NAMES,
    PART_NAMES,
    BodyModel,
    scaled_to,
)
from samba.body.segments import segment_distances
from samba.body.skeleton import standard_pose
from samba.cameras.camera import Camera
from samba.cameras.synthetic_cameras import with_size
from samba.silhouette.render import (
    BACKGROUND_LABEL,
    noisy_silhouettes,
    part_visibility,
    render_part_labels,
    render_silhouettes,
)
from samba.synthetic.motions import MOTIONS, generate

MEN_M = BodyModel.named("men-M")
FRONT = Camera.look_at("front", (0.0, 0.85, 3.0), (0.0, 0.85, 0.0), (320, 240), 60.0)
BACK = Camera.look_at("back", (0.0, 0.85, -3.0), (0.0, 0.85, 0.0), (320, 240), 60.0)
L_ARM, R_ARM, TORSO = (PART_NAMES.index(p) for p in ("l_arm", "r_arm", "torso"))


def _iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Intersection over union (n,) of masks (n, H, W)."""
    return (a & b).sum(axis=(1, 2)) / (a | b).sum(axis=(1, 2))


def _ray_cast(poses: np.ndarray, camera: Camera, body: BodyModel) -> np.ndarray:
    """The exact silhouettes (n, H, W): pixels whose centre's ray passes within a
    capsule's radius of its axis."""
    starts, ends, radii, _ = body.capsules(poses)
    width, height = camera.size
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    pixels = np.stack([u, v, np.ones_like(u)], axis=-1).reshape(-1, 3).astype(np.float64)
    rays = pixels @ np.linalg.inv(camera.matrix).T @ camera.rotation_matrix
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    centre = camera.center
    far = centre + 20.0 * rays  # (P, 3), well past the body
    masks = []
    for start, end in zip(starts, ends, strict=True):
        distance = segment_distances(centre, far[:, None], start[None], end[None])  # (P, K)
        masks.append((distance <= radii).any(axis=-1).reshape(height, width))
    return np.array(masks)


def _held_out_poses(body: BodyModel, frames_per_motion: int) -> np.ndarray:
    """Poses of every synthetic motion, scaled to `body`, hips over the origin."""
    takes = [
        generate(m, seconds=2.0, fps=frames_per_motion / 2.0, seed=40 + i).poses
        for i, m in enumerate(MOTIONS)
    ]
    poses = scaled_to(np.concatenate(takes), body.height)
    poses[..., [0, 2]] -= poses[:, [7, 8]][..., [0, 2]].mean(axis=1)[:, None]
    return poses


@pytest.mark.parametrize("name", ["men-M", "children-120"])
def test_silhouettes_match_exact_ray_casting(name: str) -> None:
    body = BodyModel.named(name)
    camera = Camera.look_at("c", (0.3, 1.0, 3.0), (0.0, body.height / 2, 0.0), (90, 120), 40.0)
    poses = _held_out_poses(body, frames_per_motion=1)
    exact = _ray_cast(poses, camera, body)
    rendered = render_silhouettes(poses, camera, body)
    assert rendered.shape == (len(poses), 120, 90) and rendered.dtype == bool
    assert _iou(rendered, exact).min() >= 0.97
    assert (rendered & ~exact).sum() <= 0.002 * exact.sum()  # never much outside


def test_a_standing_subject_is_as_tall_as_the_projection_of_its_body() -> None:
    pose = standard_pose(MEN_M.height)[None]
    mask = render_silhouettes(pose, FRONT, MEN_M)[0]
    rows = np.flatnonzero(mask.any(axis=1))
    crown_height = (1.0 - ANKLE_HEIGHT_FRACTION) * MEN_M.height  # the ankles are at y = 0
    crown = FRONT.project(np.array([0.0, crown_height, 0.0]))[1]
    _, ends, radii, _ = MEN_M.capsules(pose)
    foot = CAPSULE_NAMES.index("l_foot")
    toe = ends[0, foot] + [0.0, -radii[foot], radii[foot]]  # the sole under the toes
    expected = FRONT.project(toe)[1] - crown
    assert rows[-1] - rows[0] + 1 == pytest.approx(expected, rel=0.03)
    focal = FRONT.matrix[0, 0]
    assert rows[-1] - rows[0] + 1 == pytest.approx(focal * MEN_M.height / 3.0, rel=0.05)


def test_a_camera_behind_the_subject_sees_it_mirrored() -> None:
    pose = standard_pose(MEN_M.height, arm_angle_deg=20.0)[None]
    pose[0, [3, 5]] = [[0.35, 1.45, 0.0], [0.40, 1.70, 0.0]]  # the left arm raised
    front, back = (render_silhouettes(pose, c, MEN_M)[0] for c in (FRONT, BACK))
    assert _iou(front[None], back[None, :, ::-1])[0] > 0.95  # up to the feet's direction
    labels = {c.name: render_part_labels(pose, c, MEN_M)[0] for c in (FRONT, BACK)}
    centre = (FRONT.size[0] - 1) / 2
    assert np.nonzero(labels["front"] == L_ARM)[1].mean() > centre + 20  # viewer's right
    assert np.nonzero(labels["back"] == L_ARM)[1].mean() < centre - 20


def test_labels_cover_the_silhouette_with_the_nearest_part() -> None:
    poses = _held_out_poses(MEN_M, frames_per_motion=2)
    labels = render_part_labels(poses, FRONT, MEN_M)
    assert labels.dtype == np.int8 and labels.min() == BACKGROUND_LABEL
    assert np.array_equal(labels >= 0, render_silhouettes(poses, FRONT, MEN_M))
    arm_in_front = standard_pose(MEN_M.height)[None]
    arm_in_front[0, [3, 5]] = [[0.2, 1.1, 0.15], [-0.05, 1.1, 0.35]]  # forearm before the belly
    labels = render_part_labels(arm_in_front, FRONT, MEN_M)[0]
    u, v = np.round(FRONT.project(np.array([0.05, 1.1, 0.3]))).astype(int)
    assert labels[v, u] == L_ARM  # the arm, not the torso behind it
    visibility = part_visibility(arm_in_front, FRONT, MEN_M)[0]
    standing = part_visibility(standard_pose(MEN_M.height)[None], FRONT, MEN_M)[0]
    assert visibility[L_ARM] > 0.95 and standing[TORSO] > 0.95
    assert 0.6 < visibility[TORSO] < standing[TORSO] - 0.1  # partly hidden by the arm


def test_an_arm_behind_the_back_is_not_visible() -> None:
    pose = standard_pose(MEN_M.height, arm_angle_deg=10.0)[None]
    pose[0, [3, 5]] = [[0.06, 1.17, -0.2], [0.0, 1.05, -0.22]]  # left arm behind the back
    visibility = part_visibility(pose, FRONT, MEN_M)[0]
    assert visibility[L_ARM] < 0.1
    assert visibility[R_ARM] > 0.7 and visibility[TORSO] > 0.95
    seen_from_behind = part_visibility(pose, BACK, MEN_M)[0]
    assert seen_from_behind[L_ARM] > 0.9
    side = Camera.look_at("side", (-3.0, 0.85, 0.0), (0.0, 0.85, 0.0), (320, 240), 60.0)
    hanging = standard_pose(MEN_M.height, arm_angle_deg=5.0)[None]
    assert part_visibility(hanging, side, MEN_M)[0, L_ARM] < 0.1  # the far arm, from the side


def test_image_sizes_and_poses_outside_the_image() -> None:
    pose = standard_pose(MEN_M.height)[None]
    small = render_silhouettes(pose, with_size(FRONT, (80, 60)), MEN_M)
    assert small.shape == (1, 60, 80)
    assert small.sum() == pytest.approx(render_silhouettes(pose, FRONT, MEN_M).sum() / 16, rel=0.2)
    shifted = Camera(
        "shifted",
        FRONT.size,
        FRONT.matrix + np.array([[0.0, 0.0, 150.0], [0.0, 0.0, -100.0], [0.0, 0.0, 0.0]]),
        FRONT.rotation,
        FRONT.translation,
    )  # the same view moved 150 px right and 100 px up: the head and a hand leave it
    clean, moved = (
        render_silhouettes(pose, FRONT, MEN_M)[0],
        render_silhouettes(pose, shifted, MEN_M)[0],
    )
    assert np.array_equal(moved[: 240 - 100, 150:], clean[100:, : 320 - 150])
    assert not moved[240 - 100 :].any() and not moved[:, :150].any()
    away = pose + np.array([10.0, 0.0, 0.0])
    assert not render_silhouettes(away, FRONT, MEN_M).any()
    assert np.all(part_visibility(away, FRONT, MEN_M) == 0.0)


def test_capsules_reaching_behind_the_camera_are_clipped() -> None:
    pose = standard_pose(MEN_M.height)[None]
    pose[0, [3, 5]] = [[0.17, 1.32, 0.3], [0.17, 1.32, 0.56]]  # left arm pointing forward
    lens = Camera.look_at("lens", (0.17, 1.32, 0.45), (0.17, 1.32, 3.0), (320, 240), 60.0)
    mask = render_silhouettes(pose, lens, MEN_M)[0]
    assert mask[120, 160]  # the hand right in front of the lens fills the middle
    assert 0.1 < mask.mean() < 1.0
    behind = Camera.look_at("behind", (0.0, 1.2, 0.3), (0.0, 1.2, 3.0), (320, 240), 60.0)
    assert not render_silhouettes(standard_pose(MEN_M.height)[None], behind, MEN_M).any()


def test_noise_is_deterministic_and_scales_with_the_level() -> None:
    masks = render_silhouettes(_held_out_poses(MEN_M, frames_per_motion=1), FRONT, MEN_M)
    assert np.array_equal(noisy_silhouettes(masks, np.random.default_rng(3), 0.0), masks)
    first = noisy_silhouettes(masks, np.random.default_rng(3))
    again = noisy_silhouettes(masks, np.random.default_rng(3))
    other = noisy_silhouettes(masks, np.random.default_rng(4))
    assert first.dtype == bool and first.shape == masks.shape
    assert np.array_equal(first, again) and not np.array_equal(first, other)
    iou = {
        level: _iou(noisy_silhouettes(masks, np.random.default_rng(5), level), masks)
        for level in (0.5, 1.0, 2.0)
    }
    assert 0.85 < iou[1.0].mean() < 0.95 and iou[1.0].min() > 0.8
    assert iou[0.5].mean() > iou[1.0].mean() > iou[2.0].mean()
    bottom = np.array([np.flatnonzero(m.any(axis=1))[-1] for m in masks])
    widths = [m[b - 2 : b + 1].any(axis=0).sum() for m, b in zip(masks, bottom, strict=True)]
    noisy_widths = [m[b - 2 : b + 1].any(axis=0).sum() for m, b in zip(first, bottom, strict=True)]
    assert np.mean(noisy_widths) > np.mean(widths) + 10  # the shadow at the feet


def test_bad_input_raises_typed_errors() -> None:
    poses = np.repeat(standard_pose()[None], 5, axis=0)
    poses[3, 7, 1] = np.nan
    for render in (render_silhouettes, render_part_labels, part_visibility):
        with pytest.raises(InputError, match="pose 3 contains NaN"):
            render(poses, FRONT, MEN_M)
    with pytest.raises(InputError, match=r"\(n, 13, 3\)"):
        render_silhouettes(np.zeros((2, 12, 3)), FRONT, MEN_M)
    with pytest.raises(InputError, match="masks must be"):
        noisy_silhouettes(np.zeros((2, 60, 80), dtype=np.uint8), np.random.default_rng(0))
    with pytest.raises(InputError, match="noise level"):
        noisy_silhouettes(np.zeros((1, 60, 80), dtype=bool), np.random.default_rng(0), -1.0)
    assert render_silhouettes(np.zeros((0, 13, 3)), FRONT, MEN_M).shape == (0, 240, 320)
