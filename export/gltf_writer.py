"""glTF 2.0 binary (.glb) export: the humanoid skeleton, its animation, an optional skinned body.

Layout (FORMATS.md §2.2), which the Khronos validator passes with no errors or warnings:

* scene roots `Armature` (no transform) and, with a mesh, `Body` (mesh and skin, no
  transform); the 17 joint nodes hang under `Armature` with the Unity / VRM humanoid
  bone names, translation = rest offset from the parent (Hips: its rest position) and
  identity rotation, so the rest pose is the rig's;
* one skin over the joints in bone order, its inverse bind matrices the inverse rest
  translations (rest orientations are the identity);
* one animation: a LINEAR rotation channel per bone and a translation channel for Hips,
  sharing one key-time accessor (frame / fps seconds).

Our frame is glTF's (meters, +Y up, facing +Z), so no axis change is needed. Every
buffer view starts 4-byte aligned in one binary blob; vertex data and indices carry
their buffer-view targets, animation and bind-matrix data none.
"""

from __future__ import annotations

import os

import numpy as np
import pygltflib as gltf

from samba.base import write_bytes_atomic
from samba.export.avatar_mesh import AvatarMesh
from samba.export.errors import ExportError
from samba.export.humanoid import N_BONES
from samba.export.motion import HumanoidMotion

_COMPONENT_TYPES: dict[np.dtype, int] = {
    np.dtype(np.float32): gltf.FLOAT,
    np.dtype(np.uint16): gltf.UNSIGNED_SHORT,
    np.dtype(np.uint32): gltf.UNSIGNED_INT,
}
_ELEMENT_TYPES: dict[tuple[int, ...], str] = {
    (): gltf.SCALAR,
    (3,): gltf.VEC3,
    (4,): gltf.VEC4,
    (4, 4): gltf.MAT4,
}


def write_glb(
    path: str | os.PathLike[str], motion: HumanoidMotion, mesh: AvatarMesh | None = None
) -> None:
    """Write `motion` (and `mesh` skinned to its rig, if given) as a .glb file at `path`.

    Joint positions are in meters, key times in seconds (frame / motion.fps). The file is
    written atomically: on any failure `path` keeps its old content (or stays absent).
    Raises `ExportError` naming `path` when it cannot be written, `ValueError` for a
    mesh without triangles.
    """
    data = _glb_bytes(motion, mesh)
    try:
        write_bytes_atomic(path, data)
    except OSError as exc:
        raise ExportError(str(path), f"cannot write the file: {exc.strerror or exc}") from exc


def _glb_bytes(motion: HumanoidMotion, mesh: AvatarMesh | None) -> bytes:
    """The whole .glb file for `motion` and an optional `mesh`."""
    rig = motion.rig
    doc = gltf.GLTF2(asset=gltf.Asset(generator="samba-mocap", version="2.0"))
    blob = _Blob(doc)
    children: list[list[int]] = [[] for _ in range(N_BONES)]
    for bone, parent in enumerate(rig.parents):
        if parent >= 0:
            children[parent].append(_joint_node(bone))
    doc.nodes = [gltf.Node(name="Armature", children=[_joint_node(0)])]
    doc.nodes += [
        gltf.Node(name=name, translation=offset.tolist(), children=kids)
        for name, offset, kids in zip(rig.names, rig.offsets, children, strict=True)
    ]
    roots = [0]
    if mesh is not None:
        doc.meshes = [_skinned_mesh(blob, mesh)]
        ibm = np.tile(np.eye(4, dtype=np.float32), (N_BONES, 1, 1))
        ibm[:, 3, :3] = -rig.rest  # column-major storage: the translation is the 4th column
        doc.skins = [
            gltf.Skin(
                name=rig.name,
                joints=[_joint_node(bone) for bone in range(N_BONES)],
                inverseBindMatrices=blob.add(ibm),
                skeleton=_joint_node(0),
            )
        ]
        doc.nodes.append(gltf.Node(name="Body", mesh=0, skin=0))
        roots.append(len(doc.nodes) - 1)
    doc.scenes = [gltf.Scene(name=rig.name, nodes=roots)]
    doc.scene = 0
    doc.animations = [_animation(blob, motion)]
    doc.buffers = [gltf.Buffer(byteLength=blob.size)]
    doc.set_binary_blob(blob.data())
    return b"".join(doc.save_to_bytes())


def _joint_node(bone: int) -> int:
    """Node index of a bone's joint (node 0 is the Armature)."""
    return bone + 1


def _animation(blob: _Blob, motion: HumanoidMotion) -> gltf.Animation:
    """One animation: a rotation channel per bone, a translation channel for Hips."""
    per_bone = np.swapaxes(motion.rotations, 0, 1).astype(np.float32)
    times = blob.add((np.arange(len(motion)) / motion.fps).astype(np.float32), bounds=True)
    outputs = [(_joint_node(bone), "rotation", per_bone[bone]) for bone in range(N_BONES)]
    outputs.append((_joint_node(0), "translation", motion.root.astype(np.float32)))
    samplers, channels = [], []
    for node, target, values in outputs:
        channels.append(
            gltf.AnimationChannel(
                sampler=len(samplers), target=gltf.AnimationChannelTarget(node=node, path=target)
            )
        )
        samplers.append(
            gltf.AnimationSampler(input=times, output=blob.add(values), interpolation="LINEAR")
        )
    return gltf.Animation(name="take", samplers=samplers, channels=channels)


def _skinned_mesh(blob: _Blob, mesh: AvatarMesh) -> gltf.Mesh:
    """The body mesh: rest-pose positions (with bounds), unit normals, skin joints and
    weights normalised for the validator, triangle indices."""
    if len(mesh.faces) == 0:
        raise ValueError("avatar mesh has no triangles")
    normals = mesh.normals.astype(np.float64)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    attributes = gltf.Attributes(
        POSITION=blob.add(mesh.vertices, gltf.ARRAY_BUFFER, bounds=True),
        NORMAL=blob.add(normals.astype(np.float32), gltf.ARRAY_BUFFER),
        JOINTS_0=blob.add(mesh.joints, gltf.ARRAY_BUFFER),
        WEIGHTS_0=blob.add(_normalised_weights(mesh.weights), gltf.ARRAY_BUFFER),
    )
    indices = blob.add(mesh.faces.reshape(-1), gltf.ELEMENT_ARRAY_BUFFER)
    return gltf.Mesh(
        name="Body", primitives=[gltf.Primitive(attributes=attributes, indices=indices)]
    )


def _normalised_weights(weights: np.ndarray) -> np.ndarray:
    """Skin weights (V, 4) as float32 rows that sum to 1 within the validator's tolerance:
    normalised in float64, then the largest set to 1 minus the others' float32 sum."""
    w = np.asarray(weights, dtype=np.float64)
    w32 = (w / w.sum(axis=1, keepdims=True)).astype(np.float32)
    rows = np.arange(len(w32))
    top = np.argmax(w32, axis=1)
    others = w32.copy()
    others[rows, top] = 0.0
    w32[rows, top] = np.float32(1.0) - others.sum(axis=1, dtype=np.float32)
    return w32


class _Blob:
    """The binary chunk under construction: one buffer view and accessor per array."""

    def __init__(self, doc: gltf.GLTF2) -> None:
        self.doc = doc
        self.chunks: list[bytes] = []
        self.size = 0

    def add(self, array: np.ndarray, target: int | None = None, bounds: bool = False) -> int:
        """Append `array` (count, *element shape) as a new 4-byte aligned buffer view with
        an accessor over it; returns the accessor index. `bounds` adds min / max."""
        array = np.ascontiguousarray(array)
        raw = array.tobytes()
        self.doc.bufferViews.append(
            gltf.BufferView(buffer=0, byteOffset=self.size, byteLength=len(raw), target=target)
        )
        accessor = gltf.Accessor(
            bufferView=len(self.doc.bufferViews) - 1,
            componentType=_COMPONENT_TYPES[array.dtype],
            count=len(array),
            type=_ELEMENT_TYPES[array.shape[1:]],
        )
        if bounds:
            flat = array.reshape(len(array), -1)
            accessor.min = flat.min(axis=0).tolist()
            accessor.max = flat.max(axis=0).tolist()
        self.doc.accessors.append(accessor)
        padding = -len(raw) % 4
        self.chunks += [raw, bytes(padding)]
        self.size += len(raw) + padding
        return len(self.doc.accessors) - 1

    def data(self) -> bytes:
        """The chunk's bytes, `size` long."""
        return b"".join(self.chunks)
