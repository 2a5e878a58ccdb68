"""Nonlinear spherical shells (Chu, Jenkins, Matarić 2003, Sections 3 and 3.1): the
skeleton curve of one voxel volume.

The volume's Isomap embedding (`samba.volume.isomap`) is cut into concentric spherical shells
around its mean; each shell's points are clustered by sweep and prune (per-axis
separation thresholds, no cluster count); cluster means are principal-curve points,
linked across adjacent shells where their clusters touch in the neighbourhood graph
into a tree rooted at the innermost shell; each point is mapped back to the
Euclidean volume by Shepard interpolation. Refinement then merges the innermost
shells that enclose the mean into one root, removes short noise branches (hands,
feet) and merges branching nodes on adjacent shells.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from samba.base import InputError
from samba.volume.isomap import Embedding, VoxelGraph


@dataclass(frozen=True)
class ShellSettings:
    """Parameters of nonlinear spherical shells.

    `shell_width`: the thickness of the concentric shells, in voxels of the embedding
    (the paper fixed their number, 25; a thickness keeps the noise test below at one
    depth in voxels whatever the volume's size: at 1.4 voxels a human of 30 mm voxels
    gets about 25 shells, and its head, which reaches little beyond the shoulders from
    the volume's mean, stays deep enough to survive; on jumping jacks and waving,
    tuning seeds 1-3, the worst take's frames with human topology went from 57% with
    25 shells to 87%). `separation`: sweep-and-prune gap
    on any axis, in voxels of the embedding, that separates two clusters of a shell.
    `shepard_neighbours` and `shepard_power`: the embedded points nearest a curve point
    that interpolate its Euclidean position, weighted by 1 / distance ** power.
    `noise_depth`: leaf branches spanning fewer shells are noise. `root_spread`: a
    cluster whose mean lies closer to the centre than this fraction of its shell's
    radius encloses the mean and merges into the root.
    """

    shell_width: float = 1.4
    separation: float = 2.0
    shepard_neighbours: int = 8
    shepard_power: float = 2.0
    noise_depth: int = 3
    root_spread: float = 0.5


@dataclass(frozen=True)
class SkeletonCurve:
    """A tree of skeleton-curve points of one volume.

    `points` (k, 3) Euclidean positions, meters; `intrinsic` (k, d) positions in the
    embedding, voxels; `parents` (k,) int, -1 for the root (node 0), parents before
    children; `shell` (k,) the shell of each point (the root's is its outermost merged
    shell); `members` (m,) the node each voxel of the volume belongs to (-1 for voxels
    outside the embedded component).
    """

    points: np.ndarray
    intrinsic: np.ndarray
    parents: np.ndarray
    shell: np.ndarray
    members: np.ndarray

    def children(self) -> list[list[int]]:
        """Children of each node, in node order."""
        out: list[list[int]] = [[] for _ in self.parents]
        for node, parent in enumerate(self.parents):
            if parent >= 0:
                out[parent].append(node)
        return out

    def indicator_nodes(self) -> set[int]:
        """The root, branching nodes (>= 2 children) and leaves."""
        return {node for node, kids in enumerate(self.children()) if node == 0 or len(kids) != 1}


def sweep_and_prune(points: np.ndarray, separation: np.ndarray) -> np.ndarray:
    """Cluster labels (n,) of `points` (n, d): sweep along each axis in turn, splitting a
    cluster wherever consecutive coordinates differ by more than `separation` (d,),
    until no axis splits any cluster. Every cluster lies in an axis-aligned box whose
    projections on every axis have no gap wider than the separation."""
    n = len(points)
    labels = np.zeros(n, dtype=np.int64)
    if n == 0:
        return labels
    count, stale = 1, 0
    axis = 0
    while stale < points.shape[1]:
        order = np.lexsort((points[:, axis], labels))
        coordinate, label = points[order, axis], labels[order]
        start = np.ones(n, dtype=bool)
        start[1:] = (label[1:] != label[:-1]) | (np.diff(coordinate) > separation[axis])
        new = np.empty(n, dtype=np.int64)
        new[order] = np.cumsum(start) - 1
        stale = stale + 1 if new.max() + 1 == count else 1
        labels, count = new, int(new.max()) + 1
        axis = (axis + 1) % points.shape[1]
    return labels


def skeleton_curve(
    embedding: Embedding,
    graph: VoxelGraph,
    positions: np.ndarray,
    settings: ShellSettings | None = None,
) -> SkeletonCurve:
    """The refined skeleton curve of a connected volume.

    `embedding` and `graph` describe the same m voxels, whose Euclidean centres are
    `positions` (m, 3) meters.
    """
    settings = settings or ShellSettings()
    if not settings.shell_width > 0:
        raise InputError("shell_width", f"must be > 0 voxels, got {settings.shell_width}")
    y = embedding.points
    radius = np.linalg.norm(y, axis=1)
    shells = max(2, int(np.ceil(radius.max() / settings.shell_width)))
    width = radius.max() / shells
    shell = np.minimum((radius / width).astype(np.int64), shells - 1)
    cluster = np.empty(len(y), dtype=np.int64)
    cluster_shell = []
    separation = np.full(y.shape[1], settings.separation)
    for s in range(shells):
        inside = np.flatnonzero(shell == s)
        labels = sweep_and_prune(y[inside], separation)
        cluster[inside] = labels + len(cluster_shell)
        cluster_shell.extend([s] * (int(labels.max()) + 1 if len(inside) else 0))
    cluster, cluster_shell_array = _join_touching(cluster, np.asarray(cluster_shell), graph)
    parent = _link(cluster, cluster_shell_array, graph, y)
    nodes = _Tree.build(parent, cluster_shell_array, cluster, y, positions, settings)
    nodes.remove_noise(settings.noise_depth)
    nodes.merge_root(width, settings.root_spread)
    nodes.merge_adjacent_branchings()
    return nodes.curve()


def _join_touching(
    cluster: np.ndarray, cluster_shell: np.ndarray, graph: VoxelGraph
) -> tuple[np.ndarray, np.ndarray]:
    """Clusters of one shell joined wherever a graph edge links them (the volume runs
    on between them inside the shell: the Isomap embedding of a thin part can fan its
    cross-section out into strands that sweep and prune would separate). Returns the
    new cluster (m,) of each voxel and shell (c,) of each cluster."""
    coo = graph.edges.tocoo()
    a, b = cluster[coo.row], cluster[coo.col]
    same = cluster_shell[a] == cluster_shell[b]
    count = len(cluster_shell)
    touching = coo_matrix((np.ones(int(same.sum())), (a[same], b[same])), shape=(count, count))
    _, joined = connected_components(touching, directed=False)
    shell = np.zeros(int(joined.max()) + 1, dtype=np.int64)
    shell[joined] = cluster_shell
    return joined[cluster], shell


def _link(
    cluster: np.ndarray, cluster_shell: np.ndarray, graph: VoxelGraph, y: np.ndarray
) -> np.ndarray:
    """Parent cluster (c,) of every cluster: of the clusters on the next inner shell,
    the one joined to it by the most graph edges (nearest mean when none is joined);
    -1 for the innermost shell's clusters."""
    count = len(cluster_shell)
    coo = graph.edges.tocoo()
    a, b = cluster[coo.row], cluster[coo.col]
    inward = cluster_shell[b] == cluster_shell[a] - 1
    pairs, hits = np.unique(np.stack([a[inward], b[inward]], axis=1), axis=0, return_counts=True)
    parent = np.full(count, -1, dtype=np.int64)
    order = np.lexsort((-hits, pairs[:, 0])) if len(pairs) else np.zeros(0, dtype=np.int64)
    first = order[np.r_[True, pairs[order[1:], 0] != pairs[order[:-1], 0]]] if len(order) else order
    parent[pairs[first, 0]] = pairs[first, 1]
    means = np.zeros((count, y.shape[1]))
    np.add.at(means, cluster, y)
    means /= np.bincount(cluster, minlength=count)[:, None]
    for orphan in np.flatnonzero((parent < 0) & (cluster_shell > cluster_shell.min())):
        inner = np.flatnonzero(cluster_shell == cluster_shell[orphan] - 1)
        if len(inner):
            parent[orphan] = inner[np.argmin(np.linalg.norm(means[inner] - means[orphan], axis=1))]
    return parent


class _Tree:
    """A mutable skeleton-curve tree during refinement: nodes with a parent, a shell,
    an intrinsic and a Euclidean position, and the voxels they hold."""

    def __init__(
        self,
        parent: list[int],
        shell: list[int],
        intrinsic: list[np.ndarray],
        points: list[np.ndarray],
        members: np.ndarray,
    ) -> None:
        self.parent = parent
        self.shell = shell
        self.intrinsic = intrinsic
        self.points = points
        self.members = members
        self.alive = [True] * len(parent)

    @classmethod
    def build(
        cls,
        cluster_parent: np.ndarray,
        cluster_shell: np.ndarray,
        cluster: np.ndarray,
        y: np.ndarray,
        positions: np.ndarray,
        settings: ShellSettings,
    ) -> _Tree:
        """Nodes from clusters, with a virtual root at the centre when the innermost
        shell holds several clusters."""
        count = len(cluster_parent)
        sizes = np.bincount(cluster, minlength=count)
        intrinsic = np.zeros((count, y.shape[1]))
        np.add.at(intrinsic, cluster, y)
        intrinsic /= np.maximum(sizes, 1)[:, None]
        tree = cKDTree(y)
        k = min(settings.shepard_neighbours, len(y))
        distance, near = tree.query(intrinsic, k=k)
        distance, near = distance.reshape(count, k), near.reshape(count, k)
        weight = 1.0 / np.maximum(distance, 1e-6) ** settings.shepard_power
        euclidean = (weight[..., None] * positions[near]).sum(axis=1) / weight.sum(axis=1)[:, None]
        roots = np.flatnonzero(cluster_parent < 0)
        offset = 0 if len(roots) == 1 else 1
        parent = [-1] * offset + [int(p) + offset if p >= 0 else 0 for p in cluster_parent]
        if offset == 0:
            parent[int(roots[0])] = -1
        node_intrinsic = [np.zeros(y.shape[1])] * offset + list(intrinsic)
        node_points = [positions.mean(axis=0)] * offset + list(euclidean)
        shell = [0] * offset + [int(s) for s in cluster_shell]
        return cls(parent, shell, node_intrinsic, node_points, cluster + offset)

    def children(self) -> list[list[int]]:
        out: list[list[int]] = [[] for _ in self.parent]
        for node, parent in enumerate(self.parent):
            if self.alive[node] and parent >= 0:
                out[parent].append(node)
        return out

    def root(self) -> int:
        return next(n for n, p in enumerate(self.parent) if p < 0 and self.alive[n])

    def absorb(self, into: int, node: int) -> None:
        """Merge `node` into `into`: its voxels and children move to `into`."""
        for child, parent in enumerate(self.parent):
            if parent == node:
                self.parent[child] = into
        self.members[self.members == node] = into
        self.alive[node] = False

    def merge_root(self, width: float, spread: float) -> None:
        """Merge into the root the chain of single children from it: first the clusters
        that enclose the centre (their mean closer to it than `spread` times their
        shell's radius), whose mean point becomes the root, then the rest of the chain
        up to the first branching, so that the root has two or more children."""
        root = self.root()
        merged = [self.points[root]]
        enclosing = True
        while True:
            kids = self.children()[root]
            if len(kids) != 1:
                break
            child = kids[0]
            shell_radius = (self.shell[child] + 0.5) * width
            enclosing = enclosing and np.linalg.norm(self.intrinsic[child]) <= spread * shell_radius
            if enclosing:
                merged.append(self.points[child])
            else:
                self.points[root] = self.points[child]
            self.absorb(root, child)
        if enclosing:
            self.points[root] = np.mean(merged, axis=0)

    def remove_noise(self, depth: int) -> None:
        """Merge leaf branches with fewer than `depth` nodes into their branching node."""
        changed = True
        while changed:
            changed = False
            children = self.children()
            for leaf in [n for n, kids in enumerate(children) if self.alive[n] and not kids]:
                path = [leaf]
                while self.parent[path[-1]] >= 0 and len(children[self.parent[path[-1]]]) == 1:
                    path.append(self.parent[path[-1]])
                top = self.parent[path[-1]]
                if top >= 0 and len(path) < depth and len(children[top]) >= 2:
                    for node in path:
                        self.absorb(top, node)
                    changed = True
                    break

    def merge_adjacent_branchings(self) -> None:
        """Merge a branching node into its parent when that is branching too and on the
        adjacent inner shell."""
        changed = True
        while changed:
            changed = False
            children = self.children()
            for node, kids in enumerate(children):
                parent = self.parent[node]
                if (
                    self.alive[node]
                    and parent >= 0
                    and len(kids) >= 2
                    and len(children[parent]) >= 2
                    and self.shell[node] - self.shell[parent] <= 1
                ):
                    self.points[parent] = (self.points[parent] + self.points[node]) / 2.0
                    self.absorb(parent, node)
                    changed = True
                    break

    def curve(self) -> SkeletonCurve:
        """The live nodes renumbered depth first from the root, as a `SkeletonCurve`."""
        children = self.children()
        order: list[int] = []
        stack = [self.root()]
        while stack:
            node = stack.pop()
            order.append(node)
            stack.extend(reversed(children[node]))
        new = np.full(len(self.parent), -1, dtype=np.int64)
        new[order] = np.arange(len(order))
        parents = np.array([new[self.parent[n]] if self.parent[n] >= 0 else -1 for n in order])
        members = np.where(self.members >= 0, new[np.maximum(self.members, 0)], -1)
        return SkeletonCurve(
            points=np.array([self.points[n] for n in order]),
            intrinsic=np.array([self.intrinsic[n] for n in order]),
            parents=parents,
            shell=np.array([self.shell[n] for n in order]),
            members=members,
        )
