"""13 joints from 8 markers: the Samba paper's reconstruction (retrieval, pseudo-poses, local
pose space, energy solve) and our joint-specific part retrieval, with the named method
presets (`nn`, `chai`, `samba`, `best`), and a subject's skin-marker offsets (calibrated from
its own take, removed before retrieval). The pose database comes in as a `NeighbourSource`.
"""

from samba.reconstruct.marker_hold import MarkerHold
from samba.reconstruct.methods import METHODS, Method, method
from samba.reconstruct.neighbours import NeighbourSource
from samba.reconstruct.reconstruction import (
    PoseEstimate,
    Reconstruction,
    ReconstructionConfig,
    Reconstructor,
    reconstruct_together,
    reconstruction_kernels,
)
from samba.reconstruct.skin_offsets import (
    SkinMarkerReconstructor,
    SkinOffsets,
    calibrate_skin_offsets,
)

__all__ = [
    "METHODS",
    "MarkerHold",
    "Method",
    "NeighbourSource",
    "PoseEstimate",
    "Reconstruction",
    "ReconstructionConfig",
    "Reconstructor",
    "SkinMarkerReconstructor",
    "SkinOffsets",
    "calibrate_skin_offsets",
    "method",
    "reconstruct_together",
    "reconstruction_kernels",
]
