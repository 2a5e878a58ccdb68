"""Marker sets: which labels of a marker file give each of Samba's 8 markers.

A marker is one label, or several whose present ones are averaged (the wrist: the
midpoint of its two markers, or the one present). The built-in `PLUG_IN_GAIT` serves
CMU's and Vicon's Plug-in-Gait names (`LSHO`, `LWRA` / `LWRB`, `LKNE`, `LANK`); any other
set is a TOML file like a rig map:

    name = "my-lab"
    [markers]
    l_shoulder = "L.Shoulder"
    l_wrist = ["L.Wrist.Ulna", "L.Wrist.Radius"]
    ...                          # all 8 of samba.body.MARKER_NAMES
"""

from __future__ import annotations

import tomllib
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from samba.body import MARKER_NAMES
from samba.ingest.errors import C3dError


@dataclass(frozen=True)
class MarkerSet:
    """A named map from the 8 markers (`MARKER_NAMES` order) to the labels whose present
    ones are averaged for it."""

    name: str
    labels: tuple[tuple[str, ...], ...]

    def markers(self, points: np.ndarray, labels: tuple[str, ...], source: str) -> np.ndarray:
        """The 8 markers (n, 8, 3) of points (n, m, 3) named `labels` (m,): per frame the
        mean of each marker's labels that are present (NaN when none is). `C3dError`
        naming `source`, the markers it cannot serve and how to map them otherwise."""
        index = {label.lower(): i for i, label in enumerate(labels)}
        columns, lacking = [], []
        for ours, wanted in zip(MARKER_NAMES, self.labels, strict=True):
            found = [index[w.lower()] for w in wanted if w.lower() in index]
            if not found:
                lacking.append(f"{ours} ({' or '.join(wanted)})")
            columns.append(found)
        if lacking:
            raise C3dError(
                source,
                f"marker set {self.name!r} finds no label for {'; '.join(lacking)}; the file "
                f"has {', '.join(labels[:12])}{', ...' if len(labels) > 12 else ''}: write a "
                "marker-set TOML file ([markers] l_shoulder = \"LABEL\", ...)",
            )
        with warnings.catch_warnings():  # a frame where all of a marker's labels are missing
            warnings.simplefilter("ignore", RuntimeWarning)  # gives NaN, as it should
            return np.stack([np.nanmean(points[:, found], axis=1) for found in columns], axis=1)

    @classmethod
    def from_toml(cls, path: str | Path) -> MarkerSet:
        """Read a marker-set file; `C3dError` naming the file and the problem."""
        path = Path(path)
        try:
            doc = tomllib.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            problem = f"cannot read marker-set file: {exc.strerror or exc}"
            raise C3dError(str(path), problem) from exc
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise C3dError(str(path), f"not valid TOML: {exc}") from exc
        table = doc.get("markers")
        if not isinstance(table, dict):
            raise C3dError(str(path), "needs a [markers] table mapping our 8 markers to labels")
        unknown = sorted(set(table) - set(MARKER_NAMES))
        absent = [m for m in MARKER_NAMES if m not in table]
        if unknown or absent:
            raise C3dError(
                str(path),
                f"[markers] must map exactly {', '.join(MARKER_NAMES)}"
                + (f"; unknown {unknown}" if unknown else "")
                + (f"; missing {absent}" if absent else ""),
            )
        labels = []
        for marker in MARKER_NAMES:
            value = table[marker]
            options = [value] if isinstance(value, str) else value
            if not (isinstance(options, list) and options and all(
                isinstance(v, str) and v for v in options
            )):
                problem = f"marker {marker} must map to a label or a list of labels"
                raise C3dError(str(path), problem)
            labels.append(tuple(options))
        return cls(name=str(doc.get("name", path.stem)), labels=tuple(labels))


PLUG_IN_GAIT = MarkerSet(
    name="plug-in-gait",
    labels=(
        ("LSHO",),
        ("RSHO",),
        ("LWRA", "LWRB"),
        ("RWRA", "RWRB"),
        ("LKNE",),
        ("RKNE",),
        ("LANK",),
        ("RANK",),
    ),
)
"""CMU's and Vicon's Plug-in-Gait labels: shoulder = acromion (`SHO`), wrist = midpoint
of its two markers (`WRA`, `WRB`), knee = lateral knee (`KNE`), foot = lateral ankle
(`ANK`)."""
