"""Samba capture math: the 13-joint skeleton, the 8-marker set, alignment, synthetic motions.

This package owns no sockets and no foreign file formats; `db`, `ingest`, `export` and
`service` build on it.
"""

from samba.base.errors import InputError, SambaError

__all__ = ["InputError", "SambaError"]
