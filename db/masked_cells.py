"""Masked tables of a large pose index, made in the background from the full table's cells.

An observation with markers missing is compared with database features aligned with the
same markers masked (`samba.db.index`). On a large table a masked table's cells used to be
a k-means of its own, built by the first query that lost those markers: 2.6-4.2 s at 10^6
poses, a freeze of the live capture. Here nothing waits:

- the first query of a marker mask is answered from the full table's cells
  (`samba.db.kernels.projected_kernel`: each pose's masked features follow from its full
  ones by a turn and a centring; exact, up to the float32 rounding of the features, about
  1e-7 m), and queues the mask;
- one background thread makes the mask's table: its features (`marker_features_kernel`)
  and their Voronoi cells around the full table's centroids seen with the same markers
  (`VoronoiCells.around`, a nearest-centroid assignment, no k-means): 1.2-2.2 s at 10^6
  poses, after which the mask's queries read those cells (`cells_kernel`, the same
  answers as a scan of the masked table).

The turned cell means a heading other than the shoulders' needs (`turned_centers_kernel`,
about 0.1 s per heading at 10^6 poses) are made by the background thread when it starts,
before any table (a query that needs them sooner makes them). An index that scales
poses by tibia length compares a mask without a knee or foot at another scale, and a mask
without a left/right pair keeps the world's heading, which the full table's features do
not give: such a query waits for its table.
"""

from __future__ import annotations

import threading
from collections import OrderedDict, deque

import numpy as np

from samba.body import HEADING_PAIRS, N_MARKERS, TIBIA_PAIRS
from samba.db.cells import VoronoiCells
from samba.db.kernels import (
    marker_features_kernel,
    projected_kernel,
    turned_centers_kernel,
)

_TIBIA_MARKERS = np.array(sorted({m for pair in TIBIA_PAIRS for m in pair}))


class MaskedCells:
    """The masked tables of an index of `poses` (n, 13, 3) meters whose full table has
    `cells` (24-D features), made in the background and kept up to `capacity` (least
    recently used dropped). Thread-safe."""

    def __init__(
        self, poses: np.ndarray, cells: VoronoiCells, scale_by_tibia: bool, capacity: int
    ) -> None:
        self.poses = poses
        self.cells = cells
        self.scale_by_tibia = scale_by_tibia
        self.capacity = capacity
        self._ready: OrderedDict[int, VoronoiCells] = OrderedDict()
        self._waiting: deque[tuple[int, np.ndarray]] = deque()
        self._queued: set[int] = set()
        self._turned: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._failed: dict[int, str] = {}
        self._lock = threading.Lock()
        self._built = threading.Condition(self._lock)
        self._worker: threading.Thread | None = None
        self._start_worker()

    def query(
        self, keep: np.ndarray, f: np.ndarray, k: int, eps: float, mask: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """The k nearest of masked features f (b, 3 m), markers `keep` (8,) bool whose bit
        `mask` is given: distances (b, k) meters and table rows (b, k); by the mask's cells
        once made (`eps` as the full table's), exactly from the full table's cells before."""
        f = np.ascontiguousarray(f, dtype=np.float64)
        table = self.made(mask)
        if table is None and not self._projectable(keep):
            table = self.wait(keep)
        if table is not None:
            return table.nearest(f, k, eps)
        self.prepare(keep)
        pair = _heading_pair(keep)
        centers, radii = self._turned_centers(pair)
        cells = self.cells
        found, stored = projected_kernel(
            cells.features,
            cells.starts,
            cells.order,
            centers,
            radii,
            np.array([-1, -1] if pair == 0 else HEADING_PAIRS[pair]),
            keep,
            f,
            k,
        )
        return found, cells.rows[stored]

    def made(self, mask: int) -> VoronoiCells | None:
        """The cells of the table of bit `mask` if made (now the most recently used)."""
        with self._lock:
            table = self._ready.get(mask)
            if table is not None:
                self._ready.move_to_end(mask)
            return table

    def _projectable(self, keep: np.ndarray) -> bool:
        """Whether masked features of markers `keep` (8,) bool follow from the full ones: a
        left/right pair gives their heading, and with tibia scaling no knee or foot is
        missing."""
        if self.scale_by_tibia and not keep[_TIBIA_MARKERS].all():
            return False
        return any(keep[left] and keep[right] for left, right in HEADING_PAIRS)

    def prepare(self, keep: np.ndarray) -> None:
        """Queue the table of markers `keep` (8,) bool, unless made or queued."""
        mask = _mask_of(keep)
        with self._lock:
            if mask in self._ready or mask in self._queued:
                return
            self._queued.add(mask)
            self._waiting.append((mask, keep.copy()))
            self._start_worker()

    def _start_worker(self) -> None:
        """Start the background thread unless it runs (called with the lock held, or
        before the object is shared)."""
        if self._worker is None or not self._worker.is_alive():
            self._worker = threading.Thread(target=self._work, daemon=True)
            self._worker.start()

    def wait(self, keep: np.ndarray) -> VoronoiCells:
        """The table of markers `keep` (8,) bool, queued if needed, once made."""
        self.prepare(keep)
        mask = _mask_of(keep)
        with self._built:
            self._built.wait_for(lambda: mask in self._ready or mask not in self._queued)
            if mask not in self._ready:
                raise RuntimeError(
                    f"the masked table of markers {keep.tolist()} failed: {self._failed[mask]}"
                )
            return self._ready[mask]

    def wait_all(self) -> None:
        """Block until every queued table is made."""
        with self._built:
            self._built.wait_for(lambda: not self._waiting)

    def _work(self) -> None:
        """The background thread: the turned cell means of every heading first (a query
        losing a shoulder needs them), then the queued tables, oldest first."""
        for pair in range(1, len(HEADING_PAIRS)):
            self._turned_centers(pair)
        while True:
            with self._lock:
                if not self._waiting:
                    self._worker = None
                    return
                mask, keep = self._waiting[0]
            table = None
            try:
                table = self._table(keep)
            except Exception as error:  # reported by `wait`; queries keep the full cells
                self._failed[mask] = f"{type(error).__name__}: {error}"
            with self._built:
                self._waiting.popleft()
                self._queued.discard(mask)
                if table is not None:
                    self._ready[mask] = table
                    if len(self._ready) > self.capacity:
                        self._ready.popitem(last=False)
                self._built.notify_all()

    def _table(self, keep: np.ndarray) -> VoronoiCells:
        """The cells of the masked table of markers `keep` (8,) bool."""
        features = marker_features_kernel(np.asarray(self.poses), keep, self.scale_by_tibia)
        centers, _ = self._turned_centers(_heading_pair(keep))
        markers = centers.reshape(len(centers), N_MARKERS, 3)[:, keep]
        centroids = markers - markers.mean(axis=1, keepdims=True)
        return VoronoiCells.around(features, centroids.reshape(len(centers), -1))

    def _turned_centers(self, pair: int) -> tuple[np.ndarray, np.ndarray]:
        """The full table's cell means (cells, 24) and radii (cells,) with heading pair
        `pair` (0: the shoulders', the cells' own centroids)."""
        if pair == 0:
            return self.cells.table_centroids, self.cells.radii
        with self._lock:
            made = self._turned.get(pair)
        if made is None:
            cells = self.cells
            turn = np.array(HEADING_PAIRS[pair])
            made = turned_centers_kernel(cells.features, cells.starts, cells.order, turn)
            with self._lock:
                self._turned[pair] = made
        return made


def _mask_of(keep: np.ndarray) -> int:
    """The bit mask of markers `keep` (8,) bool."""
    return int(np.asarray(keep, dtype=np.int64) @ (1 << np.arange(N_MARKERS)))


def _heading_pair(keep: np.ndarray) -> int:
    """The first of `HEADING_PAIRS` whose markers are both in `keep` (8,) bool (0 when
    none is: the table then has no heading to turn to)."""
    for number, (left, right) in enumerate(HEADING_PAIRS):
        if keep[left] and keep[right]:
            return number
    return 0
