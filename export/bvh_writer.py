"""BVH writer: a tree skeleton's motion as a Biovision hierarchy plus motion (FORMATS.md §3.3).

`write_bvh_motion` writes any `BvhSkeleton`: its joints declared depth-first (children
in index order), an End Site at each leaf that has one. The root has `OFFSET 0 0 0` and
six channels carrying its absolute position (readers that add the channels to the OFFSET
and readers that replace it then agree); every joint rotates `Zrotation Xrotation
Yrotation`, i.e. R = Rz·Rx·Ry, in degrees. BVH carries no length unit: meters or
centimeters on request. `write_bvh` writes a `HumanoidMotion` on its rig's skeleton:
Unity / VRM humanoid joint names, OFFSETs from the rest pose, End Sites at the leaf tips.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np
from scipy.spatial.transform import Rotation

from samba.base import write_text_atomic
from samba.export.errors import ExportError
from samba.export.humanoid import TIP_BONES, HumanoidRig
from samba.export.motion import HumanoidMotion

UNITS: dict[str, float] = {"m": 1.0, "cm": 100.0}
"""Length units a BVH file can be written in: name -> factor from meters."""

_IDENTIFIER = re.compile(r"[^\s{}]+")
"""A BVH joint name: one token, so no whitespace and no braces."""


@dataclass(frozen=True)
class BvhSkeleton:
    """A tree skeleton as BVH declares it, its rest pose with identity orientations.

    `names` (J,) joint names; `parents` (J,) parent joint indices, -1 for the root, which
    is joint 0, and every parent before its children; `offsets` (J, 3) meters, each
    joint's position relative to its parent in the parent's frame (the root's entry is
    ignored: BVH gets `OFFSET 0 0 0`); `end_sites` maps leaf joints to the (3,) offset in
    meters of the leaf's end in the leaf's frame (leaves may lack one).

    Validated on creation: names unique, non-empty and printable without whitespace or
    braces; joint 0 the only root, parents before children; End Sites on leaves only;
    every offset finite. Raises `ValueError` naming the problem.
    Arrays are stored as float64 copies, `end_sites` as a read-only mapping.
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    end_sites: Mapping[int, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        names = tuple(self.names)
        _check_names(names)
        parents = _checked_parents(tuple(self.parents), names)
        offsets = _finite_array(self.offsets, "offsets", (len(names), 3))
        leaves = set(range(len(names))) - set(parents)
        end_sites: dict[int, np.ndarray] = {}
        for joint, end in self.end_sites.items():
            if not (isinstance(joint, int | np.integer) and 0 <= joint < len(names)):
                raise ValueError(f"skeleton End Site on {joint!r}, which is not a joint index")
            if joint not in leaves:
                raise ValueError(
                    f"skeleton End Site on joint {joint} ({names[joint]}), which has children;"
                    " only leaf joints end in one"
                )
            what = f"End Site offset of joint {joint} ({names[joint]})"
            end_sites[int(joint)] = _finite_array(end, what, (3,))
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "end_sites", MappingProxyType(end_sites))

    @classmethod
    def from_rig(cls, rig: HumanoidRig) -> BvhSkeleton:
        """The skeleton of a humanoid rig: its 17 bone names, rest offsets (meters) and
        the tips of its 5 leaf bones as End Sites."""
        return cls(rig.names, rig.parents, rig.offsets, dict(zip(TIP_BONES, rig.tips, strict=True)))


def _check_names(names: tuple[str, ...]) -> None:
    """Raise `ValueError` unless `names` are one or more unique BVH joint names."""
    if not names:
        raise ValueError("skeleton has no joints")
    seen: set[str] = set()
    for name in names:
        if not (isinstance(name, str) and _IDENTIFIER.fullmatch(name) and name.isprintable()):
            raise ValueError(
                f"skeleton joint name {name!r} is not a BVH name: it needs printable"
                " characters without whitespace or braces"
            )
        if name in seen:
            raise ValueError(f"skeleton joint name {name!r} is used twice")
        seen.add(name)


def _checked_parents(parents: tuple[int, ...], names: tuple[str, ...]) -> tuple[int, ...]:
    """`parents` as Python ints; `ValueError` unless they give one parent index per joint,
    -1 for joint 0 (the one root) and an earlier joint for every other joint."""
    if len(parents) != len(names):
        raise ValueError(
            f"skeleton needs one parent per joint: {len(names)} names, {len(parents)} parents"
        )
    for joint, parent in enumerate(parents):
        if not isinstance(parent, int | np.integer):
            raise ValueError(f"skeleton parent of {names[joint]} is {parent!r}, not an index")
        if joint == 0 and parent != -1:
            raise ValueError(f"skeleton joint 0 ({names[0]}) must be the root (parent -1)")
        if joint > 0 and parent == -1:
            raise ValueError(f"skeleton has a second root, {names[joint]}; BVH gets one root")
        if joint > 0 and not 0 <= parent < joint:
            raise ValueError(
                f"skeleton parent of {names[joint]} is {parent}: every parent must be a joint"
                " declared before its children"
            )
    return tuple(int(parent) for parent in parents)


def _finite_array(values: object, what: str, shape: tuple[int, ...]) -> np.ndarray:
    """`values` as a float64 copy of `shape`; `ValueError` naming `what` when it has
    another shape or non-finite entries."""
    array = np.array(values, dtype=np.float64)
    if array.shape != shape:
        raise ValueError(f"skeleton {what} must have shape {shape}, got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"skeleton {what} must be finite")
    return array


def write_bvh(path: str | os.PathLike[str], motion: HumanoidMotion, unit: str = "m") -> None:
    """Write `motion` to `path` as BVH on its rig's skeleton (`BvhSkeleton.from_rig`) with
    lengths in `unit` ('m' or 'cm'), as `write_bvh_motion` does."""
    skeleton = BvhSkeleton.from_rig(motion.rig)
    write_bvh_motion(path, skeleton, motion.rotations, motion.root, motion.fps, unit)


def write_bvh_motion(
    path: str | os.PathLike[str],
    skeleton: BvhSkeleton,
    rotations: np.ndarray,
    root: np.ndarray,
    fps: float,
    unit: str = "m",
) -> None:
    """Write a motion of `skeleton` to `path` as BVH with lengths in `unit` ('m' or 'cm').

    `rotations` (n, J, 4) are local joint quaternions (x, y, z, w; normalised here)
    relative to the rest pose, `root` (n, 3) the root joint's positions in meters, `fps`
    frames per second. One line per frame: the root position (3 values, `unit`) then Z,
    X, Y rotations in degrees (continuous over frames, see `euler_zxy`) of every joint in
    declaration order, 6 decimals; `Frame Time` is 1 / fps s. The file is written
    atomically: on any failure `path` keeps its old content (or stays absent). Raises
    `ValueError` for another unit (naming `--unit`) or a motion that does not fit the
    skeleton, `ExportError` naming `path` when it cannot be written.
    """
    if unit not in UNITS:
        raise ValueError(f"--unit must be one of {', '.join(UNITS)}, got {unit!r}")
    rotations = np.asarray(rotations, dtype=np.float64)
    root = np.asarray(root, dtype=np.float64)
    n_joints = len(skeleton.names)
    if not (
        rotations.ndim == 3
        and len(rotations) > 0
        and rotations.shape[1:] == (n_joints, 4)
        and root.shape == (len(rotations), 3)
    ):
        raise ValueError(
            f"a motion of {n_joints} joints needs rotations (n, {n_joints}, 4) and root (n, 3)"
            f" with n > 0, got {rotations.shape} and {root.shape}"
        )
    if not 0 < fps < math.inf:
        raise ValueError(f"motion fps must be positive and finite, got {fps}")
    norms = np.linalg.norm(rotations, axis=-1)
    if not (np.isfinite(root).all() and np.isfinite(norms).all() and (norms > 0).all()):
        raise ValueError("motion has non-finite root positions or non-finite / zero rotations")
    scale = UNITS[unit]
    header, order = _hierarchy(skeleton, scale)
    angles = euler_zxy(rotations)[:, order].reshape(len(rotations), -1)
    data = np.concatenate([root * scale, angles], axis=1)
    data = np.round(data, 6) + 0.0  # + 0.0 turns -0.0 into 0.0
    row = " ".join(["%.6f"] * data.shape[1])
    frames = "\n".join(row % tuple(values) for values in data.tolist())
    timing = f"MOTION\nFrames: {len(rotations)}\nFrame Time: {1.0 / fps:.8f}\n"
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


def _hierarchy(skeleton: BvhSkeleton, scale: float) -> tuple[str, list[int]]:
    """The HIERARCHY section of `skeleton` with lengths times `scale`, and the joint
    indices in declaration (depth-first) order, the order of the motion columns.

    Iterative, so that long chains do not meet Python's recursion limit."""
    children: list[list[int]] = [[] for _ in skeleton.parents]
    depth = [0] * len(skeleton.parents)
    for joint, parent in enumerate(skeleton.parents):
        if parent >= 0:
            children[parent].append(joint)
            depth[joint] = depth[parent] + 1
    offsets = skeleton.offsets * scale
    lines = ["HIERARCHY"]
    order: list[int] = []
    pending = [(0, False)]  # (joint, closing): open a joint, or close it after its children
    while pending:
        joint, closing = pending.pop()
        pad = "\t" * depth[joint]
        if closing:
            if joint in skeleton.end_sites:
                end = _vector(skeleton.end_sites[joint] * scale)
                lines.extend(
                    [f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {end}", f"{pad}\t}}"]
                )
            lines.append(f"{pad}}}")
            continue
        root = joint == 0
        offset = np.zeros(3) if root else offsets[joint]
        channels = "6 Xposition Yposition Zposition" if root else "3"
        lines.extend(
            [
                f"{pad}{'ROOT' if root else 'JOINT'} {skeleton.names[joint]}",
                f"{pad}{{",
                f"{pad}\tOFFSET {_vector(offset)}",
                f"{pad}\tCHANNELS {channels} Zrotation Xrotation Yrotation",
            ]
        )
        order.append(joint)
        pending.append((joint, True))
        pending.extend((child, False) for child in reversed(children[joint]))
    return "\n".join(lines) + "\n", order


def _vector(v: np.ndarray) -> str:
    """A 3-vector as BVH numbers with 6 decimals."""
    return " ".join(f"{x + 0.0:.6f}" for x in np.round(v, 6))
