"""Silhouette distances: the likelihood of single-camera silhouette tracking.

Section 2.2 of Okada, Stenger and Kondoh compares the silhouette S_i observed in a frame
with model silhouettes S_m rendered for database poses by a weighted XOR over the image
window w (the whole normalised image, |w| = H * W pixels)::

    d(S_i, S_m) = 1 / |w| * sum_k |S_i(k) - S_m(k)| * d_hat(k)

with one of three per-pixel weight maps d_hat (`DISTANCES`):

* "xor" (Eq. 4): d_hat = 1, the fraction of pixels that differ.
* "core" (Eq. 5-6, Chen et al.): d_hat = D(S_i) + alpha * D(S_i bar), alpha = 5. D(S_i)
  is zero inside the observed silhouette and grows with the distance (pixels) from it
  outside; D(S_i bar) is zero outside and grows towards the core inside. A model that
  fails to cover the core of the torso costs far more than one that misses a limb.
* "normalised" (Eq. 7, the paper's): d_hat = D(S_i) + alpha~ * D(S_i bar) /
  (D(S_i bar) + D(S_skl)), with S_skl the shape skeleton (`shape_skeleton`): inside the
  silhouette the weight rises from the contour to alpha~ on the skeleton of every body
  part, thin limbs and thick torso alike.

Distance transforms are Euclidean (cv2.distanceTransform, L2, precise mask) in pixels
of the image given; pixels beyond the image border count as neither inside nor outside,
so a silhouette cut by the border has no contour there. D(S_skl) uses OpenCV's 5x5
approximation (within 2 % of the exact distance, four times faster).

The weights depend on the observed silhouette only, so `SilhouetteWeights.from_mask`
computes them once per frame and each distance is linear in the model silhouette::

    sum_k |S_i - S_m| d_hat = sum_k S_i d_hat + sum_k S_m d_hat (1 - 2 S_i)

a constant plus one sparse matrix-vector product for thousands of model silhouettes at
once, stored as the rows of a `silhouette_matrix`. `downsampled` makes the image pyramid
of the paper (80x60, 160x120, 320x240 for a 3-level tree). The XOR distance is a
fraction of the image and the same at every level; the core and normalised distances
are in pixels and grow about in proportion to the image width (0.11, 0.21, 0.38 for an
arm 30 degrees off at 80, 160 and 320 pixels wide), so the likelihood's sigma (Eq. 3)
is per level.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import sparse

from samba.base import InputError

DISTANCES: tuple[str, ...] = ("xor", "core", "normalised")
"""The silhouette distances: plain XOR (Eq. 4), core-weighted XOR (Eq. 5-6) and the
normalised core-weighted XOR (Eq. 7)."""

CORE_ALPHA = 5.0
"""Chen et al.'s alpha of the core-weighted XOR (Eq. 6)."""

SKELETON_WEIGHT_320 = 25.0
"""Default alpha~ of the normalised distance (Eq. 7) for an image 320 pixels wide.

The paper does not give alpha~. At 320x240 a 1.7 m subject filling most of the image
height is about 110 px/m tall, so an arm (8-10 cm across) is about 10 px wide and its
skeleton lies 5 px from the contour, where the core weight is CORE_ALPHA * 5 = 25. With
alpha~ = 25 a skeleton pixel of any body part weighs what the core weight gives an
arm's skeleton; the torso's core, heavier under "core", is brought down to that.
"""

REFERENCE_WIDTH = 320
"""Image width (pixels) `SKELETON_WEIGHT_320` is meant for; the default alpha~ scales
with the image width so that every pyramid level keeps the balance of the outside term
D(S_i), in pixels, and the inside term, which is scale-free."""

RIDGE_BAND_PX = 1.0
"""Pixels with D(S_i bar) at most this far from the contour are never skeleton (the
contour's own staircase has spurious ridges)."""

RIDGE_DROP = 0.5
"""How much D(S_i bar) must fall, per unit of length, two pixels to either side of a
skeleton pixel along the direction in which it is a ridge (a true ridge falls by about
1 per unit of length on both sides; the digital contour's bumps hardly fall)."""

MATRIX_CHUNK = 1024
"""Silhouettes converted at once by `silhouette_matrix` (bounds its temporary memory)."""

DENSE_CHUNK_PIXELS = 1 << 21
"""Pixels of dense model silhouettes converted to float64 at once by
`SilhouetteWeights.distances` (16 MB)."""

_DIRECTIONS = ((0, 1), (1, 0), (1, 1), (1, -1))
"""Pixel steps (dy, dx) along which `shape_skeleton` looks for ridges."""


def shape_skeleton(mask: np.ndarray) -> np.ndarray:
    """The shape skeleton S_skl (H, W) bool of a silhouette (H, W) bool: the ridge of
    D(S_i bar), the distance (pixels) of each inside pixel to the contour.

    A pixel is on the ridge when, along at least one of the horizontal, vertical and two
    diagonal directions, D(S_i bar) there is at least its two neighbours' and at least
    `RIDGE_DROP` x the step length above the pixels two steps away on both sides, and it
    lies more than `RIDGE_BAND_PX` inside the contour. Limbs 3 px wide or more get a
    skeleton; even widths give a 2-pixel-wide ridge. A silhouette whose ridge test finds
    nothing (a blob at most 2 px thick) gets its deepest pixels as skeleton.
    """
    _check_mask(mask, "mask")
    box = _bounding_box(mask)
    skeleton = np.zeros(mask.shape, dtype=bool)
    skeleton[box] = _ridge(_distance_to(~mask[box]))
    return skeleton


@dataclass(frozen=True, eq=False)
class SilhouetteWeights:
    """The observed silhouette of one frame, ready to be compared with model silhouettes.

    `kind` is one of `DISTANCES` and `alpha` the weight of its inside term (0 for
    "xor"). `weights` (H, W) float32 is the per-pixel weight map d_hat; `constant` is
    sum_k S_i(k) d_hat(k) and `coefficients` (H * W,) float32 is d_hat (1 - 2 S_i),
    flattened row-major, so that a model silhouette S_m's distance is
    (constant + S_m . coefficients) / (H * W).
    """

    kind: str
    alpha: float
    weights: np.ndarray
    constant: float
    coefficients: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the silhouettes this frame compares, pixels."""
        return self.weights.shape

    @classmethod
    def from_mask(
        cls, mask: np.ndarray, kind: str = "normalised", alpha: float | None = None
    ) -> SilhouetteWeights:
        """The weights of an observed silhouette `mask` (H, W) bool, True = foreground.

        `kind` picks the distance (`DISTANCES`); `alpha` is the core weight (default
        `CORE_ALPHA`) for "core", alpha~ for "normalised" (default
        `SKELETON_WEIGHT_320` x W / `REFERENCE_WIDTH`: the weight of a skeleton pixel)
        and must be None for "xor". Raises `InputError` for a mask that is not a 2-D
        bool array, holds no foreground or no background, an unknown kind or a bad
        alpha.
        """
        _check_mask(mask, "mask")
        _check_kind(kind)
        if kind == "xor" and alpha is not None:
            raise InputError("alpha", "the xor distance has no alpha")
        alpha = 0.0 if kind == "xor" else _check_alpha(alpha, kind, mask.shape[1])
        weights = _weight_map(mask, kind, alpha)
        flat = weights.ravel()
        observed = mask.ravel()
        coefficients = np.where(observed, -flat, flat)
        constant = float(flat[observed].sum(dtype=np.float64))
        return cls(kind, float(alpha), weights, constant, coefficients)

    def distances(self, models: np.ndarray | sparse.sparray | sparse.spmatrix) -> np.ndarray:
        """Distances (n,) float64 from the observed silhouette to n model silhouettes.

        `models` is a dense (n, H, W) bool array or a scipy sparse array (n, H * W)
        whose rows are flattened silhouettes with 1 at foreground pixels (a
        `silhouette_matrix`). Dense silhouettes and float64 sparse ones are summed in
        float64. A float32 sparse matrix (the fast path: one float32 sparse
        matrix-vector product) is summed in float32, whose rounding leaves an absolute
        error of about 2e-5 x `constant` / (H * W), e.g. 1e-4 for a core-weighted
        320x240 silhouette whose one-pixel shift costs 0.04. Raises `InputError` when
        the shape does not match the observed silhouette's.
        """
        height, width = self.shape
        if sparse.issparse(models):
            if models.ndim != 2 or models.shape[1] != height * width:
                raise InputError(
                    "models",
                    f"sparse silhouettes must be (n, {height * width}) for {width}x{height} "
                    f"images, got {models.shape}",
                )
            float32 = models.dtype == np.float32
            vector = self.coefficients if float32 else self.coefficients.astype(np.float64)
            covered = np.asarray(models @ vector, dtype=np.float64)
        else:
            _check_masks(models, "models")
            if models.shape[1:] != (height, width):
                raise InputError(
                    "models",
                    f"silhouettes must be (n, {height}, {width}) like the observed one, "
                    f"got {models.shape}",
                )
            flat = models.reshape(len(models), -1)
            rows = max(1, DENSE_CHUNK_PIXELS // flat.shape[1])
            vector = self.coefficients.astype(np.float64)
            covered = np.concatenate(
                [
                    flat[first : first + rows].astype(np.float64) @ vector
                    for first in range(0, len(flat), rows)
                ]
                or [np.zeros(0)]
            )
        return (self.constant + covered) / (height * width)


def silhouette_matrix(masks: np.ndarray) -> sparse.csr_array:
    """Silhouettes (n, H, W) bool as a CSR array (n, H * W) float32: row i holds 1 at the
    row-major flat index of each foreground pixel of silhouette i.

    Indices are int32 unless the total foreground exceeds 2**31 - 1 pixels. Raises
    `InputError` for anything but a 3-D bool array.
    """
    _check_masks(masks, "masks")
    count = len(masks)
    flat = masks.reshape(count, -1)
    pixels = flat.shape[1]
    pointers = np.zeros(count + 1, dtype=np.int64)
    np.cumsum(np.count_nonzero(flat, axis=1), out=pointers[1:])
    index_type = np.int32 if pointers[-1] <= np.iinfo(np.int32).max else np.int64
    indices = np.empty(pointers[-1], dtype=index_type)
    for first in range(0, count, MATRIX_CHUNK):
        last = min(first + MATRIX_CHUNK, count)
        indices[pointers[first] : pointers[last]] = np.flatnonzero(flat[first:last]) % pixels
    data = np.ones(len(indices), dtype=np.float32)
    return sparse.csr_array(
        (data, indices, pointers.astype(index_type)), shape=flat.shape, copy=False
    )


def downsampled(masks: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Silhouettes (n, H, W) or one (H, W), bool, resampled to `size` (width, height).

    Each output pixel is the area average of the input pixels it covers
    (cv2.INTER_AREA) thresholded at 0.5: foreground when at least half of its area is.
    The result has the input's rank. Raises `InputError` for a non-bool mask or a size
    that is not two positive integers at most the input's.
    """
    masks = np.asarray(masks)
    single = masks.ndim == 2
    stack = masks[None] if single else masks
    _check_masks(stack, "masks")
    try:
        width, height = (int(s) for s in size)
    except (TypeError, ValueError):
        raise InputError("size", f"must be (width, height), got {size!r}") from None
    if not (0 < width <= stack.shape[2] and 0 < height <= stack.shape[1]):
        raise InputError(
            "size",
            f"{width}x{height} is not a positive size at most the masks' "
            f"{stack.shape[2]}x{stack.shape[1]}",
        )
    out = np.empty((len(stack), height, width), dtype=bool)
    for i, mask in enumerate(stack):
        area = cv2.resize(mask.astype(np.float32), (width, height), interpolation=cv2.INTER_AREA)
        np.greater_equal(area, 0.5, out=out[i])
    return out[0] if single else out


def model_weighted_distances(
    models: np.ndarray, observed: np.ndarray, kind: str = "core"
) -> np.ndarray:
    """Distances (n,) of an observed silhouette `observed` (H, W) bool to model
    silhouettes `models` (n, H, W) bool, each weighted by the model's own weight map of
    distance `kind` (`DISTANCES`, default alpha): the model's side of a symmetric
    distance, equal to `SilhouetteWeights.from_mask(model, kind).distances(observed)`.

    Each model's weights are computed on the bounding box of it and the observed
    silhouette only (the XOR lies inside it, and distances to the model's pixels or to
    its background are the same there as over the whole image). Raises `InputError` for
    masks that are not bool, of different sizes, or an empty model.
    """
    _check_mask(observed, "observed")
    _check_masks(models, "models")
    if models.shape[1:] != observed.shape:
        raise InputError("models", f"must be (n, {observed.shape[0]}, {observed.shape[1]})")
    _check_kind(kind)
    height, width = observed.shape
    alpha = 0.0 if kind == "xor" else _check_alpha(None, kind, width)
    out = np.empty(len(models))
    for i, model in enumerate(models):
        if not model.any():
            raise InputError("models", f"silhouette {i} is empty")
        box = _bounding_box(model | observed)
        crop = model[box]
        weights = _weight_map(crop, kind, alpha)
        out[i] = weights[crop ^ observed[box]].sum(dtype=np.float64)
    return out / (height * width)


def _weight_map(mask: np.ndarray, kind: str, alpha: float) -> np.ndarray:
    """d_hat (H, W) float32 of the distance `kind` for an observed silhouette (H, W) bool,
    with `alpha` the weight of the inside term.

    The outside term D(S_i) covers the image; the inside term is zero outside the
    silhouette, so it is computed on the silhouette's bounding box only.
    """
    if kind == "xor":
        return np.ones(mask.shape, dtype=np.float32)
    weights = _distance_to(mask)
    box = _bounding_box(mask)
    inside = _distance_to(~mask[box])
    if kind == "normalised":
        to_skeleton = _distance_to(_ridge(inside), cv2.DIST_MASK_5)
        to_skeleton += inside
        inside = np.divide(inside, to_skeleton, out=np.zeros_like(inside), where=inside > 0)
    inside *= np.float32(alpha)
    weights[box] += inside
    return weights


def _bounding_box(mask: np.ndarray) -> tuple[slice, slice]:
    """Row and column slices of the bounding box of a non-empty `mask` (H, W) bool, grown
    by one pixel (within the image) so that it holds the background around the shape:
    distances to that background, and to the image border beyond, are those of the whole
    image."""
    rows = np.flatnonzero(mask.any(axis=1))
    columns = np.flatnonzero(mask.any(axis=0))
    return (
        slice(max(rows[0] - 1, 0), rows[-1] + 2),
        slice(max(columns[0] - 1, 0), columns[-1] + 2),
    )


def _distance_to(pixels: np.ndarray, mask_size: int = cv2.DIST_MASK_PRECISE) -> np.ndarray:
    """Euclidean distance (H, W) float32, in pixels, of every pixel to the nearest True
    pixel of `pixels` (H, W) bool; zero on them. Pixels beyond the image border are
    never nearest."""
    distance = cv2.distanceTransform((~pixels).astype(np.uint8), cv2.DIST_L2, mask_size)
    # OpenCV's precise transform varies in the last bits from call to call; rounded, a
    # silhouette always gets the same skeleton and weights.
    return np.round(distance, 4)


def _ridge(depth: np.ndarray) -> np.ndarray:
    """The ridge (H, W) bool of an inside distance map `depth` (H, W); see `shape_skeleton`.

    The map is padded by repeating its border, so the image border makes no ridge.
    """
    height, width = depth.shape
    padded = np.pad(depth, 2, mode="edge")

    def shifted(dy: int, dx: int) -> np.ndarray:
        return padded[2 + dy : 2 + dy + height, 2 + dx : 2 + dx + width]

    ridge = np.zeros(depth.shape, dtype=bool)
    for dy, dx in _DIRECTIONS:
        lowered = depth - np.float32(RIDGE_DROP * np.hypot(dy, dx))
        ridge |= (
            (shifted(dy, dx) <= depth)
            & (shifted(-dy, -dx) <= depth)
            & (shifted(2 * dy, 2 * dx) <= lowered)
            & (shifted(-2 * dy, -2 * dx) <= lowered)
        )
    ridge &= depth > RIDGE_BAND_PX
    if not ridge.any():
        ridge = depth == depth.max()
    return ridge


def _check_alpha(alpha: float | None, kind: str, width: int) -> float:
    """The inside-term weight of `kind` ("core" or "normalised"): `alpha` or its default
    for an image `width` pixels wide; InputError unless positive and finite."""
    if alpha is None:
        return CORE_ALPHA if kind == "core" else SKELETON_WEIGHT_320 * width / REFERENCE_WIDTH
    if not isinstance(alpha, int | float | np.floating) or not (0 < alpha < np.inf):
        raise InputError("alpha", f"must be a positive finite number, got {alpha!r}")
    return float(alpha)


def _check_kind(kind: str) -> None:
    """InputError unless `kind` is one of `DISTANCES`."""
    if kind not in DISTANCES:
        raise InputError("kind", f"must be one of {', '.join(DISTANCES)}, got {kind!r}")


def _check_mask(mask: np.ndarray, name: str) -> None:
    """InputError naming `name` unless `mask` is an (H, W) bool array with both
    foreground and background pixels."""
    if not isinstance(mask, np.ndarray) or mask.dtype != np.bool_ or mask.ndim != 2:
        raise InputError(name, f"must be an (H, W) bool array, got {_describe(mask)}")
    if not mask.any():
        raise InputError(name, "silhouette is empty: no foreground pixel")
    if mask.all():
        raise InputError(name, "silhouette covers the whole image: no background pixel")


def _check_masks(masks: np.ndarray, name: str) -> None:
    """InputError naming `name` unless `masks` is an (n, H, W) bool array, H, W > 0."""
    if (
        not isinstance(masks, np.ndarray)
        or masks.dtype != np.bool_
        or masks.ndim != 3
        or 0 in masks.shape[1:]
    ):
        raise InputError(name, f"must be an (n, H, W) bool array, got {_describe(masks)}")


def _describe(value: object) -> str:
    """'dtype (shape)' of an array, else the type's name, for error messages."""
    if isinstance(value, np.ndarray):
        return f"{value.dtype} {value.shape}"
    return type(value).__name__
