"""What a capture session is made of: its cameras, pose database, method and outputs.

A session comes from `samba serve` flags, from a `[[session]]` table of a TOML file
(`read_sessions`), or from the JSON body of `POST /api/sessions`; the keys are the same:

| key | type | default | meaning |
|---|---|---|---|
| `name` | string | (required) | session id: 1..16 of `[A-Za-z0-9._-]`, first a letter or digit |
| `input` | string | `"markers"` | what nodes send: `"markers"` or `"poses"` (see below) |
| `calibration` | path | (markers) | camera calibration TOML; camera id n = the n-th camera table |
| `database` | path | (markers) | pose store directory (`samba db init` / `import`) |
| `method` | string | `"samba"` | reconstruction method (`samba eval --methods` names) |
| `fps` | number | 60 | nominal frame rate of the cameras |
| `vmc` | list of `"HOST:PORT"` | `[]` | VMC/OSC receivers (VSeeFace, EVMC4U, VMC4UE ...) |
| `avatar` | path | none | avatar (.vrm, .glb, .gltf, .usd/a/c) whose rig the VMC stream uses |
| `wait_ms` | number | 50 | how long a frame waits for late cameras |
| `min_cameras` | integer | 2 | fewest cameras a frame is reconstructed from |
| `gate_px` | number | 10 | triangulation outlier gate, pixels (0 = none) |
| `labels` | string | `"auto"` | who labels the markers: `"server"`, `"nodes"` or `"auto"` (below) |
| `calibrate_s` | number | 0 | seconds of markers that calibrate the subject (0: none; below) |

With `calibrate_s` > 0 a marker session calibrates its subject's skin-marker offsets
from its first `calibrate_s` seconds of markers and removes them from every frame after
(`samba.service.subject_calibration`); its takes store them.

Relative paths in a file are relative to the file's folder. A `"markers"` session
(the default) takes the marker packets of its calibrated cameras and needs
`calibration` and `database`; a `"poses"` session takes the pose packets of one
markerless node (`samba node --mode silhouette`), which tracks the body itself, and
needs neither (`method`, `min_cameras`, `gate_px` and `labels` do not apply).

With `labels = "server"` the server keeps the labels the nodes sent and
finds the ones they lost again from every camera's blobs (labelled and unlabelled),
with a tracker per camera and the cross-view labelling (`samba.markers.stage_tracking`), started
at the first frame every camera sent: a marker whose label a node dropped when it
crossed another comes back as soon as the other cameras tell which marker it is, and a
label whose views disagree is dropped. It costs the server about 2 ms per camera and
frame (`bench/bench_service.py --labels`). With `"nodes"` it triangulates the nodes'
labels as they are. `"auto"` (the default) is `"server"` with three or more cameras and
`"nodes"` with two, where labels found from the other camera are rare (a blob on an
epipolar line may be another marker) and the cost is not worth it.
"""

from __future__ import annotations

import argparse
import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from samba.base import address
from samba.reconstruct import METHODS
from samba.service.errors import ServiceError

SESSION_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,15}")
"""A session's name: what camera nodes put in their packets' session field, and the
folder of its takes (so never `.`, `..` or hidden)."""

INPUTS = ("markers", "poses")
"""What a session's camera nodes send (`input`)."""

LABELLERS = ("auto", "server", "nodes")
"""Who labels a marker session's markers (`labels`)."""

_KEYS = (
    "name",
    "input",
    "calibration",
    "database",
    "method",
    "fps",
    "vmc",
    "avatar",
    "wait_ms",
    "min_cameras",
    "gate_px",
    "labels",
    "calibrate_s",
)


@dataclass(frozen=True)
class SessionConfig:
    """One capture session's settings (see the module docstring for each field)."""

    name: str
    calibration: Path | None
    database: Path | None
    method: str = "samba"
    fps: float = 60.0
    vmc: tuple[tuple[str, int], ...] = ()
    avatar: Path | None = None
    wait_ms: float = 50.0
    min_cameras: int = 2
    gate_px: float = 10.0
    input: str = "markers"
    labels: str = "auto"
    calibrate_s: float = 0.0

    def server_labels(self, cameras: int) -> bool:
        """Whether the server finds the labels the nodes lost (`labels`) in a marker
        session with `cameras` cameras."""
        return self.labels == "server" or (self.labels == "auto" and cameras >= 3)

    @classmethod
    def from_mapping(
        cls, values: Mapping[str, Any], source: str, base: Path | None = None
    ) -> SessionConfig:
        """A config from a TOML table or JSON object; `ServiceError` naming `source` and
        the key on an unknown key, a missing one or a bad value. Relative paths are
        joined to `base` when given."""
        unknown = sorted(set(values) - set(_KEYS))
        if unknown:
            raise ServiceError(source, f"unknown key {unknown[0]!r}; known: {', '.join(_KEYS)}")
        if "name" not in values:
            raise ServiceError(source, "missing key 'name'")
        kind = _string(values, "input", source, "markers")
        if kind not in INPUTS:
            raise ServiceError(source, f"input must be one of {', '.join(INPUTS)}, got {kind!r}")
        for key in ("calibration", "database") if kind == "markers" else ():
            if key not in values:
                raise ServiceError(source, f"missing key {key!r}")
        given = [key for key in ("calibration", "database") if key in values]
        if kind == "poses" and given:
            raise ServiceError(
                source,
                f"a poses session reads no {' or '.join(given)} (its markerless node sends "
                "whole poses)",
            )
        name = _string(values, "name", source)
        if not SESSION_NAME.fullmatch(name):
            raise ServiceError(
                source, f"name {name!r} is not 1..16 of [A-Za-z0-9._-], the first a letter or digit"
            )
        where = f"{source}: session {name!r}"
        method = _string(values, "method", where, "samba")
        if method not in METHODS:
            raise ServiceError(where, f"unknown method {method!r}; known: {', '.join(METHODS)}")
        labels = _string(values, "labels", where, "auto")
        if labels not in LABELLERS:
            raise ServiceError(
                where, f"labels must be one of {', '.join(LABELLERS)}, got {labels!r}"
            )
        vmc = values.get("vmc", [])
        if not isinstance(vmc, list) or not all(isinstance(v, str) for v in vmc):
            raise ServiceError(where, 'vmc must be a list of "HOST:PORT" strings')
        try:
            targets = tuple(address(v) for v in vmc)
        except argparse.ArgumentTypeError as exc:
            raise ServiceError(where, f"vmc: {exc}") from None
        return cls(
            name=name,
            calibration=_optional_path(values, "calibration", where, base),
            database=_optional_path(values, "database", where, base),
            method=method,
            fps=_number(values, "fps", where, 60.0),
            vmc=targets,
            avatar=_optional_path(values, "avatar", where, base),
            wait_ms=_number(values, "wait_ms", where, 50.0, allow_zero=True),
            min_cameras=int(_number(values, "min_cameras", where, 2, integer=True)),
            gate_px=_number(values, "gate_px", where, 10.0, allow_zero=True),
            input=kind,
            labels=labels,
            calibrate_s=_number(values, "calibrate_s", where, 0.0, allow_zero=True),
        )


def read_sessions(path: str | Path) -> list[SessionConfig]:
    """The `[[session]]` tables of a TOML file; `ServiceError` naming the file otherwise."""
    path = Path(path)
    source = str(path)
    try:
        document = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ServiceError(source, f"cannot read: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ServiceError(source, f"not a TOML file: {exc}") from None
    extra = sorted(set(document) - {"session"})
    if extra:
        raise ServiceError(source, f"unknown top-level key {extra[0]!r}; expected [[session]]")
    tables = document.get("session")
    if not isinstance(tables, list) or not tables:
        raise ServiceError(source, "no [[session]] table")
    configs = [SessionConfig.from_mapping(t, source, path.parent) for t in tables]
    names = [c.name for c in configs]
    for name in names:
        if names.count(name) > 1:
            raise ServiceError(source, f"session name {name!r} is used twice")
    return configs


def _string(values: Mapping[str, Any], key: str, where: str, default: str | None = None) -> str:
    value = values.get(key, default)
    if not isinstance(value, str):
        raise ServiceError(where, f"{key} must be a string, got {value!r}")
    return value


def _optional_path(
    values: Mapping[str, Any], key: str, where: str, base: Path | None
) -> Path | None:
    if key not in values:
        return None
    path = Path(_string(values, key, where))
    return base / path if base is not None and not path.is_absolute() else path


def _number(
    values: Mapping[str, Any],
    key: str,
    where: str,
    default: float,
    *,
    allow_zero: bool = False,
    integer: bool = False,
) -> float:
    value = values.get(key, default)
    kind = int if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kind) or not math.isfinite(value):
        raise ServiceError(where, f"{key} must be a finite {'integer' if integer else 'number'}")
    if value < 0 or (value == 0 and not allow_zero):
        raise ServiceError(where, f"{key} must be {'>= 0' if allow_zero else '> 0'}, got {value}")
    return float(value)
