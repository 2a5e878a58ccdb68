"""Pass 1 of model and motion capture (Chu, Jenkins, Matarić 2003, Section 4): the
kinematic model of one frame from its skeleton curve and volume.

Every branch of the skeleton curve (the path between two indicator nodes: root,
branching nodes, leaves) is a kinematic link to start with. A branch is then cut into
smaller links where its volume stops being linear: starting at the branch's parent
node, skeleton points are included one by one, and when the voxels of the included
points are skewed about the line from the first to the last included point (the
sample skewness of their distances to that line exceeds a threshold), a joint is
placed at the last point that kept them linear, which starts the next link.

A leaf branch runs to the volume's tip, but the body part's end joint lies about one
local radius inside it (a capsule's axis ends one radius short of its cap): the
branch's end is placed that far inside the tip (`Branch.inset`). On the creatures of
`bench/bench_volume.py` (25 mm voxels) the quadruped's head end went from 2.6 to 1.3
voxels off and its feet from 1.4 to 0.5-0.7, its true joints within 2 voxels from 71%
to 79% (seeds 1-5 and held-out 11-13 alike); the chain's ends from 0.8-1.1 to 0.4-0.5.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from samba.body import point_segment_distances
from samba.volume.spherical_shells import SkeletonCurve

SKEWNESS = 0.0
"""Skewness of the voxels' distances to the chord above which they are not linear. A
uniformly filled straight cylinder gives about -0.57 (most volume at the surface);
volume bulging to one side of the chord (a bend) pushes it up through 0."""
HUMAN_END_BRANCHES = 5
"""End branches of a human model: head, two arms, two legs."""
MIN_VOXELS = 12
"""Fewest voxels the skewness test is applied to."""
TIP_NODES = 3
"""Curve points at a leaf branch's end whose voxels give the local radius near the tip
(refinement leaves every leaf branch at least this many, `ShellSettings.noise_depth`;
2 to 5 changed nothing on the creatures of `bench/bench_volume.py`)."""
MAX_INSET = 0.5
"""Largest share of a leaf branch's length its end is moved inside the tip."""


@dataclass(frozen=True)
class Branch:
    """One branch of a frame's kinematic model.

    `parent`: the branch ending where this one starts, -1 when it starts at the root.
    `points` (p, 3) meters: the skeleton-curve points from the parent node to the end
    node. `joints` (j,): the fractions (0..1) of the branch's arc length at which the
    skewness test placed joints inside it, increasing. `inset` (m): how far along the
    curve before its last point the branch's end lies (a leaf's: about one local radius
    inside the volume's tip; 0 for branches that carry others). `radius` (m): the
    radius of the volume around the branch (`volume_radius` of its voxels but the
    parent node's; 0 when unknown).
    """

    parent: int
    points: np.ndarray
    joints: np.ndarray
    inset: float = 0.0
    radius: float = 0.0

    @property
    def length(self) -> float:
        """Arc length of the branch, meters."""
        return float(np.linalg.norm(np.diff(self.points, axis=0), axis=1).sum())

    @property
    def end(self) -> float:
        """Fraction (0..1) of the arc length at which the branch ends (1 but for leaves)."""
        length = self.length
        return 1.0 - self.inset / length if length > 0 else 1.0

    def at(self, fractions: np.ndarray) -> np.ndarray:
        """Points (k, 3) meters at `fractions` (k,) of the arc length along the branch."""
        return points_along(self.points, fractions)


def arc_lengths(polylines: np.ndarray) -> np.ndarray:
    """Arc length (..., p) from the start to each vertex of polylines (..., p, 3)."""
    steps = np.linalg.norm(np.diff(polylines, axis=-2), axis=-1)
    start = np.zeros((*steps.shape[:-1], 1))
    return np.concatenate([start, np.cumsum(steps, axis=-1)], axis=-1)


def points_along(polylines: np.ndarray, fractions: np.ndarray) -> np.ndarray:
    """Points (..., k, 3) at `fractions` (k,) (0..1) of the arc length of each polyline
    (..., p, 3), p >= 2; a polyline of no length gives its first vertex."""
    polylines = np.asarray(polylines, dtype=np.float64)
    arc = arc_lengths(polylines)
    target = np.asarray(fractions, dtype=np.float64) * arc[..., -1:]
    last = polylines.shape[-2] - 2
    segment = np.minimum((arc[..., None, 1:-1] < target[..., None]).sum(axis=-1), last)
    start = np.take_along_axis(arc, segment, axis=-1)
    length = np.take_along_axis(arc, segment + 1, axis=-1) - start
    t = np.clip((target - start) / np.where(length > 0, length, 1.0), 0.0, 1.0)
    a = np.take_along_axis(polylines, segment[..., None], axis=-2)
    b = np.take_along_axis(polylines, segment[..., None] + 1, axis=-2)
    return a + t[..., None] * (b - a)


@dataclass(frozen=True)
class FrameModel:
    """A frame's kinematic model: `root` (3,) meters and the `branches`, parents first."""

    root: np.ndarray
    branches: tuple[Branch, ...]

    @property
    def leaf_count(self) -> int:
        """Branches no other branch starts from."""
        parents = {b.parent for b in self.branches}
        return sum(1 for i in range(len(self.branches)) if i not in parents)

    def signature(self) -> str:
        """A canonical string of the branch tree's shape (equal for isomorphic trees)."""
        children: list[list[int]] = [[] for _ in range(len(self.branches) + 1)]
        for i, branch in enumerate(self.branches):
            children[branch.parent + 1].append(i + 1)

        def encode(node: int) -> str:
            return "(" + "".join(sorted(encode(c) for c in children[node])) + ")"

        return encode(0)

    def is_humanoid(self) -> bool:
        """Five leaf branches (head, two arms, two legs) hanging off one trunk: the
        branches that carry others form a single chain from the root, or the root is the
        only branching point (a root with five branches)."""
        if self.leaf_count != HUMAN_END_BRANCHES:
            return False
        carriers = sorted({b.parent for b in self.branches if b.parent >= 0})
        starts_at_root = [i for i, b in enumerate(self.branches) if b.parent < 0]
        trunk_from_root = [i for i in starts_at_root if i in carriers]
        if len(trunk_from_root) > 2:
            return False
        for carrier in carriers:
            inner = [c for c in carriers if self.branches[c].parent == carrier]
            if len(inner) > 1:
                return False
        return True


def frame_model(
    curve: SkeletonCurve, positions: np.ndarray, skewness: float = SKEWNESS
) -> FrameModel:
    """The kinematic model of one frame from its refined skeleton `curve` and the
    Euclidean centres `positions` (m, 3) meters of the voxels `curve.members` labels."""
    children = curve.children()
    indicator = curve.indicator_nodes()
    order = np.argsort(curve.members, kind="stable")
    bounds = np.searchsorted(curve.members[order], np.arange(len(curve.parents) + 1))
    voxels = [positions[order[bounds[n] : bounds[n + 1]]] for n in range(len(curve.parents))]
    branches: list[Branch] = []
    ends: dict[int, int] = {}
    stack = [(0, kid) for kid in reversed(children[0])]
    while stack:
        start, node = stack.pop()
        path = [start, node]
        while path[-1] not in indicator:
            path.append(children[path[-1]][0])
        end = path[-1]
        points = curve.points[path]
        branch_voxels = [voxels[n] for n in path]
        branch = Branch(
            parent=ends.get(start, -1),
            points=points,
            joints=_segment(points, branch_voxels, skewness),
            inset=0.0 if children[end] else tip_inset(points, branch_voxels),
            radius=volume_radius(points, np.concatenate(branch_voxels[1:])),
        )
        ends[end] = len(branches)
        branches.append(branch)
        stack.extend((end, kid) for kid in reversed(children[end]))
    return FrameModel(root=curve.points[0].copy(), branches=tuple(branches))


def _segment(points: np.ndarray, voxels: list[np.ndarray], threshold: float) -> np.ndarray:
    """Fractions of arc length where the skewness test cuts a branch with curve `points`
    (p, 3) and per-point voxels."""
    arc = arc_lengths(points)
    if arc[-1] <= 0:
        return np.zeros(0)
    cuts: list[float] = []
    first = 0
    for last in range(2, len(points)):
        inside = np.concatenate(voxels[first + 1 : last + 1])
        if len(inside) < MIN_VOXELS:
            continue
        if linear_skewness(inside, points[first], points[last]) > threshold:
            cuts.append(arc[last - 1] / arc[-1])
            first = last - 1
    return np.asarray(cuts)


def tip_inset(points: np.ndarray, voxels: list[np.ndarray]) -> float:
    """How far (m of arc length) the end joint of a leaf branch with curve `points`
    (p, 3) m and per-point voxel centres `voxels` (p arrays (k, 3) m) lies before the
    curve's last point: one local radius inside the volume's tip, less the distance the
    tip already reaches beyond the last point along the last segment.

    The radius is that of a filled cylinder whose voxels' median distance from its axis
    is that of the last `TIP_NODES` points' voxels from the curve (median = radius /
    sqrt 2). Capped at `MAX_INSET` of the branch's length; 0 for a branch of fewer than
    three points or no length.
    """
    length = float(arc_lengths(points)[-1])
    if len(points) < 3 or length <= 0:
        return 0.0
    near = np.concatenate(voxels[max(1, len(points) - TIP_NODES) :])
    if len(near) == 0:
        return 0.0
    radius = volume_radius(points, near)
    direction = points[-1] - points[-2]
    norm = np.linalg.norm(direction)
    reach = 0.0
    if norm > 0 and len(voxels[-1]):
        reach = max(0.0, float(((voxels[-1] - points[-1]) @ (direction / norm)).max()))
    return float(np.clip(radius - reach, 0.0, MAX_INSET * length))


def volume_radius(points: np.ndarray, voxels: np.ndarray) -> float:
    """Radius (m) of a filled cylinder around the curve `points` (p, 3) m, p >= 2, whose
    voxels' median distance from its axis is that of the voxel centres `voxels` (k, 3)
    m from the curve (median = radius / sqrt 2); 0 without voxels."""
    if len(voxels) == 0:
        return 0.0
    to_curve = point_segment_distances(voxels[:, None], points[:-1], points[1:]).min(axis=1)
    return np.sqrt(2.0) * float(np.median(to_curve))


def linear_skewness(voxels: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Sample skewness of the distances of `voxels` (k, 3) to the line through `a` and
    `b` (3,): about -0.57 for a filled cylinder around the line, rising as the volume
    leaves it to one side."""
    axis = b - a
    norm = np.linalg.norm(axis)
    if norm == 0:
        return 0.0
    offset = voxels - a
    along = offset @ (axis / norm)
    distance = np.linalg.norm(offset - along[:, None] * (axis / norm), axis=1)
    spread = distance.std()
    if spread == 0:
        return 0.0
    return float(np.mean((distance - distance.mean()) ** 3) / spread**3)
