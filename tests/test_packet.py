"""The camera-node → server wire format: layout, round trips, signing and fuzzed datagrams.

The documented layout is checked twice: against the bytes `encode` writes and against
the table in `samba.service.packet`'s docstring, which the README copies.
"""

from __future__ import annotations

import hashlib
import hmac
import re
import struct

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import samba.service.packet
from samba.base.errors import InputError
from samba.service.errors import PacketError
from samba.service.packet import (
    BODY_BYTES,
    FLAG_BLOBS,
    FLAG_POSE,
    HEADER_BYTES,
    MAX_BLOBS,
    MAX_PACKET_BYTES,
    POSE_BODY_BYTES,
    TAG_BYTES,
    MarkerPacket,
    PosePacket,
    decode,
    encode,
)

KEY = b"k" * 32
OTHER_KEY = b"o" * 32
LAYOUT: tuple[tuple[int, int, str, str], ...] = (
    (0, 4, "bytes", "magic"),
    (4, 1, "uint8", "version"),
    (5, 1, "uint8", "flags"),
    (6, 2, "uint16", "camera"),
    (8, 4, "uint32", "sequence"),
    (12, 8, "uint64", "epoch"),
    (20, 8, "float64", "timestamp"),
    (28, 16, "bytes", "session"),
    (44, 64, "float32[8][2]", "markers"),
)
"""(offset, size, type, field) of every field a packet always has."""
OPTIONAL_LAYOUT: tuple[tuple[str, str, str, str], ...] = (
    ("108", "1", "uint8", "count"),
    ("109", "8n", "float32[n][2]", "blobs"),
    ("108 + b", "16", "bytes", "tag"),
)
"""(offset, size, type, field) of the fields flags announce, as the README writes them."""


def sample(**changes: object) -> MarkerPacket:
    """A packet with two missing markers and values that are not round in float32."""
    markers = np.arange(16, dtype=np.float32).reshape(8, 2) * np.float32(10.1) - 3.3
    markers[[2, 7]] = np.nan
    fields: dict[str, object] = {
        "camera": 513,
        "sequence": 0xDEADBEEF,
        "timestamp": 1234.5678,
        "markers": markers,
        "session": "take-01",
        "epoch": 0x0123456789ABCDEF,
    }
    fields.update(changes)
    return MarkerPacket(**fields)


def reason_of(data: bytes, key: bytes | None = None) -> str:
    """The reason `decode` drops `data` with; fails when it accepts it."""
    with pytest.raises(PacketError) as info:
        decode(data, key)
    return info.value.reason


# --- layout ------------------------------------------------------------------------------


def test_layout_sizes_and_offsets() -> None:
    packet = sample()
    plain, signed = encode(packet), encode(packet, KEY)
    assert (HEADER_BYTES, BODY_BYTES, TAG_BYTES) == (44, 108, 16)
    assert (len(plain), len(signed)) == (108, 124)
    assert sum(size for _, size, _, _ in LAYOUT) == len(plain)
    assert all(o + s == LAYOUT[i + 1][0] for i, (o, s, _, _) in enumerate(LAYOUT[:-1]))
    assert signed[:BODY_BYTES] == plain[:5] + b"\x01" + plain[6:]
    assert plain[0:4] == b"SMBA"
    assert (plain[4], plain[5], signed[5]) == (2, 0, 1)
    assert int.from_bytes(plain[6:8], "little") == 513
    assert int.from_bytes(plain[8:12], "little") == 0xDEADBEEF
    assert int.from_bytes(plain[12:20], "little") == 0x0123456789ABCDEF
    assert struct.unpack("<d", plain[20:28]) == (1234.5678,)
    assert plain[28:44] == b"take-01" + b"\0" * 9
    values = np.frombuffer(plain[44:108], "<f4").reshape(8, 2)
    assert np.array_equal(values, packet.markers, equal_nan=True)
    assert signed[108:124] == hmac.new(KEY, signed[:108], hashlib.sha256).digest()[:16]


def test_docstring_table_matches_layout() -> None:
    rows = re.findall(
        r"^\| ([\d +b]+) \| (\d+n?) \| ([\w\[\]]+) \| (\w+) \|", samba.service.packet.__doc__, re.M
    )
    always = tuple((int(o), int(s), t, f) for o, s, t, f in rows[: len(LAYOUT)])
    assert always == LAYOUT
    assert tuple(rows[len(LAYOUT) :]) == OPTIONAL_LAYOUT


def test_max_packet_bytes_leaves_room() -> None:
    assert BODY_BYTES + 1 + 8 * MAX_BLOBS + TAG_BYTES <= MAX_PACKET_BYTES


def test_unlabelled_blobs_follow_the_markers_under_the_tag() -> None:
    blobs = np.array([[12.25, 40.5], [100.125, 3.75], [0.0, 119.0]], dtype=np.float32)
    packet = sample(blobs=blobs)
    plain, signed = encode(packet), encode(packet, KEY)
    assert (len(plain), len(signed)) == (108 + 1 + 24, 108 + 1 + 24 + 16)
    assert (plain[5], signed[5]) == (FLAG_BLOBS, FLAG_BLOBS | 1)
    assert plain[108] == 3
    assert np.array_equal(np.frombuffer(plain[109:], "<f4").reshape(3, 2), blobs)
    assert signed[133:] == hmac.new(KEY, signed[:133], hashlib.sha256).digest()[:16]
    assert decode(plain) == packet and decode(signed, KEY) == packet
    assert decode(plain) != sample()
    assert reason_of(plain[:-1]) == "too short" and reason_of(plain + b"\0") == "bad length"
    assert reason_of(plain[:108] + b"\x00" + plain[109:]) == "bad values"
    assert reason_of(plain[:108] + bytes([MAX_BLOBS + 1]) + plain[109:]) == "bad values"
    assert reason_of(plain[:108]) == "too short"
    assert reason_of(signed[:108] + b"\x02" + signed[109:], KEY) == "bad length"
    nan = plain[:109] + np.full(6, np.nan, "<f4").tobytes()
    assert reason_of(nan) == "bad values"
    pose = encode(PosePacket(0, 0, 0.0, np.zeros((13, 3))))
    assert reason_of(pose[:5] + bytes([FLAG_POSE | FLAG_BLOBS]) + pose[6:]) == (
        "unsupported version"
    )


@pytest.mark.parametrize(
    "blobs", [np.zeros((MAX_BLOBS + 1, 2)), np.zeros((2, 3)), np.array([[1.0, np.inf]])]
)
def test_bad_blobs_rejected(blobs: np.ndarray) -> None:
    with pytest.raises(ValueError, match="blob"):
        sample(blobs=blobs)


# --- round trips -------------------------------------------------------------------------


@pytest.mark.parametrize("key", [None, KEY])
def test_round_trip_keeps_nan_and_float32_bits(key: bytes | None) -> None:
    packet = sample()
    data = encode(packet, key)
    back = decode(data, key)
    assert back == packet
    assert back.markers.dtype == np.float32
    assert back.markers.tobytes() == packet.markers.tobytes()
    assert np.isnan(back.markers[[2, 7]]).all()
    assert encode(back, key) == data


def test_round_trip_extremes() -> None:
    markers = np.full((8, 2), np.nan, dtype=np.float32)
    markers[0] = [np.finfo(np.float32).max, -np.finfo(np.float32).tiny]
    for packet in (
        sample(camera=0, sequence=0, timestamp=0.0, session="", markers=markers, epoch=0),
        sample(
            camera=65535, sequence=2**32 - 1, timestamp=-1e300, session="A" * 16, epoch=2**64 - 1
        ),
    ):
        assert decode(encode(packet)) == packet


def test_packet_copies_markers_read_only() -> None:
    markers = np.zeros((8, 2))
    packet = sample(markers=markers)
    markers[0, 0] = 5.0
    assert packet.markers[0, 0] == 0.0
    assert packet.markers.dtype == np.float32
    with pytest.raises(ValueError):
        packet.markers[0, 0] = 1.0


def test_equality() -> None:
    assert sample() == sample()
    assert sample() != sample(sequence=1)
    assert sample() != sample(epoch=1)
    assert sample() != sample(markers=np.zeros((8, 2)))
    assert sample() != "packet"


@pytest.mark.parametrize(
    "changes",
    [
        {"camera": -1},
        {"camera": 65536},
        {"camera": True},
        {"camera": 1.0},
        {"sequence": 2**32},
        {"sequence": -1},
        {"epoch": 2**64},
        {"epoch": -1},
        {"epoch": 1.0},
        {"timestamp": float("inf")},
        {"timestamp": float("nan")},
        {"timestamp": "1.0"},
        {"markers": np.zeros((7, 2))},
        {"markers": np.zeros(16)},
        {"markers": np.where(np.eye(8, 2, dtype=bool), np.inf, 0.0)},
        {"markers": np.where(np.eye(8, 2, dtype=bool), np.nan, 0.0)},
        {"session": "a" * 17},
        {"session": "take 01"},
        {"session": "café"},
        {"session": "a\0b"},
    ],
)
def test_invalid_values_rejected(changes: dict[str, object]) -> None:
    with pytest.raises(ValueError):
        sample(**changes)


# --- dropped datagrams -------------------------------------------------------------------


def test_packet_error_is_input_error_naming_source_and_reason() -> None:
    with pytest.raises(PacketError) as info:
        decode(b"SMB", source="udp 10.0.0.7:5005")
    assert isinstance(info.value, InputError)
    assert info.value.source == "udp 10.0.0.7:5005"
    assert info.value.reason == "too short"
    assert str(info.value).startswith("udp 10.0.0.7:5005: too short")
    with pytest.raises(ValueError):
        PacketError("x", "something else")


def test_length_reasons() -> None:
    plain, signed = encode(sample()), encode(sample(), KEY)
    assert reason_of(b"") == "too short"
    assert reason_of(plain[:5]) == "too short"
    for n in (6, 50, BODY_BYTES - 1):
        assert reason_of(plain[:n]) == "too short"
    assert reason_of(signed[:BODY_BYTES], KEY) == "too short"  # tag cut off
    assert reason_of(signed[:-1], KEY) == "too short"
    assert reason_of(plain + b"\0") == "bad length"
    assert reason_of(signed + b"\0", KEY) == "bad length"
    assert reason_of(plain + b"\0" * (MAX_PACKET_BYTES - BODY_BYTES)) == "bad length"
    assert reason_of(plain + b"\0" * (MAX_PACKET_BYTES - BODY_BYTES + 1)) == "too long"
    assert reason_of(b"\xff" * 100_000) == "too long"


def test_header_reasons() -> None:
    plain = encode(sample())
    assert reason_of(b"SMBB" + plain[4:]) == "bad magic"
    assert reason_of(b"\0" * 100) == "bad magic"
    assert reason_of(plain[:4] + b"\x01" + plain[5:]) == "unsupported version"
    assert reason_of(plain[:4] + b"\x03" + plain[5:]) == "unsupported version"
    assert reason_of(plain[:4] + b"\x00" + plain[5:]) == "unsupported version"
    assert reason_of(plain[:5] + b"\x08" + plain[6:]) == "unsupported version"
    assert reason_of(plain[:5] + b"\x80" + plain[6:]) == "unsupported version"


def test_signing_reasons() -> None:
    plain, signed = encode(sample()), encode(sample(), KEY)
    assert reason_of(signed, OTHER_KEY) == "bad tag"
    assert reason_of(signed) == "unexpected tag"
    assert reason_of(plain, KEY) == "missing tag"
    stripped = signed[:5] + b"\x00" + signed[6:BODY_BYTES]  # tag removed, flag cleared
    assert reason_of(stripped, KEY) == "missing tag"
    assert reason_of(signed[:-1] + bytes([signed[-1] ^ 1]), KEY) == "bad tag"
    assert reason_of(signed[:40] + bytes([signed[40] ^ 1]) + signed[41:], KEY) == "bad tag"
    assert reason_of(signed[:14] + bytes([signed[14] ^ 1]) + signed[15:], KEY) == "bad tag"


def test_a_key_lookup_picks_the_key_of_the_packets_session_and_camera() -> None:
    """Each node its own key: a packet signed with another camera's key is refused,
    and a camera no key may speak for is "no key"."""
    keys = {("take-01", 513): KEY, ("take-01", 514): OTHER_KEY}

    def key_for(session: str, camera: int) -> bytes | None:
        return keys.get((session, camera))

    assert decode(encode(sample(), KEY), key_for=key_for) == sample()
    assert decode(encode(sample(camera=514), OTHER_KEY), key_for=key_for) == sample(camera=514)
    for forged in (sample(camera=514), sample(camera=515), sample(session="other")):
        with pytest.raises(PacketError) as info:
            decode(encode(forged, KEY), key_for=key_for)
        assert info.value.reason == ("bad tag" if forged.camera == 514 else "no key")
    with pytest.raises(PacketError, match="missing tag"):
        decode(encode(sample()), key_for=key_for)
    with pytest.raises(ValueError, match="not both"):
        decode(encode(sample(), KEY), KEY, key_for=key_for)


@pytest.mark.parametrize(
    ("offset", "value"),
    [
        (20, struct.pack("<d", float("inf"))),  # timestamp
        (20, struct.pack("<d", float("nan"))),
        (28, b"take 01".ljust(16, b"\0")),  # session: a space
        (28, b"\xe9".ljust(16, b"\0")),  # session: not ASCII
        (28, b"ab\0cd".ljust(16, b"\0")),  # session: NUL inside, not padding
        (44, struct.pack("<f", float("inf"))),  # marker 0 u
        (48, struct.pack("<f", float("nan"))),  # marker 0 v only
    ],
)
def test_value_reasons(offset: int, value: bytes) -> None:
    plain = encode(sample())
    data = plain[:offset] + value + plain[offset + len(value) :]
    assert reason_of(data) == "bad values"


def test_value_errors_are_checked_after_the_tag() -> None:
    signed = encode(sample(), KEY)
    forged = signed[:20] + struct.pack("<d", float("inf")) + signed[28:]
    assert reason_of(forged, KEY) == "bad tag"


def test_empty_key_is_a_configuration_error() -> None:
    with pytest.raises(ValueError):
        encode(sample(), b"")
    with pytest.raises(ValueError):
        decode(encode(sample()), b"")


# --- fuzzing -----------------------------------------------------------------------------

keys = st.sampled_from([None, KEY])
markers_rows = st.one_of(
    st.just((float("nan"), float("nan"))),
    st.tuples(*[st.floats(allow_nan=False, allow_infinity=False, width=32)] * 2),
)
packets = st.builds(
    MarkerPacket,
    camera=st.integers(0, 65535),
    sequence=st.integers(0, 2**32 - 1),
    epoch=st.integers(0, 2**64 - 1),
    timestamp=st.floats(allow_nan=False, allow_infinity=False),
    markers=st.lists(markers_rows, min_size=8, max_size=8).map(np.array),
    session=st.from_regex(r"[A-Za-z0-9._-]{0,16}", fullmatch=True),
    blobs=st.lists(
        st.tuples(*[st.floats(allow_nan=False, allow_infinity=False, width=32)] * 2),
        max_size=MAX_BLOBS,
    ).map(lambda rows: np.array(rows, dtype=np.float32).reshape(-1, 2)),
)
datagrams = st.one_of(
    st.binary(max_size=MAX_PACKET_BYTES + 8),
    st.binary(max_size=BODY_BYTES + TAG_BYTES + 4).map(lambda b: b"SMBA\x02" + b),
    st.binary(min_size=BODY_BYTES - 6, max_size=BODY_BYTES - 6).map(lambda b: b"SMBA\x02\x00" + b),
)


def check_decode(data: bytes, key: bytes | None) -> MarkerPacket | None:
    """Decode `data`: a dropped datagram must raise `PacketError` with a known reason, an
    accepted one must be the unique encoding of the packet returned."""
    try:
        packet = decode(data, key)
    except PacketError as exc:
        assert exc.reason in PacketError.REASONS
        return None
    assert encode(packet, key) == data
    return packet


@given(data=datagrams, key=keys)
def test_fuzz_arbitrary_bytes(data: bytes, key: bytes | None) -> None:
    check_decode(data, key)


@given(packet=packets, key=keys)
def test_fuzz_round_trip(packet: MarkerPacket, key: bytes | None) -> None:
    assert check_decode(encode(packet, key), key) == packet


@given(packet=packets, key=keys, position=st.integers(0, 260), flip=st.integers(1, 255))
def test_fuzz_single_byte_mutation(
    packet: MarkerPacket, key: bytes | None, position: int, flip: int
) -> None:
    data = bytearray(encode(packet, key))
    position %= len(data)
    data[position] ^= flip
    mutated = bytes(data)
    result = check_decode(mutated, key)
    # magic, version, flags and the blob count say how long the packet is
    structural = position < 6 or (len(packet.blobs) > 0 and position == BODY_BYTES)
    if structural or key is not None:
        assert result is None  # length damage or a signed packet: always dropped
        if key is not None and not structural:
            assert reason_of(mutated, key) == "bad tag"
    elif position < 20:  # camera, sequence, epoch: every value is valid
        assert result is not None
    elif result is None:
        assert reason_of(mutated) == "bad values"


def test_a_pose_packet_carries_13_joints_under_the_same_header() -> None:
    pose = np.arange(39, dtype=np.float32).reshape(13, 3) / 10
    packet = PosePacket(7, 42, 12.5, pose, "stage", 99)
    plain, signed = encode(packet), encode(packet, KEY)
    assert (len(plain), len(signed), POSE_BODY_BYTES) == (200, 216, 200)
    assert plain[5] == FLAG_POSE and signed[5] == FLAG_POSE | 1
    assert np.array_equal(np.frombuffer(plain[44:], "<f4").reshape(13, 3), pose)
    assert decode(plain) == packet and decode(signed, KEY) == packet
    assert decode(plain).epoch == 99
    assert signed[200:] == hmac.new(KEY, signed[:200], hashlib.sha256).digest()[:16]
    assert reason_of(plain[:-1]) == "too short" and reason_of(plain + b"\0") == "bad length"
    assert reason_of(signed[:-1] + bytes([signed[-1] ^ 1]), KEY) == "bad tag"
    nan = plain[:44] + np.full(39, np.nan, "<f4").tobytes()
    assert reason_of(nan) == "bad values"
    with pytest.raises(ValueError, match="NaN or infinite"):
        PosePacket(0, 0, 0.0, np.full((13, 3), np.inf))
    with pytest.raises(ValueError, match="shape"):
        PosePacket(0, 0, 0.0, np.zeros((8, 2)))
