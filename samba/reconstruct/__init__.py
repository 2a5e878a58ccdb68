"""13 joints from 8 markers: the Samba paper's reconstruction (retrieval, pseudo-poses, local
pose space, energy solve) and our joint-specific part retrieval, with the named method
presets (`nn`, `chai`, `samba`, `best`). The pose database comes in as a `NeighbourSource`.
"""

from samba.reconstruct.methods import METHODS, Method, method
from samba.reconstruct.neighbours import NeighbourSource
from samba.reconstruct.reconstruction import (
    PoseEstimate,
    ReconstructionConfig,
    Reconstructor,
    reconstruct_together,
)

__all__ = [
    "METHODS",
    "Method",
    "NeighbourSource",
    "PoseEstimate",
    "ReconstructionConfig",
    "Reconstructor",
    "method",
    "reconstruct_together",
]
