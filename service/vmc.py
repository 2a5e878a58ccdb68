"""VMC performer: a humanoid pose as OSC bundles for VMC marionettes (FORMATS.md section 5).

Each frame is `/VMC/Ext/Root/Pos` ("root", identity), one `/VMC/Ext/Bone/Pos` per humanoid
bone (Unity `HumanBodyBones` name, local position, local rotation), `/VMC/Ext/OK 1` and
`/VMC/Ext/T <seconds>`, in that order, packed into bundles with the timetag IMMEDIATELY of
at most `MAX_BUNDLE_BYTES` each (every message stands alone, so a frame may span several).

Values are Unity Transform values: left-handed, +Y up, +Z forward, meters. Our frame
(right-handed, +Y up, avatar facing +Z, subject's left at +X) becomes Unity's by mirroring
X: p = (-x, y, z), q = (qx, -qy, -qz, qw). Rotations are local and relative to a rest pose
with identity orientations, which is what VRM0-normalised avatars have. Bone positions
other than the Hips are the receiving avatar's rest offsets, since receivers such as
EVMC4U apply them and our bone lengths would stretch a different avatar.
"""

from __future__ import annotations

import socket
import struct
from collections.abc import Iterable

import numpy as np
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder

from samba.export import BONE_NAMES, N_BONES, HumanoidMotion, HumanoidRig
from samba.service.errors import ServiceError

MARIONETTE_PORT = 39539
"""The UDP port VMC marionettes (receivers) listen on by default."""
MAX_BUNDLE_BYTES = 1400
"""Largest bundle sent, bytes: below the 1,472-byte UDP payload that Wi-Fi carries unfragmented."""

_MIRROR_POSITION = np.array([-1.0, 1.0, 1.0])
_MIRROR_QUATERNION = np.array([1.0, -1.0, -1.0, 1.0])
_ROOT = ("root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def unity_pose(
    motion: HumanoidMotion, avatar: HumanoidRig | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """A whole motion's local bone poses in Unity's convention, in `BONE_NAMES` order.

    Returns positions (n, 17, 3) in meters and quaternions (n, 17, 4) (x, y, z, w), both
    float64 and X-mirrored (see `unity_values`), with the bone offsets of `avatar`, the
    receiving avatar's rig (default: the motion's own rig).
    """
    return unity_values(motion.root, motion.rotations, avatar or motion.rig)


def unity_values(
    root: np.ndarray, rotations: np.ndarray, avatar: HumanoidRig
) -> tuple[np.ndarray, np.ndarray]:
    """Unity-convention local poses of frames given as root positions (..., 3) meters and
    local quaternions (..., 17, 4) (x, y, z, w) in our frame: positions (..., 17, 3) and
    quaternions (..., 17, 4), X-mirrored. The Hips position is the root; the other
    bones' positions are `avatar`'s rest offsets from their parents."""
    root = np.asarray(root, dtype=np.float64)
    positions = np.broadcast_to(avatar.offsets, (*root.shape[:-1], N_BONES, 3)).copy()
    positions[..., 0, :] = root
    return positions * _MIRROR_POSITION, np.asarray(rotations) * _MIRROR_QUATERNION


def frame_bundles(positions: np.ndarray, rotations: np.ndarray, time_s: float) -> list[bytes]:
    """The OSC bundles (datagrams) of one VMC frame from Unity-convention local poses:
    positions (17, 3) meters and quaternions (17, 4) (x, y, z, w) in `BONE_NAMES` order
    (a frame of `unity_pose`), and the sender's time in seconds for `/VMC/Ext/T`.

    Messages keep the VMC frame order; each bundle is at most `MAX_BUNDLE_BYTES` long.
    """
    positions = np.asarray(positions, dtype=np.float64)
    rotations = np.asarray(rotations, dtype=np.float64)
    if positions.shape != (N_BONES, 3) or rotations.shape != (N_BONES, 4):
        raise ValueError(
            f"a VMC frame needs positions (17, 3) and rotations (17, 4), got "
            f"{positions.shape} and {rotations.shape}"
        )
    values = np.concatenate([positions, rotations], axis=1).astype(">f4")
    messages = [_ROOT_MESSAGE]
    messages += [prefix + row.tobytes() for prefix, row in zip(_BONE_PREFIXES, values, strict=True)]
    messages += [_OK_MESSAGE, _T_PREFIX + struct.pack(">f", time_s)]
    return _pack(messages)


def vmc_frame(
    motion: HumanoidMotion, frame: int, time_s: float, avatar: HumanoidRig | None = None
) -> list[bytes]:
    """The OSC bundles of frame `frame` of a motion, sent at `time_s` seconds, with the
    bone positions of `avatar` (see `unity_pose`). For a whole take, convert once with
    `unity_pose` and call `frame_bundles` per frame instead."""
    positions, rotations = unity_pose(motion.frames(frame, frame + 1), avatar)
    return frame_bundles(positions[0], rotations[0], time_s)


class VmcSender:
    """Sends datagrams over UDP to every target (host, port) from one non-blocking socket.

    Host names are resolved once, here (IPv4); an unresolvable one raises `ServiceError`.
    A failed send (a target that refuses or cannot be reached, a full socket buffer) never
    raises: it drops the datagram and counts it in `errors[target]`.
    """

    def __init__(self, targets: Iterable[tuple[str, int]]) -> None:
        self.targets = list(targets)
        self.errors: dict[tuple[str, int], int] = dict.fromkeys(self.targets, 0)
        self._addresses = [_resolve(host, port) for host, port in self.targets]
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._socket.setblocking(False)

    def send(self, datagrams: Iterable[bytes]) -> None:
        """Sends each datagram (e.g. a frame's `frame_bundles`) to every target."""
        for datagram in datagrams:
            for target, address in zip(self.targets, self._addresses, strict=True):
                try:
                    self._socket.sendto(datagram, address)
                except OSError:
                    self.errors[target] += 1

    def close(self) -> None:
        """Closes the socket."""
        self._socket.close()

    def __enter__(self) -> VmcSender:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _message(address: str, types: str, args: tuple) -> bytes:
    """One OSC message as python-osc encodes it."""
    builder = OscMessageBuilder(address=address)
    for arg_type, arg in zip(types, args, strict=True):
        builder.add_arg(arg, arg_type)
    return builder.build().dgram


def _prefix(address: str, name: str | None, floats: int) -> bytes:
    """The bytes of a message with an optional leading string argument `name` and
    `floats` float32 arguments, up to where the floats start: address, type tags and
    name do not change from frame to frame, so frames append only the floats."""
    head = () if name is None else (name,)
    types = ("" if name is None else "s") + "f" * floats
    return _message(address, types, (*head, *[0.0] * floats))[: -4 * floats]


_ROOT_MESSAGE = _message("/VMC/Ext/Root/Pos", "s" + "f" * 7, _ROOT)
_BONE_PREFIXES = [_prefix("/VMC/Ext/Bone/Pos", name, 7) for name in BONE_NAMES]
_OK_MESSAGE = _message("/VMC/Ext/OK", "i", (1,))
_T_PREFIX = _prefix("/VMC/Ext/T", None, 1)
_BUNDLE_START = OscBundleBuilder(IMMEDIATELY).build().dgram
"""`#bundle`, NUL and the timetag IMMEDIATELY: the first 16 bytes of every bundle."""


def _pack(messages: list[bytes]) -> list[bytes]:
    """Messages in order, greedily packed into IMMEDIATELY bundles of at most
    `MAX_BUNDLE_BYTES` (a bundle element is its 4-byte big-endian size and the message)."""
    bundles: list[bytes] = []
    parts = [_BUNDLE_START]
    size = len(_BUNDLE_START)
    for message in messages:
        element = 4 + len(message)
        if len(parts) > 1 and size + element > MAX_BUNDLE_BYTES:
            bundles.append(b"".join(parts))
            parts, size = [_BUNDLE_START], len(_BUNDLE_START)
        parts += [struct.pack(">i", len(message)), message]
        size += element
    bundles.append(b"".join(parts))
    return bundles


def _resolve(host: str, port: int) -> tuple[str, int]:
    source = f"VMC target {host}:{port}"
    if not 0 < port < 65536:
        raise ServiceError(source, "the port must be 1 to 65535")
    try:
        info = socket.getaddrinfo(host, port, socket.AF_INET, socket.SOCK_DGRAM)
    except (OSError, UnicodeError) as e:
        raise ServiceError(source, f"cannot resolve the host as IPv4: {e}") from None
    return info[0][4][:2]
