"""`VoxelGrid`: a regular grid of cubic voxels in the world, for volume capture.

The grid has `shape` (nx, ny, nz) voxels of edge `voxel` meters, axis-aligned with the
world frame (+Y up, meters). Voxel (ix, iy, iz) is centred at
``origin + voxel * (ix, iy, iz)``, so `origin` is the centre of voxel (0, 0, 0), not a
corner. An occupancy grid is an (nx, ny, nz) bool array; flat voxel indices and the
rows of `VoxelGrid.centers` follow its C order, ``(ix * ny + iy) * nz + iz``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from samba.base import InputError


def _vector(source: str, value: Sequence[float] | np.ndarray) -> np.ndarray:
    """`value` as a finite float64 (3,) vector; `InputError` naming `source` otherwise."""
    array = np.asarray(value, dtype=np.float64)
    if array.shape != (3,) or not np.isfinite(array).all():
        raise InputError(source, f"must be 3 finite numbers (x, y, z), got {value!r}")
    return array


def _edge(voxel: float) -> float:
    """`voxel` as a float edge length (m); `InputError` unless a finite number > 0."""
    if not isinstance(voxel, int | float | np.integer | np.floating) or not (
        np.isfinite(voxel) and voxel > 0
    ):
        raise InputError("voxel", f"voxel edge must be a finite length > 0 m, got {voxel!r}")
    return float(voxel)


@dataclass(frozen=True, eq=False)
class VoxelGrid:
    """A grid of `shape` (nx, ny, nz) cubic voxels of edge `voxel` m.

    `origin` (3,) m is the centre of voxel (0, 0, 0); voxel (ix, iy, iz) is centred at
    ``origin + voxel * (ix, iy, iz)``. Invalid values raise `InputError` naming the field.
    """

    origin: np.ndarray
    voxel: float
    shape: tuple[int, int, int]

    def __post_init__(self) -> None:
        origin = _vector("origin", self.origin)
        origin.flags.writeable = False
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "voxel", _edge(self.voxel))
        shape = tuple(self.shape) if isinstance(self.shape, Sequence | np.ndarray) else ()
        if len(shape) != 3 or not all(isinstance(n, int | np.integer) and n >= 1 for n in shape):
            raise InputError("shape", f"shape must be 3 positive integers, got {self.shape!r}")
        object.__setattr__(self, "shape", tuple(int(n) for n in shape))

    @classmethod
    def from_bounds(
        cls,
        low: Sequence[float] | np.ndarray,
        high: Sequence[float] | np.ndarray,
        voxel: float,
    ) -> VoxelGrid:
        """The smallest grid of `voxel` m cubes covering the box from `low` to `high` (3,) m.

        Each axis gets ``ceil((high - low) / voxel)`` voxels (at least one), centred on
        the box, so the grid's `bounds` hold the box and exceed it by less than a voxel.
        """
        low, high = _vector("low", low), _vector("high", high)
        if not (high > low).all():
            raise InputError("high", f"high {high.tolist()} must exceed low {low.tolist()}")
        voxel = _edge(voxel)
        counts = np.maximum(np.ceil((high - low) / voxel - 1e-9), 1).astype(int)
        origin = 0.5 * (low + high) - 0.5 * (counts - 1) * voxel
        return cls(origin, voxel, (int(counts[0]), int(counts[1]), int(counts[2])))

    @property
    def count(self) -> int:
        """Number of voxels, nx * ny * nz."""
        return int(np.prod(self.shape))

    @property
    def bounds(self) -> np.ndarray:
        """The box the voxels fill, (2, 3) m: its low and its high corner (voxel faces)."""
        low = self.origin - 0.5 * self.voxel
        return np.stack([low, low + self.voxel * np.array(self.shape)])

    def centers(self) -> np.ndarray:
        """Centres (nx * ny * nz, 3) m of all voxels, in C order of (ix, iy, iz)."""
        return self.points_at(np.indices(self.shape).reshape(3, -1).T)

    def indices(self, occupancy: np.ndarray) -> np.ndarray:
        """Indices (m, 3) int64 (ix, iy, iz) of the occupied voxels of `occupancy`, C order.

        `occupancy` is an (nx, ny, nz) bool grid; `InputError` when it does not fit.
        """
        return np.argwhere(self._checked(occupancy))

    def points(self, occupancy: np.ndarray) -> np.ndarray:
        """Centres (m, 3) m of the occupied voxels of `occupancy` (nx, ny, nz) bool, C order."""
        return self.points_at(self.indices(occupancy))

    def occupancy_of(self, points: np.ndarray) -> np.ndarray:
        """The (nx, ny, nz) bool grid of the voxels holding any of `points` (..., 3) m.

        A point belongs to the voxel whose centre is nearest; points outside the grid
        (and NaN points) are ignored.
        """
        points = np.asarray(points, dtype=np.float64)
        if points.shape[-1:] != (3,):
            raise InputError("points", f"points must have shape (..., 3), got {points.shape}")
        with np.errstate(invalid="ignore"):
            index = np.floor((points.reshape(-1, 3) - self.origin) / self.voxel + 0.5)
            inside = ((index >= 0) & (index < np.array(self.shape))).all(axis=1)
        occupancy = np.zeros(self.shape, dtype=bool)
        occupancy[tuple(index[inside].astype(np.int64).T)] = True
        return occupancy

    def points_at(self, index: np.ndarray) -> np.ndarray:
        """Centres (m, 3) m of the voxels at grid indices `index` (m, 3)."""
        return self.origin + self.voxel * index

    def _checked(self, occupancy: np.ndarray) -> np.ndarray:
        """`occupancy` as an array, `InputError` unless it is an (nx, ny, nz) bool grid."""
        occupancy = np.asarray(occupancy)
        if occupancy.shape != self.shape or occupancy.dtype != bool:
            raise InputError(
                "occupancy",
                f"occupancy must be a {self.shape} bool grid, "
                f"got {occupancy.dtype} {occupancy.shape}",
            )
        return occupancy
