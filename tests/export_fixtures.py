"""Shared pieces of the export tests: a box avatar mesh, synthetic and real takes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from samba.body.take import Take
from samba.export.avatar_mesh import AvatarMesh
from samba.export.humanoid import N_BONES, TIP_BONES, HumanoidRig
from samba.export.motion import HumanoidMotion
from samba.export.retargeting import retarget
from samba.ingest.bvh_take import load_bvh_take
from samba.synthetic import motions as synthetic

RIG_FAMILIES = ("cgspeed", "daz", "iclone")
"""Prefixes of the shared CMU files; the tests export the first file of each."""


def box_mesh(rig: HumanoidRig) -> AvatarMesh:
    """A box around each bone (from its joint to its child's joint or its tip), 3 cm
    thick; the far corners move rigidly with the bone, the near corners of every bone
    but Hips blend 2/3 : 1/3 with the parent, the Chest's 0.7 : 0.2 : 0.1 with Spine and
    Hips, summing to 1 + 8e-7 as a modeller's rounding may leave them (AvatarMesh accepts
    that, the validator would not)."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    box_faces = np.array([f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))])
    ends = rig.rest.copy()
    ends[list(TIP_BONES)] += rig.tips
    for bone, parent in enumerate(rig.parents):
        if parent >= 0 and bone not in (5, 8, 11, 14):  # limbs branch off their parents
            ends[parent] = rig.rest[bone]
    vertices, faces, joints, weights = [], [], [], []
    for bone, parent in enumerate(rig.parents):
        low = np.minimum(rig.rest[bone], ends[bone]) - 0.03
        high = np.maximum(rig.rest[bone], ends[bone]) + 0.03
        vertices.append((low + high) / 2 + corners * (high - low) / 2)
        faces.append(box_faces + 8 * bone)
        near = np.linalg.norm(vertices[-1] - rig.rest[bone], axis=1) < np.linalg.norm(
            vertices[-1] - ends[bone], axis=1
        )
        for is_near in near:
            if bone == 2 and is_near:
                joints.append([2, 1, 0, 0])
                weights.append([0.7, 0.2, 0.1 + 8e-7, 0.0])
            elif parent >= 0 and is_near:
                joints.append([bone, parent, 0, 0])
                weights.append([2 / 3, 1 / 3, 0.0, 0.0])
            else:
                joints.append([bone, 0, 0, 0])
                weights.append([1.0, 0.0, 0.0, 0.0])
    return AvatarMesh(
        vertices=np.concatenate(vertices),
        normals=np.tile(corners / np.sqrt(3.0), (N_BONES, 1)),
        faces=np.concatenate(faces),
        joints=np.array(joints),
        weights=np.array(weights),
    )


def synthetic_motion(
    motion: str = "walk", seconds: float = 4.0, seed: int = 3
) -> tuple[Take, HumanoidMotion]:
    """A synthetic take and its retargeting onto the default rig."""
    take = synthetic.generate(motion, seconds=seconds, seed=seed)
    return take, retarget(take.poses, HumanoidRig.from_body(), take.fps)


def real_takes(cmu_dir: Path) -> list[Take]:
    """The first take of each of the `RIG_FAMILIES` in the shared CMU data."""
    return [load_bvh_take(min(cmu_dir.glob(f"{family}_*.bvh"))) for family in RIG_FAMILIES]
