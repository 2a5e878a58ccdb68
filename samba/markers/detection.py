"""Marker detection: bright retro-reflective blobs in one camera frame, at sub-pixel accuracy.

The paper's camera node (Section 5.4) thresholds a grey image, extracts blobs by connected
components and takes each blob's centre as a marker. `detect_markers` does the same for
frames from 160x120 to 1920x1080, grey or colour, uint8, uint16 or float:

1. grey: colour frames (H, W, 3), BGR as OpenCV reads them, go to grey by luma.
2. threshold: fixed, or automatic (`auto_threshold`): robust background level + 6 noise
   sigmas, both estimated from a strided sample of the frame. The frames are mostly dark
   background with a few small bright discs, so the background statistics are those of
   the whole frame and the markers are outliers: the threshold follows the sensor's
   noise and stays put as markers come and go. Otsu's method splits the histogram into
   two classes instead: with markers in view it moved from 51 to 114 grey levels between
   160x120 and 1920x1080 renders of the same scene (cutting into dim markers), and on a
   frame without markers it split the background noise into thousands of blobs.
3. connected components (8-connectivity, `cv2.connectedComponentsWithStats` with Grana's
   block-based algorithm, three times faster here than OpenCV's default choice), minus
   the pixels of `mask` (static bright spots, see `static_mask`).
4. filters: area in pixels, fill of the bounding box, and elongation (the square root of
   the ratio of the principal second moments; motion streaks and merged blobs are long).
5. centroids: intensity-weighted with weights (intensity - threshold), which fall to zero
   at the blob's edge so that the centroid moves continuously as pixels cross the
   threshold. Only the bounding boxes of the blobs are read, not the whole frame.

Pixel convention (OpenCV, as `samba.cameras.camera.Camera.project`): u to the right, v down,
pixel centres at integer coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from samba.base import InputError

BACKGROUND_SAMPLES = 1024
"""About how many pixels (a strided grid) estimate the background level and noise."""
MAD_TO_SIGMA = 1.4826
"""Median absolute deviation to standard deviation of a normal distribution."""
MERGED_AREA_RATIO = 1.5
"""A blob at least this many times the frame's median blob area is taken for two
markers merged (`Blobs.merged`). On synthetic takes at 160x120 and 320x240 single
markers' blobs stay below 1.4 and 1.27 times the median in 99% of cases, while two
merged markers' blobs reach 1.5 and 1.65 times it in 95%."""
MERGED_MIN_BLOBS = 3
"""`Blobs.merged` needs at least this many blobs for a median worth comparing with."""

_DTYPES = (np.uint8, np.uint16, np.float32, np.float64)


@dataclass(frozen=True, eq=False)
class Blobs:
    """The blobs found in one frame.

    `centroids` (m, 2) float64: intensity-weighted centres (u, v) in pixels (OpenCV
    convention); `areas` (m,) int64: pixels above the threshold; `peaks` (m,) float64:
    the brightest pixel of each blob, in the frame's intensity units; `threshold`: the
    intensity threshold used.
    """

    centroids: np.ndarray
    areas: np.ndarray
    peaks: np.ndarray
    threshold: float

    def __len__(self) -> int:
        return len(self.centroids)

    def merged(self, area_ratio: float | None = MERGED_AREA_RATIO) -> np.ndarray:
        """(m,) bool: the blobs at least `area_ratio` times the median blob area of the
        frame, probably two markers merged, whose centroid is neither's (None, or fewer
        than `MERGED_MIN_BLOBS` blobs: none). Markers of one size at about one depth
        make blobs of about one area."""
        if area_ratio is None or len(self) < MERGED_MIN_BLOBS:
            return np.zeros(len(self), dtype=bool)
        return self.areas >= area_ratio * np.median(self.areas)


def grey_frame(frame: np.ndarray, name: str = "frame") -> np.ndarray:
    """The frame (H, W) or (H, W, 3) BGR as a grey (H, W) array of its own dtype.

    float64 frames become float32. Raises `InputError` naming `name` for an empty frame,
    a shape other than (H, W) or (H, W, 3), or a dtype other than uint8, uint16, float32
    or float64.
    """
    if not isinstance(frame, np.ndarray):
        raise InputError(name, f"a frame must be a numpy array, got {type(frame).__name__}")
    if frame.dtype not in _DTYPES:
        raise InputError(
            name, f"frame dtype must be uint8, uint16, float32 or float64, got {frame.dtype}"
        )
    if frame.ndim not in (2, 3) or (frame.ndim == 3 and frame.shape[2] != 3):
        raise InputError(name, f"frame must be (H, W) grey or (H, W, 3) BGR, got {frame.shape}")
    if frame.shape[0] == 0 or frame.shape[1] == 0:
        raise InputError(name, f"frame is empty, shape {frame.shape}")
    if frame.dtype == np.float64:
        frame = frame.astype(np.float32)
    if frame.ndim == 3:
        frame = cv2.cvtColor(np.ascontiguousarray(frame), cv2.COLOR_BGR2GRAY)
    return frame


def auto_threshold(grey: np.ndarray, sigmas: float = 6.0, min_contrast: float = 0.0) -> float:
    """Background + max(`sigmas` x noise sigma, `min_contrast`) of a grey frame (H, W).

    Estimated on a strided grid of about `BACKGROUND_SAMPLES` pixels: the background level
    is their median; the noise sigma is the standard deviation of the samples within 5
    robust sigmas (1.4826 x the median absolute deviation, at least one intensity step
    for integer frames) of it, so that the few bright marker pixels do not count and the
    rounding of integer frames is not mistaken for no noise. Units are the frame's
    intensity units. A noise-free frame has sigma 0; `min_contrast` then keeps the
    threshold above the background.
    """
    stride = max(1, int(np.sqrt(grey.size / BACKGROUND_SAMPLES)))
    sample = grey[::stride, ::stride].astype(np.float32).ravel()
    middle = len(sample) // 2
    background = float(np.partition(sample, middle)[middle])
    deviation = np.abs(sample - background)
    step = 1.0 if np.issubdtype(grey.dtype, np.integer) else 0.0
    clip = 5.0 * max(MAD_TO_SIGMA * float(np.partition(deviation, middle)[middle]), step)
    inliers = deviation[deviation <= clip]
    sigma = float(np.sqrt(np.dot(inliers, inliers) / len(inliers)))
    return background + max(sigmas * sigma, min_contrast)


def detect_markers(
    frame: np.ndarray,
    threshold: float | Literal["auto"] = "auto",
    min_area: int = 1,
    max_area: int | None = None,
    max_elongation: float = 3.0,
    min_fill: float = 0.3,
    mask: np.ndarray | None = None,
    name: str = "frame",
) -> Blobs:
    """Bright blobs (markers) in a frame (H, W) or (H, W, 3) BGR, uint8/uint16/float.

    `threshold` is an intensity in the frame's units, or "auto" (`auto_threshold` with
    its defaults; at least one intensity step for integer frames). A blob is a set of
    8-connected pixels above the threshold, not in `mask` (bool (H, W), True = ignore;
    see `static_mask`), with `min_area` <= area <= `max_area` pixels (None: no upper
    limit), area / bounding-box area >= `min_fill`, and elongation (square root of the
    ratio of its principal second moments, a pixel counted as a unit square) at most
    `max_elongation`. Raises `InputError` naming `name` for a bad frame or mask.
    """
    grey = grey_frame(frame, name)
    height, width = grey.shape
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != (height, width) or mask.dtype != np.bool_:
            raise InputError(
                name,
                f"mask must be bool ({height}, {width}) like the frame, "
                f"got {mask.dtype} {mask.shape}",
            )
    if threshold == "auto":
        step = 1.0 if np.issubdtype(grey.dtype, np.integer) else 0.0
        level = auto_threshold(grey, min_contrast=step)
    elif isinstance(threshold, int | float) and np.isfinite(threshold):
        level = float(threshold)
    else:
        raise InputError(name, f"threshold must be a finite number or 'auto', got {threshold!r}")
    binary = _above(grey, level)
    if mask is not None:
        np.copyto(binary, 0, where=mask)
    _, labels, stats, _ = cv2.connectedComponentsWithStatsWithAlgorithm(
        binary, 8, cv2.CV_32S, cv2.CCL_GRANA
    )
    stats = stats[1:].astype(np.int64)  # (n, 5): x, y, w, h, area; label 0 is background
    area, box = stats[:, 4], stats[:, 2] * stats[:, 3]
    keep = (area >= min_area) & (area >= min_fill * box)
    if max_area is not None:
        keep &= area <= max_area
    ids = np.flatnonzero(keep)
    centroids, peaks, elongation = _weighted_moments(grey, labels, stats[ids], ids + 1, level)
    ok = elongation <= max_elongation
    return Blobs(centroids[ok], area[ids][ok], peaks[ok], level)


def static_mask(
    frames: np.ndarray,
    fraction: float = 0.8,
    threshold: float | Literal["auto"] = "auto",
    grow_px: int = 2,
) -> np.ndarray:
    """Pixels bright in most frames (static lights, reflections), to pass as `mask`.

    `frames` (F, H, W) or (F, H, W, 3), any dtype `detect_markers` takes. A pixel is in
    the mask when it is above the threshold (as in `detect_markers`) in at least
    `fraction` of the frames; the mask is then grown by `grow_px` pixels so that the dim
    rim of a static spot does not become a blob. Returns bool (H, W), True = ignore.
    """
    if not 0.0 < fraction <= 1.0:
        raise InputError("fraction", f"must be in (0, 1], got {fraction}")
    if not isinstance(frames, np.ndarray) or frames.ndim not in (3, 4) or len(frames) == 0:
        shape = getattr(frames, "shape", None)
        raise InputError("frames", f"must be a non-empty (F, H, W[, 3]) array, got {shape}")
    counts = np.zeros(frames.shape[1:3], dtype=np.int32)
    for i, frame in enumerate(frames):
        grey = grey_frame(frame, f"frames[{i}]")
        if threshold == "auto":
            step = 1.0 if np.issubdtype(grey.dtype, np.integer) else 0.0
            level = auto_threshold(grey, min_contrast=step)
        else:
            level = float(threshold)
        counts += _above(grey, level)
    bright = (counts >= fraction * len(frames)).astype(np.uint8)
    if grow_px > 0:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow_px + 1,) * 2)
        bright = cv2.dilate(bright, kernel)
    return bright.astype(bool)


def _above(grey: np.ndarray, level: float) -> np.ndarray:
    """uint8 (H, W): 1 where the grey frame is strictly above `level`, else 0."""
    if grey.dtype == np.uint16 or grey.dtype == np.uint8:
        # integer frames: "> level" is ">= floor(level) + 1"; cv2 compares with a clamped int
        _, binary = cv2.threshold(grey, np.floor(level), 1, cv2.THRESH_BINARY)
        return binary.astype(np.uint8, copy=False)
    return (grey > level).view(np.uint8)


def _weighted_moments(
    grey: np.ndarray, labels: np.ndarray, stats: np.ndarray, ids: np.ndarray, level: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Intensity-weighted centroids (n, 2), peaks (n,) and elongations (n,) of blobs.

    `stats` (n, 5) are the blobs' connected-component stats (x, y, w, h, area) and `ids`
    (n,) their labels in `labels` (H, W). All pixels of all bounding boxes are gathered
    into one flat batch (blob b owns a contiguous run), so the cost grows with the blob
    pixels, not the frame. Weights are intensity - `level`, zero outside the blob.
    """
    n = len(ids)
    if n == 0:
        return np.zeros((0, 2)), np.zeros(0), np.zeros(0)
    x0, y0, w, h = stats[:, 0], stats[:, 1], stats[:, 2], stats[:, 3]
    sizes = w * h
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    owner = np.repeat(np.arange(n), sizes)
    local = np.arange(sizes.sum()) - starts[owner]
    xs = x0[owner] + local % w[owner]
    ys = y0[owner] + local // w[owner]
    values = grey[ys, xs].astype(np.float64)
    inside = labels[ys, xs] == ids[owner]
    weights = np.where(inside, values - level, 0.0)
    total = np.bincount(owner, weights, n)
    # moments about each bounding box's corner keep the sums small and well conditioned
    dx, dy = (xs - x0[owner]).astype(np.float64), (ys - y0[owner]).astype(np.float64)
    mean_x = np.bincount(owner, weights * dx, n) / total
    mean_y = np.bincount(owner, weights * dy, n) / total
    var_x = np.bincount(owner, weights * dx * dx, n) / total - mean_x**2 + 1.0 / 12.0
    var_y = np.bincount(owner, weights * dy * dy, n) / total - mean_y**2 + 1.0 / 12.0
    cov = np.bincount(owner, weights * dx * dy, n) / total - mean_x * mean_y
    half_trace, det = (var_x + var_y) / 2.0, var_x * var_y - cov**2
    spread = np.sqrt(np.maximum(half_trace**2 - det, 0.0))
    elongation = np.sqrt((half_trace + spread) / np.maximum(half_trace - spread, 1e-12))
    peaks = np.maximum.reduceat(np.where(inside, values, -np.inf), starts)
    centroids = np.stack([x0 + mean_x, y0 + mean_y], axis=-1)
    return centroids, peaks, elongation
