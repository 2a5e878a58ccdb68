"""BVH writer: a `HumanoidMotion` as a Biovision hierarchy plus motion (FORMATS.md §3.3).

The skeleton is the rig's: Unity / VRM humanoid joint names, OFFSETs from the rest pose,
an End Site at each leaf's tip. The root Hips has `OFFSET 0 0 0` and six channels
carrying its absolute position (readers that add the channels to the OFFSET and readers
that replace it then agree); every joint rotates `Zrotation Xrotation Yrotation`, i.e.
R = Rz·Rx·Ry, in degrees. BVH carries no length unit: meters or centimeters on request.
"""

from __future__ import annotations

import os
import warnings

import numpy as np
from scipy.spatial.transform import Rotation

from export.errors import ExportError
from export.humanoid import TIP_BONES, HumanoidRig
from export.motion import HumanoidMotion
from samba.atomic_file import write_text_atomic

UNITS: dict[str, float] = {"m": 1.0, "cm": 100.0}
"""Length units a BVH file can be written in: name -> factor from meters."""


def write_bvh(path: str | os.PathLike[str], motion: HumanoidMotion, unit: str = "m") -> None:
    """Write `motion` to `path` as BVH with lengths in `unit` ('m' or 'cm').

    One line per frame: the Hips position (3 values, `unit`) then Z, X, Y rotations in
    degrees of every joint in declaration order, 6 decimals; `Frame Time` is 1 / fps s.
    The file is written atomically: on any failure `path` keeps its old content (or
    stays absent). Raises `ValueError` for another unit (naming `--unit`), `ExportError`
    naming `path` when it cannot be written.
    """
    if unit not in UNITS:
        raise ValueError(f"--unit must be one of {', '.join(UNITS)}, got {unit!r}")
    scale = UNITS[unit]
    header, order = _hierarchy(motion.rig, scale)
    angles = euler_zxy(motion.rotations)[:, order].reshape(len(motion), -1)
    data = np.concatenate([motion.root * scale, angles], axis=1)
    data = np.round(data, 6) + 0.0  # + 0.0 turns -0.0 into 0.0
    row = " ".join(["%.6f"] * data.shape[1])
    frames = "\n".join(row % tuple(values) for values in data.tolist())
    timing = f"MOTION\nFrames: {len(motion)}\nFrame Time: {1.0 / motion.fps:.8f}\n"
    try:
        write_text_atomic(path, f"{header}{timing}{frames}\n")
    except OSError as exc:
        raise ExportError(str(path), f"cannot write the file: {exc.strerror or exc}") from exc


def euler_zxy(rotations: np.ndarray) -> np.ndarray:
    """Intrinsic ZXY Euler angles (n, J, 3) in degrees, ordered (Z, X, Y), of local
    quaternions (n, J, 4) (x, y, z, w): Rz·Rx·Ry equals each rotation's matrix.

    Continuous over frames as far as the rotations allow: each frame takes, of the two
    angle triples of its rotation ((z, x, y) and (z + 180, 180 - x, y + 180)) shifted
    by whole turns, the one nearest to the previous frame's. At gimbal lock (X = ±90°)
    only Z ± Y is defined, and the split between them may jump.
    """
    q = np.asarray(rotations, dtype=np.float64)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Gimbal lock detected", category=UserWarning)
        angles = Rotation.from_quat(q.reshape(-1, 4)).as_euler("ZXY", degrees=True)
    angles = angles.reshape(*q.shape[:-1], 3)
    z, x, y = np.moveaxis(angles, -1, 0)
    alternate = np.stack([z + 180.0, 180.0 - x, y + 180.0], axis=-1)
    out = np.empty_like(angles)
    out[0] = angles[0]
    for t in range(1, len(angles)):
        previous = out[t - 1]
        first = _nearest_turn(angles[t], previous)
        second = _nearest_turn(alternate[t], previous)
        closer = np.abs(second - previous).sum(-1) < np.abs(first - previous).sum(-1)
        out[t] = np.where(closer[..., None], second, first)
    return out


def _nearest_turn(angles: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """`angles` (..., 3) degrees shifted by whole turns (per angle) nearest to `reference`."""
    return angles + 360.0 * np.round((reference - angles) / 360.0)


def _hierarchy(rig: HumanoidRig, scale: float) -> tuple[str, list[int]]:
    """The HIERARCHY section of `rig` with lengths times `scale`, and the bone indices in
    declaration (depth-first) order, the order of the motion columns."""
    children: list[list[int]] = [[] for _ in rig.parents]
    for bone, parent in enumerate(rig.parents):
        if parent >= 0:
            children[parent].append(bone)
    offsets = rig.offsets * scale
    tips = dict(zip(TIP_BONES, rig.tips * scale, strict=True))
    lines = ["HIERARCHY"]
    order: list[int] = []

    def declare(bone: int, depth: int) -> None:
        pad = "\t" * depth
        root = rig.parents[bone] < 0
        offset = np.zeros(3) if root else offsets[bone]
        channels = "6 Xposition Yposition Zposition" if root else "3"
        lines.extend(
            [
                f"{pad}{'ROOT' if root else 'JOINT'} {rig.names[bone]}",
                f"{pad}{{",
                f"{pad}\tOFFSET {_vector(offset)}",
                f"{pad}\tCHANNELS {channels} Zrotation Xrotation Yrotation",
            ]
        )
        order.append(bone)
        for child in children[bone]:
            declare(child, depth + 1)
        if bone in tips:
            lines.extend(
                [
                    f"{pad}\tEnd Site",
                    f"{pad}\t{{",
                    f"{pad}\t\tOFFSET {_vector(tips[bone])}",
                    f"{pad}\t}}",
                ]
            )
        lines.append(f"{pad}}}")

    for bone, parent in enumerate(rig.parents):
        if parent < 0:
            declare(bone, 0)
    return "\n".join(lines) + "\n", order


def _vector(v: np.ndarray) -> str:
    """A 3-vector as BVH numbers with 6 decimals."""
    return " ".join(f"{x + 0.0:.6f}" for x in np.round(v, 6))
