"""Silhouettes from real video: background subtraction, clean-up, the person's shape.

Okada, Stenger and Kondoh (Section 2.2) extract the silhouette by colour background
subtraction: colour normalised by intensity, a Gaussian per pixel, foreground where the
Mahalanobis distance exceeds a threshold. `ColourBackground` is that model, made robust
to what a living room does to a background (brightness changes, shadows):

* features per pixel: chromaticity c = (R, G) / (R + G + B) and intensity
  I = (R + G + B) / 3, in 8-bit levels; mean and covariance of c and the mean and
  variance of I learnt from N empty-stage frames, with a noise floor of `min_noise`
  levels per channel (a static camera's noise can be underestimated from few frames);
* a global brightness change (auto exposure, a light switched on) is a gain g, the
  median over the frame of the brightness I / mean(I); the background is compared at
  that gain;
* a shadow is the background colour, darker: an intensity in [`shadow_ratio`, 1] x
  g mean(I) costs nothing;
* chromaticity is noisier in the dark (sensor noise is about constant in levels), so
  its covariance grows as 1 / brightness^2 for pixels darker than learnt (down to the
  darkest shadow), and the intensity variance as g^2 when the frame is brighter;
* foreground: the chromaticity Mahalanobis distance squared plus the squared distance
  of the intensity outside the shadow band, in intensity standard deviations, above
  `threshold` squared (3.5: a few dozen noise pixels per 320x240 frame, which the
  clean-up removes). Clothing of the background's colour and somewhat darker is taken
  for shadow; hole filling recovers it inside the silhouette.

`OpenCVBackground` wraps OpenCV's MOG2 or KNN subtractors (shadows detected and left
out) behind the same small interface (`BackgroundModel`); `learn_background` picks one
by name (`BACKGROUND_METHODS`). `clean_silhouette` closes and opens the raw foreground,
keeps the largest connected component and fills its holes; `SilhouetteExtractor` does
both over frames (n, H, W, 3) uint8 BGR (OpenCV's order) or any iterator of frames.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Protocol

import cv2
import numpy as np

from samba.base import InputError

BACKGROUND_METHODS: tuple[str, ...] = ("colour", "mog2", "knn")
"""Background models `learn_background` knows: the paper's normalised-colour Gaussian,
OpenCV's MOG2 and KNN subtractors."""

MIN_BACKGROUND_FRAMES = 5
"""Empty-stage frames needed at least to learn a background."""

TRACKING_CLOSE_VIEW_PX = 1
"""Closing radius of the silhouettes the single-camera tracker compares with its shape
tree, in pixels of the tracker's view (320 wide). The tree's silhouettes are rendered,
not cleaned: the gaps between an arm and the trunk and between the legs (2-5 view
pixels) are in them. A wider closing bridges those gaps and hole filling then fills
them, so a walking stride looks like legs together and an arm at the side like a
wider trunk (bench_silhouette's 42 takes and 42 others, mean over the seven motions: 3
view pixels scored 9.7 and 9.5 cm, 1 view pixel 7.7 and 8.3 cm)."""

GAIN_SAMPLES = 4096
"""About how many pixels (a strided grid) estimate a frame's global brightness gain."""


class BackgroundModel(Protocol):
    """A learnt background: `foreground(frame)` is the raw foreground (H, W) bool of a
    frame (H, W, 3) uint8 BGR of the learnt `size` (the model may adapt to the frame)."""

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the frames the model takes, pixels."""
        ...

    def foreground(self, frame: np.ndarray) -> np.ndarray:
        """Raw foreground (H, W) bool of one frame (H, W, 3) uint8 BGR."""
        ...


@dataclass(eq=False)
class ColourBackground:
    """The paper's background: a Gaussian per pixel over chromaticity and intensity.

    Arrays are float32 planes: `chroma_mean` (2, H, W) the mean chromaticity (r, g);
    `chroma_covariance` (3, H, W) its covariance entries (rr, gg, rg); `intensity_mean`
    and `intensity_variance` (H, W) in 8-bit levels and levels squared. `threshold` is
    the Mahalanobis distance above which a pixel is foreground, `shadow_ratio` the
    darkest intensity ratio still taken for shadow, `min_noise` the noise floor (levels
    per channel) and `learning_rate` the weight in [0, 1) of each frame's background
    pixels in the running mean and variance (0: the model stays as learnt).
    """

    chroma_mean: np.ndarray
    chroma_covariance: np.ndarray
    intensity_mean: np.ndarray
    intensity_variance: np.ndarray
    threshold: float = 3.5
    shadow_ratio: float = 0.5
    min_noise: float = 2.0
    learning_rate: float = 0.0
    _chroma_precision: np.ndarray = field(init=False, repr=False)
    """(3, H, W) float32: the inverse of the floored chromaticity covariance, (rr, gg, rg)."""
    _intensity_precision: np.ndarray = field(init=False, repr=False)
    """(H, W) float32: 1 / the floored intensity variance."""

    def __post_init__(self) -> None:
        self._refresh_precision()

    @classmethod
    def learn(
        cls,
        frames: np.ndarray | Iterable[np.ndarray],
        threshold: float = 3.5,
        shadow_ratio: float = 0.5,
        min_noise: float = 2.0,
        learning_rate: float = 0.0,
    ) -> ColourBackground:
        """The background of N >= `MIN_BACKGROUND_FRAMES` frames of the empty stage:
        an (N, H, W, 3) uint8 BGR array or an iterable of (H, W, 3) frames.

        Raises `InputError` for a frame of the wrong shape or dtype, too few frames or
        an option out of range (threshold > 0, shadow_ratio in (0, 1], min_noise > 0,
        learning_rate in [0, 1)).
        """
        _check_option("threshold", threshold, 0.0, np.inf, low_open=True)
        _check_option("shadow_ratio", shadow_ratio, 0.0, 1.0, low_open=True)
        _check_option("min_noise", min_noise, 0.0, np.inf, low_open=True)
        _check_option("learning_rate", learning_rate, 0.0, 1.0, high_open=True)
        count, sums, products = 0, 0.0, 0.0
        for frame in _checked_frames(frames, "background frames"):
            values = np.stack(_features(frame)).astype(np.float64)  # r, g, I
            sums = sums + values
            products = products + _pair_products(values)
            count += 1
        if count < MIN_BACKGROUND_FRAMES:
            raise InputError(
                "background frames",
                f"need at least {MIN_BACKGROUND_FRAMES} frames of the empty stage, got {count}",
            )
        mean = sums / count
        moments = products / count - _pair_products(mean)  # rr, gg, II, rg
        return cls(
            chroma_mean=mean[:2].astype(np.float32),
            chroma_covariance=moments[[0, 1, 3]].astype(np.float32),
            intensity_mean=mean[2].astype(np.float32),
            intensity_variance=moments[2].astype(np.float32),
            threshold=float(threshold),
            shadow_ratio=float(shadow_ratio),
            min_noise=float(min_noise),
            learning_rate=float(learning_rate),
        )

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the frames the model was learnt from, pixels."""
        height, width = self.intensity_mean.shape
        return width, height

    def foreground(self, frame: np.ndarray) -> np.ndarray:
        """Raw foreground (H, W) bool of a frame (H, W, 3) uint8 BGR; then, with a
        learning rate, the background pixels update the model."""
        frame = _check_frame(frame, "frame", self.size)
        r, g, intensity = _features(frame)
        brightness = intensity / np.maximum(self.intensity_mean, 1.0)
        gain = _global_gain(brightness)
        dimming = np.clip(brightness, self.shadow_ratio * min(gain, 1.0), 1.0)
        dr = r - self.chroma_mean[0]
        dg = g - self.chroma_mean[1]
        precision = self._chroma_precision
        chroma_distance = dimming**2 * (
            precision[0] * dr * dr + precision[1] * dg * dg + 2.0 * precision[2] * dr * dg
        )
        expected = gain * self.intensity_mean
        beyond_band = np.maximum(
            np.maximum(self.shadow_ratio * expected - intensity, intensity - expected), 0.0
        )
        intensity_distance = beyond_band**2 * self._intensity_precision / max(gain, 1.0) ** 2
        mask = chroma_distance + intensity_distance > self.threshold**2
        if self.learning_rate > 0:
            self._adapt(r, g, intensity, ~mask)
        return mask

    def _adapt(
        self, r: np.ndarray, g: np.ndarray, intensity: np.ndarray, background: np.ndarray
    ) -> None:
        """Move the mean and (co)variance towards this frame's features (H, W) at the
        `background` pixels (H, W) bool, by `learning_rate`."""
        rate = background * np.float32(self.learning_rate)
        dr = r - self.chroma_mean[0]
        dg = g - self.chroma_mean[1]
        di = intensity - self.intensity_mean
        self.chroma_mean[0] += rate * dr
        self.chroma_mean[1] += rate * dg
        for moment, spread in zip(self.chroma_covariance, (dr * dr, dg * dg, dr * dg), strict=True):
            moment += rate * (spread - moment)
        self.intensity_mean += rate * di
        self.intensity_variance += rate * (di * di - self.intensity_variance)
        self._refresh_precision()

    def _refresh_precision(self) -> None:
        """Recompute the inverse covariances from the statistics, with the noise floor:
        `min_noise` levels per channel, i.e. min_noise / (R + G + B) in chromaticity."""
        floor = (self.min_noise / np.maximum(3.0 * self.intensity_mean, 1.0)) ** 2
        rr = self.chroma_covariance[0] + floor
        gg = self.chroma_covariance[1] + floor
        rg = self.chroma_covariance[2]
        determinant = rr * gg - rg * rg
        self._chroma_precision = np.stack([gg, rr, -rg]) / determinant
        self._intensity_precision = 1.0 / np.maximum(self.intensity_variance, self.min_noise**2)


@dataclass(eq=False)
class OpenCVBackground:
    """OpenCV's MOG2 or KNN background subtractor, learnt from empty-stage frames.

    `method` is "mog2" or "knn"; `size` (width, height) the frames' size;
    `learning_rate` in [0, 1) how much each frame updates the model (0: frozen). Pixels
    the subtractor marks as shadow are background.
    """

    subtractor: cv2.BackgroundSubtractor
    method: str
    size: tuple[int, int]
    learning_rate: float = 0.0

    @classmethod
    def learn(
        cls,
        frames: np.ndarray | Iterable[np.ndarray],
        method: str = "mog2",
        learning_rate: float = 0.0,
    ) -> OpenCVBackground:
        """The subtractor fed N >= `MIN_BACKGROUND_FRAMES` frames of the empty stage
        ((N, H, W, 3) uint8 BGR or an iterable of frames), with a history of N frames
        and OpenCV's automatic learning rate.

        Raises `InputError` for an unknown method, a bad frame, too few frames or a
        learning rate outside [0, 1).
        """
        if method not in ("mog2", "knn"):
            raise InputError("method", f"must be 'mog2' or 'knn', got {method!r}")
        _check_option("learning_rate", learning_rate, 0.0, 1.0, high_open=True)
        checked = list(_checked_frames(frames, "background frames"))
        if len(checked) < MIN_BACKGROUND_FRAMES:
            raise InputError(
                "background frames",
                f"need at least {MIN_BACKGROUND_FRAMES} frames of the empty stage, "
                f"got {len(checked)}",
            )
        if method == "mog2":
            subtractor = cv2.createBackgroundSubtractorMOG2(
                history=len(checked), detectShadows=True
            )
        else:
            subtractor = cv2.createBackgroundSubtractorKNN(history=len(checked), detectShadows=True)
        for frame in checked:
            subtractor.apply(frame, learningRate=-1)  # OpenCV's own schedule
        height, width = checked[0].shape[:2]
        return cls(subtractor, method, (width, height), float(learning_rate))

    def foreground(self, frame: np.ndarray) -> np.ndarray:
        """Raw foreground (H, W) bool of a frame (H, W, 3) uint8 BGR; shadows excluded."""
        frame = _check_frame(frame, "frame", self.size)
        return self.subtractor.apply(frame, learningRate=self.learning_rate) == 255


def learn_background(
    frames: np.ndarray | Iterable[np.ndarray], method: str = "colour", learning_rate: float = 0.0
) -> BackgroundModel:
    """The background model `method` (one of `BACKGROUND_METHODS`) learnt from frames
    of the empty stage ((N, H, W, 3) uint8 BGR or an iterable), with its default
    options. Raises `InputError` for an unknown method or bad frames."""
    if method == "colour":
        return ColourBackground.learn(frames, learning_rate=learning_rate)
    if method in BACKGROUND_METHODS:
        return OpenCVBackground.learn(frames, method, learning_rate)
    raise InputError("method", f"must be one of {', '.join(BACKGROUND_METHODS)}, got {method!r}")


def clean_silhouette(mask: np.ndarray, close_px: int = 3, open_px: int = 1) -> np.ndarray:
    """The person (H, W) bool in a raw foreground mask (H, W) bool.

    Morphological closing with a disc of radius `close_px` pixels (bridges the gaps of
    clothing close to the background's colour, which comes out speckled), then opening
    with a disc of radius `open_px` (removes the specks of noise and thin bridges the
    closing made between them), the largest 8-connected component, and its holes
    filled (background not 4-connected to the image border). Closing first keeps a
    speckled limb that an opening would erode away. An empty mask stays empty. Raises
    `InputError` for a mask that is not 2-D bool or negative radii.
    """
    if not isinstance(mask, np.ndarray):
        raise InputError("mask", f"must be a numpy array, got {type(mask).__name__}")
    if mask.dtype != np.bool_ or mask.ndim != 2:
        raise InputError("mask", f"must be an (H, W) bool array, got {mask.dtype} {mask.shape}")
    for name, radius in (("close_px", close_px), ("open_px", open_px)):
        if not isinstance(radius, int | np.integer) or radius < 0:
            raise InputError(name, f"must be a non-negative integer, got {radius!r}")
    image = mask.astype(np.uint8)
    if close_px > 0:
        image = cv2.morphologyEx(image, cv2.MORPH_CLOSE, _disc(close_px))
    if open_px > 0:
        image = cv2.morphologyEx(image, cv2.MORPH_OPEN, _disc(open_px))
    count, labels, stats, _ = cv2.connectedComponentsWithStats(image, connectivity=8)
    if count < 2:
        return np.zeros(mask.shape, dtype=bool)
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    padded = np.pad((labels == largest).astype(np.uint8), 1)
    cv2.floodFill(padded, None, (0, 0), 2)  # the background reachable from the border
    return padded[1:-1, 1:-1] != 2


def tracking_close_px(frame_width: int, view_width: int) -> int:
    """The closing radius in pixels of a frame `frame_width` pixels wide whose silhouette
    the single-camera tracker will see at `view_width`: `TRACKING_CLOSE_VIEW_PX` view
    pixels, at least 1."""
    return max(1, round(TRACKING_CLOSE_VIEW_PX * frame_width / view_width))


@dataclass(eq=False)
class SilhouetteExtractor:
    """Silhouettes (H, W) bool of frames: `background` subtraction, then
    `clean_silhouette` with radii `close_px` and `open_px`."""

    background: BackgroundModel
    close_px: int = 3
    open_px: int = 1

    @classmethod
    def learn(
        cls,
        empty_frames: np.ndarray | Iterable[np.ndarray],
        method: str = "colour",
        learning_rate: float = 0.0,
        close_px: int = 3,
        open_px: int = 1,
    ) -> SilhouetteExtractor:
        """An extractor whose background (`learn_background`) is learnt from frames of
        the empty stage."""
        return cls(learn_background(empty_frames, method, learning_rate), close_px, open_px)

    @classmethod
    def for_tracking(
        cls,
        empty_frames: np.ndarray | Iterable[np.ndarray],
        view_width: int,
        method: str = "colour",
        learning_rate: float = 0.0,
    ) -> SilhouetteExtractor:
        """An extractor (`learn`) for the single-camera tracker whose view is `view_width`
        pixels wide: its closing radius is `tracking_close_px` of the frames' width."""
        return cls.tracking(learn_background(empty_frames, method, learning_rate), view_width)

    @classmethod
    def tracking(cls, background: BackgroundModel, view_width: int) -> SilhouetteExtractor:
        """An extractor over `background` (a learnt background, or a person segmenter) for
        the single-camera tracker whose view is `view_width` pixels wide: its closing
        radius is `tracking_close_px` of the frames' width."""
        return cls(background, tracking_close_px(background.size[0], view_width))

    def silhouette(self, frame: np.ndarray) -> np.ndarray:
        """The person's silhouette (H, W) bool in one frame (H, W, 3) uint8 BGR."""
        return clean_silhouette(self.background.foreground(frame), self.close_px, self.open_px)

    def silhouettes(self, frames: np.ndarray | Iterable[np.ndarray]) -> Iterator[np.ndarray]:
        """The silhouette (H, W) bool of each frame of an (n, H, W, 3) uint8 BGR array
        or an iterable of (H, W, 3) frames, lazily, in order. A bad frame raises
        `InputError` naming its index when it is reached."""
        for frame in _checked_frames(frames, "frames", self.background.size):
            yield self.silhouette(frame)


def _features(frame: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Chromaticity r = R / (R + G + B), g = G / (R + G + B) and intensity
    (R + G + B) / 3 in levels, each (H, W) float32, of a frame (H, W, 3) uint8 BGR;
    black has chromaticity (0, 0)."""
    blue, green, red = cv2.split(frame.astype(np.float32))
    total = blue + green + red
    safe = np.maximum(total, np.float32(1.0))
    return red / safe, green / safe, total / np.float32(3.0)


def _global_gain(brightness: np.ndarray) -> float:
    """A frame's global brightness gain: the median of its pixels' `brightness` (H, W)
    (intensity / the background's) over a strided grid of about `GAIN_SAMPLES` pixels,
    most of which see the background."""
    stride = max(1, int(np.sqrt(brightness.size / GAIN_SAMPLES)))
    return float(np.median(brightness[::stride, ::stride]))


def _pair_products(values: np.ndarray) -> np.ndarray:
    """Per-pixel products (4, H, W) rr, gg, II, rg of feature planes (3, H, W) (r, g, I)."""
    return np.concatenate([values**2, values[:1] * values[1:2]])


def _disc(radius: int) -> np.ndarray:
    """A disc-shaped structuring element of `radius` pixels."""
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def _checked_frames(
    frames: np.ndarray | Iterable[np.ndarray], name: str, size: tuple[int, int] | None = None
) -> Iterator[np.ndarray]:
    """The frames of an (n, H, W, 3) uint8 array or an iterable, each checked by
    `_check_frame` against `size` (width, height), by default the first frame's; `name`
    names them in errors."""
    if isinstance(frames, np.ndarray) and frames.ndim != 4:
        raise InputError(name, f"must be an (n, H, W, 3) uint8 array, got shape {frames.shape}")
    for i, frame in enumerate(frames):
        frame = _check_frame(frame, f"{name}[{i}]", size)
        size = (frame.shape[1], frame.shape[0])
        yield frame


def _check_frame(frame: np.ndarray, name: str, size: tuple[int, int] | None) -> np.ndarray:
    """`frame` if it is an (H, W, 3) uint8 array of `size` (width, height) when given;
    otherwise InputError naming `name`."""
    if not isinstance(frame, np.ndarray):
        raise InputError(name, f"must be a numpy array, got {type(frame).__name__}")
    if frame.dtype != np.uint8:
        raise InputError(name, f"must be a uint8 BGR image, got dtype {frame.dtype}")
    if frame.ndim != 3 or frame.shape[2] != 3 or 0 in frame.shape:
        raise InputError(name, f"must be an (H, W, 3) BGR image, got shape {frame.shape}")
    if size is not None and (frame.shape[1], frame.shape[0]) != tuple(size):
        raise InputError(
            name,
            f"is {frame.shape[1]}x{frame.shape[0]} but the background is {size[0]}x{size[1]}",
        )
    return frame


def _check_option(
    name: str,
    value: float,
    low: float,
    high: float,
    low_open: bool = False,
    high_open: bool = False,
) -> None:
    """InputError naming `name` unless `value` is a number in the interval low..high
    (bounds excluded where `low_open` / `high_open`)."""
    number = isinstance(value, int | float | np.number) and not isinstance(value, bool)
    inside = (
        number
        and (value > low if low_open else value >= low)
        and (value < high if high_open else value <= high)
    )
    if not inside:
        left, right = "(" if low_open else "[", ")" if high_open else "]"
        raise InputError(name, f"must be in {left}{low}, {high}{right}, got {value!r}")
