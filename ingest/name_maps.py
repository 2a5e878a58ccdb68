"""Mapping files: TOML that names, for each of our joints or markers, the joint names or
point labels of a foreign file (a rig map, a marker set).

    name = "my-rig"          # optional, default: the file's stem
    [joints]                 # the table: [joints] for a rig, [markers] for a marker set
    head = "Head"            # one name, or a list of alternatives
    l_hip = ["L_Thigh", "L_UpLeg"]
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from samba.base import InputError


def read_name_map(
    path: str | Path,
    table: str,
    ours: tuple[str, ...],
    value: str,
    error: type[InputError],
) -> tuple[str, tuple[tuple[str, ...], ...]]:
    """The map's name and, for each of `ours` (in order), the names it accepts (a `value`
    each: "name", "label"), from the `[table]` of the TOML file `path`. Raises `error`
    naming the file and the problem: unreadable, not TOML, no table, a key not ours,
    one of ours missing, a value that is not a name or a list of them."""
    path = Path(path)
    thing = table.removesuffix("s")
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise error(str(path), f"cannot read mapping file: {exc.strerror or exc}") from exc
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise error(str(path), f"not valid TOML: {exc}") from exc
    entries = doc.get(table)
    if not isinstance(entries, dict):
        raise error(
            str(path), f"needs a [{table}] table mapping our {len(ours)} {table} to {value}s"
        )
    unknown = sorted(set(entries) - set(ours))
    if unknown:
        raise error(str(path), f"unknown {table} {unknown}; ours are {list(ours)}")
    absent = [key for key in ours if key not in entries]
    if absent:
        raise error(str(path), f"[{table}] does not map {', '.join(absent)}")
    names = []
    for key in ours:
        entry = entries[key]
        options = [entry] if isinstance(entry, str) else entry
        if not (
            isinstance(options, list) and options and all(isinstance(v, str) and v for v in options)
        ):
            raise error(str(path), f"{thing} {key} must map to a {value} or a list of {value}s")
        names.append(tuple(options))
    return str(doc.get("name", path.stem)), tuple(names)
