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

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from samba.body import MARKER_NAMES
from samba.ingest.errors import C3dError
from samba.ingest.name_maps import read_name_map


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
                'marker-set TOML file ([markers] l_shoulder = "LABEL", ...)',
            )
        with warnings.catch_warnings():  # a frame where all of a marker's labels are missing
            warnings.simplefilter("ignore", RuntimeWarning)  # gives NaN, as it should
            return np.stack([np.nanmean(points[:, found], axis=1) for found in columns], axis=1)

    @classmethod
    def named(cls, path: str | Path | None) -> MarkerSet:
        """The marker set of a `--marker-set` file, or `PLUG_IN_GAIT` for None."""
        return PLUG_IN_GAIT if path is None else cls.from_toml(path)

    @classmethod
    def from_toml(cls, path: str | Path) -> MarkerSet:
        """Read a marker-set file; `C3dError` naming the file and the problem."""
        name, labels = read_name_map(path, "markers", MARKER_NAMES, "label", C3dError)
        return cls(name=name, labels=labels)


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
