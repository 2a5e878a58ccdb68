"""The capture chain on real footage: the measures and pictures of docs/real-footage.md,
from the shared lab session (../shared/data/pose2sim: four synchronised videos, the
lab's Qualisys calibration).

Run from the project root, after the two captures of docs/real-footage.md (made in the
examples' folder DIR, `samba examples DIR`):

    python bench/real_footage.py --bvh DIR/walk.bvh [--take DIR/walk.mcap] [--frame 99]
                                 [--tolerance PX] [--pictures docs/img/real-footage]

Every frame of the four videos is segmented again as `samba capture-volume --segment`
does and carved in its default capture volume (with `--tolerance PX` as given to it),
so the hull's top and bottom can be measured; the derived skeleton of the BVH (its
forward kinematics: joints and End Sites) and the 13 joints of the take are measured
against the walkway and against the silhouettes:

- height: the skeleton's highest point above the walkway per frame (median, 10th-90th
  percentile), and in frame 99, where the top of the head was triangulated at 1.65 m
  from clicked pixels (tests/test_foreign_calibrations.py);
- feet: the skeleton's lowest point above the walkway per frame;
- path: the root's (the take's hip midpoint's) floor position at the first and last
  frame, the distance between them, the length of the path (low-passed at 2 Hz) and
  the mean speed;
- in the silhouettes: the share of the skeleton's points that project into each
  camera's silhouette or within `SLACK_PX` of it (the lab's calibration is up to 15 px
  off the videos).

`--pictures DIR` writes the silhouettes of `--frame` in the four views, its visual hull,
the derived skeleton over the four views and, with `--take`, the tracked pose over
cam01 and cam03, the paths seen from above, and the highest and lowest points over the
frames.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from PIL import Image
from scipy.ndimage import label
from scipy.signal import butter, filtfilt

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from samba.body import BONES  # noqa: E402
from samba.cameras import CameraGroup, open_frames, read_calibration, sized_frames  # noqa: E402
from samba.ingest import read_bvh, read_take  # noqa: E402
from samba.silhouette import PersonSegmenter, SilhouetteExtractor  # noqa: E402
from samba.volume import VisualHull, VoxelGrid, capture_region  # noqa: E402

WALKWAY_Y = -0.004
"""Height (m) of the walkway in our frame: the mean of its four bolts (-0.007..0.001 m),
triangulated from the pixels clicked in tests/test_foreign_calibrations.py."""
WALKWAY = np.array([[-0.571, -0.601], [0.59, -0.5], [0.6, -1.616], [-0.564, -1.72]])
"""The walkway's four bolts (x, z) m, as triangulated there."""
HEAD_TOP_99 = 1.646
"""The top of the head in frame 99, m above y = 0, triangulated there."""
VOXEL = 0.03
"""Voxel edge (m) of `samba capture-volume`'s default."""
SLACK_PX = 15
"""Pixels around a silhouette that still count as in it (the calibration's error)."""
PATH_CUTOFF_HZ = 2.0
"""Low-pass cutoff of the paths whose length is measured."""
PANEL = (216, 384)
"""(width, height) of one view in the pictures."""
PICTURE_COLOURS = 96
"""Colours of the palette the photographic pictures are written with (small PNGs)."""


def lab_folder() -> Path:
    """The shared lab session: `$SAMBA_DATA/pose2sim` or ../shared/data/pose2sim."""
    data = Path(os.environ.get("SAMBA_DATA") or ROOT.parent / "shared" / "data")
    return data / "pose2sim"


@dataclass
class FrameRecord:
    """What one pass over the four videos keeps: per frame the hull's lowest and highest
    point (m), the share of each point set's points in the silhouettes (name -> (n,)),
    and of the picture frame its images, silhouettes and hull."""

    hull_low: list[float]
    hull_high: list[float]
    inside: dict[str, list[float]]
    images: list[np.ndarray]
    silhouettes: list[np.ndarray]
    hull: np.ndarray | None


def lab_frames(cameras: CameraGroup, calibration: str) -> Iterator[list[np.ndarray]]:
    """The four videos' frames (H, W, 3) BGR at the calibration's image size, in lockstep."""
    videos = [str(lab_folder() / "videos" / f"{camera.name}.mp4") for camera in cameras]
    streams = [
        sized_frames(open_frames(video).frames(), video, camera, calibration)
        for video, camera in zip(videos, cameras, strict=True)
    ]
    for frames in zip(*streams, strict=False):
        yield [frame for _, frame in frames]


def measured_pass(
    cameras: CameraGroup,
    calibration: str,
    grid: VoxelGrid,
    tolerance: int,
    points: dict[str, np.ndarray],
    picture: int,
) -> FrameRecord:
    """Segment and carve every frame (as `samba capture-volume --segment`), measuring
    the hull and how many of each of `points` (name -> (n, k, 3) m) lie in the
    silhouettes; keep frame `picture`."""
    hull = VisualHull(grid, cameras)
    record = FrameRecord([], [], {name: [] for name in points}, [], [], None)
    slack = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * SLACK_PX + 1,) * 2)
    with contextlib.ExitStack() as workers:
        extractors = [
            SilhouetteExtractor(workers.enter_context(PersonSegmenter(camera.name, camera.size)))
            for camera in cameras
        ]
        for t, frames in enumerate(lab_frames(cameras, calibration)):
            masks = [e.silhouette(frame) for e, frame in zip(extractors, frames, strict=True)]
            volume = largest_part(hull.carve(masks, None, tolerance))
            heights = grid.points(volume)[:, 1]
            record.hull_low.append(float(heights.min()) - grid.voxel / 2)
            record.hull_high.append(float(heights.max()) + grid.voxel / 2)
            wide = [cv2.dilate(m.view(np.uint8), slack).view(bool) for m in masks]
            for name, sets in points.items():
                if t < len(sets):
                    record.inside[name].append(inside_share(cameras, wide, sets[t]))
            if t == picture:
                record.images, record.silhouettes, record.hull = frames, masks, volume
    return record


def largest_part(volume: np.ndarray) -> np.ndarray:
    """The largest 26-connected part of an occupancy grid (nx, ny, nz) bool."""
    labels, count = label(volume, np.ones((3, 3, 3)))
    if count < 2:
        return volume
    return labels == 1 + np.argmax(np.bincount(labels.ravel())[1:])


def inside_share(cameras: CameraGroup, masks: list[np.ndarray], points: np.ndarray) -> float:
    """Share of the points (k, 3) m, over all views, that project into the masks."""
    hits = []
    for camera, mask in zip(cameras, masks, strict=True):
        pixels = np.round(camera.project(points)).astype(int)
        seen = camera.in_image(pixels)
        hits.append(np.where(seen, mask[pixels[:, 1].clip(0), pixels[:, 0].clip(0)], False))
    return float(np.mean(hits))


def bvh_skeleton(path: str) -> tuple[np.ndarray, list[int]]:
    """The BVH's joints and End Sites (n, k, 3) m by its forward kinematics, and each
    one's parent (-1 for the root)."""
    motion = read_bvh(path)
    positions = motion.positions(list(range(len(motion.joints))))
    return positions, [joint.parent for joint in motion.joints]


def spread(values: np.ndarray) -> str:
    """Median and 10th-90th percentile of values, in centimetres or meters as given."""
    low, mid, high = np.percentile(values, [10, 50, 90])
    return f"{mid:.3f} ({low:.3f}..{high:.3f})"


def path_measures(floor: np.ndarray, fps: float) -> str:
    """Start, end, distance, path length and speed of floor positions (n, 2) m (x, z)."""
    b, a = butter(2, PATH_CUTOFF_HZ / (fps / 2))
    smooth = filtfilt(b, a, floor, axis=0)
    length = np.linalg.norm(np.diff(smooth, axis=0), axis=1).sum()
    distance = np.linalg.norm(floor[-1] - floor[0])
    seconds = (len(floor) - 1) / fps
    return (
        f"({floor[0, 0]:.2f}, {floor[0, 1]:.2f}) -> ({floor[-1, 0]:.2f}, {floor[-1, 1]:.2f}) m, "
        f"{distance:.2f} m apart, path {length:.2f} m in {seconds:.2f} s, "
        f"{distance / seconds:.2f} m/s"
    )


def print_measures(name: str, points: np.ndarray, floor: np.ndarray, fps: float) -> None:
    """Height, feet and path of one capture: points (n, k, 3) m, root floor (n, 2) m."""
    top, low = points[..., 1].max(axis=1) - WALKWAY_Y, points[..., 1].min(axis=1) - WALKWAY_Y
    print(f"{name}: height above the walkway, m: {spread(top)}; frame 99: {top[99]:.3f}")
    print(f"{name}: lowest point above the walkway, m: {spread(low)}")
    print(f"{name}: path {path_measures(floor, fps)}")


def write_png(image: np.ndarray, out: Path) -> None:
    """A BGR image (H, W, 3) uint8 as a PNG of `PICTURE_COLOURS` colours."""
    rgb = Image.fromarray(np.ascontiguousarray(image[..., ::-1]))
    rgb.quantize(PICTURE_COLOURS, Image.Quantize.MEDIANCUT).save(out, optimize=True)


def panel(image: np.ndarray) -> np.ndarray:
    """An image scaled to one `PANEL`."""
    return cv2.resize(image, PANEL, interpolation=cv2.INTER_AREA)


def draw_skeleton(
    image: np.ndarray, pixels: np.ndarray, bones: list[tuple[int, int]], colour: tuple
) -> np.ndarray:
    """`image` with lines between the pixels (k, 2) of each bone and a dot per point."""
    out = image.copy()
    for a, b in bones:
        if np.isfinite(pixels[[a, b]]).all():
            start, end = np.round(pixels[[a, b]]).astype(int)
            cv2.line(out, tuple(start), tuple(end), colour, 7, cv2.LINE_AA)
    for point in np.round(pixels[np.isfinite(pixels).all(axis=1)]).astype(int):
        cv2.circle(out, tuple(point), 9, (255, 255, 255), -1, cv2.LINE_AA)
    return out


def silhouettes_picture(record: FrameRecord, out: Path) -> None:
    """The picture frame's four views with their silhouettes tinted."""
    views = []
    for image, mask in zip(record.images, record.silhouettes, strict=True):
        tinted = image.copy()
        tinted[mask] = (0.45 * tinted[mask] + (0, 0, 140)).astype(np.uint8)
        outline = cv2.dilate(mask.view(np.uint8), np.ones((5, 5), np.uint8)).view(bool) & ~mask
        tinted[outline] = (0, 255, 255)
        views.append(panel(tinted))
    write_png(np.hstack(views), out)


def skeleton_picture(
    record: FrameRecord, cameras: CameraGroup, points: np.ndarray, parents: list[int], out: Path
) -> None:
    """The derived skeleton (k, 3) m of the picture frame over its four views."""
    bones = [(parent, j) for j, parent in enumerate(parents) if parent >= 0]
    views = [
        panel(draw_skeleton(image, camera.project(points), bones, (40, 220, 40)))
        for image, camera in zip(record.images, cameras, strict=True)
    ]
    write_png(np.hstack(views), out)


def track_picture(record: FrameRecord, cameras: CameraGroup, pose: np.ndarray, out: Path) -> None:
    """The tracked pose (13, 3) m over the picture frame of cam01 (tracked) and cam03."""
    views = []
    for index in (0, 2):
        pixels = cameras[index].project(pose)
        views.append(panel(draw_skeleton(record.images[index], pixels, list(BONES), (0, 140, 255))))
    write_png(np.hstack(views), out)


def hull_picture(record: FrameRecord, grid: VoxelGrid, out: Path) -> None:
    """The picture frame's visual hull (largest part) above the walkway."""
    assert record.hull is not None
    index = np.argwhere(record.hull)
    low, high = index.min(axis=0), index.max(axis=0) + 1
    part = record.hull[low[0] : high[0], low[1] : high[1], low[2] : high[2]]
    heights = grid.points_at(index)[:, 1]
    colours = plt.cm.viridis((np.arange(part.shape[1]) + low[1]) * grid.voxel / heights.max())
    faces = np.broadcast_to(colours[None, :, None], (*part.shape, 4))
    edges = grid.bounds[0] + grid.voxel * np.stack([low, high])
    figure = plt.figure(figsize=(4.2, 5.0), dpi=80)
    axes = figure.add_subplot(projection="3d")
    x, y, z = np.meshgrid(
        *(np.linspace(a, b, n + 1) for a, b, n in zip(*edges, part.shape, strict=True)),
        indexing="ij",
    )
    axes.voxels(
        *(corners.transpose(2, 0, 1) for corners in (z, x, y)),
        part.transpose(2, 0, 1),
        facecolors=faces.transpose(2, 0, 1, 3),
    )
    walkway = np.vstack([WALKWAY, WALKWAY[:1]])
    axes.plot(walkway[:, 1], walkway[:, 0], WALKWAY_Y, color="k")
    axes.set_xlabel("z (m)")
    axes.set_ylabel("x (m)")
    axes.set_zlabel("y (m)")
    axes.set_box_aspect((1.2, 1.2, 1.7))
    axes.set_xlim(-1.8, -0.4)
    axes.set_ylim(-0.7, 0.7)
    axes.set_zlim(0.0, 1.8)
    axes.view_init(elev=15, azim=-60)
    figure.tight_layout()
    figure.savefig(out)
    plt.close(figure)


def paths_picture(paths: dict[str, np.ndarray], out: Path) -> None:
    """Floor paths (name -> (n, 2) m, x and z) over the walkway, seen from above."""
    figure, axes = plt.subplots(figsize=(4.0, 4.0), dpi=80)
    walkway = np.vstack([WALKWAY, WALKWAY[:1]])
    axes.plot(walkway[:, 0], walkway[:, 1], color="k", label="walkway (bolts)")
    for name, floor in paths.items():
        axes.plot(floor[:, 0], floor[:, 1], label=name)
        axes.plot(*floor[0], "o", color=axes.lines[-1].get_color())
    axes.set_xlabel("x (m)")
    axes.set_ylabel("z (m)")
    axes.set_aspect("equal")
    axes.legend(fontsize=7, loc="upper left")
    figure.tight_layout()
    figure.savefig(out)
    plt.close(figure)


def heights_picture(
    tops: dict[str, np.ndarray], bottoms: dict[str, np.ndarray], fps: float, out: Path
) -> None:
    """Over the frames, the highest (name -> (n,) m) and lowest points (name -> (n,) m)
    above the walkway: the head's top triangulated in frame 99 and the walkway with
    the acceptance bands (10% of the height, 10 cm)."""
    figure, (upper, lower) = plt.subplots(2, 1, figsize=(5.0, 4.4), dpi=80, sharex=True)
    top = HEAD_TOP_99 - WALKWAY_Y
    upper.axhspan(0.9 * top, 1.1 * top, color="0.9")
    upper.plot([99 / fps], [top], "k*", markersize=10, label="head top, clicked (frame 99)")
    lower.axhspan(-0.1, 0.1, color="0.9")
    lower.axhline(0.0, color="k", linewidth=1, label="walkway")
    for axes, series in ((upper, tops), (lower, bottoms)):
        for name, heights in series.items():
            axes.plot(np.arange(len(heights)) / fps, heights, label=name)
        axes.legend(fontsize=7, loc="lower left" if axes is upper else "upper left")
    upper.set_ylabel("highest point (m)")
    lower.set_ylabel("lowest point (m)")
    lower.set_xlabel("time (s)")
    figure.tight_layout()
    figure.savefig(out)
    plt.close(figure)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--bvh", required=True, help="samba capture-volume's BVH of the walk")
    parser.add_argument("--take", help="samba track-video's take of cam01 (.mcap)")
    parser.add_argument("--frame", type=int, default=99, help="video frame of the pictures")
    parser.add_argument("--tolerance", type=int, default=0, help="capture-volume's --tolerance")
    parser.add_argument("--pictures", type=Path, help="folder to write the pictures to")
    args = parser.parse_args()
    calibration = str(lab_folder() / "calibration" / "Calib.qca.txt")
    cameras = read_calibration(calibration)
    grid = VoxelGrid.from_bounds(*capture_region(cameras), VOXEL)
    skeleton, parents = bvh_skeleton(args.bvh)
    fps = read_bvh(args.bvh).fps
    points = {"skeleton": skeleton}
    poses = None
    if args.take:
        poses = read_take(args.take).poses.astype(np.float64)
        points["take"] = poses
    record = measured_pass(cameras, calibration, grid, args.tolerance, points, args.frame)
    high, low = np.array(record.hull_high) - WALKWAY_Y, np.array(record.hull_low) - WALKWAY_Y
    print(f"frames: {len(record.hull_high)}; walkway at y = {WALKWAY_Y} m")
    print(f"head top in frame 99, triangulated from clicked pixels: {HEAD_TOP_99 - WALKWAY_Y:.3f}")
    print(f"visual hull: top above the walkway, m: {spread(high)}; frame 99: {high[99]:.3f}")
    print(f"visual hull: bottom above the walkway, m: {spread(low)}")
    tops = {
        "visual hull": high,
        "capture-volume skeleton": skeleton[..., 1].max(axis=1) - WALKWAY_Y,
    }
    bottoms = {
        "visual hull": low,
        "capture-volume skeleton": skeleton[..., 1].min(axis=1) - WALKWAY_Y,
    }
    paths = {"capture-volume root": skeleton[:, 0][:, [0, 2]]}
    print_measures("capture-volume skeleton", skeleton, paths["capture-volume root"], fps)
    share = np.array(record.inside["skeleton"])
    print(f"capture-volume skeleton: share of points in the silhouettes: {spread(share)}")
    if poses is not None:
        pelvis = poses[:, [7, 8]].mean(axis=1)[:, [0, 2]]
        paths["track-video hip midpoint"] = pelvis
        feet = poses[:, [11, 12], 1].min(axis=1) - WALKWAY_Y
        tops["track-video head joint"] = poses[:, 0, 1] - WALKWAY_Y
        bottoms["track-video lower ankle"] = feet
        print(
            f"track-video: {len(poses)} poses; head joint above the walkway, m: "
            f"{spread(poses[:, 0, 1] - WALKWAY_Y)}"
        )
        print(f"track-video: lower ankle joint above the walkway, m: {spread(feet)}")
        print(f"track-video: hip midpoint path {path_measures(pelvis, fps)}")
        n = min(len(pelvis), len(skeleton))
        apart = np.linalg.norm(pelvis[:n] - skeleton[:n, 0, [0, 2]], axis=1)
        print(
            f"track-video: hip midpoint from the capture-volume root on the floor, m: "
            f"{spread(apart)}"
        )
        print(
            f"track-video: share of joints in the silhouettes: "
            f"{spread(np.array(record.inside['take']))}"
        )
    if args.pictures:
        args.pictures.mkdir(parents=True, exist_ok=True)
        silhouettes_picture(record, args.pictures / "silhouettes.png")
        hull_picture(record, grid, args.pictures / "hull.png")
        skeleton_picture(
            record, cameras, skeleton[args.frame], parents, args.pictures / "skeleton.png"
        )
        paths_picture(paths, args.pictures / "paths.png")
        heights_picture(tops, bottoms, fps, args.pictures / "heights.png")
        if poses is not None:
            track_picture(record, cameras, poses[args.frame], args.pictures / "track.png")


if __name__ == "__main__":
    main()
