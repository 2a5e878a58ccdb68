"""The pose database: a crash-safe store of 13-joint takes (`PoseStore`), its prebuilt
k-nearest index (`PoseIndex`), and the silhouette shape trees saved beside the poses.
Foreign file formats are `samba.ingest`'s business.
"""

from samba.db.errors import QueryError, StoreCorruptedError, StoreError
from samba.db.index import PoseIndex, index_kernels
from samba.db.shape_tree_file import read_shape_tree, stored_tree, tree_path, write_shape_tree
from samba.db.store import AddResult, PoseStore, VerifyReport
from samba.db.synthetic_store import build_synthetic_store
from samba.db.take_rows import check_addable

__all__ = [
    "AddResult",
    "PoseIndex",
    "PoseStore",
    "QueryError",
    "StoreCorruptedError",
    "StoreError",
    "VerifyReport",
    "build_synthetic_store",
    "check_addable",
    "index_kernels",
    "read_shape_tree",
    "stored_tree",
    "tree_path",
    "write_shape_tree",
]
