"""What a server admits of a camera's packets: the replay guard (epochs, counters, the
window around the server clock), the nodes' keys file, and marker pixels outside the
image. Issue 41, items 2 and 3."""

from __future__ import annotations

import math
import random
from pathlib import Path

import numpy as np
import pytest

from samba.cameras.camera import Camera
from samba.service.errors import ServiceError
from samba.service.image_bounds import keep_inside
from samba.service.node_keys import NodeKey, NodeKeys, read_node_keys
from samba.service.packet import MarkerPacket
from samba.service.replay_guard import REPLAY_WINDOW, RETIRED_EPOCHS, ReplayGuard, Verdict

NOW = 1_700_000_000.0
"""Server time (UNIX s) of the first packet."""
FPS = 60.0


def packet(sequence: int, epoch: int = 1, timestamp: float | None = None, camera: int = 0):
    """Camera `camera`'s packet `sequence` of `epoch`, captured at NOW + sequence / FPS
    unless `timestamp` is given."""
    stamp = NOW + sequence / FPS if timestamp is None else timestamp
    return MarkerPacket(camera, sequence, stamp, np.zeros((8, 2)), epoch=epoch)


def test_a_stream_in_order_and_reordered_within_the_window_is_new() -> None:
    guard = ReplayGuard()
    order = list(range(600))
    rng = random.Random(3)
    for i in range(0, 600, 20):  # reordered within blocks of 20
        block = order[i : i + 20]
        rng.shuffle(block)
        order[i : i + 20] = block
    verdicts = [guard.check(packet(s), NOW + s / FPS + 0.01) for s in order]
    assert verdicts == [Verdict.NEW] * 600


def test_every_copy_of_an_accepted_packet_is_dropped_in_any_order() -> None:
    """A replay of a whole recorded stream, shuffled, adds nothing: each copy is a
    duplicate, or more than the window behind, or out of the clock window."""
    guard = ReplayGuard()
    stream = [packet(s) for s in range(400)]
    for p in stream:
        assert guard.check(p, p.timestamp + 0.002) is Verdict.NEW
    replay = stream[:]
    random.Random(5).shuffle(replay)
    now = stream[-1].timestamp + 0.1
    verdicts = {guard.check(p, now) for p in replay}
    assert verdicts <= {Verdict.DUPLICATE, Verdict.REPLAYED, Verdict.OFF_CLOCK}
    later = {guard.check(p, now + 10.0) for p in replay}
    assert later == {Verdict.OFF_CLOCK}


@pytest.mark.parametrize("offset", [-(2**31), -300, -REPLAY_WINDOW, -1])
def test_counters_behind_the_stream_are_never_restarts(offset: int) -> None:
    """The attack of item 2: old packets re-sent with sequence numbers just behind the
    live ones, in the live epoch: duplicates or replays, never a restart."""
    guard = ReplayGuard()
    for s in range(300):
        assert guard.check(packet(s + 2**31, timestamp=NOW + s / FPS), NOW + s / FPS).accepted
    last = 2**31 + 299
    for s in range(300):
        sequence = last + offset - s
        if sequence < 0:
            continue
        now = NOW + 300 / FPS  # within the clock window: the counter alone decides
        verdict = guard.check(packet(sequence, timestamp=now - 0.5), now)
        behind = last - sequence
        assert verdict is (Verdict.DUPLICATE if behind < REPLAY_WINDOW else Verdict.REPLAYED)


def test_a_restart_is_a_new_epoch_and_the_old_epoch_is_retired() -> None:
    guard = ReplayGuard()
    old = [packet(s, epoch=7) for s in range(100)]
    for p in old:
        guard.check(p, p.timestamp)
    restarted = packet(0, epoch=8, timestamp=NOW + 2.0)
    assert guard.check(restarted, NOW + 2.0) is Verdict.RESTART
    assert guard.check(packet(1, epoch=8, timestamp=NOW + 2.0 + 1 / FPS), NOW + 2.02) is Verdict.NEW
    # the old run's packets, even ones never seen, and with any sequence: replayed
    for sequence in (99, 100, 5000):
        stale = packet(sequence, epoch=7, timestamp=NOW + 1.9)
        assert guard.check(stale, NOW + 2.05) is Verdict.REPLAYED
    # a new epoch whose timestamps are not newer than the current run's: replayed
    assert guard.check(packet(0, epoch=9, timestamp=NOW + 1.5), NOW + 2.05) is Verdict.REPLAYED
    # a later restart still works, and every camera is on its own
    assert guard.check(packet(0, epoch=9, timestamp=NOW + 3.0), NOW + 3.0) is Verdict.RESTART
    assert guard.check(packet(0, epoch=7, camera=1), NOW + 0.01) is Verdict.NEW


def test_retired_epochs_are_forgotten_once_their_packets_are_off_clock() -> None:
    guard = ReplayGuard(max_skew_s=1.0)
    for epoch in range(RETIRED_EPOCHS + 10):
        stamp = NOW + epoch * 0.01
        assert guard.check(packet(0, epoch, stamp), stamp).accepted
    assert len(guard._retired[0]) == RETIRED_EPOCHS
    late = NOW + 10.0
    guard.check(packet(0, epoch=1000, timestamp=late), late)
    assert len(guard._retired[0]) == 1  # the epoch just retired


def test_timestamps_far_from_the_server_clock_are_off_clock() -> None:
    guard = ReplayGuard(max_skew_s=2.0)
    assert guard.check(packet(0, timestamp=NOW), NOW + 1.9) is Verdict.NEW
    for stamp in (NOW + 1e6, NOW - 3.0, NOW + 2.5, 1e300, -1e300):
        assert guard.check(packet(1, timestamp=stamp), NOW) is Verdict.OFF_CLOCK
    assert guard.check(packet(1, timestamp=NOW + 1.0), NOW) is Verdict.NEW
    with pytest.raises(ValueError, match="max_skew_s"):
        ReplayGuard(max_skew_s=0.0)
    with pytest.raises(ValueError, match="max_skew_s"):
        ReplayGuard(max_skew_s=math.nan)


def test_a_dropped_packet_changes_nothing() -> None:
    guard = ReplayGuard()
    assert guard.check(packet(10), NOW) is Verdict.NEW
    assert guard.check(packet(11, timestamp=NOW + 1e6), NOW) is Verdict.OFF_CLOCK
    assert guard.check(packet(11), NOW + 0.02) is Verdict.NEW  # 11 was not taken


# ---- node keys -------------------------------------------------------------------------


def write_keys(folder: Path, text: str, *names: str) -> Path:
    """A keys file `text` in `folder`, with a distinct 32-byte key file per name."""
    for i, name in enumerate(names):
        (folder / name).write_bytes(bytes([i + 1]) * 32)
    path = folder / "keys.toml"
    path.write_text(text)
    return path


def test_a_keys_file_gives_each_camera_its_nodes_key(tmp_path: Path) -> None:
    path = write_keys(
        tmp_path,
        '[[node]]\nkey_file = "a.key"\ncameras = [0, 1]\n\n'
        '[[node]]\nkey_file = "b.key"\ncameras = [2]\n\n'
        '[[node]]\nkey_file = "c.key"\ncameras = [0]\nsession = "s2"\n',
        "a.key",
        "b.key",
        "c.key",
    )
    keys = read_node_keys(path)
    assert len(keys) == 4
    assert keys.key_for("s1", 0) == keys.key_for("s1", 1) == bytes([1]) * 32
    assert keys.key_for("s1", 2) == bytes([2]) * 32
    assert keys.key_for("s2", 0) == bytes([3]) * 32  # the table naming the session wins
    assert keys.key_for("s2", 1) == bytes([1]) * 32
    assert keys.key_for("s1", 3) is None


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "no \\[\\[node\\]\\] table"),
        ("[node]\nkey_file = 'a.key'\n", "no \\[\\[node\\]\\] table"),
        ("[[node]]\nkey_file = 'a.key'\ncameras = [0]\nkye = 1\n", "node 1: unknown key 'kye'"),
        ("[[node]]\ncameras = [0]\n", "node 1: key_file must be"),
        ("[[node]]\nkey_file = 'a.key'\ncameras = []\n", "cameras must be a list"),
        ("[[node]]\nkey_file = 'a.key'\ncameras = [70000]\n", "cameras must be a list"),
        ("[[node]]\nkey_file = 'a.key'\ncameras = [true]\n", "cameras must be a list"),
        ("[[node]]\nkey_file = 'a.key'\ncameras = [0]\nsession = '..'\n", "session '..'"),
        ("[[node]]\nkey_file = 'nothere.key'\ncameras = [0]\n", "nothere.key: cannot read"),
        ("[[node]]\nkey_file = 'short.key'\ncameras = [0]\n", "at least 16 bytes"),
        (
            "[[node]]\nkey_file = 'a.key'\ncameras = [0]\n[[node]]\nkey_file = 'b.key'\n"
            "cameras = [1, 0]\n",
            "node 2 .*camera 0 of every session already has the key of .*node 1",
        ),
        (
            "[[node]]\nkey_file = 'a.key'\ncameras = [0]\n[[node]]\nkey_file = 'a2.key'\n"
            "cameras = [1]\n",
            "node 2 .*holds the same key as .*node 1 .*: every node needs its own",
        ),
        ("[[node]\n", "not a TOML file"),
    ],
)
def test_a_bad_keys_file_is_one_error_naming_it(tmp_path: Path, text: str, message: str) -> None:
    path = write_keys(tmp_path, text, "a.key", "b.key")
    (tmp_path / "a2.key").write_bytes((tmp_path / "a.key").read_bytes())
    (tmp_path / "short.key").write_bytes(b"12345678")
    with pytest.raises(ServiceError, match=message) as info:
        read_node_keys(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_node_keys_from_code() -> None:
    keys = NodeKeys([NodeKey(b"k" * 32, frozenset({0}), "stage", "demo node 0")])
    assert keys.key_for("stage", 0) == b"k" * 32
    assert keys.key_for("other", 0) is None


# ---- pixels outside the image -----------------------------------------------------------


def test_markers_and_blobs_outside_the_image_are_dropped_and_counted() -> None:
    camera = Camera.look_at("cam", (0.0, 1.0, 4.0), (0.0, 1.0, 0.0), (640, 480), 60.0)
    markers = np.full((8, 2), 100.0)
    markers[1] = [3e38, 10.0]
    markers[2] = [-1.0, 10.0]
    markers[3] = [639.5, 479.5]  # the last pixel's far edge: inside
    markers[4] = np.nan
    markers[5] = [10.0, -1e9]
    blobs = np.array([[5.0, 5.0], [700.0, 5.0], [-3e38, 0.0]])
    sent = MarkerPacket(0, 1, NOW, markers, "s", blobs, epoch=3)
    kept, dropped_markers, dropped_blobs = keep_inside(sent, camera)
    assert (dropped_markers, dropped_blobs) == (3, 2)
    expected = markers.copy()
    expected[[1, 2, 5]] = np.nan
    np.testing.assert_array_equal(kept.markers, expected.astype(np.float32))
    np.testing.assert_array_equal(kept.blobs, [[5.0, 5.0]])
    assert (kept.camera, kept.sequence, kept.epoch, kept.session) == (0, 1, 3, "s")
    inside = MarkerPacket(0, 1, NOW, np.full((8, 2), 50.0))
    assert keep_inside(inside, camera) == (inside, 0, 0)


def test_guard_verdicts_name_the_drop_reasons() -> None:
    accepted = [v for v in Verdict if v.accepted]
    assert accepted == [Verdict.NEW, Verdict.RESTART]
    assert [v.value for v in Verdict if not v.accepted] == ["duplicate", "replayed", "off clock"]
