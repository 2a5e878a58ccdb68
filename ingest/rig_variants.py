"""Variants of a BVH rig as other tools write them: the same motion under other joint
names, with extra twist and roll bones, position channels on every joint, bones laid
along local X, or a dummy root above the hips. Every variant keeps every joint's world
position in every frame, so an importer must give the same 13 joints from each (the
rig tests check it; `samba examples` writes a game-studio walk with them)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from samba.ingest.bvh import BvhFile
from samba.ingest.resolver import resolve_humanoid

ROLES = (
    "Hips",
    "Spine",
    "Chest",
    "Neck",
    "Head",
    "Shoulder",
    "UpperArm",
    "LowerArm",
    "Hand",
    "LegRoot",
    "UpperLeg",
    "LowerLeg",
    "Foot",
)
RIG_CONVENTIONS: dict[str, dict[str, str]] = {
    "blender": dict(
        zip(
            ROLES,
            (
                "pelvis",
                "spine",
                "spine.001",
                "neck",
                "head",
                "shoulder.{L}",
                "upper_arm.{L}",
                "forearm.{L}",
                "hand.{L}",
                "pelvis.{L}",
                "thigh.{L}",
                "shin.{L}",
                "foot.{L}",
            ),
            strict=True,
        )
    ),
    "maya": dict(
        zip(
            ROLES,
            (
                "Root_M",
                "Spine1_M",
                "Chest_M",
                "Neck_M",
                "Head_M",
                "{L}_Clavicle",
                "{L}_UpperArm",
                "{L}_ForeArm",
                "{L}_Hand",
                "{L}_HipJoint",
                "{L}_Thigh",
                "{L}_Knee",
                "{L}_Ankle",
            ),
            strict=True,
        )
    ),
    "unreal": dict(
        zip(
            ROLES,
            (
                "pelvis",
                "spine_01",
                "spine_02",
                "neck_01",
                "head",
                "clavicle_{l}",
                "upperarm_{l}",
                "lowerarm_{l}",
                "hand_{l}",
                "hipjoint_{l}",
                "thigh_{l}",
                "calf_{l}",
                "foot_{l}",
            ),
            strict=True,
        )
    ),
    "unity": dict(
        zip(
            ROLES,
            (
                "Hips",
                "Spine",
                "Chest",
                "Neck",
                "Head",
                "{Left}Shoulder",
                "{Left}UpperArm",
                "{Left}LowerArm",
                "{Left}Hand",
                "{Left}HipJoint",
                "{Left}UpperLeg",
                "{Left}LowerLeg",
                "{Left}Foot",
            ),
            strict=True,
        )
    ),
    "lower case": dict(
        zip(
            ROLES,
            (
                "hips",
                "spine",
                "spine1",
                "neck",
                "head",
                "{left}shoulder",
                "{left}arm",
                "{left}forearm",
                "{left}hand",
                "{left}hipjoint",
                "{left}upleg",
                "{left}leg",
                "{left}foot",
            ),
            strict=True,
        )
    ),
    "game studio": dict(
        zip(
            ROLES,
            (
                "Hips",
                "Spine",
                "Chest",
                "Neck",
                "Head",
                "Shoulder_{L}",
                "UpperArm_{L}",
                "LowerArm_{L}",
                "Hand_{L}",
                "HipJoint_{L}",
                "UpperLeg_{L}",
                "LowerLeg_{L}",
                "Foot_{L}",
            ),
            strict=True,
        )
    ),
}
"""Joint names per convention, `{L}` / `{l}` / `{Left}` / `{left}` standing for the side."""
RIG_STRUCTURES = ("twist and roll bones", "position channels", "bones along X", "dummy root")


@dataclass
class _Node:
    name: str
    parent: int
    offset: np.ndarray
    channels: list[str]
    values: np.ndarray  # (frames, len(channels))
    end_site: bool
    children: list[int] = field(default_factory=list)


def rig_variant(
    bvh: BvhFile, convention: str, structures: tuple[str, ...] = (), frames: int = 40
) -> str:
    """BVH text of the first `frames` frames of `bvh` renamed after `convention` (a key of
    `RIG_CONVENTIONS`, or "original") with the changes `structures` (of `RIG_STRUCTURES`)."""
    nodes = [
        _Node(
            j.name,
            j.parent,
            np.array(j.offset, dtype=np.float64),
            list(j.channels),
            bvh.motion[:frames, j.first_channel : j.first_channel + len(j.channels)].copy(),
            j.end_site,
        )
        for j in bvh.joints
    ]
    bones = resolve_humanoid(bvh.skeleton(), bvh.source).bones
    if convention != "original":
        _rename(nodes, bones, RIG_CONVENTIONS[convention])
    if "twist and roll bones" in structures:
        _twists(nodes, bones)
    if "position channels" in structures:
        for node in nodes[1:]:
            if not node.end_site and "Xposition" not in node.channels:
                node.channels = ["Xposition", "Yposition", "Zposition", *node.channels]
                moving = np.broadcast_to(node.offset, (len(node.values), 3))
                node.values = np.concatenate([moving, node.values], axis=1)
    if "bones along X" in structures:
        _along_x(nodes)
    if "dummy root" in structures:
        root = _Node(
            "joint_Root",
            -1,
            np.zeros(3),
            ["Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"],
            np.zeros((frames, 6)),
            False,
        )
        nodes.insert(0, root)
        for node in nodes[1:]:
            node.parent += 1
        nodes[1].parent = 0
    return _text(nodes, bvh.frame_time)


def _rename(nodes: list[_Node], bones: dict[str, int], names: dict[str, str]) -> None:
    for bone, index in bones.items():
        side = next((s for s in ("Left", "Right") if bone.startswith(s)), "")
        role = bone.removeprefix(side)
        if role in names:
            letter = side[:1]
            nodes[index].name = names[role].format(
                L=letter, l=letter.lower(), Left=side, left=side.lower()
            )


def _twists(nodes: list[_Node], bones: dict[str, int]) -> None:
    """An upper-arm twist bone in each arm's chain, a roll bone hanging off each shin."""
    for side in ("Left", "Right"):
        upper, lower = bones[side + "UpperArm"], bones[side + "LowerArm"]
        shin = bones[side + "LowerLeg"]
        twist = _Node(
            nodes[upper].name + "_twist",
            upper,
            nodes[lower].offset / 2,
            ["Zrotation", "Xrotation", "Yrotation"],
            np.zeros((len(nodes[0].values), 3)),
            False,
        )
        nodes.append(twist)
        nodes[lower].parent = len(nodes) - 1
        nodes[lower].offset = nodes[lower].offset / 2
        roll = _Node(
            nodes[shin].name + "_roll",
            shin,
            np.array([0.0, -1.0, 0.0]),
            ["Zrotation", "Xrotation", "Yrotation"],
            np.zeros((len(nodes[0].values), 3)),
            False,
        )
        nodes.append(roll)
        nodes.append(
            _Node(
                roll.name + "_end",
                len(nodes) - 1,
                np.array([0.0, -1.0, 0.0]),
                [],
                np.zeros((len(nodes[0].values), 0)),
                True,
            )
        )


def _along_x(nodes: list[_Node]) -> None:
    """Each joint's rest frame turned so that its bone (to its first child) lies along
    local +X; offsets and rotation channels change so that the motion stays the same."""
    children: list[list[int]] = [[] for _ in nodes]
    for i, node in enumerate(nodes):
        if node.parent >= 0:
            children[node.parent].append(i)
    turns = []
    for i, node in enumerate(nodes):
        first = next((c for c in children[i] if np.linalg.norm(nodes[c].offset) > 1e-9), None)
        if first is None or node.end_site:
            turns.append(Rotation.identity())
            continue
        bone = nodes[first].offset / np.linalg.norm(nodes[first].offset)
        turn, _ = Rotation.align_vectors([bone], [[1.0, 0.0, 0.0]])
        turns.append(turn)
    for i, node in enumerate(nodes):
        parent_turn = turns[node.parent] if node.parent >= 0 else Rotation.identity()
        node.offset = parent_turn.inv().apply(node.offset)
        rotation_axes = "".join(c[0] for c in node.channels if c.endswith("rotation"))
        if not rotation_axes:
            continue
        columns = [k for k, c in enumerate(node.channels) if c.endswith("rotation")]
        local = Rotation.from_euler(rotation_axes, node.values[:, columns], degrees=True)
        turned = parent_turn.inv() * local * turns[i]
        node.values[:, columns] = turned.as_euler(rotation_axes, degrees=True)
        positions = [k for k, c in enumerate(node.channels) if c.endswith("position")]
        if positions and node.parent >= 0:
            node.values[:, positions] = parent_turn.inv().apply(node.values[:, positions])


def _text(nodes: list[_Node], frame_time: float) -> str:
    children: list[list[int]] = [[] for _ in nodes]
    for i, node in enumerate(nodes):
        if node.parent >= 0:
            children[node.parent].append(i)
    lines, order = ["HIERARCHY"], []

    def write(i: int, depth: int) -> None:
        node, pad = nodes[i], "  " * depth
        x, y, z = node.offset
        if node.end_site:
            lines.extend(
                [f"{pad}End Site", f"{pad}{{", f"{pad}  OFFSET {x:.6f} {y:.6f} {z:.6f}", f"{pad}}}"]
            )
            return
        lines.extend(
            [
                f"{pad}{'ROOT' if node.parent < 0 else 'JOINT'} {node.name}",
                f"{pad}{{",
                f"{pad}  OFFSET {x:.6f} {y:.6f} {z:.6f}",
                f"{pad}  CHANNELS {len(node.channels)} {' '.join(node.channels)}",
            ]
        )
        order.append(i)
        for c in children[i]:
            write(c, depth + 1)
        lines.append(f"{pad}}}")

    write(next(i for i, n in enumerate(nodes) if n.parent < 0), 0)
    motion = np.concatenate([nodes[i].values for i in order], axis=1)
    lines += ["MOTION", f"Frames: {len(motion)}", f"Frame Time: {frame_time:.7f}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in motion]
    return "\n".join(lines) + "\n"
