"""Samba: low-cost real-time motion capture from eight markers, a few cameras and a database
of real human poses.

The capture math lives in one subpackage per concern (`samba.body`, `samba.reconstruct`,
`samba.cameras`, `samba.markers`, `samba.silhouette`, `samba.volume`, `samba.synthetic`,
`samba.evaluation`, on `samba.base`); above it the pose database (`samba.db`), importers
(`samba.ingest`), avatars and file writers (`samba.export`), the live service
(`samba.service`) and the `samba` command (`samba.cli`). Each package imports the others
only through their faces (their `__init__`), in that order of layers.
"""

import time

from samba.base import InputError, SambaError

LAUNCHED_AT = time.time()
"""When this process first imported samba, UNIX seconds: for a `samba` command, about
when it was launched, before its own start-up (importing, loading, compiling)."""

__all__ = ["LAUNCHED_AT", "InputError", "SambaError"]
