"""A user's humanoid avatar (glTF binary or JSON / VRM 0.x / VRM 1.0 / USD) as a
`HumanoidRig`.

Bones are found by the VRM humanoid table when the file has one (`VRMC_vrm` or `VRM`
extension), otherwise by the humanoid resolver (`samba.ingest.resolve_humanoid`: node
or joint names and the skeleton's tree together), so Unity / VRM, Mixamo, Blender,
Unreal, Character Creator and unnamed skeletons alike. Hips, Head and both arms' and
legs' three bones are required; Spine, Chest and Neck are placed on the line from the
hips to the middle of the shoulders where the avatar lacks them. The rest pose is the
file's node transforms (glTF) or the UsdSkel Skeleton's rest transforms, else its bind
transforms (USD: the first Skeleton that is a humanoid's), in meters with +Y up; a
model facing -Z (VRM 0.x) is turned to face +Z, as the retargeting expects.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from samba.export.errors import ExportError
from samba.export.gltf_reader import node_rest_positions, node_tree, read_gltf
from samba.export.humanoid import BONE_INDEX, BONE_NAMES, HumanoidRig
from samba.ingest import HumanoidMap, RigError, SkeletonTree, resolve_humanoid

REQUIRED: tuple[str, ...] = tuple(
    name for name in BONE_NAMES if name not in ("Spine", "Chest", "Neck")
)

_NOT_HUMANOID = "avatar has no humanoid skeleton: "
T = TypeVar("T")


USD_SUFFIXES: tuple[str, ...] = (".usd", ".usda", ".usdc", ".usdz")
"""Suffixes (any letter case) of the avatars read as USD: `samba.export.usd_writer.SUFFIXES`,
spelt out so that reading a glTF avatar does not load usd-core."""

MIN_BONE_M = 1e-3
"""Shortest bone (meters, rest pose) an avatar may have: a bone of zero length has no
direction to turn, and retargeting onto it divides by zero."""


def read_avatar_rig(path: str | Path) -> HumanoidRig:
    """The humanoid rig of the avatar file at `path`, rest pose (17, 3) in meters, +Y up,
    facing +Z. USD (.usd, .usda, .usdc, .usdz) by its suffix, any other file as glTF:
    binary (.glb, .vrm) or JSON (.gltf), told apart by content. Raises `ExportError`
    naming the file when it cannot be read or has no humanoid skeleton (saying what
    could not be placed)."""
    source = str(path)
    if Path(path).suffix.lower() not in USD_SUFFIXES:
        file = read_gltf(path)
        nodes = _malformed_is_named(file.source, _vrm_nodes, file.doc)
        if nodes is not None:  # a VRM file says where its bones are
            world = _malformed_is_named(file.source, node_rest_positions, file)
            return _rig(source, {name: world[node] for name, node in nodes.items()})
    humanoid = avatar_humanoid(path)
    positions = humanoid.tree.positions
    bones = {name: positions[j] for name, j in humanoid.bones.items() if name in BONE_INDEX}
    return _rig(source, bones)


def avatar_humanoid(path: str | Path) -> HumanoidMap:
    """The humanoid resolver's map of the avatar's skeleton (`samba.ingest.HumanoidMap`,
    positions in meters, +Y up): of a glTF file, the skins' joints and their ancestors;
    of a USD file, the first UsdSkel Skeleton that is a humanoid's (a Skeleton that
    cannot be posed, or is no humanoid's, is passed over when another one is). Raises
    `ExportError` naming the file and what could not be placed."""
    if Path(path).suffix.lower() in USD_SUFFIXES:
        return _usd_humanoid(path)
    file = read_gltf(path)
    names, parents, keep = _malformed_is_named(file.source, node_tree, file)
    world = _malformed_is_named(file.source, node_rest_positions, file)
    index = {node: i for i, node in enumerate(keep)}
    tree = SkeletonTree(
        tuple(names[n] for n in keep), tuple(index.get(parents[n], -1) for n in keep), world[keep]
    )
    return _resolved(tree, file.source)


def _malformed_is_named(source: str, read: Callable[[Any], T], what: Any) -> T:
    """`read(what)`, with the errors of a malformed glTF document as `ExportError`."""
    try:
        return read(what)
    except (KeyError, IndexError, TypeError, ValueError, AttributeError) as exc:
        raise ExportError(source, f"malformed glTF: {type(exc).__name__}: {exc}") from exc


def _usd_humanoid(path: str | Path) -> HumanoidMap:
    """`avatar_humanoid` of a USD file."""
    from samba.export.usd_reader import read_usd_skeleton_rests  # pxr loads only for USD avatars

    skeletons = read_usd_skeleton_rests(path)
    reasons = []
    for skeleton in skeletons:
        if skeleton.problem is not None:
            reasons.append(skeleton.problem)
            continue
        tree = SkeletonTree(skeleton.names, skeleton.parents, skeleton.positions)
        try:
            return _resolved(tree, str(path))
        except ExportError as exc:
            if len(skeletons) == 1:
                raise
            reasons.append(f"{skeleton.path}: {exc.problem.removeprefix(_NOT_HUMANOID)}")
    if len(skeletons) == 1:
        raise ExportError(str(path), reasons[0])
    raise ExportError(
        str(path),
        f"{_NOT_HUMANOID}none of its {len(skeletons)} skeletons is a humanoid's "
        f"({'; '.join(reasons)})",
    )


def _resolved(tree: SkeletonTree, source: str) -> HumanoidMap:
    """The resolver's map of `tree`; `ExportError` naming `source` and what could not be
    placed."""
    try:
        return resolve_humanoid(tree, source)
    except RigError as exc:
        problem = exc.problem.removeprefix("not a humanoid skeleton: ")
        raise ExportError(source, f"{_NOT_HUMANOID}{problem}") from None


def _rig(source: str, bones: dict[str, np.ndarray]) -> HumanoidRig:
    """The rig of an avatar's humanoid bones (name -> rest position (3,) in meters, +Y up):
    turned to face +Z, Spine, Chest and Neck filled in where absent, checked for missing,
    non-finite and zero-length bones (`ExportError` naming `source`)."""
    missing = _missing(bones)
    if missing:
        raise ExportError(
            source, f"avatar has no humanoid skeleton: no bone for {', '.join(missing)}"
        )
    rest = np.full((len(BONE_NAMES), 3), np.nan)
    for name, position in bones.items():
        rest[BONE_INDEX[name]] = position
    if rest[BONE_INDEX["LeftUpperArm"], 0] < rest[BONE_INDEX["RightUpperArm"], 0]:
        rest *= [-1.0, 1.0, -1.0]
    _fill_spine(rest)
    if not np.isfinite(rest).all():
        raise ExportError(source, "avatar skeleton has non-finite node transforms")
    rig = HumanoidRig(rest=rest, tips=_tips(rest), name=Path(source).stem)
    lengths = np.linalg.norm(rig.offsets[1:], axis=1)
    if (lengths < MIN_BONE_M).any():
        short = [BONE_NAMES[i + 1] for i in np.flatnonzero(lengths < MIN_BONE_M)]
        raise ExportError(
            source,
            f"avatar bones of (nearly) zero length: {', '.join(short)} (scaled to nothing?)",
        )
    return rig


def _missing(bones: dict[str, np.ndarray]) -> list[str]:
    """The required bones (`REQUIRED` order) that `bones` lacks."""
    return [name for name in REQUIRED if name not in bones]


def _vrm_nodes(doc: dict[str, Any]) -> dict[str, int] | None:
    """Humanoid bone name -> node index from the VRM humanoid table; None without one."""
    extensions = doc.get("extensions") or {}
    nodes = doc.get("nodes", [])
    by_vrm_name = {name[0].lower() + name[1:]: name for name in BONE_NAMES}
    if "VRMC_vrm" in extensions:
        bones = extensions["VRMC_vrm"].get("humanoid", {}).get("humanBones", {})
        pairs = [(key, value.get("node")) for key, value in bones.items()]
    elif "VRM" in extensions:
        bones = extensions["VRM"].get("humanoid", {}).get("humanBones", [])
        pairs = [(b.get("bone", ""), b.get("node")) for b in bones]
    else:
        return None
    wanted = [(key, node) for key, node in pairs if key in by_vrm_name]
    for key, node in wanted:
        if not (isinstance(node, int) and 0 <= node < len(nodes)):
            raise ValueError(f"the VRM humanoid table puts {key} on node {node!r} of {len(nodes)}")
    return {by_vrm_name[key]: node for key, node in wanted}


def _fill_spine(rest: np.ndarray) -> None:
    """Place missing Spine, Chest and Neck on the hips-to-shoulders line, in place."""
    hips = rest[BONE_INDEX["Hips"]]
    shoulders = (rest[BONE_INDEX["LeftUpperArm"]] + rest[BONE_INDEX["RightUpperArm"]]) / 2
    for name, share in (("Neck", 1.0), ("Spine", 0.25), ("Chest", 0.6)):
        if np.isnan(rest[BONE_INDEX[name]]).any():
            rest[BONE_INDEX[name]] = hips + share * (shoulders - hips)


def _tips(rest: np.ndarray) -> np.ndarray:
    """Leaf ends (head top, finger tips, toes) in proportion to the avatar's height."""
    height = (
        rest[BONE_INDEX["Head"], 1]
        - rest[[BONE_INDEX["LeftFoot"], BONE_INDEX["RightFoot"]], 1].mean()
    )
    height = max(height, 1e-3) / 0.86
    tips = [[0.0, 0.10 * height, 0.0]]
    for upper, hand in (("LeftLowerArm", "LeftHand"), ("RightLowerArm", "RightHand")):
        forearm = rest[BONE_INDEX[hand]] - rest[BONE_INDEX[upper]]
        tips.append(0.108 * height * forearm / max(np.linalg.norm(forearm), 1e-9))
    for foot in ("LeftFoot", "RightFoot"):
        ankle = max(rest[BONE_INDEX[foot], 1], 0.0)
        tips.append([0.0, -ankle, 0.11 * height])
    return np.array(tips)
