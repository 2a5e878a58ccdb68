"""The pose database: a crash-safe store of 13-joint takes (`PoseStore`), its prebuilt
k-nearest index (`PoseIndex`), and the silhouette shape trees saved beside the poses.
Foreign file formats are `samba.ingest`'s business.
"""

from samba.db.errors import QueryError, StoreCorruptedError, StoreError
from samba.db.index import PoseIndex, index_kernels
from samba.db.shape_tree_file import read_shape_tree, stored_tree, tree_path, write_shape_tree
from samba.db.store import AddResult, PoseStore, VerifyReport
from samba.db.synthetic_store import build_synthetic_store
from samba.db.take_checks import (
    FPS_RANGE,
    MAX_COORDINATE_M,
    MAX_TAKE_FRAMES,
    check_addable,
    frame_count_problem,
    frame_rate_problem,
    take_problems,
)
from samba.db.take_refs import id_text

__all__ = [
    "FPS_RANGE",
    "MAX_COORDINATE_M",
    "MAX_TAKE_FRAMES",
    "AddResult",
    "PoseIndex",
    "PoseStore",
    "QueryError",
    "StoreCorruptedError",
    "StoreError",
    "VerifyReport",
    "build_synthetic_store",
    "check_addable",
    "frame_count_problem",
    "frame_rate_problem",
    "id_text",
    "index_kernels",
    "read_shape_tree",
    "stored_tree",
    "take_problems",
    "tree_path",
    "write_shape_tree",
]
