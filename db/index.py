"""The prebuilt k-d tree index: k nearest database poses for observed markers.

Features are the 8 markers of each pose after `samba.body.alignment.align_markers` (24
numbers, meters). The distance between an observation and a pose is the Euclidean
distance between their features over the markers the observation has.

Design, for 10^6 poses and sub-100-microsecond queries: the k-d tree (scipy `cKDTree`)
holds a PCA projection of the features to `dims` dimensions. Projection onto an
orthonormal basis never lengthens a vector, so a pose's projected distance is a lower
bound of its true distance. A query takes `EXACT_FETCH` * k nearest poses from the tree,
re-ranks them by true distance, and accepts the top k once the k-th true distance is no
more than the largest projected distance fetched; otherwise it fetches more. Results
are therefore exact, equal to brute force.

In 14 dimensions a tree over a few ten thousand poses is too shallow to split most axes,
so an exact search visits most of its leaves. Up to `scan_limit` poses (`SCAN_LIMIT`,
the crossover `bench/bench_db.py` measures), exact queries scan the features instead;
approximate ones still use the tree, which is then faster. A scan ranks every pose by
|f|^2 - 2 f.q in float32 (one matrix product per chunk of queries), re-ranks the best
`EXACT_FETCH` * k by true distance, and scans a row again in full precision when its
k-th distance is not clear, by the float32 error bound, of the best pose left out.

An observation with missing markers is compared with features of the database poses
computed by the same alignment with the same markers masked, so that the origin and
heading agree; a table for each such mask is made on first use and kept (the 8 masks of
one missing marker are the common ones). With the compiled kernels a small masked table
is scanned, and a large index's are made in the background while the full table's cells
answer (`samba.db.masked_cells`), so that no query waits for one.
"""

from __future__ import annotations

import os
import tempfile
import zipfile
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np
import scipy
from scipy.spatial import cKDTree

from samba.base import KernelSet, kernels_enabled, usable_cores
from samba.body import N_MARKERS, align_markers, markers_of
from samba.db.cells import VoronoiCells
from samba.db.errors import QueryError, StoreError

if TYPE_CHECKING:
    from samba.db.masked_cells import MaskedCells

FORMAT = 3
DEFAULT_DIMS = 14
LEAF_SIZE = 32
MAX_MASK_TREES = 64
"""Masked tables kept (least recently used dropped): enough for every pattern of one or two
missing markers (8 + 28) and the masks `best`'s parts query with them (63 in all), which a
live capture prepares (`Reconstructor.prepare`) and random dropout keeps asking for. A
table holds about 200-300 bytes per pose (features, their scan copy, the tree once
searched)."""
APPROXIMATE_EPS = 0.75
"""The eps of approximate queries that keeps recall@10 >= 0.99 at 10^6 poses (bench_db)."""
EXACT_FETCH = 2
"""Exact queries first fetch this many times k candidates (more when not certified)."""
APPROXIMATE_FETCH = 4
"""Approximate queries fetch this many times k candidates and re-rank them."""
SCAN_LIMIT = 100_000
"""Largest table a query scans rather than searching its cells (compiled kernels; any
eps) or its tree (numpy; exact queries). A scan needs nothing built: a masked table
searched by cells or a tree is built when a marker is first lost (a k-means of 0.05 s at
3 x 10^4 poses, 0.2 s at 10^5), which stalls a live frame (`best` with 10% dropout:
p99 55 ms with a limit of 20,000, 2026-12-05). bench_db, single queries, 2026-12-05:
the compiled scan 0.05 ms at 1.6 x 10^4 poses and 0.5 ms at 10^5, the cells 0.06-0.1 ms;
numpy's scan ties the exact tree at 10^4 and takes 1.7x its time at 3 x 10^4."""
SCAN_CHUNK = 64
"""Queries scanned per matrix product (bounds the (chunk, n) distance block)."""
MASKED_CELLS_FROM = 20_000
"""With the compiled kernels, an index of more poses answers queries with markers missing
from masked cells made in the background (`samba.db.masked_cells`) instead of scanning a
masked table (the compiled scan: 0.05 ms at 1.6 x 10^4 poses, 0.5 ms at 10^5; the cells
0.06-0.1 ms)."""
_MASK_BITS = 1 << np.arange(N_MARKERS)
"""A marker set's bit mask is its presence (8,) bool times these."""
THREADED_BATCH = 64
"""Batches of at least this many queries are split over the cores (compiled kernels)."""


@dataclass(frozen=True)
class _Tree:
    """A reduced-space k-d tree over the features of one marker mask. `prebuilt` is a tree
    built in advance (the full index's, built with it and saved with the store); without
    one the tree is built on the first search, so tables that are only scanned (masked
    ones of small stores) never build it."""

    features: np.ndarray  # (n, 3 * present) float32, aligned markers present in the mask
    dims: int  # principal dimensions the tree keeps
    prebuilt_projection: tuple[np.ndarray, np.ndarray] | None = None
    prebuilt: cKDTree | None = None
    prebuilt_cells: VoronoiCells | None = None

    @cached_property
    def projection(self) -> tuple[np.ndarray, np.ndarray]:
        """The tree's (mean (D,), basis (D, dims) orthonormal columns) of the features'
        principal dimensions, made on first use unless prebuilt (the compiled search
        never needs them)."""
        if self.prebuilt_projection is not None:
            return self.prebuilt_projection
        features = self.features
        mean = features.mean(axis=0, dtype=np.float64)
        centered = features - mean.astype(np.float32)
        cov = (centered.T @ centered).astype(np.float64) / max(len(features), 1)
        _, vectors = np.linalg.eigh(cov)
        dims = min(self.dims, features.shape[1])
        return mean, np.ascontiguousarray(vectors[:, ::-1][:, :dims])

    @cached_property
    def cells(self) -> VoronoiCells:
        """The k-means cells of the features (`samba.db.cells`), built on first use unless
        prebuilt (the full index's, built with it and saved with the store)."""
        if self.prebuilt_cells is not None:
            return self.prebuilt_cells
        return VoronoiCells.build(self.features)

    @cached_property
    def tree(self) -> cKDTree:
        """The k-d tree over the features projected onto `basis`."""
        if self.prebuilt is not None:
            return self.prebuilt
        return _reduced_tree(self.features, *self.projection)

    @cached_property
    def _scanned(self) -> tuple[np.ndarray, np.ndarray, float]:
        """What scans read, made on the first: the features transposed and scaled by -2
        (D, n) float32 (a contiguous copy, which the matrix product reads twice as fast),
        their squared norms (n,) float32 and the largest of those."""
        norms = np.einsum("nd,nd->n", self.features, self.features, dtype=np.float64)
        scaled = np.ascontiguousarray(-2.0 * self.features.T, dtype=np.float32)
        return scaled, norms.astype(np.float32), float(norms.max())

    @classmethod
    def build(cls, features: np.ndarray, dims: int, prebuild: bool = False) -> _Tree:
        """The table of features (n, D), its tree to keep `dims` principal dimensions,
        with its projection, tree and cells built now when `prebuild`."""
        table = cls(np.ascontiguousarray(features, dtype=np.float32), dims)
        if not prebuild:
            return table
        projection = table.projection
        tree = _reduced_tree(table.features, *projection)
        return cls(table.features, dims, projection, tree, VoronoiCells.build(table.features))

    def query(self, f: np.ndarray, k: int, eps: float, scan: bool) -> tuple[np.ndarray, np.ndarray]:
        """k nearest of features f (b, D): distances (b, k), indices (b, k).

        `scan` searches by scanning every feature (exact); otherwise the tree: with
        eps == 0 the result is exact (fetching more candidates until certified), with
        eps > 0 the tree search is approximate and one batch of candidates is used.
        """
        if kernels_enabled():
            return self._compiled_query(np.ascontiguousarray(f, dtype=np.float64), k, eps, scan)
        if scan:
            return self._scan(f, k)
        n = len(self.features)
        mean, basis = self.projection
        z = (f - mean) @ basis
        f32 = f.astype(np.float32)
        fetch = min((EXACT_FETCH if eps == 0 else APPROXIMATE_FETCH) * k, n)
        dist, idx, bound = self._rerank(z, f32, k, fetch, eps)
        unsure = np.flatnonzero(dist[:, -1] > bound) if eps == 0 else ()
        while len(unsure) and fetch < n:
            fetch = min(fetch * 4, n)
            d, i, b = self._rerank(z[unsure], f32[unsure], k, fetch, eps)
            dist[unsure], idx[unsure] = d, i
            unsure = unsure[d[:, -1] > b]
        return dist, idx

    def _compiled_query(
        self, f: np.ndarray, k: int, eps: float, scan: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """`query` by the compiled kernels: the scan, or the cells (`eps` as the tree's).
        Batches of `THREADED_BATCH` or more queries are split over the cores (the kernels
        release the GIL)."""
        kernels = _kernels()
        if scan:

            def search(part: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                return kernels.scan_kernel(self.features, part, k)

        else:
            cells = self.cells

            def search(part: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                return cells.nearest(part, k, eps)

        workers = usable_cores()
        if len(f) < THREADED_BATCH or workers == 1:
            return search(f)
        with ThreadPoolExecutor(workers) as pool:
            parts = list(pool.map(search, np.array_split(f, workers)))
        return np.concatenate([d for d, _ in parts]), np.concatenate([i for _, i in parts])

    def _rerank(
        self, z: np.ndarray, f32: np.ndarray, k: int, fetch: int, eps: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Fetch `fetch` tree candidates per query and keep the k truly nearest.

        Returns (distances (b, k), indices (b, k), the largest reduced distance fetched
        (b,)), the last being a lower bound of the distance of every pose not fetched.
        """
        workers = -1 if len(z) >= 256 else 1
        bound, cand = self.tree.query(
            z, k=[fetch] if fetch == 1 else fetch, eps=eps, workers=workers
        )
        return (*self._nearest_of(cand, f32, k), bound[:, -1])

    def _nearest_of(self, cand: np.ndarray, q: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The k of candidate rows `cand` (b, m) truly nearest to features q (b, D)
        float32: (distances (b, k) float64, indices (b, k)), nearest first."""
        diff = self.features[cand] - q[:, None]
        true = np.sqrt(np.einsum("bkd,bkd->bk", diff, diff, dtype=np.float64))
        rows = np.arange(len(q))[:, None]
        if cand.shape[1] > 256:
            part = np.argpartition(true, k - 1, axis=1)[:, :k]
            true, cand = true[rows, part], cand[rows, part]
        order = np.argsort(true, axis=1, kind="stable")[:, :k]
        return true[rows, order], cand[rows, order]

    def _scan(self, f: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The exact k nearest of features f (b, D) by scanning all features, chunk by
        chunk: (distances (b, k), indices (b, k))."""
        n, width = self.features.shape
        scaled, norms, big = self._scanned
        fetch = min(EXACT_FETCH * k, n)
        # The ranking's float32 rounding is at most (width + 2) units in the last place of
        # |f|^2 + 2 |f| |q| <= 2 (|f|^2 + |q|^2), |f|^2 <= big: a pose left out ranks no
        # better than the fetch-th candidate, so a k-th distance clear of that by twice
        # the bound is exact.
        rounding = 4.0 * (width + 2) * float(np.finfo(np.float32).eps)
        f32 = f.astype(np.float32)
        dist, idx = [], []
        for start in range(0, len(f), SCAN_CHUNK):
            q = f32[start : start + SCAN_CHUNK]
            ranked = q @ scaled
            ranked += norms  # (c, n): |f - q|^2 - |q|^2
            cand = np.argpartition(ranked, fetch - 1, axis=1)[:, :fetch]
            d, i = self._nearest_of(cand, q, k)
            if fetch < n:
                q2 = np.einsum("bd,bd->b", q, q, dtype=np.float64)
                left_out = ranked[np.arange(len(q)), cand[:, -1]] + q2 * (1.0 - rounding)
                for r in np.flatnonzero(d[:, -1] ** 2 > left_out - rounding * big):
                    every = np.arange(n)[None]
                    d[r], i[r] = (a[0] for a in self._nearest_of(every, q[r : r + 1], k))
            dist.append(d)
            idx.append(i)
        return np.concatenate(dist), np.concatenate(idx)


class PoseIndex:
    """k nearest database poses for marker observations; see the module docstring.

    Build with `build(poses)`, persist with `save(path)` / `load(path, poses)`. `poses`
    (n, 13, 3) stays referenced (it may be a memory map) for trees of masked markers.
    `scan_limit`: exact queries of tables of at most this many poses scan them instead of
    searching the tree (`SCAN_LIMIT`; 0 always uses the tree).
    """

    def __init__(
        self, poses: np.ndarray, full: _Tree, generation: str, dims: int, scale_by_tibia: bool
    ) -> None:
        self.poses = poses
        self.generation = generation
        self.dims = dims
        self.scale_by_tibia = scale_by_tibia
        self._full = full
        self._masked: OrderedDict[int, _Tree] = OrderedDict()
        self._masked_large: MaskedCells | None = None
        self.scan_limit = SCAN_LIMIT
        if kernels_enabled():
            _kernels().KERNELS.warm_up()
            self._masked_cells()  # a large index starts its background work now

    def __len__(self) -> int:
        return len(self.poses)

    @property
    def features(self) -> np.ndarray:
        """Aligned marker features (n, 24) float32 of every pose, meters."""
        return self._full.features

    @classmethod
    def build(
        cls,
        poses: np.ndarray,
        generation: str = "",
        dims: int = DEFAULT_DIMS,
        scale_by_tibia: bool = False,
    ) -> PoseIndex:
        """Index poses (n, 13, 3) in meters; `generation` names the store state indexed.

        With `scale_by_tibia` every pose and observation is scaled to the reference tibia
        length before comparison, so bodies of other sizes find the same poses.
        """
        if len(poses) == 0:
            raise StoreError("index", "cannot index an empty pose set")
        features = marker_features(poses, np.ones(N_MARKERS, dtype=bool), scale_by_tibia)
        full = _Tree.build(features, dims, prebuild=True)
        return cls(poses, full, generation, dims, scale_by_tibia)

    def query(
        self, markers: np.ndarray, k: int = 10, eps: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """The k nearest poses to observations (b, 8, 3) or (8, 3), meters, NaN = missing.

        `eps` = 0 gives the exact k nearest (equal to brute force); `eps` > 0 trades
        exactness for speed (scipy's approximate k-d tree search with that eps; recall is
        measured in `bench/bench_db.py`, APPROXIMATE_EPS is the tuned value). Returns
        (distances, indices), each (b, k) or (k,) for a single observation:
        feature distances in meters over the markers present, and row numbers in the
        store's pose array, nearest first. Raises `QueryError` for a wrong shape, a bad
        k or an observation without markers.
        """
        markers = np.asarray(markers, dtype=np.float64)
        single = markers.ndim == 2
        if single:
            markers = markers[None]
        if markers.ndim != 3 or markers.shape[1:] != (N_MARKERS, 3):
            raise QueryError("markers", f"expected (8, 3) or (b, 8, 3), got {markers.shape}")
        if not eps >= 0:
            raise QueryError("eps", f"eps must be >= 0, got {eps}")
        if not 1 <= k <= len(self):
            raise QueryError("k", f"k must be in 1..{len(self)}, got {k}")
        present = ~np.isnan(markers).any(axis=-1)
        live = kernels_enabled() and len(markers) < THREADED_BATCH
        if live and present.all():
            dist, idx = self._full.cells.nearest_to_markers(markers, self.scale_by_tibia, k, eps)
            return (dist[0], idx[0]) if single else (dist, idx)
        masked_cells = self._masked_cells()
        if live and len(markers) == 1 and masked_cells is not None:  # a live frame
            made = masked_cells.made(int(present[0] @ _MASK_BITS))
            if made is not None:
                dist, idx = made.nearest_to_markers(markers, self.scale_by_tibia, k, eps)
                return (dist[0], idx[0]) if single else (dist, idx)
        if present.all():
            f = self._aligned(markers).reshape(len(markers), -1)
            dist, idx = self._full.query(f, k, eps, self._scans(eps, self._full))
            return (dist[0], idx[0]) if single else (dist, idx)
        if not present.any(axis=1).all():
            raise QueryError("markers", "an observation has no marker present")
        masks = present @ _MASK_BITS
        dist = np.empty((len(markers), k))
        idx = np.empty((len(markers), k), dtype=np.int64)
        groups: dict[int, list[int]] = {}
        for row, mask in enumerate(masks.tolist()):
            groups.setdefault(mask, []).append(row)
        aligned = None
        for mask, members in groups.items():
            rows = np.array(members)
            keep = present[members[0]]
            made = masked_cells.made(mask) if live and masked_cells is not None else None
            if made is not None:
                found = made.nearest_to_markers(markers[rows], self.scale_by_tibia, k, eps)
                dist[rows], idx[rows] = found
                continue
            aligned = self._aligned(markers) if aligned is None else aligned
            f = aligned[rows][:, keep].reshape(len(rows), -1)
            if masked_cells is not None:
                dist[rows], idx[rows] = masked_cells.query(keep, f, k, eps, mask)
                continue
            tree = self._tree(int(mask), keep)
            dist[rows], idx[rows] = tree.query(f, k, eps, self._scans(eps, tree))
        return (dist[0], idx[0]) if single else (dist, idx)

    def _aligned(self, markers: np.ndarray) -> np.ndarray:
        """Observations (b, 8, 3) world meters, NaN = missing, in the canonical frame of
        their own markers present (`align_markers`, compiled with the kernels)."""
        if kernels_enabled():
            return _kernels().aligned_markers_kernel(
                np.ascontiguousarray(markers), self.scale_by_tibia
            )
        return align_markers(markers, scale_by_tibia=self.scale_by_tibia)[0]

    def _masked_cells(self) -> MaskedCells | None:
        """The masked cells (`samba.db.masked_cells`) that answer queries with markers
        missing: with the compiled kernels, for an index of more than `scan_limit` or
        `MASKED_CELLS_FROM` poses; None when masked tables are scanned or searched by
        their trees."""
        if not kernels_enabled() or len(self) <= min(self.scan_limit, MASKED_CELLS_FROM):
            return None
        if self._masked_large is None:
            from samba.db.masked_cells import MaskedCells

            self._masked_large = MaskedCells(
                self.poses, self._full.cells, self.scale_by_tibia, MAX_MASK_TREES
            )
        return self._masked_large

    def wait_for_masked_tables(self) -> None:
        """Block until the masked tables queued in the background are made (tests and
        benchmarks that time their searches)."""
        if self._masked_large is not None:
            self._masked_large.wait_all()

    def _scans(self, eps: float, table: _Tree) -> bool:
        """Whether a query of `table` with this eps scans it. With the compiled kernels a
        table whose cells are prebuilt (the full one) is searched by them and a masked one
        scanned (exact, whatever the eps; large indexes use `_masked_cells` instead); by
        numpy, exact queries of small tables scan and the rest search the tree."""
        if kernels_enabled():
            return table.prebuilt_cells is None
        return eps == 0 and len(self) <= self.scan_limit

    def _tree(self, mask: int, keep: np.ndarray) -> _Tree:
        """The tree for a marker mask: the full one, or a cached masked one (LRU)."""
        if keep.all():
            return self._full
        tree = self._masked.get(mask)
        if tree is None:
            if kernels_enabled():
                features = _kernels().marker_features_kernel(
                    np.asarray(self.poses), keep, self.scale_by_tibia
                )
            else:
                features = marker_features(self.poses, keep, self.scale_by_tibia)
            tree = _Tree.build(features, self.dims)
            self._masked[mask] = tree
            if len(self._masked) > MAX_MASK_TREES:
                self._masked.popitem(last=False)
        else:
            self._masked.move_to_end(mask)
        return tree

    def save(self, path: str | Path) -> None:
        """Write the index to `path` atomically (temp file + rename); no pickle inside."""
        path = Path(path)
        full = self._full
        state = full.tree.__getstate__()
        arrays = {
            "format": np.array(FORMAT),
            "generation": np.array(self.generation),
            "scipy": np.array(scipy.__version__),
            "dims": np.array(self.dims),
            "scale_by_tibia": np.array(self.scale_by_tibia),
            "features": full.features,
            "mean": full.projection[0],
            "basis": full.projection[1],
            "tree_state": np.array(len(state)),
            **full.cells.arrays("cells_"),
        }
        for i, item in enumerate(state):
            if item is not None:
                arrays[f"tree_{i}"] = np.asarray(item)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".index-", suffix=".npz")
        try:
            with os.fdopen(fd, "wb") as fh:
                np.savez(fh, **arrays)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise

    @classmethod
    def load(cls, path: str | Path, poses: np.ndarray) -> PoseIndex | None:
        """Read an index saved by `save` for `poses`; None if absent, unreadable or stale
        for this scipy version or pose count (the caller rebuilds)."""
        try:
            with np.load(path, allow_pickle=False) as data:
                if int(data["format"]) != FORMAT or str(data["scipy"]) != scipy.__version__:
                    return None
                features = data["features"]
                if len(features) != len(poses):
                    return None
                n_state = int(data["tree_state"])
                state = tuple(
                    _state_item(data[f"tree_{i}"]) if f"tree_{i}" in data else None
                    for i in range(n_state)
                )
                tree = cKDTree.__new__(cKDTree)
                tree.__setstate__(state)
                cells = VoronoiCells.from_arrays(features, data, "cells_")
                projection = (data["mean"], data["basis"])
                full = _Tree(features, int(data["dims"]), projection, tree, cells)
                return cls(
                    poses,
                    full,
                    str(data["generation"]),
                    int(data["dims"]),
                    bool(data["scale_by_tibia"]),
                )
        except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
            return None


def _reduced_tree(features: np.ndarray, mean: np.ndarray, basis: np.ndarray) -> cKDTree:
    """The k-d tree over features (n, D) float32 centred on `mean` and projected onto the
    columns of `basis` (D, dims)."""
    reduced = (features - mean.astype(np.float32)) @ basis.astype(np.float32)
    return cKDTree(
        reduced.astype(np.float64), leafsize=LEAF_SIZE, balanced_tree=False, compact_nodes=False
    )


def _state_item(value: np.ndarray) -> object:
    return value.item() if value.ndim == 0 else value


def marker_features(
    poses: np.ndarray, keep: np.ndarray, scale_by_tibia: bool = False, chunk: int = 200_000
) -> np.ndarray:
    """The index's features of poses (n, 13, 3), meters: the markers in `keep` (8,) bool,
    aligned by `align_markers` with the other markers masked; (n, 3 * keep.sum()) float32.
    Processed in chunks of `chunk` poses to bound memory."""
    out = np.empty((len(poses), 3 * int(keep.sum())), dtype=np.float32)
    for start in range(0, len(poses), chunk):
        markers = markers_of(np.asarray(poses[start : start + chunk], dtype=np.float64))
        markers[:, ~keep] = np.nan
        aligned, _ = align_markers(markers, scale_by_tibia=scale_by_tibia)
        out[start : start + chunk] = aligned[:, keep].reshape(len(markers), -1)
    return out


def _kernels() -> ModuleType:
    """`samba.db.kernels`, imported on first use: numba's import (0.2 s) stays off
    commands that never query (`samba --help`)."""
    import samba.db.kernels as kernels

    return kernels


def index_kernels() -> KernelSet:
    """The pose index's compiled kernels (`samba.db.kernels.KERNELS`), for `samba warmup`;
    importing them imports numba."""
    return _kernels().KERNELS
