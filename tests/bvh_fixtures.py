"""BVH text of a humanoid test skeleton for any built-in rig, and its independent FK.

Not a test module: tests import `make_humanoid` / `humanoid_bvh` to write fixture files
and compare the importer's output with `HumanoidFixture.positions`, computed here with
plain rotation matrices straight from the generated joint rotations (never from the BVH
text), so a reader bug cannot hide in both sides of a comparison.

The subject (in meters, right-handed, +Y up, facing +Z, left at +X): root hips -> spine
-> chest -> neck -> head (+End Site); chest -> l/r collar -> shoulder -> elbow -> wrist
(+End Site); hips -> l/r hip -> knee -> ankle -> toe (+End Site). The rest pose is a
T-pose with a leg (hip to ankle) of 0.85 m. The motion is a deterministic mix of joint
angle oscillations (knees always bent forward by 8..32 degrees, arms lowered by about
65 degrees) and root translation, with the root height chosen so that the lower ankle
touches y = 0 in every frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

SKELETON: tuple[tuple[str, str | None, tuple[float, float, float]], ...] = (
    ("hips", None, (0.0, 0.0, 0.0)),
    ("spine", "hips", (0.0, 0.10, 0.0)),
    ("chest", "spine", (0.0, 0.22, 0.0)),
    ("neck", "chest", (0.0, 0.24, 0.0)),
    ("head", "neck", (0.0, 0.12, 0.02)),
    ("head_end", "head", (0.0, 0.16, 0.0)),
    ("l_collar", "chest", (0.03, 0.20, 0.0)),
    ("l_shoulder", "l_collar", (0.15, 0.0, 0.0)),
    ("l_elbow", "l_shoulder", (0.29, 0.0, 0.0)),
    ("l_wrist", "l_elbow", (0.25, 0.0, 0.0)),
    ("l_wrist_end", "l_wrist", (0.08, 0.0, 0.0)),
    ("r_collar", "chest", (-0.03, 0.20, 0.0)),
    ("r_shoulder", "r_collar", (-0.15, 0.0, 0.0)),
    ("r_elbow", "r_shoulder", (-0.29, 0.0, 0.0)),
    ("r_wrist", "r_elbow", (-0.25, 0.0, 0.0)),
    ("r_wrist_end", "r_wrist", (-0.08, 0.0, 0.0)),
    ("l_hip", "hips", (0.09, -0.06, 0.0)),
    ("l_knee", "l_hip", (0.0, -0.43, 0.0)),
    ("l_ankle", "l_knee", (0.0, -0.42, 0.0)),
    ("l_toe", "l_ankle", (0.0, -0.06, 0.13)),
    ("l_toe_end", "l_toe", (0.0, 0.0, 0.05)),
    ("r_hip", "hips", (-0.09, -0.06, 0.0)),
    ("r_knee", "r_hip", (0.0, -0.43, 0.0)),
    ("r_ankle", "r_knee", (0.0, -0.42, 0.0)),
    ("r_toe", "r_ankle", (0.0, -0.06, 0.13)),
    ("r_toe_end", "r_toe", (0.0, 0.0, 0.05)),
)
"""(key, parent key, rest offset in meters) in hierarchy order; '*_end' keys are End Sites."""

LEG_LENGTH = 0.85
"""Hip-to-ankle length of the test subject in meters (thigh 0.43 + shin 0.42)."""

OPTIONAL_JOINTS = ("spine", "neck", "l_collar", "r_collar", "l_toe", "r_toe")
"""Joints left out (their offsets merged into their children) when extra_joints=False."""

MAPPED_KEYS = (
    "head",
    "l_shoulder",
    "r_shoulder",
    "l_elbow",
    "r_elbow",
    "l_wrist",
    "r_wrist",
    "l_hip",
    "r_hip",
    "l_knee",
    "r_knee",
    "l_ankle",
    "r_ankle",
)
"""Skeleton keys of Samba's 13 joints, in `samba.body.skeleton.JOINT_NAMES` order."""

_SIDED = ("collar", "shoulder", "elbow", "wrist", "hip", "knee", "ankle", "toe")


def _sided(center: list[str], left: list[str], right: list[str]) -> dict[str, str]:
    """A rig name table from hips/spine/chest/neck/head names and per-side names."""
    names = dict(zip(("hips", "spine", "chest", "neck", "head"), center, strict=True))
    names.update({f"l_{k}": n for k, n in zip(_SIDED, left, strict=True)})
    names.update({f"r_{k}": n for k, n in zip(_SIDED, right, strict=True)})
    return names


def _lr(
    pattern: str, parts: list[str], sides: tuple[str, str] = ("Left", "Right")
) -> tuple[list[str], list[str]]:
    """Left and right names from a pattern with '{s}' for the side and '{p}' for the part."""
    left = [pattern.format(s=sides[0], p=p) for p in parts]
    right = [pattern.format(s=sides[1], p=p) for p in parts]
    return left, right


_MB_PARTS = ["Shoulder", "Arm", "ForeArm", "Hand", "UpLeg", "Leg", "Foot", "ToeBase"]
RIG_NAMES: dict[str, dict[str, str]] = {
    "cmu-max": _sided(
        ["Hips", "Spine", "Chest", "Neck", "Head"],
        *_lr("{s}{p}", ["Collar", "Shoulder", "Elbow", "Wrist", "Hip", "Knee", "Ankle", "Toe"]),
    ),
    "iclone": _sided(
        ["CC_Base_Hip", "CC_Base_Waist", "CC_Base_Spine02", "CC_Base_NeckTwist01", "CC_Base_Head"],
        *_lr(
            "CC_Base_{s}_{p}",
            ["Clavicle", "Upperarm", "Forearm", "Hand", "Thigh", "Calf", "Foot", "ToeBase"],
            ("L", "R"),
        ),
    ),
    "daz": _sided(
        ["hip", "abdomen", "chest", "neck", "head"],
        ["lCollar", "lShldr", "lForeArm", "lHand", "lThigh", "lShin", "lFoot", "lToe"],
        ["rCollar", "rShldr", "rForeArm", "rHand", "rThigh", "rShin", "rFoot", "rToe"],
    ),
    "mixamo": _sided(
        [f"mixamorig:{n}" for n in ("Hips", "Spine", "Spine1", "Neck", "Head")],
        *_lr("mixamorig:{s}{p}", _MB_PARTS),
    ),
    "motionbuilder": _sided(["Hips", "Spine", "Spine1", "Neck", "Head"], *_lr("{s}{p}", _MB_PARTS)),
    "humanoid": _sided(
        ["Hips", "Spine", "Chest", "Neck", "Head"],
        *_lr(
            "{s}{p}",
            ["Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes"],
        ),
    ),
}
"""Joint names of the test skeleton in each built-in rig of `samba.ingest.rigs.BUILTIN_RIGS`."""


def rig_names(rig: str | Mapping[str, str]) -> dict[str, str]:
    """The full key -> joint name table for a rig name, or a partial table over cmu-max."""
    if isinstance(rig, str):
        return dict(RIG_NAMES[rig])
    names = dict(RIG_NAMES["cmu-max"])
    unknown = set(rig) - set(names)
    if unknown:
        raise KeyError(f"not keys of the test skeleton: {sorted(unknown)}")
    names.update(rig)
    return names


@dataclass(frozen=True)
class HumanoidFixture:
    """A generated BVH file and what a correct importer must make of it.

    `names` are the file's joint names in hierarchy order, End Sites named
    '<parent>_end' as `samba.ingest.bvh` names them; `file_positions` (n, J, 3) their world
    positions in the file's units and axes; `positions` (n, 13, 3) Samba's 13 joints in
    meters, right-handed, +Y up (before any mirroring), with the lower ankle at y = 0
    when the root has position channels; `leg` the hip-to-ankle length in file units.
    """

    text: str
    names: tuple[str, ...]
    file_positions: np.ndarray
    positions: np.ndarray
    leg: float


def _keep(extra_joints: bool) -> list[int]:
    """Indices into SKELETON of the joints written to the file."""
    return [i for i, (k, _, _) in enumerate(SKELETON) if extra_joints or k not in OPTIONAL_JOINTS]


def _local_rotations(
    frames: int, fps: float, seed: int, extra_joints: bool, tpose_frames: int
) -> dict[str, np.ndarray]:
    """Local rotation matrices (n, 3, 3) of every channel-bearing joint key."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / fps
    w = 2 * np.pi * (0.9 + 0.2 * rng.random())

    def osc(amp: float, speed: float = 1.0, base: float = 0.0) -> np.ndarray:
        return base + amp * np.sin(speed * w * t + rng.uniform(0, 2 * np.pi))

    def zxy(z: np.ndarray | float, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray:
        angles = np.stack(np.broadcast_arrays(z, x, y, t)[:3], axis=1)
        return Rotation.from_euler("ZXY", angles, degrees=True).as_matrix()

    gait = rng.uniform(0, 2 * np.pi)
    swing_l = 18 * np.sin(w * t + gait)
    swing_r = 18 * np.sin(w * t + gait + np.pi)
    rot = {
        "hips": zxy(osc(3, 0.7), osc(3, 0.6), osc(12, 0.4)),
        "spine": zxy(osc(3), osc(5), 0.0),
        "chest": zxy(osc(2), osc(4), osc(8)),
        "neck": zxy(0.0, osc(5), osc(4)),
        "head": zxy(osc(4), osc(8), osc(15)),
        "l_collar": zxy(osc(5), 0.0, osc(3)),
        "r_collar": zxy(osc(5), 0.0, osc(3)),
        "l_shoulder": zxy(osc(10, base=-65), osc(10), -swing_r),
        "r_shoulder": zxy(osc(10, base=65), osc(10), swing_l),
        "l_elbow": zxy(0.0, 0.0, osc(15, base=-25)),
        "r_elbow": zxy(0.0, 0.0, osc(15, base=25)),
        "l_wrist": zxy(osc(10), osc(5), osc(5)),
        "r_wrist": zxy(osc(10), osc(5), osc(5)),
        "l_hip": zxy(osc(2, base=3), -swing_l, osc(5)),
        "r_hip": zxy(osc(2, base=-3), -swing_r, osc(5)),
        "l_knee": zxy(0.0, 20 + 12 * np.sin(w * t + gait + 1.0), 0.0),
        "r_knee": zxy(0.0, 20 + 12 * np.sin(w * t + gait + np.pi + 1.0), 0.0),
        "l_ankle": zxy(osc(3), osc(10), osc(3)),
        "r_ankle": zxy(osc(3), osc(10), osc(3)),
        "l_toe": zxy(0.0, osc(10), 0.0),
        "r_toe": zxy(0.0, osc(10), 0.0),
    }
    for key in rot:
        if not extra_joints and key in OPTIONAL_JOINTS:
            rot[key] = np.broadcast_to(np.eye(3), rot[key].shape).copy()
        rot[key][:tpose_frames] = np.eye(3)
    return rot


def _world(rot: dict[str, np.ndarray], root: np.ndarray) -> np.ndarray:
    """World positions (n, len(SKELETON), 3) by forward kinematics with matrices."""
    n = len(root)
    index = {k: i for i, (k, _, _) in enumerate(SKELETON)}
    world_rot = np.empty((n, len(SKELETON), 3, 3))
    world_pos = np.empty((n, len(SKELETON), 3))
    identity = np.broadcast_to(np.eye(3), (n, 3, 3))
    for i, (key, parent, offset) in enumerate(SKELETON):
        local = rot.get(key, identity)
        if parent is None:
            world_rot[:, i] = local
            world_pos[:, i] = root
        else:
            p = index[parent]
            world_rot[:, i] = world_rot[:, p] @ local
            world_pos[:, i] = world_pos[:, p] + world_rot[:, p] @ np.array(offset)
    return world_pos


def _axes(up: str, mirror: bool) -> np.ndarray:
    """The matrix taking Samba's frame (+Y up) to the file's frame."""
    if up == "+y":
        c = np.eye(3)
    elif up == "+z":
        c = Rotation.from_euler("X", 90, degrees=True).as_matrix()  # +Y -> +Z, +Z -> -Y
    else:
        raise ValueError(f"up must be '+y' or '+z', got {up!r}")
    if mirror:
        c = c @ np.diag([-1.0, 1.0, 1.0])
    return c


def make_humanoid(
    rig: str | Mapping[str, str] = "cmu-max",
    frames: int = 10,
    fps: float = 30.0,
    unit_scale: float = 1.0,
    up: str = "+y",
    channel_order: str | Sequence[str] = "ZXY",
    root_position_channels: bool = True,
    extra_joints: bool = True,
    seed: int = 0,
    line_ending: str = "\n",
    indent: str = "\t",
    tpose_frames: int = 0,
    mirror: bool = False,
    number_format: str = ".6f",
) -> HumanoidFixture:
    """Generate the test subject as BVH text plus its independently computed positions.

    `rig`: a built-in rig name or a partial key -> name table over the cmu-max names.
    `unit_scale`: file units per meter (100 for cm, 1 / 0.056444 for CMU units). `up`:
    '+y', or '+z' to lay the skeleton and motion along +Z (rotated +90 degrees about X).
    `channel_order`: rotation channel order, or a sequence used per joint in turn.
    `root_position_channels`: False writes a fixed root OFFSET instead (the feet then
    never go below the floor and touch it in one frame). `extra_joints`: False leaves
    out spine, neck, collars and toes. `tpose_frames`: leading frames in the rest
    T-pose. `mirror`: negate X of every offset and position (a left-handed recording,
    whose knees seem to bend backwards). `number_format`: format spec of every number.
    """
    names = rig_names(rig)
    rot = _local_rotations(frames, fps, seed, extra_joints, tpose_frames)
    rng = np.random.default_rng(seed + 1)
    t = np.arange(frames) / fps
    root = np.zeros((frames, 3))
    root[:, 0] = 0.05 * np.sin(1.3 * t + rng.uniform(0, 2 * np.pi))
    root[:, 2] = 0.25 * np.sin(0.8 * t + rng.uniform(0, 2 * np.pi))
    world = _world(rot, root)
    ankles = [i for i, (k, _, _) in enumerate(SKELETON) if k.endswith("_ankle")]
    root[:, 1] = -world[:, ankles, 1].min(axis=1)
    if not root_position_channels:
        root = np.broadcast_to([0.0, root[:, 1].max(), 0.0], root.shape).copy()
    world = _world(rot, root)

    c = _axes(up, mirror)
    keep = _keep(extra_joints)
    key_of = [SKELETON[i][0] for i in keep]
    file_world = unit_scale * np.einsum("ij,nkj->nki", c, world[:, keep])
    parent_of: dict[str, str | None] = {}
    offset_of: dict[str, np.ndarray] = {}
    for key, parent, offset in SKELETON:
        merged = np.array(offset)
        while parent in OPTIONAL_JOINTS and not extra_joints:
            grand = next(s for s in SKELETON if s[0] == parent)
            merged = merged + np.array(grand[2])
            parent = grand[1]
        parent_of[key], offset_of[key] = parent, merged

    def name(key: str) -> str:
        parent = parent_of[key]
        return f"{names[parent]}_end" if key.endswith("_end") and parent else names[key]

    orders = [channel_order] if isinstance(channel_order, str) else list(channel_order)
    fmt = f"{{:{number_format}}}"
    lines = ["HIERARCHY"]
    columns: list[np.ndarray] = []

    def write(key: str, depth: int) -> None:
        pad = indent * depth
        is_end = key.endswith("_end")
        if is_end:
            lines.append(f"{pad}End Site")
        else:
            lines.append(f"{pad}{'ROOT' if depth == 0 else 'JOINT'} {names[key]}")
        lines.append(f"{pad}{{")
        offset = unit_scale * c @ offset_of[key]
        if depth == 0:
            offset = np.zeros(3) if root_position_channels else unit_scale * c @ root[0]
        lines.append(f"{pad}{indent}OFFSET " + " ".join(fmt.format(v) for v in offset))
        if not is_end:
            order = orders[len(columns) % len(orders)].upper()
            channels = [f"{a}rotation" for a in order]
            local = c @ rot[key] @ c.T
            angles = Rotation.from_matrix(local).as_euler(order, degrees=True)
            if depth == 0 and root_position_channels:
                channels = ["Xposition", "Yposition", "Zposition", *channels]
                angles = np.concatenate([unit_scale * root @ c.T, angles], axis=1)
            lines.append(f"{pad}{indent}CHANNELS {len(channels)} {' '.join(channels)}")
            columns.append(angles)
        for child in key_of:
            if parent_of[child] == key:
                write(child, depth + 1)
        lines.append(f"{pad}}}")

    write("hips", 0)
    motion = np.concatenate(columns, axis=1)
    lines += ["MOTION", f"Frames: {frames}", f"Frame Time: {1.0 / fps:.8f}"]
    lines += [" ".join(fmt.format(v) for v in row) for row in motion]
    text = line_ending.join(lines) + line_ending

    index = {k: i for i, (k, _, _) in enumerate(SKELETON)}
    return HumanoidFixture(
        text=text,
        names=tuple(name(k) for k in key_of),  # SKELETON is listed depth-first, like the file
        file_positions=file_world,
        positions=world[:, [index[k] for k in MAPPED_KEYS]],
        leg=LEG_LENGTH * unit_scale,
    )


def humanoid_bvh(rig: str | Mapping[str, str] = "cmu-max", **options: object) -> str:
    """BVH text of the test subject; options as for `make_humanoid`."""
    return make_humanoid(rig, **options).text  # type: ignore[arg-type]


def humanoid_positions(**options: object) -> np.ndarray:
    """Expected 13-joint positions (n, 13, 3), meters, +Y up; options as for `make_humanoid`."""
    return make_humanoid(**options).positions  # type: ignore[arg-type]
