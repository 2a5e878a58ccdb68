"""Importers: BVH of any rig and recorded MCAP takes to 13-joint takes in meters, +Y up
(rig mapping, unit and up-axis detection, resampling), and batch import into a pose store;
marker takes (C3D files, recorded takes' markers) with their marker sets, the reference
joint centres of a full marker set by published rules, and a BVH rig rewritten as other
tools write theirs (`rig_variant`); skeletons sketched as joint lists, written as BVH
(`rest_pose_bvh`, the refused `QUADRUPED`).
"""

from samba.ingest.batch import FileResult, expand_paths, import_paths, read_file
from samba.ingest.bvh import BvhFile, BvhJoint, parse_bvh, read_bvh
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take
from samba.ingest.c3d_take import MarkerTake, read_c3d
from samba.ingest.errors import BvhError, C3dError, RigError
from samba.ingest.joint_centres import JointWidths, reference_joints
from samba.ingest.marker_sets import PLUG_IN_GAIT, MarkerSet
from samba.ingest.marker_takes import read_marker_take, read_recorded_markers
from samba.ingest.mcap_take import POSE_TOPIC, SUBJECT_METADATA, TAKE_METADATA, read_take
from samba.ingest.motion_table import reader_kernels
from samba.ingest.normalize import floor_height
from samba.ingest.resolver import HumanoidMap, SkeletonTree, name_kind, resolve_humanoid
from samba.ingest.rig_sketches import QUADRUPED, SketchJoint, rest_pose_bvh, unnamed_rig
from samba.ingest.rig_variants import RIG_CONVENTIONS, RIG_STRUCTURES, rig_variant
from samba.ingest.rigs import BUILTIN_RIGS, DETECTED, RigMap, detect_rig, rig_of

__all__ = [
    "BUILTIN_RIGS",
    "DETECTED",
    "PLUG_IN_GAIT",
    "POSE_TOPIC",
    "QUADRUPED",
    "RIG_CONVENTIONS",
    "RIG_STRUCTURES",
    "SUBJECT_METADATA",
    "TAKE_METADATA",
    "BvhError",
    "BvhFile",
    "BvhImportOptions",
    "BvhJoint",
    "C3dError",
    "FileResult",
    "HumanoidMap",
    "JointWidths",
    "MarkerSet",
    "MarkerTake",
    "RigError",
    "RigMap",
    "SkeletonTree",
    "SketchJoint",
    "detect_rig",
    "expand_paths",
    "floor_height",
    "import_paths",
    "load_bvh_take",
    "name_kind",
    "parse_bvh",
    "read_bvh",
    "read_c3d",
    "read_file",
    "read_marker_take",
    "read_recorded_markers",
    "read_take",
    "reader_kernels",
    "reference_joints",
    "resolve_humanoid",
    "rest_pose_bvh",
    "rig_of",
    "rig_variant",
    "unnamed_rig",
]
