"""Skeletons sketched as a list of joints and written as BVH in their rest pose
(`rest_pose_bvh`): a four-legged rig (`QUADRUPED`), which an importer must refuse when
nothing but its tree goes by (`unnamed_rig`). The rig tests refuse it, and `samba
examples` writes it as `quadruped.bvh` for the database page's example of a refused rig."""

from __future__ import annotations

SketchJoint = tuple[str, str | None, tuple[float, float, float]]
"""A joint of a sketched rig: its name, its parent's name (None at the root) and its
offset from the parent (x, y, z) in centimetres, +Y up."""

QUADRUPED: list[SketchJoint] = [
    ("Hips", None, (0, 60, 0)),
    ("Spine", "Hips", (0, 0, 30)),
    ("Chest", "Spine", (0, 0, 30)),
    ("Neck", "Chest", (0, 10, 15)),
    ("Head", "Neck", (0, 5, 15)),
    ("LeftUpLeg", "Hips", (10, 0, 0)),
    ("LeftLeg", "LeftUpLeg", (0, -30, 0)),
    ("LeftFoot", "LeftLeg", (0, -28, 0)),
    ("RightUpLeg", "Hips", (-10, 0, 0)),
    ("RightLeg", "RightUpLeg", (0, -30, 0)),
    ("RightFoot", "RightLeg", (0, -28, 0)),
    ("LeftArm", "Chest", (10, 0, 0)),
    ("LeftForeArm", "LeftArm", (0, -30, 0)),
    ("LeftHand", "LeftForeArm", (0, -28, 0)),
    ("RightArm", "Chest", (-10, 0, 0)),
    ("RightForeArm", "RightArm", (0, -30, 0)),
    ("RightHand", "RightForeArm", (0, -28, 0)),
]
"""A four-legged rig (60 cm at the hips, its trunk along +Z), its legs named as a
humanoid's arms and legs."""


def unnamed_rig(rig: list[SketchJoint]) -> list[SketchJoint]:
    """`rig` with every joint named `Bone<i>` (i its place in the list): nothing but the
    tree to go by."""
    names = {name: f"Bone{i}" for i, (name, _, _) in enumerate(rig)}
    return [(names[name], names.get(parent) if parent else None, o) for name, parent, o in rig]


def rest_pose_bvh(rig: list[SketchJoint], frames: int = 2, fps: float = 30.0) -> str:
    """BVH text of `rig` (joints in centimetres, parents before children, one root): six
    channels on the root and three rotation channels on every other joint, an End Site
    3 cm below each leaf, `frames` frames at `fps` frames per second all in the rest
    pose (every channel 0)."""
    children: dict[str | None, list[int]] = {}
    for i, (_, parent, _) in enumerate(rig):
        children.setdefault(parent, []).append(i)
    lines, count = ["HIERARCHY"], 0

    def write(i: int, depth: int) -> None:
        nonlocal count
        name, parent, (x, y, z) = rig[i]
        pad = "  " * depth
        channels = "6 Xposition Yposition Zposition" if parent is None else "3"
        lines.extend(
            [
                f"{pad}{'ROOT' if parent is None else 'JOINT'} {name}",
                f"{pad}{{",
                f"{pad}  OFFSET {x} {y} {z}",
                f"{pad}  CHANNELS {channels} Zrotation Xrotation Yrotation",
            ]
        )
        count += 6 if parent is None else 3
        for child in children.get(name, []):
            write(child, depth + 1)
        if name not in children:
            end = [f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET 0 -3 0", f"{pad}  }}"]
            lines.extend(end)
        lines.append(f"{pad}}}")

    write(children[None][0], 0)
    lines += ["MOTION", f"Frames: {frames}", f"Frame Time: {1.0 / fps:.7f}"]
    lines += [" ".join(["0"] * count)] * frames
    return "\n".join(lines) + "\n"
