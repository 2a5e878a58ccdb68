"""The camera-node → server wire format: one UDP datagram per camera frame.

A camera node sends, for each frame, the 8 labelled marker positions its tracker found
(`samba.markers.tracking`) and the blobs its tracker left unlabelled as one
`MarkerPacket`. `encode` and `decode` turn it into bytes
and back; `decode` raises `PacketError` (and nothing else) on any datagram it drops,
with a `reason` from a small fixed set the server counts drops by.

A markerless node (`samba node --mode silhouette`) tracks the whole body itself and
sends a `PosePacket` instead: the same header with flags bit 1 set, and the 13 joints
(world meters, +Y up, `samba.body.skeleton.JOINT_NAMES` order) where the markers would be.

Layout (version 2, little-endian, no padding; 108 bytes, plus 1 + 8 n with n unlabelled
blobs, plus 16 with the tag; a pose packet 200 bytes, 216 with the tag):

| offset | size | type | field | meaning |
|---:|---:|---|---|---|
| 0 | 4 | bytes | magic | `b"SMBA"` |
| 4 | 1 | uint8 | version | 2 |
| 5 | 1 | uint8 | flags | bit 0: tag at the end; bit 1: pose packet; bit 2: blobs; bits 3-7: 0 |
| 6 | 2 | uint16 | camera | camera id, 0..65535 |
| 8 | 4 | uint32 | sequence | frame counter of this camera in this epoch, strictly increasing |
| 12 | 8 | uint64 | epoch | random number the node draws when it starts: one run of the node |
| 20 | 8 | float64 | timestamp | capture time of the frame, UNIX seconds on the node's clock |
| 28 | 16 | bytes | session | ASCII id `[A-Za-z0-9._-]`, 0..16 characters, NUL-padded |
| 44 | 64 | float32[8][2] | markers | (u, v) pixels per marker in marker order, NaN = missing |
| 108 | 1 | uint8 | count | only if flags bit 2: n, the blobs that follow, 1..`MAX_BLOBS` |
| 109 | 8n | float32[n][2] | blobs | only if flags bit 2: (u, v) of blobs no label took |
| 108 + b | 16 | bytes | tag | only if flags bit 0: HMAC-SHA256(key, the b + 108 bytes before) |

Here b = 1 + 8n with blobs, else 0; the tag is the first 16 bytes of the HMAC. In a pose
packet the 156 bytes from offset 44 are the pose, float32[13][3], all finite, flags bit
2 is 0 and the tag follows at offset 200.

Markers follow `samba.body.skeleton.MARKER_NAMES` (l/r shoulder, l/r wrist, l/r knee, l/r foot)
with pixels in the OpenCV convention. A missing marker has both coordinates NaN; a
marker with one NaN coordinate or an infinite one is invalid. The blobs are bright spots
the node's tracker did not label (a marker whose label it lost, or a stray reflection):
a server that labels the markers itself (`samba.markers.stage_tracking`) uses them with the
labelled ones; a packet without blobs has flags bit 2 clear and ends after the markers.
The timestamp must be finite. The session id lets a server ignore nodes still streaming
for another capture stage or an earlier session; empty means none.

Epoch and sequence: a node draws a random epoch when it starts and counts its frames
from its start sequence; it never lets the sequence wrap within an epoch (it draws a new
epoch instead). A restarted node is a new epoch, so a server tells a restart from a
replay of old packets without trusting sequence numbers alone
(`samba.service.replay_guard`).

Signing: with a key, the sender appends the tag and sets flags bit 0. `decode` with a
key (or a `key_for` lookup, which picks the key of the packet's session and camera:
each node its own key, `samba.service.node_keys`) drops untagged packets ("missing
tag"), packets of a camera no key may speak for ("no key") and packets whose tag does
not match ("bad tag", compared in constant time); without a key it drops tagged packets
("unexpected tag"), since one side is misconfigured. The tag covers the flags, so it
cannot be stripped unnoticed, and the epoch, sequence and timestamp, so a replay is a
byte-exact copy that the server's replay guard drops. Use a random key of 32 bytes.

`decode` checks, in this order, and drops the datagram with the first reason that
applies: longer than `MAX_PACKET_BYTES` ("too long"); shorter than magic, version and
flags ("too short"); magic ("bad magic"); version or an unknown flag bit ("unsupported
version"); blobs announced in a pose packet ("unsupported version"); a blob count outside
1..`MAX_BLOBS` ("bad values"); shorter than the flags and the blob count announce
("too short") or longer ("bad length"); tag
present without a key ("unexpected tag") or absent with one ("missing tag"); no key
for the packet's session and camera ("no key"); the tag ("bad tag"); the field values
("bad values"). Every valid packet has exactly one encoding, so
`encode(decode(data, key), key) == data`.
"""

from __future__ import annotations

import hashlib
import hmac
import math
import re
import secrets
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from samba.body import N_JOINTS, N_MARKERS
from samba.service.errors import PacketError, ServiceError

MAGIC = b"SMBA"
VERSION = 2
FLAG_TAG = 0x01
"""Flags bit: an HMAC tag ends the packet."""
FLAG_POSE = 0x02
"""Flags bit: a `PosePacket`, 13 joints where a `MarkerPacket` has its markers."""
FLAG_BLOBS = 0x04
"""Flags bit: a blob count and the unlabelled blobs follow a `MarkerPacket`'s markers."""
MAX_BLOBS = 16
"""Most unlabelled blobs one `MarkerPacket` carries."""
TAG_BYTES = 16
"""Length of the truncated HMAC-SHA256 tag."""
SESSION_BYTES = 16
MIN_KEY_BYTES = 16
"""Shortest shared key `read_key_file` accepts."""
MAX_PACKET_BYTES = 256
"""Datagrams longer than this are dropped unread; receive with a buffer one byte larger."""

_HEADER = struct.Struct("<4sBBHIQd16s")
_MARKER_DTYPE = np.dtype("<f4")
HEADER_BYTES = _HEADER.size
"""Offset of the markers: 44."""
BODY_BYTES = HEADER_BYTES + N_MARKERS * 2 * _MARKER_DTYPE.itemsize
"""Length of an untagged packet and offset of the tag: 108."""
POSE_BODY_BYTES = HEADER_BYTES + N_JOINTS * 3 * _MARKER_DTYPE.itemsize
"""Length of an untagged pose packet: 200."""
_PREFIX_BYTES = 6
"""Magic, version and flags: what `decode` needs to know the expected length."""
_SESSION = re.compile(rf"[A-Za-z0-9._-]{{0,{SESSION_BYTES}}}")
_SEQUENCE_MODULUS = 2**32
_EPOCH_MODULUS = 2**64

KeyLookup = Callable[[str, int], bytes | None]
"""The key that may speak for (session id, camera id), None when none may."""


@dataclass(frozen=True, eq=False)
class MarkerPacket:
    """One camera frame's labelled markers, as a camera node sends it.

    `camera` is 0..65535, `sequence` 0..2^32 - 1 (increasing within an epoch),
    `timestamp` the finite capture time in UNIX seconds, `markers` (8, 2) pixels stored
    as a read-only float32 copy (NaN rows = missing), `session` an ASCII id of at most
    16 characters from `[A-Za-z0-9._-]`, empty for none, `blobs` (n, 2) pixels of at
    most `MAX_BLOBS` unlabelled blobs, all finite, stored as a read-only float32 copy,
    `epoch` 0..2^64 - 1 the node's run (`random_epoch`). Invalid values raise
    `ValueError`. Packets compare equal when all fields are equal, NaN markers included.
    """

    camera: int
    sequence: int
    timestamp: float
    markers: np.ndarray
    session: str = ""
    blobs: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.float32))
    epoch: int = 0

    def __post_init__(self) -> None:
        markers = np.array(self.markers, dtype=np.float32)
        if markers.shape != (N_MARKERS, 2):
            raise ValueError(f"markers have shape {markers.shape}, expected ({N_MARKERS}, 2)")
        markers.flags.writeable = False
        object.__setattr__(self, "markers", markers)
        blobs = np.array(self.blobs, dtype=np.float32)
        if blobs.size == 0:
            blobs = blobs.reshape(0, 2)
        if blobs.ndim != 2 or blobs.shape[1] != 2 or len(blobs) > MAX_BLOBS:
            raise ValueError(f"blobs have shape {blobs.shape}, expected (0..{MAX_BLOBS}, 2)")
        if not np.isfinite(blobs).all():
            raise ValueError("a blob coordinate is NaN or infinite")
        blobs.flags.writeable = False
        object.__setattr__(self, "blobs", blobs)
        _check_header(self.camera, self.sequence, self.timestamp, self.session, self.epoch)
        missing = np.isnan(markers)
        if not (np.isfinite(markers) | missing).all():
            raise ValueError("a marker coordinate is infinite")
        if (missing[:, 0] != missing[:, 1]).any():
            raise ValueError("a marker has one coordinate NaN and the other not")

    def __eq__(self, other: object) -> bool:
        """All fields equal; markers compared with NaN equal to NaN."""
        if not isinstance(other, MarkerPacket):
            return NotImplemented
        return (
            _header(self) == _header(other)
            and np.array_equal(self.markers, other.markers, equal_nan=True)
            and np.array_equal(self.blobs, other.blobs)
        )


@dataclass(frozen=True, eq=False)
class PosePacket:
    """One frame of a markerless camera node: the 13-joint `pose` it tracked, (13, 3)
    world meters stored as a read-only float32 copy, all finite; the other fields as in
    `MarkerPacket`. Invalid values raise `ValueError`; packets compare equal when all
    fields are equal."""

    camera: int
    sequence: int
    timestamp: float
    pose: np.ndarray
    session: str = ""
    epoch: int = 0

    def __post_init__(self) -> None:
        pose = np.array(self.pose, dtype=np.float32)
        if pose.shape != (N_JOINTS, 3):
            raise ValueError(f"pose has shape {pose.shape}, expected ({N_JOINTS}, 3)")
        if not np.isfinite(pose).all():
            raise ValueError("a joint coordinate is NaN or infinite")
        pose.flags.writeable = False
        object.__setattr__(self, "pose", pose)
        _check_header(self.camera, self.sequence, self.timestamp, self.session, self.epoch)

    def __eq__(self, other: object) -> bool:
        """All fields equal."""
        if not isinstance(other, PosePacket):
            return NotImplemented
        return _header(self) == _header(other) and np.array_equal(self.pose, other.pose)


Packet = MarkerPacket | PosePacket
"""Either kind of camera-node packet."""


def encode(packet: Packet, key: bytes | None = None) -> bytes:
    """The datagram of `packet`, signed with `key` when one is given (see the layout)."""
    _check_key(key)
    pose = isinstance(packet, PosePacket)
    values = packet.pose if pose else packet.markers
    blobs = 0 if pose else len(packet.blobs)
    flags = (FLAG_TAG if key is not None else 0) | (FLAG_POSE if pose else 0)
    body = (
        _HEADER.pack(
            MAGIC,
            VERSION,
            flags | (FLAG_BLOBS if blobs else 0),
            packet.camera,
            packet.sequence,
            packet.epoch,
            packet.timestamp,
            packet.session.encode("ascii"),
        )
        + values.astype(_MARKER_DTYPE, copy=False).tobytes()
    )
    if blobs:
        body += bytes([blobs]) + packet.blobs.astype(_MARKER_DTYPE, copy=False).tobytes()
    return body if key is None else body + _tag(key, body)


def decode(
    data: bytes,
    key: bytes | None = None,
    *,
    source: str = "packet",
    key_for: KeyLookup | None = None,
) -> Packet:
    """The packet in datagram `data`; a server with a `key` accepts only packets signed
    with it, one with `key_for` only packets signed with the key `key_for(session,
    camera)` gives for the packet's session id and camera id (None: "no key").

    Raises `PacketError` naming `source` (e.g. the sender's address) for any datagram
    that is not a valid packet, and no other exception whatever the bytes; an empty
    `key`, or both `key` and `key_for`, is a configuration mistake and raises `ValueError`.
    """
    _check_key(key)
    if key is not None and key_for is not None:
        raise ValueError("give a key or a key lookup, not both")
    size = len(data)
    if size > MAX_PACKET_BYTES:
        raise PacketError(source, "too long", f"{size} bytes, at most {MAX_PACKET_BYTES}")
    if size < _PREFIX_BYTES:
        raise PacketError(source, "too short", f"{size} bytes")
    if data[:4] != MAGIC:
        raise PacketError(source, "bad magic", f"{bytes(data[:4])!r} instead of {MAGIC!r}")
    version, flags = data[4], data[5]
    if version != VERSION:
        raise PacketError(
            source, "unsupported version", f"version {version}, this server reads {VERSION}"
        )
    if flags & ~(FLAG_TAG | FLAG_POSE | FLAG_BLOBS):
        raise PacketError(source, "unsupported version", f"unknown flags 0x{flags:02x}")
    tagged = bool(flags & FLAG_TAG)
    pose = bool(flags & FLAG_POSE)
    blobs = 0
    if flags & FLAG_BLOBS:
        if pose:
            raise PacketError(source, "unsupported version", "blobs announced in a pose packet")
        if size <= BODY_BYTES:
            raise PacketError(source, "too short", f"{size} bytes, blobs announced")
        blobs = data[BODY_BYTES]
        if not 1 <= blobs <= MAX_BLOBS:
            raise PacketError(source, "bad values", f"{blobs} blobs, expected 1..{MAX_BLOBS}")
    body = POSE_BODY_BYTES if pose else BODY_BYTES + (1 + 8 * blobs if blobs else 0)
    expected = body + (TAG_BYTES if tagged else 0)
    if size < expected:
        raise PacketError(source, "too short", f"{size} bytes, expected {expected}")
    if size > expected:
        raise PacketError(source, "bad length", f"{size} bytes, expected {expected}")
    signed = key is not None or key_for is not None
    if tagged and not signed:
        raise PacketError(source, "unexpected tag", "signed packet but the server has no key")
    if signed and not tagged:
        raise PacketError(source, "missing tag", "the server accepts only signed packets")
    _, _, _, camera, sequence, epoch, timestamp, session = _HEADER.unpack_from(data)
    name = session.rstrip(b"\0").decode("latin-1")
    if key_for is not None:
        key = key_for(name, camera)
        if key is None:
            raise PacketError(source, "no key", f"no key may speak for camera {camera} of {name!r}")
    if key is not None and not hmac.compare_digest(_tag(key, data[:body]), data[body:]):
        raise PacketError(source, "bad tag", "wrong key or altered packet")
    try:
        if pose:
            joints = np.frombuffer(data, _MARKER_DTYPE, 3 * N_JOINTS, HEADER_BYTES)
            pose_joints = joints.reshape(N_JOINTS, 3)
            return PosePacket(camera, sequence, timestamp, pose_joints, name, epoch)
        markers = np.frombuffer(data, _MARKER_DTYPE, 2 * N_MARKERS, HEADER_BYTES)
        extra = np.frombuffer(data, _MARKER_DTYPE, 2 * blobs, BODY_BYTES + 1) if blobs else ()
        return MarkerPacket(
            camera=camera,
            sequence=sequence,
            timestamp=timestamp,
            markers=markers.reshape(N_MARKERS, 2),
            session=name,
            blobs=np.reshape(extra, (-1, 2)),
            epoch=epoch,
        )
    except ValueError as exc:
        raise PacketError(source, "bad values", str(exc)) from None


def random_epoch() -> int:
    """A fresh epoch for a node's run: 64 random bits."""
    return secrets.randbits(64)


def read_key_file(path: str | Path) -> bytes:
    """A node's HMAC key stored in a file: its raw bytes, at least `MIN_KEY_BYTES`.

    `ServiceError` naming the file when it cannot be read or is too short. Make one per
    node with e.g. `head -c 32 /dev/urandom > cam0.key`, give it to that node and list
    it in the server's keys file (`samba.service.node_keys`).
    """
    try:
        key = Path(path).read_bytes()
    except OSError as exc:
        raise ServiceError(str(path), f"cannot read the key file: {exc.strerror or exc}") from None
    if len(key) < MIN_KEY_BYTES:
        raise ServiceError(
            str(path), f"a key file holds at least {MIN_KEY_BYTES} bytes, this one {len(key)}"
        )
    return key


def _header(packet: MarkerPacket | PosePacket) -> tuple[int, int, int, float, str]:
    """The header fields every packet has, for comparisons."""
    return packet.camera, packet.sequence, packet.epoch, packet.timestamp, packet.session


def _check_header(
    camera: object, sequence: object, timestamp: object, session: object, epoch: object
) -> None:
    """`ValueError` unless the header fields a packet shares are valid."""
    if not _is_int(camera) or not 0 <= camera <= 0xFFFF:
        raise ValueError(f"camera {camera!r} is not an integer in 0..65535")
    if not _is_int(sequence) or not 0 <= sequence < _SEQUENCE_MODULUS:
        raise ValueError(f"sequence {sequence!r} is not an integer in 0..2^32 - 1")
    if not _is_int(epoch) or not 0 <= epoch < _EPOCH_MODULUS:
        raise ValueError(f"epoch {epoch!r} is not an integer in 0..2^64 - 1")
    if not _is_real(timestamp) or not math.isfinite(timestamp):
        raise ValueError(f"timestamp {timestamp!r} is not a finite number")
    if not isinstance(session, str) or not _SESSION.fullmatch(session):
        raise ValueError(
            f"session {session!r} is not 0..{SESSION_BYTES} characters of [A-Za-z0-9._-]"
        )


def _tag(key: bytes, body: bytes) -> bytes:
    return hmac.new(key, body, hashlib.sha256).digest()[:TAG_BYTES]


def _check_key(key: bytes | None) -> None:
    if key is not None and len(key) == 0:
        raise ValueError("the HMAC key is empty; pass None to send or accept unsigned packets")


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_real(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)
