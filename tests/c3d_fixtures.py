"""C3D marker files written with the `c3d` package: a subject of the test skeleton with
Plug-in-Gait labels (and a few others), Z up, for the C3D reader's tests."""

from __future__ import annotations

import io
import warnings

import c3d
import numpy as np

from samba.synthetic.motions import generate

LABELS = (
    "LSHO",
    "RSHO",
    "LWRA",
    "LWRB",
    "RWRA",
    "RWRB",
    "LKNE",
    "RKNE",
    "LANK",
    "RANK",
    "C7",
    "CLAV",
)
"""Plug-in-Gait labels the fixture writes (the wrists' two markers each side of the joint)."""
WRIST_HALF_WIDTH = 0.025
"""Half the distance between a wrist's two markers, meters."""


def walk_points(frames: int = 30) -> np.ndarray:
    """Points (frames, 12, 3) in meters, +Y up, of `LABELS` on a synthetic walk: the
    markers at the joints, each wrist's two markers either side of its joint along X."""
    poses = generate("walk", seconds=frames / 30.0, seed=4).poses[:frames].astype(np.float64)
    joint = {"SHO": (1, 2), "WR": (5, 6), "KNE": (9, 10), "ANK": (11, 12)}
    out = []
    for label in LABELS:
        side = 0 if label[0] == "L" else 1
        if label in ("C7", "CLAV"):
            out.append((poses[:, 1] + poses[:, 2]) / 2 + [0.0, 0.05, 0.0])
            continue
        key = label[1:4] if label[1:4] in joint else label[1:3]
        point = poses[:, joint[key][side]].copy()
        if key == "WR":
            point[:, 0] += WRIST_HALF_WIDTH if label.endswith("A") else -WRIST_HALF_WIDTH
        out.append(point)
    return np.stack(out, axis=1)


def c3d_bytes(
    points_m: np.ndarray,
    labels: tuple[str, ...] = LABELS,
    units: str = "mm",
    missing: tuple[tuple[int, int], ...] = (),
    prefix: str = "Subject:",
) -> bytes:
    """A C3D file of points (n, m, 3) in meters, +Y up, written Z up in `units` (mm, cm
    or m), float storage, 120 Hz; (frame, point) pairs in `missing` get residual -1."""
    scale = {"mm": 1000.0, "cm": 100.0, "m": 1.0}.get(units, 1000.0)
    zup = points_m[..., [0, 2, 1]] * [1.0, -1.0, 1.0] * scale  # (x, y, z) -> (x, -z, y)
    writer = c3d.Writer(point_rate=120.0, point_units=f"{units:<4}")
    writer.set_point_labels([prefix + label for label in labels])
    frames = []
    for i, frame in enumerate(zup):
        data = np.zeros((len(labels), 5), dtype=np.float32)
        data[:, :3] = frame
        for f, p in missing:
            if f == i:
                data[p, 3] = -1.0
        frames.append((data, np.zeros((0, 0), dtype=np.float32)))
    writer.add_frames(frames)
    out = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        writer.write(out)
    return out.getvalue()
