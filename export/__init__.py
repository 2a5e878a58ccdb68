"""Retargeting the 13-joint skeleton onto humanoid avatars (the built-in mannequin, or a
user's USD / glTF / VRM avatar), live for VMC and offline for takes, and the USD, glTF
and BVH writers (`samba export`); skeleton-only avatars named as other tools name bones.
"""

from samba.export.avatar_file import avatar_humanoid, read_avatar_rig
from samba.export.bvh_writer import UNITS, BvhSkeleton, write_bvh_motion
from samba.export.gltf_reader import read_glb
from samba.export.gltf_writer import write_glb
from samba.export.humanoid import BONE_NAMES, N_BONES, HumanoidRig
from samba.export.live_retarget import LiveRetarget, retarget_together
from samba.export.mannequin import mannequin
from samba.export.motion import HumanoidMotion
from samba.export.named_avatars import AVATAR_CONVENTIONS, glb_with_json, write_named_avatar
from samba.export.outputs import FORMAT_SUFFIXES, Avatar, format_of, load_avatar, write_export
from samba.export.retargeting import retarget

__all__ = [
    "AVATAR_CONVENTIONS",
    "BONE_NAMES",
    "FORMAT_SUFFIXES",
    "N_BONES",
    "UNITS",
    "Avatar",
    "BvhSkeleton",
    "HumanoidMotion",
    "HumanoidRig",
    "LiveRetarget",
    "avatar_humanoid",
    "format_of",
    "glb_with_json",
    "load_avatar",
    "mannequin",
    "read_avatar_rig",
    "read_glb",
    "retarget",
    "retarget_together",
    "write_bvh_motion",
    "write_export",
    "write_glb",
    "write_named_avatar",
]
