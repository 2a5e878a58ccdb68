"""Editing the JSON chunk of a .glb in tests (the binary chunk is kept as it is), and
saving a .glb as JSON glTF."""

from __future__ import annotations

import base64
import json
import struct
from collections.abc import Callable
from pathlib import Path
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


def write_gltf(glb: bytes, path: Path, bin_name: str | None) -> None:
    """The .glb `glb` saved as JSON glTF at `path`: its binary chunk as the file
    `bin_name` beside it (`buffers[0].uri`), or as a base64 data URI when None."""
    size = struct.unpack_from("<I", glb, 12)[0]
    doc = json.loads(glb[20 : 20 + size])
    binary_size = struct.unpack_from("<I", glb, 20 + size)[0]
    binary = glb[28 + size : 28 + size + binary_size]
    if bin_name is None:
        uri = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
    else:
        (path.parent / bin_name).write_bytes(binary)
        uri = bin_name
    doc["buffers"][0]["uri"] = uri
    path.write_text(json.dumps(doc))
