"""Tests of marker detection `samba.markers.detection`: accuracy on rendered discs, inputs."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from samba.base.errors import InputError
from samba.cameras.synthetic_cameras import with_size
from samba.markers.detection import auto_threshold, detect_markers, static_mask
from samba.markers.observation import evaluation_cameras
from samba.markers.render import RenderOptions, film_empty_stage, render
from samba.synthetic.motions import generate

RESOLUTIONS = [(160, 120), (320, 240), (640, 480), (1280, 720), (1920, 1080)]


def _rendered(size: tuple[int, int], frames: int, options: RenderOptions | None = None):
    """One camera's render of a synthetic take at `size`: (frames, truth pixels, visible)."""
    poses = generate("jumping_jacks", seconds=frames / 30, fps=30, seed=4).poses
    camera = with_size(evaluation_cameras(poses)[0], size)
    view = render(poses, [camera], options or RenderOptions(), seed=1)[0]
    return view.frames, view.pixels, view.visible


def _errors(frames: np.ndarray, truth: np.ndarray, visible: np.ndarray, **kwargs) -> np.ndarray:
    """Distance (px) from each visible marker to the nearest detected blob, all frames."""
    errors = []
    for frame, pixels, seen in zip(frames, truth, visible, strict=True):
        centroids = detect_markers(frame, **kwargs).centroids
        gaps = np.linalg.norm(pixels[seen][:, None] - centroids[None], axis=-1)
        errors.append(gaps.min(axis=1))
    return np.concatenate(errors)


def test_centroids_are_sub_pixel_at_640x480() -> None:
    frames, truth, visible = _rendered((640, 480), 20)
    errors = _errors(frames, truth, visible)
    assert visible.sum() > 100
    assert errors.max() < 0.1
    assert np.sqrt(np.mean(errors**2)) < 0.05


@pytest.mark.parametrize("size", RESOLUTIONS)
def test_every_visible_marker_is_found_at_every_resolution(size: tuple[int, int]) -> None:
    frames, truth, visible = _rendered(size, 3)
    errors = _errors(frames, truth, visible)
    assert errors.max() < 0.25 * size[0] / 160 + 0.1
    blobs = [len(detect_markers(frame)) for frame in frames]
    assert blobs == list(visible.sum(axis=1))  # nothing else: no noise blobs


def test_grey_levels_of_any_dtype_and_colour_give_the_same_centroids() -> None:
    frame = _rendered((320, 240), 1)[0][0]
    reference = detect_markers(frame).centroids
    variants = {
        "uint16": frame.astype(np.uint16) * 257,
        "float32": frame.astype(np.float32) / 255,
        "float64": frame.astype(np.float64),
        "bgr": cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR),
    }
    for name, variant in variants.items():
        centroids = detect_markers(variant).centroids
        assert centroids.shape == reference.shape, name
        assert np.abs(centroids - reference).max() < 1e-3, name


def test_fixed_threshold_and_blob_fields() -> None:
    frame = np.zeros((120, 160), np.uint8)
    cv2.circle(frame, (40, 30), 3, 200, -1)
    cv2.circle(frame, (100, 80), 5, 250, -1)
    blobs = detect_markers(frame, threshold=100)
    assert len(blobs) == 2 and blobs.threshold == 100
    order = np.argsort(blobs.centroids[:, 0])
    assert np.allclose(blobs.centroids[order], [[40, 30], [100, 80]], atol=1e-9)
    assert list(blobs.peaks[order]) == [200, 250]
    assert blobs.areas[order][0] < blobs.areas[order][1]


def test_a_blob_of_two_markers_merged_is_flagged_by_its_area() -> None:
    frame = np.zeros((120, 160), np.uint8)
    for u in (20, 50, 80, 110):
        cv2.circle(frame, (u, 30), 2, 255, -1)  # single markers
    cv2.circle(frame, (60, 80), 2, 255, -1)
    cv2.circle(frame, (63, 80), 2, 255, -1)  # two markers 3 px apart: one blob
    blobs = detect_markers(frame, threshold=128)
    assert len(blobs) == 5
    merged = blobs.merged()
    assert merged.sum() == 1 and np.allclose(blobs.centroids[merged], [[61.5, 80]])
    assert not blobs.merged(None).any()
    few = detect_markers(frame[60:100], threshold=128)  # the merged blob alone
    assert len(few) == 1 and not few.merged().any()


def test_area_and_shape_filters() -> None:
    frame = np.zeros((120, 160), np.uint8)
    cv2.circle(frame, (30, 30), 2, 255, -1)  # a marker
    cv2.circle(frame, (90, 30), 12, 255, -1)  # a lamp
    cv2.line(frame, (20, 90), (60, 100), 255, 2)  # a streak
    cv2.circle(frame, (130, 90), 12, 255, 1)  # a ring: sparse bounding box
    kept = detect_markers(frame, threshold=128, max_area=100)
    assert np.allclose(kept.centroids, [[30, 30]])
    everything = detect_markers(frame, threshold=128, max_elongation=100, min_fill=0)
    assert len(everything) == 4


def test_static_mask_removes_a_fixed_bright_spot() -> None:
    options = RenderOptions(static_spots=((0.8, 0.2),))
    camera = evaluation_cameras(generate("wave", seed=2).poses)[0]
    empty = film_empty_stage(camera, options, 10, np.random.default_rng(0))
    mask = static_mask(empty)
    spot = np.array([0.8 * 160, 0.2 * 120])
    assert mask[int(spot[1]), int(spot[0])] and mask.mean() < 0.05
    poses = generate("wave", seconds=0.2, fps=30, seed=2).poses
    view = render(poses, [camera], options, seed=3)[0]
    for frame, seen in zip(view.frames, view.visible, strict=True):
        unmasked = detect_markers(frame).centroids
        masked = detect_markers(frame, mask=mask).centroids
        assert np.linalg.norm(unmasked - spot, axis=-1).min() < 1.0
        assert np.linalg.norm(masked - spot, axis=-1).min() > 3.0
        assert len(masked) == seen.sum()


def test_noise_alone_gives_no_blobs_and_a_threshold_above_it() -> None:
    rng = np.random.default_rng(0)
    noise = np.clip(rng.normal(20, 3, (480, 640)), 0, 255).round().astype(np.uint8)
    assert len(detect_markers(noise)) == 0
    assert 20 + 4 * 3 < auto_threshold(noise) < 20 + 8 * 3
    assert len(detect_markers(np.zeros((120, 160), np.uint8))) == 0


@pytest.mark.parametrize(
    ("frame", "problem"),
    [
        (np.zeros((0, 160), np.uint8), "empty"),
        (np.zeros((120, 160), np.int32), "dtype"),
        (np.zeros((120, 160, 4), np.uint8), r"\(H, W, 3\)"),
        (np.zeros(160, np.uint8), r"\(H, W, 3\)"),
        ([[0, 1], [2, 3]], "numpy array"),
    ],
)
def test_bad_frames_raise_input_errors_naming_the_frame(frame: object, problem: str) -> None:
    with pytest.raises(InputError, match=problem) as error:
        detect_markers(frame, name="cam0 frame 7")  # type: ignore[arg-type]
    assert str(error.value).startswith("cam0 frame 7:")


def test_bad_mask_and_threshold_raise_input_errors() -> None:
    frame = np.zeros((120, 160), np.uint8)
    with pytest.raises(InputError, match="mask"):
        detect_markers(frame, mask=np.zeros((60, 80), bool))
    with pytest.raises(InputError, match="threshold"):
        detect_markers(frame, threshold="otsu")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="frames"):
        static_mask(np.zeros((0, 120, 160), np.uint8))
