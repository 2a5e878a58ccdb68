"""`AvatarMesh`: a triangle mesh skinned to the humanoid rig, in the rig's rest pose."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from samba.export.humanoid import N_BONES

MAX_INFLUENCES = 4
"""Bones that may move one vertex (the glTF / game-engine limit)."""


@dataclass(frozen=True)
class AvatarMesh:
    """`vertices` (V, 3) float32 meters and `normals` (V, 3) float32 unit vectors in the
    rest pose (the same frame as `HumanoidRig.rest`), `faces` (F, 3) uint32 vertex indices
    counter-clockwise seen from outside, `joints` (V, 4) uint16 bone indices and
    `weights` (V, 4) float32 skin weights: non-negative, summing to 1 per vertex, unused
    slots with weight 0 and bone 0, the largest weight first."""

    vertices: np.ndarray
    normals: np.ndarray
    faces: np.ndarray
    joints: np.ndarray
    weights: np.ndarray

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(self.vertices, dtype=np.float32)
        n_v = len(v)
        checks = {
            "vertices": (v, (n_v, 3)),
            "normals": (np.asarray(self.normals), (n_v, 3)),
            "faces": (np.asarray(self.faces), (len(self.faces), 3)),
            "joints": (np.asarray(self.joints), (n_v, MAX_INFLUENCES)),
            "weights": (np.asarray(self.weights), (n_v, MAX_INFLUENCES)),
        }
        for name, (array, shape) in checks.items():
            if array.shape != shape:
                raise ValueError(f"avatar mesh {name} must have shape {shape}, got {array.shape}")
        faces = np.ascontiguousarray(self.faces, dtype=np.uint32)
        joints = np.ascontiguousarray(self.joints, dtype=np.uint16)
        weights = np.ascontiguousarray(self.weights, dtype=np.float32)
        if faces.size and faces.max() >= n_v:
            raise ValueError("avatar mesh faces refer to missing vertices")
        if joints.size and joints.max() >= N_BONES:
            raise ValueError("avatar mesh joints refer to missing bones")
        if (weights < 0).any() or not np.allclose(weights.sum(axis=1), 1.0, atol=1e-6):
            raise ValueError("avatar mesh weights must be >= 0 and sum to 1 per vertex")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "normals", np.ascontiguousarray(self.normals, dtype=np.float32))
        object.__setattr__(self, "faces", faces)
        object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "weights", weights)
