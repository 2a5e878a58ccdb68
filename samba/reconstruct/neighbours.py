"""`NeighbourSource`: what the reconstruction needs of a pose database, as a protocol.

The reconstruction takes its neighbours from anything with a k-nearest query over a pose
array (`samba.db.PoseIndex`, or a test's own), so it imports nothing of `samba.db`.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np


class NeighbourSource(Protocol):
    """Anything with a k-nearest-pose query over a pose array, e.g. `samba.db.PoseIndex`."""

    poses: np.ndarray
    """(n, 13, 3) database poses, meters."""
    scale_by_tibia: bool
    """Whether the query compares tibia-normalised markers (`samba.body.alignment`)."""

    def query(
        self, markers: np.ndarray, k: int = 10, eps: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """(distances, row indices), each (b, k), of markers (b, 8, 3) with NaN = missing."""
        ...
