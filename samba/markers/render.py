"""The synthetic camera rig: what each camera of a capture would film of the 8 markers.

From poses (F, 13, 3) in meters and calibrated cameras, `render_camera` draws each frame
as a real marker camera sees it: a dark background with sensor noise and bright discs
where the markers are. A disc's radius is the marker's (2-3 cm across) at its depth; its
profile is a disc blurred by a Gaussian point-spread function of `psf_sigma_px` (the
lens blur), ``I(d) = level * erfc((d - r) / (sqrt(2) sigma)) / 2`` at distance d from
the centre, evaluated at pixel centres; a marker much smaller than a pixel (160x120 at
4 m) becomes a dimmer spot of about 3x3 pixels. Optional: motion blur (the disc swept
over the exposure), static bright spots (lamps, reflections), dropped frames.

Occlusion by the body: capsules (segments with a radius) around the eight limb bones,
the spine (hip midpoint to shoulder midpoint) and the neck (shoulder midpoint to the
head joint) stand in for the body. A marker is hidden from a camera when the segment
from the camera centre to the marker passes through a capsule; capsules that contain the
marker itself (its own limb, whose surface it sits on) do not hide it.

Ground truth comes with the frames: each marker's projected centre (OpenCV pixel
convention, as `Camera.project`) and whether the camera sees it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.special import erfc

from samba.body import BONES, MARKER_JOINTS, N_JOINTS, pose_batch, segment_distances
from samba.cameras import Camera

CHUNK_FRAMES = 32
"""Frames rendered at once in float32 before conversion to uint8 (bounds the memory)."""


@dataclass(frozen=True)
class BodyCapsules:
    """Radii in meters of the capsules that approximate the body for occlusion."""

    upper_arm: float = 0.05
    forearm: float = 0.04
    thigh: float = 0.075
    shin: float = 0.05
    spine: float = 0.12
    neck: float = 0.08

    def axes(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Capsule axis starts (F, K, 3), ends (F, K, 3) in meters and radii (K,).

        K = 10: the eight `BONES` in order, then the spine and the neck.
        """
        starts, ends = _capsule_endpoints()
        limb = (self.upper_arm, self.forearm) * 2 + (self.thigh, self.shin) * 2
        radii = np.array([*limb, self.spine, self.neck])
        return (
            np.einsum("kj,fjd->fkd", starts, poses),
            np.einsum("kj,fjd->fkd", ends, poses),
            radii,
        )


@dataclass(frozen=True)
class RenderOptions:
    """How the synthetic cameras film the markers.

    Intensities are 8-bit grey levels. `marker_diameter` in meters; `psf_sigma_px` the
    Gaussian lens blur in pixels (raise it for defocus blur); `motion_blur` the fraction
    of the frame interval the shutter is open (0 = frozen motion), sampled at
    `blur_samples` instants centred on the frame time; `drop_rate` the probability that
    a camera delivers no frame (an all-zero image, flagged in `CameraRender.dropped`);
    `static_spots` fixed bright spots at (u, v) as fractions of the image width and
    height, of radius `static_spot_radius` x the image width; `occlusion` switches the
    body capsules on.
    """

    marker_diameter: float = 0.025
    psf_sigma_px: float = 0.6
    background: float = 12.0
    noise_sigma: float = 2.0
    marker_level: float = 230.0
    motion_blur: float = 0.0
    blur_samples: int = 5
    drop_rate: float = 0.0
    static_spots: tuple[tuple[float, float], ...] = ()
    static_spot_radius: float = 0.01
    occlusion: bool = True
    capsules: BodyCapsules = field(default_factory=BodyCapsules)

    def __post_init__(self) -> None:
        if not self.marker_diameter > 0 or not self.psf_sigma_px > 0:
            raise ValueError("marker_diameter and psf_sigma_px must be positive")
        if not self.noise_sigma >= 0 or not 0 <= self.motion_blur <= 1:
            raise ValueError("noise_sigma must be >= 0 and motion_blur in [0, 1]")
        if not 0 <= self.drop_rate < 1 or self.blur_samples < 1:
            raise ValueError("drop_rate must be in [0, 1) and blur_samples >= 1")


@dataclass(frozen=True, eq=False)
class MarkerViews:
    """The 8 markers of F frames as one camera sees them.

    `pixels` (F, 8, 2): projected centres (u, v) in pixels, NaN behind the camera;
    `radii` (F, 8): disc radii in pixels; `visible` (F, 8) bool: in front of the camera,
    inside the image and not hidden by the body.
    """

    pixels: np.ndarray
    radii: np.ndarray
    visible: np.ndarray


@dataclass(frozen=True, eq=False)
class CameraRender:
    """One camera's rendered take: `frames` (F, H, W) uint8 grey; the truth `pixels`
    (F, 8, 2) of the markers' centres; `visible` (F, 8) bool, False where hidden, out of
    the image or in a dropped frame; `dropped` (F,) bool frames the camera did not deliver.
    """

    camera: Camera
    frames: np.ndarray
    pixels: np.ndarray
    visible: np.ndarray
    dropped: np.ndarray


def hidden_by_body(poses: np.ndarray, camera: Camera, capsules: BodyCapsules) -> np.ndarray:
    """Whether the body hides each marker of poses (F, 13, 3) from `camera`: bool (F, 8).

    A marker is hidden when the segment from the camera centre to it comes closer than a
    capsule's radius to that capsule's axis, for a capsule that does not contain the
    marker (a marker inside a capsule sits on that body part's surface).
    """
    poses = pose_batch(poses)
    starts, ends, radii = capsules.axes(poses)
    markers = poses[:, MARKER_JOINTS]  # (F, 8, 3)
    centre = np.broadcast_to(camera.center, markers.shape)
    ray_to_axis = segment_distances(
        centre[:, :, None], markers[:, :, None], starts[:, None], ends[:, None]
    )  # (F, 8, K)
    marker_to_axis = segment_distances(
        markers[:, :, None], markers[:, :, None], starts[:, None], ends[:, None]
    )
    return ((ray_to_axis < radii) & (marker_to_axis >= radii)).any(axis=-1)


def marker_views(poses: np.ndarray, camera: Camera, options: RenderOptions) -> MarkerViews:
    """Projected centres, disc radii and visibility of the markers of poses (F, 13, 3)."""
    poses = pose_batch(poses)
    markers = poses[:, MARKER_JOINTS]
    pixels = camera.project(markers)
    depth = camera.to_camera(markers)[..., 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        radii = np.where(depth > 0, camera.matrix[0, 0] * options.marker_diameter / 2 / depth, 0)
    visible = camera.in_image(pixels) & (depth > 0)
    if options.occlusion:
        visible &= ~hidden_by_body(poses, camera, options.capsules)
    return MarkerViews(pixels=pixels, radii=radii, visible=visible)


def render_camera(
    poses: np.ndarray, camera: Camera, options: RenderOptions, rng: np.random.Generator
) -> CameraRender:
    """Render the frames (F, H, W) uint8 that `camera` films of poses (F, 13, 3), meters.

    `rng` draws the dropped frames first, then the noise chunk by chunk.
    """
    views = marker_views(poses, camera, options)
    dropped = rng.random(len(views.pixels)) < options.drop_rate
    visible = views.visible & ~dropped[:, None]
    centres = _exposure_positions(views.pixels, options)  # (F, S, 8, 2)
    samples = centres.shape[1]
    levels = np.where(visible, options.marker_level / samples, 0.0)[:, None, :]
    frames = _film(
        camera,
        centres.reshape(len(centres), -1, 2),
        np.broadcast_to(views.radii[:, None, :], centres.shape[:-1]).reshape(len(centres), -1),
        np.broadcast_to(levels, centres.shape[:-1]).reshape(len(centres), -1),
        options,
        rng,
    )
    frames[dropped] = 0
    return CameraRender(camera, frames, views.pixels, visible, dropped)


def film_empty_stage(
    camera: Camera, options: RenderOptions, frames: int, rng: np.random.Generator
) -> np.ndarray:
    """`frames` frames (n, H, W) uint8 of the stage without the subject: background,
    noise and the static spots, as a camera films before the subject steps in."""
    return _film(
        camera, np.zeros((frames, 0, 2)), np.zeros((frames, 0)), np.zeros((frames, 0)), options, rng
    )


def _film(
    camera: Camera,
    centres: np.ndarray,
    radii: np.ndarray,
    levels: np.ndarray,
    options: RenderOptions,
    rng: np.random.Generator,
) -> np.ndarray:
    """Frames (n, H, W) uint8 of discs at `centres` (n, m, 2) px with `radii` (n, m) px and
    peak `levels` (n, m), plus the options' background, static spots and noise."""
    count = len(centres)
    width, height = camera.size
    spots = np.asarray(options.static_spots, dtype=np.float64).reshape(-1, 2) * (width, height)
    spot_radius = options.static_spot_radius * width
    frames = np.zeros((count, height, width), dtype=np.uint8)
    for first in range(0, count, CHUNK_FRAMES):
        chunk = slice(first, min(first + CHUNK_FRAMES, count))
        n = chunk.stop - chunk.start
        image = np.full((n, height, width), options.background, dtype=np.float32)
        _splat(image, centres[chunk], radii[chunk], levels[chunk], options.psf_sigma_px)
        if len(spots):
            _splat(
                image,
                np.broadcast_to(spots, (n, *spots.shape)),
                np.full((n, len(spots)), spot_radius),
                np.full((n, len(spots)), options.marker_level),
                options.psf_sigma_px,
            )
        if options.noise_sigma > 0:
            image += rng.standard_normal(image.shape, dtype=np.float32) * options.noise_sigma
        frames[chunk] = np.clip(np.rint(image), 0, 255)
    return frames


def render(
    poses: np.ndarray, cameras: Sequence[Camera], options: RenderOptions, seed: int = 0
) -> list[CameraRender]:
    """Every camera's `render_camera` of poses (F, 13, 3); deterministic in `seed`."""
    rngs = [np.random.default_rng([seed, i]) for i in range(len(cameras))]
    return [render_camera(poses, c, options, rng) for c, rng in zip(cameras, rngs, strict=True)]


def _exposure_positions(pixels: np.ndarray, options: RenderOptions) -> np.ndarray:
    """Marker centres (F, S, 8, 2) at S instants over the exposure centred on each frame.

    Linear between the neighbouring frames' positions (the frame's own where a
    neighbour is missing or absent); S = 1 without motion blur.
    """
    if options.motion_blur == 0 or options.blur_samples == 1 or len(pixels) < 2:
        return pixels[:, None]
    offsets = np.linspace(-options.motion_blur / 2, options.motion_blur / 2, options.blur_samples)
    previous = np.concatenate([pixels[:1], pixels[:-1]])
    following = np.concatenate([pixels[1:], pixels[-1:]])
    back = np.where(np.isnan(previous), 0.0, pixels - previous)
    ahead = np.where(np.isnan(following), 0.0, following - pixels)
    step = np.where(offsets[None, :, None, None] < 0, back[:, None], ahead[:, None])
    return pixels[:, None] + offsets[None, :, None, None] * step


def _splat(
    image: np.ndarray, centres: np.ndarray, radii: np.ndarray, levels: np.ndarray, sigma: float
) -> None:
    """Add blurred discs to `image` (n, H, W) in place.

    `centres` (n, m, 2) pixels (NaN: skipped), `radii` (n, m) pixels, `levels` (n, m)
    peak intensity of a large disc (0: skipped). Each disc is drawn on a square window
    around its centre wide enough for the radius plus 4 sigma of blur.
    """
    n, height, width = image.shape
    draw = (levels > 0) & ~np.isnan(centres).any(axis=-1)
    if not draw.any():
        return
    frame_index = np.broadcast_to(np.arange(n)[:, None], draw.shape)[draw]
    centre, radius, level = centres[draw], radii[draw], levels[draw]
    half = int(np.ceil(radius.max() + 4.0 * sigma))
    offsets = np.arange(-half, half + 1)
    base = np.rint(centre).astype(np.int64)
    xs = base[:, 0, None, None] + offsets[None, None, :]  # (d, 1, w)
    ys = base[:, 1, None, None] + offsets[None, :, None]  # (d, w, 1)
    distance = np.hypot(xs - centre[:, 0, None, None], ys - centre[:, 1, None, None])
    value = (
        0.5
        * level[:, None, None]
        * erfc((distance - radius[:, None, None]) / (np.sqrt(2.0) * sigma))
    )
    inside = (xs >= 0) & (xs < width) & (ys >= 0) & (ys < height)
    flat = (frame_index[:, None, None] * height + ys) * width + xs
    np.add.at(image.reshape(-1), flat[inside], value[inside].astype(np.float32))


def _capsule_endpoints() -> tuple[np.ndarray, np.ndarray]:
    """Joint weights (K, 13) of the capsule axis starts and ends: bones, spine, neck."""
    starts, ends = np.zeros((len(BONES) + 2, N_JOINTS)), np.zeros((len(BONES) + 2, N_JOINTS))
    for k, (parent, child) in enumerate(BONES):
        starts[k, parent] = ends[k, child] = 1.0
    spine, neck = len(BONES), len(BONES) + 1
    starts[spine, [7, 8]] = 0.5  # hip midpoint
    ends[spine, [1, 2]] = 0.5  # shoulder midpoint
    starts[neck, [1, 2]] = 0.5
    ends[neck, 0] = 1.0  # head
    return starts, ends
