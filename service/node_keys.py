"""`NodeKeys`: which node's key may speak for which camera, read from the server's keys file.

Every camera node signs its packets with a key of its own (`samba node --key-file`), and
the server checks each packet with the key listed for the packet's session and camera
(`samba.service.packet.decode`), so a node can speak only for its own cameras. The
keys file (`samba serve --keys FILE`) is TOML, one `[[node]]` table per node:

| key | type | meaning |
|---|---|---|
| `key_file` | path | the node's key file (raw bytes, at least 16; relative to this file) |
| `cameras` | list of integers | the camera ids the node may send, 0..65535 |
| `session` | string | the session those cameras belong to; absent: every session |

A (session, camera) pair has at most one key, and no two nodes share a key; a table
naming the session wins over one that does not. Make a key with
`head -c 32 /dev/urandom > cam0.key` and keep it readable by its owner only.
"""

from __future__ import annotations

import tomllib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from samba.service.errors import ServiceError
from samba.service.packet import read_key_file
from samba.service.session_config import SESSION_NAME

_KEYS = ("key_file", "cameras", "session")


@dataclass(frozen=True)
class NodeKey:
    """One node's `key` (bytes), the `cameras` (ids) it may speak for, in `session`
    (None: every session); `source` names it in error messages."""

    key: bytes
    cameras: frozenset[int]
    session: str | None = None
    source: str = "node key"


class NodeKeys:
    """The keys of a server's nodes; `key_for` picks a packet's. `ServiceError` naming
    the two keys when two speak for the same camera of the same session or are equal."""

    def __init__(self, keys: Iterable[NodeKey]) -> None:
        self._keys: dict[tuple[str | None, int], NodeKey] = {}
        by_bytes: dict[bytes, NodeKey] = {}
        for node in keys:
            twin = by_bytes.setdefault(node.key, node)
            if twin is not node:
                raise ServiceError(
                    node.source, f"holds the same key as {twin.source}: every node needs its own"
                )
            for camera in sorted(node.cameras):
                other = self._keys.setdefault((node.session, camera), node)
                if other is not node:
                    where = "every session" if node.session is None else f"session {node.session!r}"
                    raise ServiceError(
                        node.source,
                        f"camera {camera} of {where} already has the key of {other.source}",
                    )

    def __len__(self) -> int:
        """How many (session, camera) pairs have a key."""
        return len(self._keys)

    def key_for(self, session: str, camera: int) -> bytes | None:
        """The key that may speak for camera id `camera` of session `session`: the one
        listed for that session, else the one listed for every session; None if none."""
        node = self._keys.get((session, camera)) or self._keys.get((None, camera))
        return None if node is None else node.key


def read_node_keys(path: str | Path) -> NodeKeys:
    """The `[[node]]` tables of a keys file and the key files they name; `ServiceError`
    naming the file (and table) on anything unreadable or invalid."""
    path = Path(path)
    source = str(path)
    try:
        document = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ServiceError(source, f"cannot read the keys file: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ServiceError(source, f"not a TOML file: {exc}") from None
    extra = sorted(set(document) - {"node"})
    if extra:
        raise ServiceError(source, f"unknown top-level key {extra[0]!r}; expected [[node]]")
    tables = document.get("node")
    if not isinstance(tables, list) or not tables:
        raise ServiceError(source, "no [[node]] table")
    return NodeKeys(
        _node_key(table, f"{source}: node {i + 1}", path.parent) for i, table in enumerate(tables)
    )


def _node_key(table: Mapping[str, Any], where: str, base: Path) -> NodeKey:
    """One `[[node]]` table as a `NodeKey`, its key file read."""
    unknown = sorted(set(table) - set(_KEYS))
    if unknown:
        raise ServiceError(where, f"unknown key {unknown[0]!r}; known: {', '.join(_KEYS)}")
    key_file = table.get("key_file")
    if not isinstance(key_file, str) or not key_file:
        raise ServiceError(where, "key_file must be the path of the node's key file")
    cameras = table.get("cameras")
    if (
        not isinstance(cameras, list)
        or not cameras
        or not all(isinstance(c, int) and not isinstance(c, bool) for c in cameras)
        or not all(0 <= c <= 0xFFFF for c in cameras)
    ):
        raise ServiceError(where, "cameras must be a list of camera ids 0..65535")
    session = table.get("session")
    if session is not None and not (isinstance(session, str) and SESSION_NAME.fullmatch(session)):
        raise ServiceError(where, f"session {session!r} is not a session name")
    file = base / key_file
    try:
        key = read_key_file(file)
    except ServiceError as exc:
        raise ServiceError(where, str(exc)) from None
    return NodeKey(key, frozenset(cameras), session, f"{where} ({file})")
