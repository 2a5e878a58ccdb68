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

Every table of the index (the full one, each masked one) gets its own cells; the full
table's are built with the index and saved with the store, a masked table's with the table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

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
    cells are their Voronoi cells). Meters throughout."""

    features: np.ndarray
    rows: np.ndarray
    starts: np.ndarray
    centroids: np.ndarray
    radii: np.ndarray
    between: np.ndarray

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
        threads = faiss.omp_get_max_threads()
        faiss.omp_set_num_threads(1)  # OpenMP's spinning threads cost 2-10x on a busy machine
        try:
            kmeans.train(features)
            _, assigned = kmeans.index.search(features, 1)
        finally:
            faiss.omp_set_num_threads(threads)
        centroids = kmeans.centroids.astype(np.float64)
        between = cdist(centroids, centroids)
        return cls._of(features, assigned.ravel(), count, between, centroids)

    @classmethod
    def _of(
        cls,
        features: np.ndarray,
        assigned: np.ndarray,
        count: int,
        between: np.ndarray,
        centroids: np.ndarray,
    ) -> VoronoiCells:
        """Features stored by their cells `assigned` (n,) of `count` around `centroids`."""
        rows = np.argsort(assigned, kind="stable")
        ordered = np.ascontiguousarray(features[rows])
        starts = np.searchsorted(assigned[rows], np.arange(count + 1)).astype(np.int64)
        sizes = np.diff(starts)
        cell_of = np.repeat(np.arange(count), sizes)
        gaps = np.linalg.norm(ordered.astype(np.float64) - centroids[cell_of], axis=1)
        radii = np.zeros(count)
        np.maximum.at(radii, cell_of, gaps)
        # float32 features are compared with float32 queries: a margin for the rounding.
        radii = radii * (1.0 + 1e-6) + 1e-6
        return cls(ordered, rows.astype(np.int64), starts, centroids, radii, between)

    def __len__(self) -> int:
        return len(self.features)

    def arrays(self, prefix: str) -> dict[str, np.ndarray]:
        """The arrays to save, named `prefix` + field (the features are the table's own,
        saved by the index in table order)."""
        return {
            f"{prefix}rows": self.rows,
            f"{prefix}starts": self.starts,
            f"{prefix}centroids": self.centroids,
            f"{prefix}radii": self.radii,
            f"{prefix}between": self.between,
        }

    @classmethod
    def from_arrays(
        cls, features: np.ndarray, arrays: dict[str, np.ndarray], prefix: str
    ) -> VoronoiCells:
        """The cells saved by `arrays`, over the table's features (n, D) in table order."""
        rows = arrays[f"{prefix}rows"]
        return cls(
            np.ascontiguousarray(features[rows]),
            rows,
            arrays[f"{prefix}starts"],
            arrays[f"{prefix}centroids"],
            arrays[f"{prefix}radii"],
            arrays[f"{prefix}between"],
        )
