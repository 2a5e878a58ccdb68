"""Editing the JSON chunk of a .glb in tests (the binary chunk is kept as it is)."""

from __future__ import annotations

import json
import struct
from collections.abc import Callable
from typing import Any


def with_json(glb: bytes, edit: Callable[[dict[str, Any]], None]) -> bytes:
    """A .glb whose JSON chunk is `edit`ed in place (the binary chunk kept)."""
    size = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20 : 20 + size])
    edit(doc)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    rest = glb[20 + size :]
    head = struct.pack("<4sII", b"glTF", 2, 20 + len(text) + len(rest))
    return head + struct.pack("<I4s", len(text), b"JSON") + text + rest
