"""Reading joint motion back from a glTF 2.0 binary (.glb) file.

The verification reader of `export.gltf_writer`, written for any reasonable .glb: it
parses the GLB container itself, reads accessors of any component type (normalised
integers included, interleaved views too) and samples STEP, LINEAR and CUBICSPLINE
animation channels. The joints are the nodes of the file's skins (first skin's order,
then any others); a file without skins takes every node the first animation moves,
directly or through an ancestor. World transforms follow the spec (FORMATS.md §2.9): at
each key time the animated TRS replaces the node's own, and world = parentWorld·T·R·S.
"""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from export.errors import ExportError

_MAGIC = b"glTF"
_JSON_CHUNK = 0x4E4F534A
_BIN_CHUNK = 0x004E4942
_COMPONENTS: dict[int, type[np.generic]] = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
_WIDTHS: dict[str, int] = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}
"""Element widths of the accessors an animation reads: key times, vectors, quaternions."""
_TRS: dict[str, list[float]] = {
    "translation": [0.0, 0.0, 0.0],
    "rotation": [0.0, 0.0, 0.0, 1.0],
    "scale": [1.0, 1.0, 1.0],
}


def read_glb_joint_positions(path: str | os.PathLike[str]) -> tuple[tuple[str, ...], np.ndarray]:
    """Joint node names and their world positions (n_keys, n_joints, 3) at every key time
    of the file's first animation (file units, meters for glTF; one key, the static pose,
    when there is no animation). Key times are the union of the animation's sampler
    inputs. Raises `ExportError` naming the file when it cannot be read, is not a .glb or
    is malformed.
    """
    file = read_glb(path)
    try:
        return _joint_positions(file)
    except (KeyError, IndexError, TypeError, ValueError, AttributeError) as exc:
        raise ExportError(file.source, f"malformed glTF: {type(exc).__name__}: {exc}") from exc


def read_glb(path: str | os.PathLike[str]) -> GlbDocument:
    """The parsed .glb (or .vrm, the same container) at `path`; `ExportError` naming the
    file when it cannot be read or is not a GLB container."""
    source = str(path)
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ExportError(source, f"cannot read the file: {exc.strerror or exc}") from exc
    doc, binary = _parse_glb(data, source)
    return GlbDocument(doc, binary, source)


def _parse_glb(data: bytes, source: str) -> tuple[dict[str, Any], bytes]:
    """The JSON document and the binary chunk (b"" if none) of a GLB container."""
    if len(data) < 20 or data[:4] != _MAGIC:
        raise ExportError(
            source, "not a binary glTF (.glb) file: avatars are read from .glb or .vrm files"
        )
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise ExportError(source, f"glTF container version {version} is not supported (need 2)")
    if length != len(data):
        raise ExportError(source, f"the header says {length} bytes but the file has {len(data)}")
    chunks: list[tuple[int, bytes]] = []
    offset = 12
    while offset < length:
        if offset + 8 > length:
            raise ExportError(source, f"truncated chunk header at byte {offset}")
        size, kind = struct.unpack_from("<II", data, offset)
        if offset + 8 + size > length:
            raise ExportError(source, f"chunk at byte {offset} runs past the end of the file")
        chunks.append((kind, data[offset + 8 : offset + 8 + size]))
        offset += 8 + size
    if not chunks or chunks[0][0] != _JSON_CHUNK:
        raise ExportError(source, "the first chunk is not the JSON chunk")
    try:
        doc = json.loads(chunks[0][1].decode("utf-8"))
    except ValueError as exc:
        raise ExportError(source, f"the JSON chunk is not valid JSON: {exc}") from exc
    if not isinstance(doc, dict):
        raise ExportError(source, "the JSON chunk is not a glTF object")
    binary = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == _BIN_CHUNK else b""
    return doc, binary


class GlbDocument:
    """A parsed .glb: the JSON document, its binary chunk and where it came from."""

    def __init__(self, doc: dict[str, Any], binary: bytes, source: str) -> None:
        self.doc = doc
        self.binary = binary
        self.source = source

    def accessor(self, index: int) -> np.ndarray:
        """Accessor `index` as float64 (count, width), normalised integers mapped to
        [0, 1] / [-1, 1]."""
        acc = self.doc["accessors"][index]
        if "sparse" in acc:
            raise ExportError(self.source, f"accessor {index}: sparse accessors are not supported")
        dtype = np.dtype(_COMPONENTS[acc["componentType"]]).newbyteorder("<")
        width, count = _WIDTHS[acc["type"]], int(acc["count"])
        if "bufferView" not in acc:
            return np.zeros((count, width))
        view = self.doc["bufferViews"][acc["bufferView"]]
        if self.doc["buffers"][view["buffer"]].get("uri") is not None:
            raise ExportError(self.source, f"accessor {index}: external buffers are not supported")
        element = dtype.itemsize * width
        stride = view.get("byteStride") or element
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        end = start + stride * (count - 1) + element
        if count < 1 or end > view.get("byteOffset", 0) + view["byteLength"]:
            raise ExportError(self.source, f"accessor {index} does not fit its buffer view")
        if end > len(self.binary):
            raise ExportError(self.source, f"accessor {index} runs past the binary chunk")
        values = np.ndarray(
            (count, width), dtype, self.binary, start, (stride, dtype.itemsize)
        ).astype(np.float64)
        if acc.get("normalized"):
            values = np.maximum(values / np.iinfo(dtype).max, -1.0)
        return values

    def sample(self, sampler: dict[str, Any], path: str, times: np.ndarray) -> np.ndarray:
        """Values (n_keys, width) of an animation sampler at `times` (n_keys,) seconds,
        held at the first / last key outside its time range."""
        t = self.accessor(sampler["input"])[:, 0]
        values = self.accessor(sampler["output"])
        mode = sampler.get("interpolation", "LINEAR")
        if mode == "CUBICSPLINE":
            in_tangents, values, out_tangents = values[0::3], values[1::3], values[2::3]
        if len(values) != len(t):
            raise ExportError(self.source, "an animation sampler's output count does not match")
        if np.any(np.diff(t) <= 0):
            raise ExportError(self.source, "an animation sampler's key times do not increase")
        if len(t) == 1:
            return np.repeat(values, len(times), axis=0)
        k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)
        dt = (t[k + 1] - t[k])[:, None]
        u = np.clip((times[:, None] - t[k][:, None]) / dt, 0.0, 1.0)
        if mode == "STEP":
            out = np.where(u < 1.0, values[k], values[k + 1])
        elif mode == "CUBICSPLINE":
            out = (
                (2 * u**3 - 3 * u**2 + 1) * values[k]
                + dt * (u**3 - 2 * u**2 + u) * out_tangents[k]
                + (-2 * u**3 + 3 * u**2) * values[k + 1]
                + dt * (u**3 - u**2) * in_tangents[k + 1]
            )
        elif mode == "LINEAR" and path == "rotation":
            out = _slerp(values[k], values[k + 1], u)
        elif mode == "LINEAR":
            out = (1 - u) * values[k] + u * values[k + 1]
        else:
            raise ExportError(self.source, f"unknown interpolation {mode!r}")
        return out


def node_rest_positions(file: GlbDocument) -> np.ndarray:
    """World positions (n_nodes, 3) of every node with its own transform (no animation),
    in file units (meters for glTF)."""
    nodes = file.doc.get("nodes", [])
    parents = _parents(nodes, file.source)
    world: dict[int, np.ndarray] = {}
    order = sorted(range(len(nodes)), key=lambda i: len(_ancestry(parents, i)))
    for i in order:
        local = _local_matrices(file, nodes[i], i, {}, np.zeros(1))[0]
        world[i] = local if parents[i] < 0 else world[parents[i]] @ local
    return np.array([world[i][:3, 3] for i in range(len(nodes))]).reshape(-1, 3)


def _joint_positions(file: GlbDocument) -> tuple[tuple[str, ...], np.ndarray]:
    """Joint names and world positions (n_keys, n_joints, 3) of a parsed file."""
    doc = file.doc
    nodes = doc.get("nodes", [])
    parents = _parents(nodes, file.source)
    animations = doc.get("animations", [])
    channels = animations[0]["channels"] if animations else []
    samplers = animations[0]["samplers"] if animations else []
    tracks = {
        (c["target"]["node"], c["target"]["path"]): samplers[c["sampler"]]
        for c in channels
        if "node" in c["target"] and c["target"]["path"] in _TRS
    }
    joints = list(dict.fromkeys(j for skin in doc.get("skins", []) for j in skin["joints"]))
    if not joints:
        animated = {node for node, _ in tracks}
        joints = [i for i in range(len(nodes)) if animated.intersection(_ancestry(parents, i))]
    if not joints:
        raise ExportError(file.source, "no skin and no animated nodes: no joints to read")
    key_sets = [file.accessor(s["input"])[:, 0] for s in tracks.values()]
    times = np.unique(np.concatenate(key_sets)) if key_sets else np.zeros(1)
    needed = sorted(
        {a for j in joints for a in _ancestry(parents, j)},
        key=lambda i: len(_ancestry(parents, i)),
    )
    world: dict[int, np.ndarray] = {}
    for i in needed:
        local = _local_matrices(file, nodes[i], i, tracks, times)
        world[i] = local if parents[i] < 0 else world[parents[i]] @ local
    names = tuple(nodes[j].get("name", f"node{j}") for j in joints)
    positions = np.stack(
        [np.broadcast_to(world[j][..., :3, 3], (len(times), 3)) for j in joints], axis=1
    )
    return names, positions


def _local_matrices(
    file: GlbDocument,
    node: dict[str, Any],
    index: int,
    tracks: dict[tuple[int, str], dict[str, Any]],
    times: np.ndarray,
) -> np.ndarray:
    """A node's local transforms (n_keys or 1, 4, 4): its matrix, or T·R·S with the
    animated components sampled at `times`."""
    if "matrix" in node:
        return np.asarray(node["matrix"], dtype=np.float64).reshape(1, 4, 4).swapaxes(1, 2)
    trs = {
        path: (
            file.sample(tracks[(index, path)], path, times)
            if (index, path) in tracks
            else np.asarray([node.get(path, rest)], dtype=np.float64)
        )
        for path, rest in _TRS.items()
    }
    n = max(len(v) for v in trs.values())
    out = np.zeros((n, 4, 4))
    rotation = Rotation.from_quat(trs["rotation"]).as_matrix()
    out[:, :3, :3] = rotation * trs["scale"][:, None, :]
    out[:, :3, 3] = trs["translation"]
    out[:, 3, 3] = 1.0
    return out


def _parents(nodes: list[dict[str, Any]], source: str) -> list[int]:
    """Parent node index of every node (-1 for roots); a node with two parents is an error."""
    parents = [-1] * len(nodes)
    for i, node in enumerate(nodes):
        for child in node.get("children", []):
            if parents[child] >= 0 or child == i:
                raise ExportError(source, f"node {child} has two parents or is its own child")
            parents[child] = i
    return parents


def _ancestry(parents: list[int], node: int) -> list[int]:
    """`node` and its ancestors up to the root (the node first)."""
    chain = [node]
    while parents[chain[-1]] >= 0:
        chain.append(parents[chain[-1]])
        if len(chain) > len(parents):
            raise ValueError(f"node {node} lies on a cycle of the node hierarchy")
    return chain


def _slerp(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Shortest-path spherical interpolation between unit quaternions (n, 4) at (n, 1)."""
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    angle = np.arccos(np.clip(np.abs(dot), 0.0, 1.0))
    sin = np.sin(angle)
    close = sin < 1e-6
    safe = np.where(close, 1.0, sin)
    a = np.where(close, 1 - u, np.sin((1 - u) * angle) / safe)
    b = np.where(close, u, np.sin(u * angle) / safe)
    return a * q0 + b * q1
