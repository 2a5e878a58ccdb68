"""Importers: BVH of any rig and recorded MCAP takes to 13-joint takes in meters, +Y up
(rig mapping, unit and up-axis detection, resampling), and batch import into a pose store.
"""

from samba.ingest.batch import FileResult, expand_paths, import_paths
from samba.ingest.bvh import BvhFile, BvhJoint, parse_bvh, read_bvh
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take
from samba.ingest.errors import BvhError, RigError
from samba.ingest.mcap_take import POSE_TOPIC, TAKE_METADATA, read_take
from samba.ingest.resolver import HumanoidMap, SkeletonTree, name_kind, resolve_humanoid
from samba.ingest.rigs import BUILTIN_RIGS, DETECTED, RigMap, detect_rig, rig_of

__all__ = [
    "BUILTIN_RIGS",
    "DETECTED",
    "POSE_TOPIC",
    "TAKE_METADATA",
    "BvhError",
    "BvhFile",
    "BvhImportOptions",
    "BvhJoint",
    "FileResult",
    "HumanoidMap",
    "RigError",
    "RigMap",
    "SkeletonTree",
    "detect_rig",
    "expand_paths",
    "import_paths",
    "load_bvh_take",
    "name_kind",
    "parse_bvh",
    "read_bvh",
    "read_take",
    "resolve_humanoid",
    "rig_of",
]
