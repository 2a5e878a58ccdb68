"""The pose index's inverted file for large tables: k-means cells searched exactly.

The features (n, D) are split into about sqrt(n) cells by k-means (FAISS's `Kmeans`,
trained on at most `TRAIN_PER_CELL` features a cell) and stored cell by cell. A query
visits the cells in order of a lower bound of the distance of any pose in them and stops
when the next bound is no less than its k-th distance: the result is exact, equal to
brute force. The bound is the larger of two (`samba.db.kernels.cells_kernel`): the
distance from the query to the bisector between a cell's centroid and the query's nearest
centroid (valid because every pose sits in its nearest centroid's cell: the cells are
Voronoi cells) and the distance to the centroid less the cell's radius. With an `eps`
the search stops once the next bound times (1 + eps) reaches the k-th distance: every
distance returned is then within (1 + eps) of the true one, as with the k-d tree.

The features and centroids are stored with their dimensions in `order`, the centroids'
spread largest first, so that a row's partial distance over the first half of them
already exceeds the k-th distance for most rows the search reads, which then skip the
rest (`cells_kernel`).

The full table's cells are built with the index and saved with the store. A masked table
(markers missing) of a large index gets its cells from the full table's: the Voronoi cells,
in the masked feature space, of the full table's centroids seen with the same markers
(`around`, a nearest-centroid assignment instead of a k-means; `samba.db.masked_cells`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import ModuleType

import numpy as np
from scipy.spatial.distance import cdist

TRAIN_PER_CELL = 64
"""Features k-means trains on per cell (FAISS warns below 39; more costs build time)."""
ITERATIONS = 12
"""k-means iterations."""


@dataclass(frozen=True)
class VoronoiCells:
    """Features (n, D) float32 stored cell by cell: `features` in cell order, `rows` (n,)
    the table row of each, `starts` (cells + 1,) each cell's first position,
    `centroids` (cells, D) float64, `radii` (cells,) the largest distance of a cell's
    features from its centroid, `between` (cells, cells) the centroids' distances (the
    cells are their Voronoi cells), `order` (D,) the table dimension stored in each column
    of `features` and `centroids`. Meters throughout."""

    features: np.ndarray
    rows: np.ndarray
    starts: np.ndarray
    centroids: np.ndarray
    radii: np.ndarray
    between: np.ndarray
    order: np.ndarray

    @classmethod
    def build(cls, features: np.ndarray, seed: int = 0) -> VoronoiCells:
        """The cells of features (n, D) float32: about sqrt(n) of them, by k-means."""
        import faiss

        features = np.ascontiguousarray(features, dtype=np.float32)
        n, d = features.shape
        count = max(1, round(math.sqrt(n)))
        kmeans = faiss.Kmeans(
            d,
            count,
            niter=ITERATIONS,
            seed=seed,
            max_points_per_centroid=TRAIN_PER_CELL,
            min_points_per_centroid=1,
            verbose=False,
        )
        with _one_thread(faiss):
            kmeans.train(features)
        return cls.around(features, kmeans.centroids.astype(np.float64))

    @classmethod
    def around(cls, features: np.ndarray, centroids: np.ndarray) -> VoronoiCells:
        """The Voronoi cells of `centroids` (cells, D) over features (n, D) float32: each
        feature in its nearest centroid's cell (FAISS's exact flat search)."""
        import faiss

        features = np.ascontiguousarray(features, dtype=np.float32)
        centroids = np.asarray(centroids, dtype=np.float64)
        nearest = faiss.IndexFlatL2(features.shape[1])
        nearest.add(centroids.astype(np.float32))
        with _one_thread(faiss):
            _, assigned = nearest.search(features, 1)
        return cls._of(features, assigned.ravel(), centroids)

    @classmethod
    def _of(cls, features: np.ndarray, assigned: np.ndarray, centroids: np.ndarray) -> VoronoiCells:
        """Features stored by their cells `assigned` (n,) around `centroids` (cells, D)."""
        count = len(centroids)
        rows = np.argsort(assigned, kind="stable")
        ordered = features[rows]
        starts = np.searchsorted(assigned[rows], np.arange(count + 1)).astype(np.int64)
        cell_of = np.repeat(np.arange(count), np.diff(starts))
        gaps = np.linalg.norm(ordered.astype(np.float64) - centroids[cell_of], axis=1)
        radii = np.zeros(count)
        np.maximum.at(radii, cell_of, gaps)
        # float32 features are compared with float32 queries: a margin for the rounding.
        radii = radii * (1.0 + 1e-6) + 1e-6
        order = spread_order(centroids)
        return cls(
            np.ascontiguousarray(ordered[:, order]),
            rows.astype(np.int64),
            starts,
            np.ascontiguousarray(centroids[:, order]),
            radii,
            cdist(centroids, centroids),
            order,
        )

    def __len__(self) -> int:
        return len(self.features)

    def arrays(self, prefix: str) -> dict[str, np.ndarray]:
        """The arrays to save, named `prefix` + field (the features are the table's own,
        saved by the index in table order)."""
        return {
            f"{prefix}rows": self.rows,
            f"{prefix}starts": self.starts,
            f"{prefix}centroids": self.table_centroids,
            f"{prefix}radii": self.radii,
            f"{prefix}between": self.between,
        }

    @classmethod
    def from_arrays(
        cls, features: np.ndarray, arrays: dict[str, np.ndarray], prefix: str
    ) -> VoronoiCells:
        """The cells saved by `arrays`, over the table's features (n, D) in table order."""
        rows = arrays[f"{prefix}rows"]
        centroids = arrays[f"{prefix}centroids"]
        order = spread_order(centroids)
        return cls(
            np.ascontiguousarray(features[rows][:, order]),
            rows,
            arrays[f"{prefix}starts"],
            np.ascontiguousarray(centroids[:, order]),
            arrays[f"{prefix}radii"],
            arrays[f"{prefix}between"],
            order,
        )

    def nearest(self, queries: np.ndarray, k: int, eps: float) -> tuple[np.ndarray, np.ndarray]:
        """The k nearest features to queries (b, D) meters, in the table's dimensions
        (`samba.db.kernels.cells_kernel`): (distances (b, k) meters, table rows (b, k))."""
        from samba.db.kernels import cells_kernel  # numba only when a search runs

        found, stored = cells_kernel(*self._searched, queries, k, float(eps))
        return found, self.rows[stored]

    def nearest_to_markers(
        self, markers: np.ndarray, scale_by_tibia: bool, k: int, eps: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """`nearest` of observations (b, 8, 3) world meters that share the markers present
        (NaN = missing) these cells hold, aligned in the same compiled call
        (`nearest_poses_kernel`): (distances (b, k) meters, table rows (b, k))."""
        from samba.db.kernels import nearest_poses_kernel

        return nearest_poses_kernel(
            np.ascontiguousarray(markers),
            scale_by_tibia,
            *self._searched,
            self.rows,
            k,
            float(eps),
        )

    @property
    def _searched(self) -> tuple[np.ndarray, ...]:
        """What the cells' search kernels read, in their order."""
        return (self.features, self.starts, self.centroids, self.between, self.radii, self.order)

    @property
    def table_centroids(self) -> np.ndarray:
        """The centroids (cells, D) with their dimensions in the table's order."""
        return np.ascontiguousarray(self.centroids[:, np.argsort(self.order)])


def spread_order(centroids: np.ndarray) -> np.ndarray:
    """The dimensions (D,) of centroids (cells, D) by their spread, largest first."""
    return np.argsort(-np.var(centroids, axis=0), kind="stable").astype(np.int64)


@contextmanager
def _one_thread(faiss: ModuleType) -> Iterator[None]:
    """FAISS on one OpenMP thread (its spinning threads cost 2-10x on a busy machine)."""
    threads = faiss.omp_get_max_threads()
    faiss.omp_set_num_threads(1)
    try:
        yield
    finally:
        faiss.omp_set_num_threads(threads)
