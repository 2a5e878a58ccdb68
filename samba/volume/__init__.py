"""Multi-camera volumetric capture (Chu, Jenkins, Mataric): visual-hull voxels from
calibrated silhouettes, Isomap and spherical shells per frame, one kinematic model for the
whole sequence, its joint angles, and the 13 joints of a humanoid capture.
"""

from samba.volume.capture import MIN_VOXELS, KinematicMotion, VolumeCapture, capture_volumes
from samba.volume.carving import Frames, carve_streams, learn_extractors
from samba.volume.floor_coverage import capture_region
from samba.volume.frame_kinematics import HUMAN_END_BRANCHES
from samba.volume.humanoid import humanoid_joints, walked_direction
from samba.volume.visual_hull import VisualHull, volume_cameras
from samba.volume.voxel_grid import VoxelGrid

__all__ = [
    "HUMAN_END_BRANCHES",
    "MIN_VOXELS",
    "Frames",
    "KinematicMotion",
    "VisualHull",
    "VolumeCapture",
    "VoxelGrid",
    "capture_region",
    "capture_volumes",
    "carve_streams",
    "humanoid_joints",
    "learn_extractors",
    "volume_cameras",
    "walked_direction",
]
