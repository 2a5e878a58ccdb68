"""The pose database: a crash-safe store of 13-joint poses and its prebuilt k-d tree index.

`PoseStore` (store.py) holds takes and poses; `PoseIndex` (index.py) answers k-nearest
queries for marker observations. Foreign formats are `ingest`'s business.
"""

from samba.db.errors import QueryError, StoreCorruptedError, StoreError
from samba.db.index import PoseIndex
from samba.db.store import AddResult, PoseStore, VerifyReport

__all__ = [
    "AddResult",
    "PoseIndex",
    "PoseStore",
    "QueryError",
    "StoreCorruptedError",
    "StoreError",
    "VerifyReport",
]
