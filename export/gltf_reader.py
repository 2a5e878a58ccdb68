"""Reading glTF 2.0 files: GLB containers (.glb, .vrm) and JSON glTF (.gltf).

The verification reader of `samba.export.gltf_writer`, written for any reasonable glTF: it
parses the GLB container itself, loads JSON glTF's buffers from the files beside it or
from base64 `data:` URIs, reads accessors of any component type (normalised integers
included, interleaved views too) and samples STEP, LINEAR and CUBICSPLINE animation
channels. The joints are the nodes of the file's skins (first skin's order, then any
others); a file without skins takes every node the first animation moves, directly or
through an ancestor. World transforms follow the spec (FORMATS.md §2.9): at each key
time the animated TRS replaces the node's own, and world = parentWorld·T·R·S.
"""

from __future__ import annotations

import base64
import binascii
import json
import os
import struct
import urllib.parse
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from samba.export.errors import ExportError

_MAGIC = b"glTF"
_JSON_CHUNK = 0x4E4F534A
_BIN_CHUNK = 0x004E4942
_UTF8_BOM = b"\xef\xbb\xbf"
_AVATAR_FORMATS = "avatars are read from .glb, .vrm, .gltf, .usd, .usda, .usdc or .usdz files"
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


def read_glb(path: str | os.PathLike[str]) -> GltfDocument:
    """The parsed .glb (or .vrm, the same container) at `path`, its buffers loaded (the
    binary chunk, and any buffer given by a URI: see `read_gltf`); `ExportError` naming
    the file when it cannot be read or is not a GLB container."""
    source = str(path)
    doc, chunk = _parse_glb(_read_bytes(path, source), source)
    return GltfDocument(doc, _load_buffers(doc, chunk, Path(path).parent, source), source)


def read_gltf(path: str | os.PathLike[str]) -> GltfDocument:
    """The glTF file at `path` in either form, told apart by its content: a GLB container
    (.glb, .vrm) or JSON glTF (.gltf) whose buffers are files beside it (relative,
    percent-encoded URIs) or base64 `data:` URIs. Every buffer is loaded and must hold at
    least its `byteLength` bytes. Raises `ExportError` naming the file when it, or one of
    its buffers, cannot be read or is malformed."""
    source = str(path)
    data = _read_bytes(path, source)
    if data[:4] == _MAGIC:
        doc, chunk = _parse_glb(data, source)
    elif data.removeprefix(_UTF8_BOM).lstrip()[:1] == b"{":
        doc, chunk = _parse_json(data.removeprefix(_UTF8_BOM), source, "the file"), None
    else:
        raise ExportError(source, f"not a glTF file (.glb, .vrm or .gltf): {_AVATAR_FORMATS}")
    return GltfDocument(doc, _load_buffers(doc, chunk, Path(path).parent, source), source)


def _read_bytes(path: str | os.PathLike[str], source: str) -> bytes:
    """The content of the file at `path`; `ExportError` naming `source` when unreadable."""
    try:
        return Path(path).read_bytes()
    except OSError as exc:
        raise ExportError(source, f"cannot read the file: {exc.strerror or exc}") from exc


def _parse_glb(data: bytes, source: str) -> tuple[dict[str, Any], bytes | None]:
    """The JSON document and the binary chunk (None if none) of a GLB container."""
    if len(data) < 20 or data[:4] != _MAGIC:
        raise ExportError(source, f"not a binary glTF (.glb) container: {_AVATAR_FORMATS}")
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
    doc = _parse_json(chunks[0][1], source, "the JSON chunk")
    binary = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == _BIN_CHUNK else None
    return doc, binary


def _parse_json(text: bytes, source: str, what: str) -> dict[str, Any]:
    """The glTF object of JSON `text` (`what` names it in errors: the file or the chunk)."""
    try:
        doc = json.loads(text.decode("utf-8"))
    except ValueError as exc:
        raise ExportError(source, f"{what} is not valid JSON: {exc}") from exc
    if not isinstance(doc, dict):
        raise ExportError(source, f"{what} is not a glTF object")
    return doc


def _load_buffers(
    doc: dict[str, Any], chunk: bytes | None, folder: Path, source: str
) -> list[bytes]:
    """The bytes of every buffer of `doc`, in order: the GLB binary `chunk` for a first
    buffer without a URI, a base64 `data:` URI decoded, or a file in `folder` (the glTF
    file's own) for a relative URI. `ExportError` naming `source` and the buffer when one
    cannot be had or is shorter than its `byteLength`."""
    buffers = doc.get("buffers", [])
    if not isinstance(buffers, list):
        raise ExportError(source, "malformed glTF: 'buffers' is not a list")
    loaded = []
    for i, buffer in enumerate(buffers):
        if not isinstance(buffer, dict) or not isinstance(buffer.get("byteLength"), int):
            raise ExportError(source, f"buffer {i} has no whole-number byteLength")
        uri = buffer.get("uri")
        if uri is None and i == 0 and chunk is not None:
            data, where = chunk, "the binary chunk"
        elif uri is None:
            raise ExportError(source, f"buffer {i} has no uri and there is no binary chunk")
        elif not isinstance(uri, str):
            raise ExportError(source, f"buffer {i} has a uri that is not a string: {uri!r}")
        elif uri.startswith("data:"):
            data, where = _data_uri_bytes(uri, i, source), "its data URI"
        else:
            data, where = _buffer_file_bytes(folder, uri, i, source), repr(uri)
        if len(data) < buffer["byteLength"]:
            raise ExportError(
                source,
                f"buffer {i} is too short: {where} holds {len(data)} bytes, "
                f"its byteLength says {buffer['byteLength']}",
            )
        loaded.append(data)
    return loaded


def _data_uri_bytes(uri: str, index: int, source: str) -> bytes:
    """The bytes of buffer `index`'s base64 `data:` URI."""
    header, comma, payload = uri.partition(",")
    if not comma or not header.endswith(";base64"):
        raise ExportError(source, f"buffer {index}: only base64 data URIs are supported")
    try:
        return base64.b64decode(payload, validate=True)
    except (binascii.Error, ValueError) as exc:
        raise ExportError(source, f"buffer {index}: bad base64 in its data URI: {exc}") from exc


def _buffer_file_bytes(folder: Path, uri: str, index: int, source: str) -> bytes:
    """The content of buffer `index`'s file, named by the relative `uri` from `folder`."""
    parts = urllib.parse.urlsplit(uri)
    if parts.scheme or parts.netloc or uri.startswith("/"):
        raise ExportError(
            source,
            f"buffer {index}: only relative file names and data: URIs are supported, not {uri!r}",
        )
    path = folder / urllib.parse.unquote(parts.path)
    try:
        return path.read_bytes()
    except OSError as exc:
        raise ExportError(
            source, f"buffer {index}: cannot read its file {path}: {exc.strerror or exc}"
        ) from exc


class GltfDocument:
    """A parsed glTF file: the JSON document, the bytes of its buffers (in `buffers`
    order) and where it came from."""

    def __init__(self, doc: dict[str, Any], buffers: list[bytes], source: str) -> None:
        self.doc = doc
        self.buffers = buffers
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
        buffer = self.buffers[view["buffer"]]
        element = dtype.itemsize * width
        stride = view.get("byteStride") or element
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        end = start + stride * (count - 1) + element
        if count < 1 or end > view.get("byteOffset", 0) + view["byteLength"]:
            raise ExportError(self.source, f"accessor {index} does not fit its buffer view")
        if end > len(buffer):
            raise ExportError(self.source, f"accessor {index} runs past buffer {view['buffer']}")
        values = np.ndarray((count, width), dtype, buffer, start, (stride, dtype.itemsize)).astype(
            np.float64
        )
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


def node_rest_positions(file: GltfDocument) -> np.ndarray:
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


def node_tree(file: GltfDocument) -> tuple[tuple[str, ...], list[int], list[int]]:
    """Node names, each node's parent (-1 for a root) and the nodes of the skeleton: the
    skins' joints and their ancestors, or every node of a file without a skin."""
    nodes = file.doc.get("nodes", [])
    parents = _parents(nodes, file.source)
    joints = [j for skin in file.doc.get("skins", []) for j in skin["joints"]]
    keep = sorted({a for j in joints for a in _ancestry(parents, j)}) or list(range(len(nodes)))
    return tuple(str(node.get("name", "")) for node in nodes), parents, keep


def _joint_positions(file: GltfDocument) -> tuple[tuple[str, ...], np.ndarray]:
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
    file: GltfDocument,
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
