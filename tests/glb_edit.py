"""Saving a .glb as JSON glTF in tests (`samba.export.glb_with_json` edits a .glb's JSON)."""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path


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
