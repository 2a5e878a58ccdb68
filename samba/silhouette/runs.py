"""`SilhouetteRuns`: many binary silhouettes stored as horizontal runs, compared in O(runs).

A silhouette of a person is a few runs of foreground pixels per image row, so the shape
tree stores each one as its runs: run r covers pixels x0 <= x < x1 of row y. A weighted
XOR distance (`samba.silhouette.distance.SilhouetteWeights`) is a constant plus the sum
of per-pixel coefficients over the model's foreground; with the coefficients summed
along each row once per frame (a prefix grid P of shape (H, W + 1), P[y, x] = sum of the
row's first x coefficients), a run's share is P[y, x1] - P[y, x0]. A 320x240 silhouette
of about 10,000 pixels has about 300 runs: a distance costs 600 look-ups, and the
store takes 8 bytes per run (a run is two int32 flat indices into P).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from samba.base import InputError
from samba.silhouette.distance import SilhouetteWeights


def run_pixels(first: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Flat indices (lengths.sum(),) of every pixel of runs that start at flat index
    `first` (m,) and are `lengths` (m,) pixels long, run after run."""
    lengths = np.asarray(lengths, dtype=np.int64)
    skipped = np.cumsum(lengths) - lengths
    return np.repeat(first - skipped, lengths) + np.arange(lengths.sum())


@dataclass(frozen=True, eq=False)
class RowSums:
    """One frame's `SilhouetteWeights` prepared for runs: `prefix` (H * (W + 1),) float64,
    the row-wise prefix sums of the coefficients, flattened; `constant` and `pixels`
    (H * W) as in the weighted XOR."""

    size: tuple[int, int]
    prefix: np.ndarray
    constant: float
    pixels: int

    @classmethod
    def from_weights(cls, weights: SilhouetteWeights) -> RowSums:
        """The prefix grid of an observed silhouette's weights."""
        height, width = weights.shape
        prefix = np.zeros((height, width + 1))
        np.cumsum(weights.coefficients.reshape(height, width), axis=1, out=prefix[:, 1:])
        return cls((width, height), prefix.ravel(), weights.constant, height * width)


@dataclass(frozen=True, eq=False)
class SilhouetteRuns:
    """m silhouettes of `size` (W, H) as runs: silhouette i owns runs
    `offsets[i]:offsets[i + 1]`; run r spans flat indices `starts[r]` to `ends[r]` of
    the (H, W + 1) prefix grid (y * (W + 1) + x0 and y * (W + 1) + x1)."""

    size: tuple[int, int]
    offsets: np.ndarray
    starts: np.ndarray
    ends: np.ndarray

    def __len__(self) -> int:
        return len(self.offsets) - 1

    @property
    def nbytes(self) -> int:
        """Memory held by the arrays, bytes."""
        return self.offsets.nbytes + self.starts.nbytes + self.ends.nbytes

    @classmethod
    def from_masks(cls, masks: np.ndarray) -> SilhouetteRuns:
        """Runs of silhouettes (n, H, W) bool."""
        masks = np.asarray(masks)
        if masks.ndim != 3 or masks.dtype != bool:
            raise InputError(
                "silhouettes", f"expected (n, H, W) bool, got {masks.shape} {masks.dtype}"
            )
        n, height, width = masks.shape
        padded = np.zeros((n, height, width + 2), dtype=np.int8)
        padded[:, :, 1:-1] = masks
        change = np.diff(padded, axis=2)
        image, row, up = np.nonzero(change == 1)
        _, _, down = np.nonzero(change == -1)
        base = row * (width + 1)
        offsets = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.bincount(image, minlength=n), out=offsets[1:])
        return cls(
            (width, height),
            offsets,
            (base + up).astype(np.int32),
            (base + down).astype(np.int32),
        )

    @classmethod
    def concatenate(cls, parts: Sequence[SilhouetteRuns]) -> SilhouetteRuns:
        """The silhouettes of `parts` one after the other (all of one size)."""
        if not parts or len({p.size for p in parts}) != 1:
            raise ValueError("concatenate needs one or more run sets of one size")
        counts = np.concatenate([np.diff(p.offsets) for p in parts])
        offsets = np.zeros(len(counts) + 1, dtype=np.int64)
        np.cumsum(counts, out=offsets[1:])
        return cls(
            parts[0].size,
            offsets,
            np.concatenate([p.starts for p in parts]),
            np.concatenate([p.ends for p in parts]),
        )

    def subset(self, indices: np.ndarray) -> SilhouetteRuns:
        """The silhouettes at `indices` (k,), in that order."""
        indices = np.asarray(indices, dtype=np.int64)
        runs = self._run_indices(indices)
        counts = self.offsets[indices + 1] - self.offsets[indices]
        offsets = np.zeros(len(indices) + 1, dtype=np.int64)
        np.cumsum(counts, out=offsets[1:])
        return SilhouetteRuns(self.size, offsets, self.starts[runs], self.ends[runs])

    def to_masks(self) -> np.ndarray:
        """The silhouettes (m, H, W) bool."""
        width, height = self.size
        owner = np.repeat(np.arange(len(self)), np.diff(self.offsets))
        first = owner * (height * (width + 1)) + self.starts
        masks = np.zeros((len(self), height, width + 1), dtype=bool)
        masks.reshape(-1)[run_pixels(first, self.ends - self.starts)] = True
        return np.ascontiguousarray(masks[:, :, :width])

    def top_rows(self) -> np.ndarray:
        """The first image row (m,) int64 each silhouette covers (H for an empty one)."""
        width, height = self.size
        tops = np.full(len(self), height, dtype=np.int64)
        nonempty = self.offsets[1:] > self.offsets[:-1]
        tops[nonempty] = self.starts[self.offsets[:-1][nonempty]] // (width + 1)
        return tops

    def distances(self, sums: RowSums, indices: np.ndarray | None = None) -> np.ndarray:
        """Weighted XOR distances (k,) of the silhouettes at `indices` (default: all) to
        the observed silhouette whose weights `sums` holds, as
        `SilhouetteWeights.distances` gives them."""
        if sums.size != self.size:
            raise InputError(
                "silhouettes", f"size {self.size} differs from the frame's {sums.size}"
            )
        if indices is None:
            offsets, starts, ends = self.offsets, self.starts, self.ends
        else:
            indices = np.asarray(indices, dtype=np.int64)
            runs = self._run_indices(indices)
            counts = self.offsets[indices + 1] - self.offsets[indices]
            offsets = np.zeros(len(indices) + 1, dtype=np.int64)
            np.cumsum(counts, out=offsets[1:])
            starts, ends = self.starts[runs], self.ends[runs]
        shares = sums.prefix[ends] - sums.prefix[starts]
        totals = np.zeros(len(offsets) - 1)
        nonempty = offsets[1:] > offsets[:-1]
        totals[nonempty] = np.add.reduceat(shares, offsets[:-1][nonempty])
        return (sums.constant + totals) / sums.pixels

    def _run_indices(self, indices: np.ndarray) -> np.ndarray:
        counts = self.offsets[indices + 1] - self.offsets[indices]
        total = int(counts.sum())
        firsts = np.repeat(self.offsets[indices] - np.cumsum(counts) + counts, counts)
        return firsts + np.arange(total)
