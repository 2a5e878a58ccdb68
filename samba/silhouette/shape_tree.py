"""`ShapeTree`: the shape hierarchy of single-camera silhouette tracking (Okada, Stenger,
Kondoh, Section 2.1).

Built once per camera and body model from a set of database poses:

1. every pose is scaled to the body model's height, moved to the home point, turned to
   face the camera and then turned by each of `headings` (a single camera sees the
   subject from any side), and
   only poses that differ by at least `min_degrees` in some joint are kept (the paper's
   5 degrees; `samba.silhouette.pose_selection.distinct_poses`);
2. each kept pose, standing at the view's home point, is rendered as a silhouette of the
   body model, normalised (`samba.silhouette.view`) and stored at the pyramid sizes of
   `LEVEL_SIZES` (80x60, 160x120, 320x240) as runs (`samba.silhouette.runs`);
3. the poses become the leaves; clustering them by silhouette distance with a maximum
   within-cluster distance (leader clustering: a silhouette joins the first cluster
   whose leader is within the radius, else it leads a new one) gives the middle level,
   clustering the middle level's leaders with a larger radius gives the top level. A
   node carries its leader's pose and its leader's silhouette at the level's size.

The clustering measures silhouettes by the plain XOR distance at the top level's size,
approximated in the space of their first `FEATURE_DIMS` principal components (the
Euclidean distance between binary images is the square root of their XOR count; the
projection shortens it, about 3x for a person). `radii` are XOR counts as fractions of
the mean silhouette area, measured in that space: members may differ from their
leader by more.

Poses are (n, 13, 3) meters, +Y up; tree poses stand at `view.home`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from scipy.spatial import cKDTree

from samba.base import InputError
from samba.body import BodyModel, scaled_to
from samba.cameras import with_size
from samba.silhouette.distance import downsampled
from samba.silhouette.pose_selection import distinct_poses, turned
from samba.silhouette.render import part_visibility, render_silhouettes
from samba.silhouette.runs import SilhouetteRuns
from samba.silhouette.view import Placement, SilhouetteView

LEVEL_SIZES: tuple[tuple[int, int], ...] = ((80, 60), (160, 120), (320, 240))
"""(width, height) of the silhouettes of the top, middle and leaf level."""
DEFAULT_HEADINGS = np.arange(-180.0, 180.0, 15.0)
"""Turns (degrees, counterclockwise from above) added to each pose after it is turned to
face the camera: all round, every 15 degrees (30-degree steps leave the trunk too far
from any leaf while the subject turns)."""
DEFAULT_RADII = (0.08, 0.03)
"""Largest XOR between a top-level / middle-level leader and its members, as a fraction
of the mean silhouette area."""
FEATURE_DIMS = 48
"""Principal components of the thumbnails the clustering keeps."""
PCA_SAMPLE = 1500
"""Silhouettes the principal axes of the clustering are computed from."""
CHUNK = 512
"""Poses rendered at once while building (bounds the memory of full-size masks)."""
REBUILD_EVERY = 512
"""Leader clustering re-indexes its leaders in a k-d tree after this many new ones."""

PART_JOINTS: tuple[tuple[int, ...], ...] = (
    (1, 2, 7, 8),
    (0,),
    (3, 5),
    (4, 6),
    (9, 11),
    (10, 12),
)
"""Joints of each body part of `samba.body.body_model.PART_NAMES` (torso, head, arms, legs)."""


@dataclass(frozen=True, eq=False)
class TreeLevel:
    """One level of the tree, m nodes: `silhouettes` (runs at the level's size), `poses`
    (m, 13, 3) float32 meters at home, `floor_offsets` (m, 3) float32 meters from the
    silhouette's anchor floor point to the pose's hip midpoint on the floor,
    `visibility` (m, parts) float32 (`part_visibility`) and `parents` (m,) int32 node
    index on the level above (-1 on the top level)."""

    silhouettes: SilhouetteRuns
    poses: np.ndarray
    floor_offsets: np.ndarray
    visibility: np.ndarray
    parents: np.ndarray

    def __len__(self) -> int:
        return len(self.poses)


class ShapeTree:
    """The shape hierarchy: `levels` from the top to the leaves, for `view` and `body`."""

    def __init__(
        self, view: SilhouetteView, body: BodyModel, levels: tuple[TreeLevel, ...]
    ) -> None:
        self.view = view
        self.body = body
        self.levels = levels
        self._children = []
        for upper, lower in pairwise(levels):
            order = np.argsort(lower.parents, kind="stable")
            offsets = np.searchsorted(lower.parents[order], np.arange(len(upper) + 1))
            self._children.append((offsets, order))

    @property
    def leaves(self) -> TreeLevel:
        """The bottom level: one node per kept pose."""
        return self.levels[-1]

    @property
    def nbytes(self) -> int:
        """Memory held by the tree's arrays, bytes."""
        arrays = [
            a
            for level in self.levels
            for a in (level.poses, level.floor_offsets, level.visibility, level.parents)
        ]
        return sum(a.nbytes for a in arrays) + sum(lv.silhouettes.nbytes for lv in self.levels)

    def placed(self, leaves: np.ndarray, placement: Placement) -> np.ndarray:
        """The poses (k, 13, 3) float64 meters of `leaves` (k,) indices, moved on the floor
        from the tree's home to where a silhouette with `placement` stands and scaled
        about the floor point under their hip midpoint to the subject's size."""
        roots = placement.floor + placement.size * self.leaves.floor_offsets[leaves]
        roots[:, 1] = 0.0
        at_home = self.leaves.poses[leaves].astype(np.float64) - self.view.home
        return roots[:, None] + placement.size * at_home

    def children(self, level: int, nodes: np.ndarray) -> np.ndarray:
        """Indices on level `level + 1` of the children of `nodes` on level `level`."""
        offsets, order = self._children[level]
        nodes = np.asarray(nodes, dtype=np.int64)
        counts = offsets[nodes + 1] - offsets[nodes]
        firsts = np.repeat(offsets[nodes] - np.cumsum(counts) + counts, counts)
        return order[firsts + np.arange(int(counts.sum()))]

    @classmethod
    def build(
        cls,
        poses: np.ndarray,
        view: SilhouetteView,
        body: BodyModel,
        *,
        headings: np.ndarray = DEFAULT_HEADINGS,
        min_degrees: float = 5.0,
        radii: tuple[float, float] = DEFAULT_RADII,
        progress: Callable[[int, int], None] | None = None,
    ) -> ShapeTree:
        """Build the tree of database `poses` (n, 13, 3) meters for `view` and `body`
        (see the module docstring). `progress(done, total)` is called as leaves render.
        `InputError` for bad poses or radii."""
        if not (len(radii) == 2 and 0 < radii[1] < radii[0]):
            raise InputError("radii", f"need top > middle > 0 XOR fractions, got {radii}")
        standing = at_home(scaled_to(poses, body.height), view.home)
        candidates = turned(facing(standing, view), headings)
        leaves = candidates[distinct_poses(candidates, min_degrees)]
        rendered = _render(leaves, view, body, progress)
        top_size = rendered.runs[0]
        area = len(top_size.starts) and float(
            np.mean(np.add.reduceat(top_size.ends - top_size.starts, top_size.offsets[:-1]))
        )
        features = _principal_features(top_size)
        middle_leaders, middle_of = _leader_clusters(features, np.sqrt(radii[1] * area))
        top_leaders, top_of = _leader_clusters(features[middle_leaders], np.sqrt(radii[0] * area))
        leaders = (middle_leaders[top_leaders], middle_leaders, np.arange(len(leaves)))
        parents = (np.full(len(top_leaders), -1), top_of, middle_of)
        levels = tuple(
            TreeLevel(
                silhouettes=rendered.runs[level].subset(leaders[level]),
                poses=leaves[leaders[level]].astype(np.float32),
                floor_offsets=rendered.floor_offsets[leaders[level]],
                visibility=rendered.visibility[leaders[level]],
                parents=parents[level].astype(np.int32),
            )
            for level in range(len(LEVEL_SIZES))
        )
        return cls(view, body, levels)


def facing(poses: np.ndarray, view: SilhouetteView) -> np.ndarray:
    """Poses (n, 13, 3) meters turned about the vertical through their hip midpoint so
    that each faces the camera: its front (the hip line, left minus right, crossed with
    +Y up; +Z for the standard pose) points at the camera centre, seen from above."""
    poses = np.asarray(poses, dtype=np.float64)
    left = poses[:, 7] - poses[:, 8]
    front = np.stack([-left[:, 2], np.zeros(len(poses)), left[:, 0]], axis=1)
    root = poses[:, [7, 8]].mean(axis=1)
    to_camera = view.camera.center - root
    current = np.arctan2(front[:, 0], front[:, 2])
    wanted = np.arctan2(to_camera[:, 0], to_camera[:, 2])
    angle = wanted - current
    c, s = np.cos(angle), np.sin(angle)
    offset = poses - root[:, None]
    x = c[:, None] * offset[..., 0] + s[:, None] * offset[..., 2]
    z = -s[:, None] * offset[..., 0] + c[:, None] * offset[..., 2]
    return root[:, None] + np.stack([x, offset[..., 1], z], axis=-1)


def at_home(poses: np.ndarray, home: np.ndarray) -> np.ndarray:
    """Poses (n, 13, 3) moved on the floor so their hip midpoint is above `home` (3,)."""
    root = np.asarray(poses)[:, [7, 8]].mean(axis=1)
    shift = np.asarray(home, dtype=np.float64) - root
    shift[:, 1] = 0.0
    return poses + shift[:, None]


@dataclass(frozen=True)
class _Rendered:
    runs: tuple[SilhouetteRuns, ...]
    floor_offsets: np.ndarray
    visibility: np.ndarray


def _render(
    poses: np.ndarray,
    view: SilhouetteView,
    body: BodyModel,
    progress: Callable[[int, int], None] | None,
) -> _Rendered:
    """Silhouettes of `poses` at home, normalised, at every level size, with floor
    offsets and part visibility."""
    runs: list[list[SilhouetteRuns]] = [[] for _ in LEVEL_SIZES]
    offsets, visibility = [], []
    root_floor = poses[:, [7, 8]].mean(axis=1)
    root_floor[:, 1] = 0.0
    small_camera = with_size(view.camera, LEVEL_SIZES[0])
    for first in range(0, len(poses), CHUNK):
        chunk = poses[first : first + CHUNK]
        masks = render_silhouettes(chunk, view.camera, body)
        normalised = np.empty_like(masks)
        for i, mask in enumerate(masks):
            normalised[i], placement = view.normalise(mask)
            offsets.append(root_floor[first + i] - placement.floor)
        for level, size in enumerate(LEVEL_SIZES):
            scaled = normalised if size == view.size else downsampled(normalised, size)
            runs[level].append(SilhouetteRuns.from_masks(scaled))
        visibility.append(part_visibility(chunk, small_camera, body))
        if progress is not None:
            progress(first + len(chunk), len(poses))
    return _Rendered(
        tuple(SilhouetteRuns.concatenate(r) for r in runs),
        np.array(offsets, dtype=np.float32),
        np.concatenate(visibility).astype(np.float32),
    )


def _principal_features(silhouettes: SilhouetteRuns) -> np.ndarray:
    """Silhouettes on their first `FEATURE_DIMS` principal axes, (n, d) float32:
    Euclidean distances approximate sqrt(XOR pixel count). The axes come from at most
    `PCA_SAMPLE` silhouettes, through the eigenvectors of their Gram matrix."""
    n = len(silhouettes)
    sample = silhouettes.subset(np.linspace(0, n - 1, min(n, PCA_SAMPLE)).astype(int))
    data = sample.to_masks().reshape(len(sample), -1).astype(np.float32)
    mean = data.mean(axis=0)
    data -= mean
    values, vectors = np.linalg.eigh(data @ data.T)
    top = np.argsort(values)[::-1][:FEATURE_DIMS]
    axes = data.T @ (vectors[:, top] / np.sqrt(np.maximum(values[top], 1e-9)))
    parts = []
    for first in range(0, n, CHUNK):
        masks = silhouettes.subset(np.arange(first, min(first + CHUNK, n))).to_masks()
        parts.append((masks.reshape(len(masks), -1) - mean) @ axes)
    return np.concatenate(parts).astype(np.float32)


def _leader_clusters(features: np.ndarray, limit: float) -> tuple[np.ndarray, np.ndarray]:
    """Leader clustering with Euclidean radius `limit`: (leaders (k,) indices into
    `features`, cluster (n,) index into leaders of every feature row), in input order."""
    leaders: list[int] = []
    cluster = np.empty(len(features), dtype=np.int64)
    indexed = 0
    tree: cKDTree | None = None
    for i, point in enumerate(features):
        best, where = np.inf, -1
        if tree is not None:
            best, where = tree.query(point, distance_upper_bound=limit)
        recent = leaders[indexed:]
        if recent:
            gaps = np.linalg.norm(features[recent] - point, axis=1)
            j = int(np.argmin(gaps))
            if gaps[j] < best:
                best, where = gaps[j], indexed + j
        if best <= limit:
            cluster[i] = where
            continue
        cluster[i] = len(leaders)
        leaders.append(i)
        if len(leaders) - indexed >= REBUILD_EVERY:
            tree, indexed = cKDTree(features[leaders]), len(leaders)
    return np.array(leaders, dtype=np.int64), cluster
