"""Tests of silhouette extraction from video `samba.silhouette.extraction`, on synthetic
frames: a textured noisy wall, a person in several colours (trousers close to the wall's
colour), a global brightness change and a cast shadow."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from samba.base.errors import InputError
from samba.body.body_model import BodyModel
from samba.cameras.camera import Camera
from samba.silhouette.evaluation import staged
from samba.silhouette.extraction import (
    BACKGROUND_METHODS,
    MIN_BACKGROUND_FRAMES,
    ColourBackground,
    OpenCVBackground,
    SilhouetteExtractor,
    clean_silhouette,
    learn_background,
    tracking_close_px,
)
from samba.silhouette.render import render_silhouettes
from samba.silhouette.view import SilhouetteView
from samba.synthetic.motions import generate

HEIGHT, WIDTH = 240, 320
WALL = np.array([105, 118, 128], np.float32)
"""The wall's mean colour, BGR levels."""
NOISE = 3.0
"""Sensor noise, levels per channel."""
SHADOW = 0.6
"""Intensity ratio of the cast shadow on the floor."""
CLOTHES = np.array(
    [
        [0, 0, 0],  # 0: background (unused)
        [120, 150, 200],  # 1: skin
        [60, 50, 170],  # 2: red shirt
        [90, 118, 143],  # 3: trousers: the wall -15 blue +15 red (chromaticity 0.04 off)
        [40, 40, 45],  # 4: black shoes
    ],
    np.float32,
)


def _wall(rng: np.random.Generator) -> np.ndarray:
    """The empty stage (H, W, 3) float32 BGR: the wall colour with a 15 % luminance
    texture, a little colour texture and diagonal stripes of +-10 levels."""

    def smooth(channels: int, std: float) -> np.ndarray:
        field = cv2.GaussianBlur(rng.normal(0, 1, (HEIGHT, WIDTH, channels)), (0, 0), 6)
        return field.reshape(HEIGHT, WIDTH, channels) * (std / field.std())

    yy, xx = np.mgrid[:HEIGHT, :WIDTH]
    stripes = 10 * np.sign(np.sin(xx / 6.0 + yy / 11.0))[..., None]
    return (WALL * (1 + smooth(1, 0.15)) + smooth(3, 4.0) + stripes).astype(np.float32)


def _person() -> np.ndarray:
    """Labels (H, W) uint8 of the person: 0 none, else the row of `CLOTHES`."""
    labels = np.zeros((HEIGHT, WIDTH), np.uint8)
    cv2.line(labels, (150, 140), (138, 222), 3, 16)
    cv2.line(labels, (170, 140), (182, 222), 3, 16)
    cv2.ellipse(labels, (160, 100), (27, 48), 0, 0, 360, 2, -1)
    cv2.line(labels, (138, 66), (92, 128), 2, 11)
    cv2.line(labels, (182, 66), (236, 100), 2, 11)
    cv2.circle(labels, (92, 130), 6, 1, -1)
    cv2.circle(labels, (238, 101), 6, 1, -1)
    cv2.circle(labels, (160, 38), 15, 1, -1)
    cv2.rectangle(labels, (154, 48), (166, 56), 1, -1)
    for foot in ((136, 226), (184, 226)):
        cv2.ellipse(labels, foot, (10, 5), 0, 0, 360, 4, -1)
    return labels


def _film(
    wall: np.ndarray,
    labels: np.ndarray,
    rng: np.random.Generator,
    gain: float = 1.0,
    shadow: bool = False,
) -> np.ndarray:
    """One frame (H, W, 3) uint8 BGR: the wall, the cast shadow beside the right foot,
    the person, all times `gain`, plus sensor noise."""
    image = wall.copy()
    if shadow:
        cast = np.zeros((HEIGHT, WIDTH), np.uint8)
        cv2.ellipse(cast, (218, 226), (45, 10), 0, 0, 360, 1, -1)
        image[cast > 0] *= SHADOW
    person = labels > 0
    image[person] = CLOTHES[labels[person]]
    image = image * gain + rng.normal(0, NOISE, image.shape)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


@pytest.fixture(scope="module")
def stage() -> tuple[np.ndarray, np.ndarray, np.random.Generator]:
    """(the wall, 20 empty-stage frames (20, H, W, 3) uint8, a random generator)."""
    rng = np.random.default_rng(3)
    wall = _wall(rng)
    empty = np.zeros((HEIGHT, WIDTH), np.uint8)
    return wall, np.stack([_film(wall, empty, rng) for _ in range(20)]), rng


@pytest.mark.parametrize("gain", [1.0, 0.8, 1.25])
def test_colour_background_finds_the_person_under_a_new_brightness_with_a_shadow(
    stage: tuple[np.ndarray, np.ndarray, np.random.Generator], gain: float
) -> None:
    wall, empty, rng = stage
    labels = _person()
    truth = labels > 0
    frame = _film(wall, labels, rng, gain=gain, shadow=True)
    scores = {
        method: _iou(SilhouetteExtractor.learn(empty, method).silhouette(frame), truth)
        for method in BACKGROUND_METHODS
    }
    print(f"gain {gain}: IoU", {m: round(s, 3) for m, s in scores.items()})
    assert scores["colour"] >= 0.95


def test_shadow_and_brightness_change_alone_are_background(
    stage: tuple[np.ndarray, np.ndarray, np.random.Generator],
) -> None:
    wall, empty, rng = stage
    model = ColourBackground.learn(empty)
    nobody = np.zeros((HEIGHT, WIDTH), np.uint8)
    for gain in (0.7, 1.0, 1.3):
        raw = model.foreground(_film(wall, nobody, rng, gain=gain, shadow=True))
        assert raw.mean() < 0.002, gain
        assert clean_silhouette(raw).sum() == 0, gain


def test_adaptation_follows_a_slow_change_of_the_background(
    stage: tuple[np.ndarray, np.ndarray, np.random.Generator],
) -> None:
    """Sunlight warming a patch of wall by half a level of red per frame: after 80
    frames (+40 levels) a frozen model sees the patch as foreground, an adapting one
    has followed it."""
    wall, empty, rng = stage
    patch = np.zeros((HEIGHT, WIDTH), bool)
    patch[20:100, 220:310] = True
    nobody = np.zeros((HEIGHT, WIDTH), np.uint8)
    adaptive = ColourBackground.learn(empty, learning_rate=0.1)
    frozen = ColourBackground.learn(empty)
    warmed = wall.copy()
    for _ in range(80):
        warmed[patch, 2] += 0.5
        frame = _film(warmed, nobody, rng)
        seen_adaptive, seen_frozen = adaptive.foreground(frame), frozen.foreground(frame)
    assert seen_frozen[patch].mean() > 0.9
    assert seen_adaptive.mean() < 0.002


def test_extractor_gives_the_same_silhouettes_for_an_array_and_an_iterator(
    stage: tuple[np.ndarray, np.ndarray, np.random.Generator],
) -> None:
    wall, empty, rng = stage
    frames = np.stack([_film(wall, _person(), rng, gain=0.9) for _ in range(3)])
    extractor = SilhouetteExtractor.learn(iter(list(empty)))
    from_array = list(extractor.silhouettes(frames))
    from_iterator = list(extractor.silhouettes(iter(list(frames))))
    assert len(from_array) == 3
    for a, b in zip(from_array, from_iterator, strict=True):
        assert a.shape == (HEIGHT, WIDTH) and a.dtype == bool
        assert np.array_equal(a, b)


def test_clean_silhouette_keeps_the_largest_shape_without_specks_or_holes() -> None:
    mask = np.zeros((HEIGHT, WIDTH), bool)
    mask[50:200, 100:160] = True  # the person
    mask[100:110, 120:130] = False  # a hole inside
    mask[10:30, 10:30] = True  # a smaller object
    mask[150, 250] = mask[5, 300] = True  # specks of noise
    mask[60:180:2, 160] = True  # a speckled edge, bridged by the closing
    expected = np.zeros((HEIGHT, WIDTH), bool)
    expected[50:200, 100:160] = True
    cleaned = clean_silhouette(mask)
    assert cleaned.dtype == bool and cleaned.shape == mask.shape
    assert (cleaned != expected).sum() <= 2 * 120  # at most the bridged column
    assert cleaned[100:110, 120:130].all()
    assert not cleaned[10:30, 10:30].any() and not cleaned[150, 250]
    assert not clean_silhouette(np.zeros((HEIGHT, WIDTH), bool)).any()


def test_bad_inputs_raise_typed_errors(
    stage: tuple[np.ndarray, np.ndarray, np.random.Generator],
) -> None:
    _, empty, _ = stage
    model = ColourBackground.learn(empty)
    cases = {
        "background frames": lambda: ColourBackground.learn(empty[: MIN_BACKGROUND_FRAMES - 1]),
        "background frames ": lambda: OpenCVBackground.learn(empty[:2], "knn"),
        "background frames[0]": lambda: ColourBackground.learn(empty.astype(np.float32)),
        "background frames[1]": lambda: ColourBackground.learn([empty[0], empty[1, :100]]),
        "background frames  ": lambda: ColourBackground.learn(empty[..., 0]),
        "frame": lambda: model.foreground(empty[0, :, :200]),
        "frame ": lambda: model.foreground(empty[0, :, :, :2]),
        "frames[1]": lambda: list(SilhouetteExtractor(model).silhouettes([empty[0], None])),
        "frames[0]": lambda: next(SilhouetteExtractor(model).silhouettes(empty[:, :120])),
        "method": lambda: learn_background(empty, "median"),
        "threshold": lambda: ColourBackground.learn(empty, threshold=0.0),
        "learning_rate": lambda: learn_background(empty, "mog2", learning_rate=1.5),
        "mask": lambda: clean_silhouette(np.zeros((HEIGHT, WIDTH), np.uint8)),
        "close_px": lambda: clean_silhouette(np.zeros((HEIGHT, WIDTH), bool), close_px=-1),
    }
    for name, call in cases.items():
        with pytest.raises(InputError) as error:
            call()
        assert error.value.source == name.strip()


def test_the_tracking_extractor_keeps_the_gaps_the_shape_tree_has() -> None:
    # The shape tree's silhouettes are rendered, with the gaps between a walker's legs and
    # between the arms and the trunk. The tracker's extractor closes by one pixel of its
    # 320-wide view (2 px at 640 wide); a 3-view-pixel closing fills those gaps.
    camera = Camera.look_at("front", (0.0, 1.2, 3.6), (0.0, 0.9, 0.0), (320, 240), 55.0)
    walk = generate("walk", 4.0, 15.0, 2000).poses.astype(np.float64)
    stride = staged(walk, SilhouetteView(camera), 1.75, in_place=True)[6:7]
    rendered = render_silhouettes(stride, camera, BodyModel.for_subject(1.75))[0]
    tracked = clean_silhouette(rendered, tracking_close_px(320, 320))
    assert (tracked ^ rendered).sum() < 0.02 * rendered.sum()
    assert (clean_silhouette(rendered, 3) ^ rendered).sum() > 0.08 * rendered.sum()
    empty = np.random.default_rng(0).integers(90, 110, (5, 480, 640, 3)).astype(np.uint8)
    assert SilhouetteExtractor.for_tracking(empty, 320).close_px == 2
    assert [tracking_close_px(width, 320) for width in (160, 320, 1920)] == [1, 1, 6]
