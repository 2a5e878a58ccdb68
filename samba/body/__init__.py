"""The 13-joint body every part of Samba shares: joints, the 8-marker set, bones and the
standard pose (`skeleton`), forward kinematics, the canonical alignment of markers, takes,
line-segment distances, the frame of the segment each joint rides on, and the capsule body
model of the markerless modes.
"""

from samba.body.alignment import Alignment, align_markers, has_heading
from samba.body.body_model import (
    CAPSULE_NAMES,
    CAPSULE_PARTS,
    KINDS,
    PART_NAMES,
    BodyModel,
    checked_poses,
    scaled_to,
)
from samba.body.kinematics import (
    continuous_quaternions,
    euler_to_quaternions,
    forward_kinematics,
    resample_times,
    sample_linear,
    sample_rotations,
    unit_vectors,
    whole_fps,
)
from samba.body.segment_frames import SEGMENT_OF, joint_frames, trunk_frames
from samba.body.segments import point_segment_distances, segment_distances
from samba.body.skeleton import (
    BONES,
    JOINT_INDEX,
    JOINT_NAMES,
    MARKER_JOINTS,
    MARKER_NAMES,
    N_JOINTS,
    N_MARKERS,
    TORSO_EDGES,
    UNOBSERVED_JOINTS,
    Body,
    facing_directions,
    markers_of,
    mean_facing,
    mirror_poses,
    pose_batch,
    standard_pose,
    standing_pose,
)
from samba.body.take import Take

__all__ = [
    "BONES",
    "CAPSULE_NAMES",
    "CAPSULE_PARTS",
    "JOINT_INDEX",
    "JOINT_NAMES",
    "KINDS",
    "MARKER_JOINTS",
    "MARKER_NAMES",
    "N_JOINTS",
    "N_MARKERS",
    "PART_NAMES",
    "SEGMENT_OF",
    "TORSO_EDGES",
    "UNOBSERVED_JOINTS",
    "Alignment",
    "Body",
    "BodyModel",
    "Take",
    "align_markers",
    "checked_poses",
    "continuous_quaternions",
    "euler_to_quaternions",
    "facing_directions",
    "forward_kinematics",
    "has_heading",
    "joint_frames",
    "markers_of",
    "mean_facing",
    "mirror_poses",
    "point_segment_distances",
    "pose_batch",
    "resample_times",
    "sample_linear",
    "sample_rotations",
    "scaled_to",
    "segment_distances",
    "standard_pose",
    "standing_pose",
    "trunk_frames",
    "unit_vectors",
    "whole_fps",
]
