"""Run inside Blender's Python (`bpy`): open each file given (BVH or glTF) as Blender's own
importers do and print, as one JSON line per file, what a user would look at: frames,
bones, the lower ankle's height over the take and how often the head is above the hips
(Blender's world: Z up, meters)."""

import json
import sys

import bpy
import numpy as np


def bone(armature, *keys: str) -> str:
    """The first pose bone whose lower-case name contains one of `keys`."""
    for key in keys:
        for name in armature.pose.bones.keys():  # noqa: SIM118 - a Blender collection
            if key in name.lower():
                return name
    raise KeyError(f"no bone named like {keys}")


def measure(path: str) -> dict:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if path.lower().endswith(".bvh"):
        bpy.ops.import_anim.bvh(filepath=path, axis_forward="-Z", axis_up="Y")
    else:
        bpy.ops.import_scene.gltf(filepath=path)
    armature = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
    start, end = (int(v) for v in armature.animation_data.action.frame_range)
    names = [
        bone(armature, "leftfoot", "foot.l"),
        bone(armature, "rightfoot", "foot.r"),
        bone(armature, "head"),
        bone(armature, "hips", "pelvis"),
    ]
    heights = []
    for frame in range(start, end + 1):
        bpy.context.scene.frame_set(frame)
        world = armature.matrix_world
        heights.append([(world @ armature.pose.bones[n].head).z for n in names])
    h = np.array(heights)
    ankle = h[:, :2].min(axis=1)
    return {
        "path": path,
        "blender": bpy.app.version_string,
        "frames": len(h),
        "bones": len(armature.pose.bones),
        "ankle_p10_m": float(np.percentile(ankle, 10)),
        "ankle_median_m": float(np.median(ankle)),
        "head_above_hips": float(np.mean(h[:, 2] > h[:, 3])),
        "head_median_m": float(np.median(h[:, 2])),
    }


for argument in sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else sys.argv[1:]:
    print("SAMBA " + json.dumps(measure(argument)), flush=True)
