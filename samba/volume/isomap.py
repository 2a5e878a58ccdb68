"""Isomap of a voxel volume: geodesic distances over the voxels' neighbourhood graph,
embedded in 3-D (or more, `TIED`), so a posed articulated body unfolds to a
pose-invariant "Da Vinci" posture (Chu, Jenkins, Matarić 2003, Section 3; Tenenbaum et
al. 2000).

The neighbourhood graph joins voxels within an epsilon ball: with the default
epsilon of sqrt(3) voxels, each voxel is joined to its 26 grid neighbours, with the
Euclidean distance between their centres as edge length. The embedding is Landmark
Isomap (de Silva and Tenenbaum 2003): exact geodesic distances from a few landmarks
chosen by farthest-point sampling, classical MDS of the landmarks, and every other
voxel placed by distance-based triangulation against them. It agrees with full
Isomap up to the landmarks' sampling of the shape and costs O(landmarks x voxels)
instead of O(voxels^2) in time and memory.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from samba.base import InputError

LANDMARKS = 48
"""Landmarks of the embedding by default; 3-D needs >= 4, the shape needs a few dozen."""
TIED = 0.8
"""Share of the last kept eigenvalue above which the next one ties it and the embedding
takes its dimension too (when it is `SIGNIFICANT`). Cutting between two near-equal
eigenvalues keeps an arbitrary mix of their directions and folds what the dropped one
separates: the quadruped of `bench/bench_volume.py` spreads its front legs and its hind
legs left and right alike (the spread of the 4th embedded coordinate is 0.56-1.06 of the
3rd's, median 0.9), and its 3-D embedding put the front feet 1-4 voxels apart in most
frames, 32 voxels apart along the volume, so one shell cluster held both legs and the
frame model had one front leg. Human volumes' 4th spread is 0.14-0.6 of the 3rd with the
limbs held apart, 0.3-2 with the arms at the body; a human volume embedded in 4-D gets
short extra branches where the visual hull's blocky limbs fan out, so the share is set
high: at 0.8 the quadruped's 12 takes (seeds 1-5, 11-13, 31-34) went from 190 to 170
links (true 156) with true joints within 2 voxels 77% -> 91% on average, the 68 human
takes of those seeds kept their human models (the exaggerated ones within 0.03 cm, 17
natural ones moved by more than 0.1 cm: 8.81 -> 8.86 cm on average); at 0.7 one natural
take lost its human model and the rest went to 9.03 cm."""
SIGNIFICANT = 0.02
"""Share of the first eigenvalue below which a dimension never joins the embedding: a
thin chain's 2nd to 4th spreads (0.005-0.015 of the 1st) are its thickness, and ties
among them are noise (with no floor, the 6-link chain of `bench/bench_volume.py` lost
a link in one of 12 takes); the quadruped's 4th is 0.037-0.051 of its 1st."""


@dataclass(frozen=True)
class VoxelGraph:
    """The epsilon-ball neighbourhood graph of occupied voxels.

    `indices` (m, 3) int are the voxels' grid indices, `edges` the (m, m) symmetric
    sparse matrix of edge lengths in voxel units, `component` (m,) the connected
    component of each voxel, numbered by decreasing size (0 is the largest).
    """

    indices: np.ndarray
    edges: csr_matrix
    component: np.ndarray

    @classmethod
    def from_indices(cls, indices: np.ndarray, epsilon: float = float(np.sqrt(3.0))) -> VoxelGraph:
        """The graph of voxels at grid `indices` (m, 3) int joining voxel centres at most
        `epsilon` voxels apart (>= 1; sqrt(3) gives the 26-neighbourhood)."""
        indices = np.asarray(indices)
        if (
            indices.ndim != 2
            or indices.shape[1] != 3
            or not np.issubdtype(indices.dtype, np.integer)
        ):
            raise InputError(
                "voxels", f"voxel indices must be (m, 3) integers, got {indices.shape}"
            )
        if not (np.isfinite(epsilon) and epsilon >= 1.0):
            raise InputError("epsilon", f"neighbourhood radius must be >= 1 voxel, got {epsilon}")
        reach = int(np.floor(epsilon))
        steps = np.stack(
            np.meshgrid(*[np.arange(-reach, reach + 1)] * 3, indexing="ij"), axis=-1
        ).reshape(-1, 3)
        length = np.linalg.norm(steps, axis=1)
        forward = (length > 0) & (length <= epsilon + 1e-9) & _lexicographic_positive(steps)
        steps, length = steps[forward], length[forward]
        low = indices.min(axis=0) - reach if len(indices) else np.zeros(3, dtype=np.int64)
        span = (indices.max(axis=0) + reach + 1 - low) if len(indices) else np.ones(3, np.int64)
        keys = _keys(indices - low, span)
        order = np.argsort(keys)
        sorted_keys = keys[order]
        rows, cols, weights = [], [], []
        for step, size in zip(steps, length, strict=True):
            target = _keys(indices + step - low, span)
            at = np.searchsorted(sorted_keys, target)
            at = np.minimum(at, len(sorted_keys) - 1)
            hit = sorted_keys[at] == target if len(sorted_keys) else np.zeros(0, bool)
            rows.append(np.flatnonzero(hit))
            cols.append(order[at[hit]])
            weights.append(np.full(int(hit.sum()), size))
        row, col, weight = (np.concatenate(x) if x else np.zeros(0) for x in (rows, cols, weights))
        m = len(indices)
        edges = coo_matrix(
            (
                np.concatenate([weight, weight]),
                (np.concatenate([row, col]), np.concatenate([col, row])),
            ),
            shape=(m, m),
        ).tocsr()
        count, labels = connected_components(edges, directed=False)
        sizes = np.bincount(labels, minlength=count)
        rank = np.empty(count, dtype=np.int64)
        rank[np.argsort(-sizes, kind="stable")] = np.arange(count)
        return cls(indices=indices, edges=edges, component=rank[labels])

    def largest(self) -> np.ndarray:
        """Indices (k,) of the voxels in the largest connected component."""
        return np.flatnonzero(self.component == 0)

    def subgraph(self, keep: np.ndarray) -> VoxelGraph:
        """The graph restricted to voxels `keep` (k,) (indices into this graph)."""
        keep = np.asarray(keep)
        edges = self.edges[keep][:, keep].tocsr()
        return VoxelGraph(self.indices[keep], edges, np.zeros(len(keep), dtype=np.int64))


def _lexicographic_positive(steps: np.ndarray) -> np.ndarray:
    """Of each pair of opposite steps (k, 3), the one whose first non-zero entry is > 0."""
    first = np.argmax(steps != 0, axis=1)
    return steps[np.arange(len(steps)), first] > 0


def _keys(indices: np.ndarray, span: np.ndarray) -> np.ndarray:
    """One int64 key per grid index (m, 3) inside a box of size `span` (3,)."""
    return (indices[:, 0] * span[1] + indices[:, 1]) * span[2] + indices[:, 2]


@dataclass(frozen=True)
class Embedding:
    """An Isomap embedding: `points` (m, d) intrinsic coordinates in voxel units centred on
    their mean (d >= 3 dimensions), the `landmarks` (L,) used and their geodesic
    distances `geodesic` (L, m) in voxel units."""

    points: np.ndarray
    landmarks: np.ndarray
    geodesic: np.ndarray


def isomap(graph: VoxelGraph, landmarks: int = LANDMARKS, dims: int = 3) -> Embedding:
    """Landmark Isomap of a connected `graph` into `dims` dimensions, and one more for
    each further eigenvalue of the landmarks' MDS that ties the last one kept (`TIED`)
    and is `SIGNIFICANT`.

    Landmarks are picked by farthest-point sampling in geodesic distance, starting from
    the voxel farthest from the first one (deterministic). The edge matrix holds both
    directions of every edge, so the searches treat it as directed (scipy's undirected
    mode would symmetrise it again on every search, at twice the cost). Raises
    `InputError` when the graph is not connected or too small for `dims` + 1 landmarks.
    """
    edges = graph.edges
    m = edges.shape[0]
    if m < dims + 2:
        raise InputError("volume", f"{m} voxels are too few for a {dims}-D embedding")
    if np.any(graph.component != 0):
        raise InputError("volume", "the voxel graph is not connected; embed its largest part")
    count = min(landmarks, m)
    chosen = np.empty(count, dtype=np.int64)
    geodesic = np.empty((count, m))
    start = int(np.argmax(dijkstra(edges, indices=0)))
    nearest = np.full(m, np.inf)
    chosen[0] = start
    for k in range(count):
        geodesic[k] = dijkstra(edges, indices=int(chosen[k]))
        nearest = np.minimum(nearest, geodesic[k])
        if k + 1 < count:
            chosen[k + 1] = int(np.argmax(nearest))
    squared = geodesic**2
    landmark_squared = squared[:, chosen]
    centring = np.eye(count) - 1.0 / count
    gram = -0.5 * centring @ landmark_squared @ centring
    values, vectors = np.linalg.eigh(gram)
    order = np.argsort(values)[::-1]
    least = SIGNIFICANT * values[order[0]]
    while dims < count and values[order[dims]] >= max(TIED * values[order[dims - 1]], least):
        dims += 1
    top = order[:dims]
    values = np.maximum(values[top], 1e-12)
    pseudo_inverse = vectors[:, top].T / np.sqrt(values)[:, None]
    points = -0.5 * (pseudo_inverse @ (squared - landmark_squared.mean(axis=1, keepdims=True))).T
    points -= points.mean(axis=0)
    return Embedding(points=points, landmarks=chosen, geodesic=geodesic)
