"""Importers: BVH of any rig (and, later, recorded takes) to 13-joint takes in meters, +Y up.

`read_bvh` / `parse_bvh` (bvh.py) read the format, `load_bvh_take` (bvh_take.py) maps a
rig (rigs.py) and normalises units and axes (normalize.py), `import_paths` (batch.py)
fills a pose store.
"""

from samba.ingest.batch import FileResult, import_paths
from samba.ingest.bvh import BvhFile, BvhJoint, parse_bvh, read_bvh
from samba.ingest.bvh_take import BvhImportOptions, load_bvh_take
from samba.ingest.errors import BvhError, RigError
from samba.ingest.rigs import BUILTIN_RIGS, RigMap, detect_rig

__all__ = [
    "BUILTIN_RIGS",
    "BvhError",
    "BvhFile",
    "BvhImportOptions",
    "BvhJoint",
    "FileResult",
    "RigError",
    "RigMap",
    "detect_rig",
    "import_paths",
    "load_bvh_take",
    "parse_bvh",
    "read_bvh",
]
