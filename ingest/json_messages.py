"""The JSON documents of a recorded take's messages, read with a depth limit: nesting is
measured before the document is parsed, so no message makes the parser recurse without
bound."""

from __future__ import annotations

import json
import re

import numpy as np

from samba.ingest.errors import TakeFileError

MAX_JSON_DEPTH = 32
"""Deepest nesting of arrays and objects in a message (a pose nests 3 deep)."""
_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"')
_OPEN = np.zeros(256, dtype=np.int8)
_OPEN[[ord("["), ord("{")]] = 1
_OPEN[[ord("]"), ord("}")]] = -1


def json_depth(data: bytes) -> int:
    """How deep arrays and objects nest in the JSON text `data` (brackets inside strings
    do not count); 0 for a plain value."""
    steps = _OPEN[np.frombuffer(_STRING.sub(b'""', data), dtype=np.uint8)]
    return int(np.cumsum(steps, dtype=np.int64).max(initial=0))


def json_message(data: bytes, source: str, where: str) -> object:
    """The JSON document of the message `where` of the take file `source`;
    `TakeFileError` naming both when it nests deeper than `MAX_JSON_DEPTH` or is not
    JSON."""
    brackets = data.count(b"[") + data.count(b"{")  # no deeper than this: a quick pass
    if brackets > MAX_JSON_DEPTH and json_depth(data) > MAX_JSON_DEPTH:
        raise TakeFileError(source, f"{where} nests deeper than {MAX_JSON_DEPTH} levels")
    try:
        return json.loads(data)
    except ValueError as exc:
        raise TakeFileError(source, f"{where} is malformed: {exc}") from None
