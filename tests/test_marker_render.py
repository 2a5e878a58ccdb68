"""Tests of the synthetic camera rig `samba.markers.render` and frame files
`samba.cameras.frame_io`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from samba.base.errors import InputError
from samba.body.segments import segment_distances
from samba.body.skeleton import markers_of, standard_pose
from samba.cameras.camera import Camera
from samba.cameras.frame_io import read_frames, write_images, write_video
from samba.markers.detection import detect_markers
from samba.markers.observation import evaluation_cameras
from samba.markers.render import (
    BodyCapsules,
    RenderOptions,
    film_empty_stage,
    hidden_by_body,
    marker_views,
    render,
)
from samba.synthetic.motions import generate

FRONT = Camera.look_at("front", (0.0, 1.2, 4.0), (0.0, 0.9, 0.0), (160, 120), 60.0)
BACK = Camera.look_at("back", (0.0, 1.2, -4.0), (0.0, 0.9, 0.0), (160, 120), 60.0)
SIDE = Camera.look_at("side", (4.0, 1.2, 0.0), (0.0, 0.9, 0.0), (160, 120), 60.0)


def _take(frames: int = 12) -> np.ndarray:
    return generate("arm_swing", seconds=frames / 30, fps=30, seed=5).poses


def test_truth_pixels_are_the_camera_projection() -> None:
    poses = _take()
    camera = evaluation_cameras(poses)[0]
    view = render(poses, [camera], RenderOptions(), seed=0)[0]
    assert view.frames.shape == (12, 120, 160) and view.frames.dtype == np.uint8
    assert np.allclose(view.pixels, camera.project(markers_of(poses)))
    assert view.visible.shape == (12, 8) and not view.dropped.any()


def test_the_body_hides_markers_behind_it() -> None:
    pose = standard_pose(1.75)[None]
    assert not hidden_by_body(pose, FRONT, BodyCapsules()).any()
    assert not hidden_by_body(pose, BACK, BodyCapsules()).any()  # A-pose: all outside
    side = hidden_by_body(pose, SIDE, BodyCapsules())[0]  # from +X the right side hides
    assert list(side) == [False, True, False, True, False, True, False, True]
    arms_front = pose.copy()
    arms_front[0, [5, 6]] = [[0.05, 1.1, 0.35], [-0.05, 1.1, 0.35]]  # wrists before the belly
    assert hidden_by_body(arms_front, BACK, BodyCapsules())[0, [2, 3]].all()
    assert not hidden_by_body(arms_front, FRONT, BodyCapsules())[0].any()
    views = marker_views(arms_front, BACK, RenderOptions(occlusion=False))
    assert views.visible.all()


def test_disc_size_follows_the_marker_size_and_distance() -> None:
    pose = standard_pose(1.75)[None]
    near = marker_views(pose, FRONT, RenderOptions(marker_diameter=0.03)).radii
    far_camera = Camera.look_at("far", (0.0, 1.2, 8.0), (0.0, 0.9, 0.0), (160, 120), 60.0)
    far = marker_views(pose, far_camera, RenderOptions(marker_diameter=0.03)).radii
    focal = FRONT.matrix[0, 0]
    depth = FRONT.to_camera(markers_of(pose))[..., 2]
    assert np.allclose(near, focal * 0.015 / depth)
    assert (far < near).all()


def test_background_noise_and_blobs() -> None:
    poses = _take(4)
    camera = evaluation_cameras(poses)[0]
    quiet = render(poses, [camera], RenderOptions(noise_sigma=0.0), seed=0)[0]
    noisy = render(poses, [camera], RenderOptions(noise_sigma=3.0), seed=0)[0]
    background = np.median(quiet.frames)
    assert background == 12
    assert 2.5 < np.std(noisy.frames[noisy.frames < 40].astype(float)) < 3.5
    assert [len(detect_markers(f)) for f in noisy.frames] == list(noisy.visible.sum(axis=1))


def test_dropped_frames_are_black_and_flagged() -> None:
    poses = _take(40)
    camera = evaluation_cameras(poses)[0]
    view = render(poses, [camera], RenderOptions(drop_rate=0.25), seed=3)[0]
    assert 3 < view.dropped.sum() < 20
    assert (view.frames[view.dropped] == 0).all()
    assert not view.visible[view.dropped].any()
    assert (view.frames[~view.dropped].max(axis=(1, 2)) > 100).all()


def test_motion_blur_streaks_stay_centred_on_the_frame_time() -> None:
    poses = _take(20)
    camera = evaluation_cameras(poses)[0]
    sharp = render(poses, [camera], RenderOptions(), seed=0)[0]
    blurred = render(poses, [camera], RenderOptions(motion_blur=0.8), seed=0)[0]
    assert not np.array_equal(sharp.frames, blurred.frames)
    for frame, pixels, seen in zip(
        blurred.frames[1:-1], blurred.pixels[1:-1], blurred.visible[1:-1], strict=True
    ):
        centroids = detect_markers(frame, max_elongation=10).centroids
        gaps = np.linalg.norm(pixels[seen][:, None] - centroids[None], axis=-1).min(axis=1)
        assert gaps.max() < 0.3


def test_render_is_deterministic_in_its_seed() -> None:
    poses = _take(3)
    cameras = evaluation_cameras(poses)
    first = render(poses, cameras, RenderOptions(), seed=7)
    again = render(poses, cameras, RenderOptions(), seed=7)
    other = render(poses, cameras, RenderOptions(), seed=8)
    assert all(np.array_equal(a.frames, b.frames) for a, b in zip(first, again, strict=True))
    assert not np.array_equal(first[0].frames, other[0].frames)
    assert not np.array_equal(first[0].frames, first[1].frames)


def test_empty_stage_shows_only_the_static_spots() -> None:
    options = RenderOptions(static_spots=((0.25, 0.5), (0.75, 0.5)))
    frames = film_empty_stage(FRONT, options, 3, np.random.default_rng(0))
    assert frames.shape == (3, 120, 160)
    assert [len(detect_markers(f)) for f in frames] == [2, 2, 2]


def test_rendered_video_reads_back_losslessly(tmp_path: Path) -> None:
    poses = _take(15)
    view = render(poses, evaluation_cameras(poses)[:1], RenderOptions(), seed=0)[0]
    write_video(view.frames, tmp_path / "cam0.avi", fps=30)
    assert np.array_equal(read_frames(tmp_path / "cam0.avi"), view.frames)
    assert [p.name for p in tmp_path.iterdir()] == ["cam0.avi"]  # no temporary left
    colour = np.repeat(view.frames[..., None], 3, axis=-1)
    colour[..., 2] //= 2
    write_video(colour, tmp_path / "colour.avi")
    assert np.array_equal(read_frames(tmp_path / "colour.avi", grey=False), colour)


def test_image_sequences_read_back_losslessly_in_8_and_16_bits(tmp_path: Path) -> None:
    frames = render(_take(5), [FRONT], RenderOptions(), seed=0)[0].frames
    paths = write_images(frames, tmp_path / "eight")
    assert [p.name for p in paths] == [f"frame_{i:06d}.png" for i in range(5)]
    assert np.array_equal(read_frames(tmp_path / "eight"), frames)
    deep = frames.astype(np.uint16) * 257
    write_images(deep, tmp_path / "sixteen")
    back = read_frames(tmp_path / "sixteen")
    assert back.dtype == np.uint16 and np.array_equal(back, deep)


def test_unreadable_files_raise_input_errors_naming_them(tmp_path: Path) -> None:
    corrupt = tmp_path / "corrupt.avi"
    corrupt.write_bytes(b"not a video at all" * 50)
    with pytest.raises(InputError, match=r"corrupt\.avi: cannot be opened as a video"):
        read_frames(corrupt)
    with pytest.raises(InputError, match=r"missing\.avi: no such"):
        read_frames(tmp_path / "missing.avi")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="empty: holds no images"):
        read_frames(tmp_path / "empty")
    folder = tmp_path / "images"
    write_images(np.zeros((2, 120, 160), np.uint8), folder)
    write_images(np.zeros((1, 60, 80), np.uint8), folder, prefix="other")
    with pytest.raises(InputError, match=r"other_000000\.png: image is 80x60 but"):
        read_frames(folder)
    (folder / "frame_000001.png").write_bytes(b"\x89PNG broken")
    with pytest.raises(InputError, match=r"frame_000001\.png: not a readable image"):
        read_frames(folder)


def test_bad_frames_and_codecs_raise_input_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="frames: must be uint8"):
        write_video(np.zeros((2, 120, 160), np.float32), tmp_path / "a.avi")
    with pytest.raises(InputError, match="frames: are empty"):
        write_video(np.zeros((0, 120, 160), np.uint8), tmp_path / "a.avi")
    with pytest.raises(InputError, match="frames: must be"):
        write_images(np.zeros((2, 120, 160, 4), np.uint8), tmp_path / "x")
    with pytest.raises(InputError, match=r"a\.nope: OpenCV cannot write"):
        write_video(np.zeros((2, 120, 160), np.uint8), tmp_path / "a.nope")
    assert list(tmp_path.iterdir()) == []


def test_segment_distances_match_a_dense_search() -> None:
    rng = np.random.default_rng(0)
    p0, p1, q0, q1 = rng.normal(size=(4, 60, 3))
    p1[::5] = p0[::5]  # points
    q1[::7] = q0[::7]
    s = np.linspace(0.0, 1.0, 301)[:, None, None]
    dense = np.linalg.norm((p0 + s * (p1 - p0))[:, None] - (q0 + s * (q1 - q0))[None], axis=-1).min(
        axis=(0, 1)
    )
    exact = segment_distances(p0, p1, q0, q1)
    assert (exact <= dense + 1e-12).all() and np.abs(exact - dense).max() < 2e-3
