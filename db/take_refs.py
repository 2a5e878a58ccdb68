"""How a command line names a take: by its name, or by its id written `#3`. A bare number
is a name (a take may be called `1`); the shell reads an unquoted `#` as a comment, so an
id is typed `'#3'`."""

from __future__ import annotations

import re
import shlex
from collections.abc import Sequence

import numpy as np

from samba.db.catalog import TakeInfo
from samba.db.errors import StoreError

_ID = re.compile(r"#(\d+)")


def id_text(take_id: int) -> str:
    """A take id as commands write and read it: `#3`."""
    return f"#{take_id}"


def find_take(takes: Sequence[TakeInfo], ref: int | str, store: str) -> TakeInfo:
    """The take of `takes` that `ref` names: an int (or numpy integer) or `#3` is an id,
    any other text a name. `StoreError` naming the store `store` when none or several
    match; the message says how to name the one meant."""
    if isinstance(ref, int | np.integer):
        take_id: int | None = int(ref)
    else:
        match = _ID.fullmatch(ref)
        take_id = int(match.group(1)) if match else None
    if take_id is not None:
        hits = [t for t in takes if t.id == take_id]
        if not hits:
            raise StoreError(store, f"no take with id {id_text(take_id)}")
        return hits[0]
    hits = [t for t in takes if t.name == ref]
    if len(hits) == 1:
        return hits[0]
    if hits:
        ids = ", ".join(id_text(t.id) for t in hits)
        raise StoreError(store, f"{len(hits)} takes are named {ref!r} ({ids}): name one by its id")
    hint = ""
    if ref.isdigit() and any(t.id == int(ref) for t in takes):
        hint = f" (a take id is written '#{ref}')"
    raise StoreError(store, f"no take named {ref!r}{hint}")


def command_ref(take: TakeInfo, takes: Sequence[TakeInfo]) -> str:
    """`take` as a shell word naming it on a command line (quoted as needed): its name
    when that names it alone (and does not read as an id), else its id."""
    unique = sum(t.name == take.name for t in takes) == 1
    if unique and not _ID.fullmatch(take.name):
        return shlex.quote(take.name)
    return shlex.quote(id_text(take.id))
