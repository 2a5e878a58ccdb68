"""Grouping camera packets into capture frames: `samba.service.frame_sync.FrameSync`.

Arrival times are passed explicitly (server seconds); nothing sleeps. Helpers build the
deliveries of cameras at 60 fps, send them in arrival order like the server would (expire
before each add, a final expire; a camera's first packet of an epoch it has not sent
before restarts it, as the server's replay guard says) and collect the emitted frames.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from itertools import pairwise

import numpy as np
import pytest

from samba.service.frame_sync import RECENT_PACKETS, FrameSync, SyncedFrame
from samba.service.packet import MarkerPacket

FPS = 60.0
PERIOD = 1.0 / FPS
T0 = 100.0
"""Server time (s) of the first capture."""

Delivery = tuple[float, MarkerPacket]


def packet(camera: int, sequence: int, timestamp: float, epoch: int = 0) -> MarkerPacket:
    return MarkerPacket(
        camera=camera,
        sequence=sequence,
        timestamp=timestamp,
        markers=np.zeros((8, 2)),
        epoch=epoch,
    )


def capture_time(k: int) -> float:
    """Server time (s) of capture k."""
    return T0 + k * PERIOD


def run(sync: FrameSync, deliveries: Iterable[Delivery]) -> list[SyncedFrame]:
    """Offer the deliveries in arrival order as the server does; the frames emitted."""
    frames: list[SyncedFrame] = []
    last = -math.inf
    epochs: dict[int, set[int]] = {}
    for arrival, pkt in sorted(deliveries, key=lambda d: d[0]):
        frames += sync.expire(arrival)
        seen = epochs.setdefault(pkt.camera, set())
        if seen and pkt.epoch not in seen:
            sync.restart(pkt.camera)
        seen.add(pkt.epoch)
        frames += sync.add(pkt, arrival)
        last = arrival
    return frames + sync.expire(last + 10.0)


def in_step(
    cameras: int, frames: range, delays: list[float], node_offsets: list[float] | None = None
) -> list[Delivery]:
    """Every camera sends every capture; camera c with fixed delay and node clock offset."""
    node_offsets = node_offsets or [0.0] * cameras
    return [
        (capture_time(k) + delays[c], packet(c, k, capture_time(k) + node_offsets[c]))
        for k in frames
        for c in range(cameras)
    ]


def sequences(frame: SyncedFrame) -> list[int]:
    return [p.sequence for p in frame.packets.values()]


def assert_increasing(frames: list[SyncedFrame]) -> None:
    times = [f.time for f in frames]
    assert all(a < b for a, b in pairwise(times))


# ---------------------------------------------------------------- cameras in step


@pytest.mark.parametrize("cameras", [2, 3])
def test_cameras_in_step_emit_every_frame_complete_at_once(cameras: int) -> None:
    sync = FrameSync(range(cameras), FPS)
    delays = [0.001 * (c + 1) for c in range(cameras)]
    deliveries = sorted(in_step(cameras, range(50), delays), key=lambda d: d[0])
    frames = []
    for i, (arrival, pkt) in enumerate(deliveries):
        out = sync.add(pkt, arrival)
        last_of_capture = i % cameras == cameras - 1
        assert len(out) == (1 if last_of_capture else 0)
        if out:
            assert out[0].last_arrival == arrival
        frames += out
    assert [sequences(f) for f in frames] == [[k] * cameras for k in range(50)]
    assert all(f.complete for f in frames)
    assert all(list(f.packets) == list(range(cameras)) for f in frames)
    for k, frame in enumerate(frames):
        assert frame.time == pytest.approx(capture_time(k) + np.mean(delays), abs=1e-9)
        assert frame.last_arrival == pytest.approx(capture_time(k) + delays[-1], abs=1e-12)
    assert_increasing(frames)
    assert sync.deadline() is None
    counts = sync.counts
    assert (counts.packets, counts.frames, counts.complete) == (50 * cameras, 50, 50)
    assert counts.partial == counts.skipped == counts.late == counts.duplicates == 0
    assert counts.conflicts == counts.unknown_camera == counts.restarts == 0


def test_unsynchronised_clocks_and_different_jittery_delays() -> None:
    """Node clocks +1000 s and -3 s off; delays 1 ms and 3 ms plus up to 12 ms of jitter,
    more than `tolerance_s`: the minimum-delay packets pin the offsets."""
    extra = ([0.0, 0.012, 0.005, 0.009, 0.002], [0.0, 0.008, 0.011, 0.003, 0.012, 0.006])
    base = (0.001, 0.003)
    node = (1000.0, -3.0)
    deliveries = [
        (
            capture_time(k) + base[c] + extra[c][k % len(extra[c])],
            packet(c, k, capture_time(k) + node[c]),
        )
        for k in range(120)
        for c in (0, 1)
    ]
    sync = FrameSync([0, 1], FPS)
    frames = run(sync, deliveries)
    assert [sequences(f) for f in frames] == [[k, k] for k in range(120)]
    assert all(f.complete for f in frames)
    assert_increasing(frames)
    for k, frame in enumerate(frames):
        assert frame.time == pytest.approx(capture_time(k) + 0.002, abs=1e-9)
    assert sync.clock_offset(0) == pytest.approx(-1000.0 + 0.001, abs=1e-9)
    assert sync.clock_offset(1) == pytest.approx(3.0 + 0.003, abs=1e-9)


# ---------------------------------------------------------------- lossy simulation

SIM_CAPTURES = 600
WARM_UP = 60
"""Captures (1 s) within which the clock estimates may still be off by a frame period."""


def simulate(seed: int) -> tuple[list[Delivery], dict[tuple[int, int], float]]:
    """2 cameras x 60 fps x 10 s, 10 % loss, 10 % duplicated, delays uniform 0..50 ms.

    Returns the deliveries and the first arrival of each delivered (capture, camera).
    """
    rng = np.random.default_rng(seed)
    node = (rng.uniform(-1e4, 1e4), rng.uniform(-1e4, 1e4))
    deliveries: list[Delivery] = []
    first: dict[tuple[int, int], float] = {}
    for k in range(SIM_CAPTURES):
        for c in (0, 1):
            if rng.random() < 0.1:
                continue
            pkt = packet(c, k, capture_time(k) + node[c])
            copies = 2 if rng.random() < 0.1 else 1
            arrivals = capture_time(k) + rng.uniform(0.0, 0.05, copies)
            deliveries += [(float(a), pkt) for a in arrivals]
            first[k, c] = float(arrivals.min())
    return deliveries, first


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lossy_jittery_simulation(seed: int) -> None:
    deliveries, first = simulate(seed)
    sync = FrameSync([0, 1], FPS)
    frames = run(sync, deliveries)
    counts = sync.counts

    assert_increasing(frames)
    assert all(f.complete and list(f.packets) == [0, 1] for f in frames)
    for frame in frames:
        a, b = sequences(frame)
        if max(a, b) >= WARM_UP:
            assert a == b
        else:
            # A clock estimate from a few packets can be late by up to the 50 ms jitter.
            assert abs(a - b) <= 3
    emitted = {sequences(f)[0] for f in frames if len(set(sequences(f))) == 1}
    finished = np.array([f.last_arrival for f in frames])
    newest = np.array([max(sequences(f)) for f in frames])
    for k in range(WARM_UP, SIM_CAPTURES):
        if (k, 0) in first and (k, 1) in first and k not in emitted:
            # Resolved early: a newer frame was complete before k's second packet came.
            assert np.any((newest > k) & (finished < max(first[k, 0], first[k, 1])))
    assert len(emitted) > 0.6 * SIM_CAPTURES

    assert counts.packets == len(deliveries)
    assert counts.frames == counts.complete == len(frames)
    assert counts.partial == counts.restarts == counts.unknown_camera == 0
    assert counts.skipped > 0 and counts.duplicates > 0 and counts.late > 0
    members = sum(len(f.packets) for f in frames)
    # With 2 cameras and min_cameras 2, a skipped frame held one packet.
    assert counts.packets == (
        members + counts.duplicates + counts.late + counts.conflicts + counts.skipped
    )
    assert sync.deadline() is None


# ---------------------------------------------------------------- restarts and pauses


def restarted_stream(
    restart_at: int, clock_shift: float, captures: int, new_epoch: bool = True
) -> list[Delivery]:
    """Cameras 0 and 1 in step (delays 1 and 2 ms); camera 1 restarts at capture
    `restart_at` with sequence 0 and its clock moved by `clock_shift` s, in a new epoch
    unless `new_epoch` is False."""
    deliveries = []
    for k in range(captures):
        t = capture_time(k)
        deliveries.append((t + 0.001, packet(0, k, t)))
        if k < restart_at:
            deliveries.append((t + 0.002, packet(1, k, t)))
        else:
            restarted = packet(1, k - restart_at, t + clock_shift, epoch=int(new_epoch))
            deliveries.append((t + 0.002, restarted))
    return deliveries


@pytest.mark.parametrize(
    ("restart_at", "clock_shift"),
    [(100, 0.0), (100, 500.0), (100, -500.0), (400, 0.0), (400, 500.0), (400, -500.0)],
)
def test_camera_restart_is_picked_up_at_once(restart_at: int, clock_shift: float) -> None:
    """A restart (a new epoch) is picked up with its first packet, whatever its sequence
    and clock: at 100 it repeats remembered sequences, at 400 it goes back beyond them."""
    sync = FrameSync([0, 1], FPS)
    frames = run(sync, restarted_stream(restart_at, clock_shift, restart_at + 60))
    assert sync.counts.restarts == 1
    assert all(f.complete for f in frames)
    pairs = [sequences(f) for f in frames]
    expected = [[k, k if k < restart_at else k - restart_at] for k in range(restart_at + 60)]
    assert pairs == expected
    assert sync.clock_offset(1) == pytest.approx(0.002 - clock_shift, abs=1e-6)


def test_sequence_numbers_alone_never_restart_a_camera() -> None:
    """Remembered sequences with other timestamps in the same epoch (a replay with
    shifted sequence numbers, or a forged stream) are conflicts, not a restart: they
    add nothing, and the camera's frames are skipped meanwhile."""
    sync = FrameSync([0, 1], FPS)
    frames = run(sync, restarted_stream(100, 0.0, 160, new_epoch=False))
    assert sync.counts.restarts == 0
    assert sync.counts.conflicts == 60 and sync.counts.skipped == 60
    assert [sequences(f) for f in frames] == [[k, k] for k in range(100)]


def test_stale_packet_after_a_restart_is_not_another_restart() -> None:
    """Camera 1's last packet before restarting arrives after its first one after: it
    still completes its frame, which the newer frames wait for."""
    deliveries = restarted_stream(400, 0.0, 420)
    stale = next(i for i, (_, p) in enumerate(deliveries) if p.camera == 1 and p.sequence == 399)
    arrival, pkt = deliveries[stale]
    deliveries[stale] = (arrival + 1.5 * PERIOD, pkt)
    deliveries.sort(key=lambda d: d[0])
    sync = FrameSync([0, 1], FPS)
    frames = run(sync, deliveries)
    assert sync.counts.restarts == 1
    assert sync.counts.late == 0
    assert [sequences(f)[0] for f in frames] == list(range(420))
    assert all(f.complete for f in frames)


def test_camera_paused_for_3_s_is_not_a_restart() -> None:
    deliveries = [d for d in in_step(2, range(600), [0.001, 0.002]) if not pause(d)]
    sync = FrameSync([0, 1], FPS)
    frames = run(sync, deliveries)
    assert sync.counts.restarts == 0
    assert [sequences(f)[0] for f in frames] == [k for k in range(600) if not 200 <= k < 380]
    assert all(f.complete for f in frames)
    assert sync.counts.skipped == 180


def pause(delivery: Delivery) -> bool:
    """Camera 1 sends nothing for captures 200..379 (3 s)."""
    pkt = delivery[1]
    return pkt.camera == 1 and 200 <= pkt.sequence < 380


def test_sequence_wrap_is_not_a_restart() -> None:
    start = 2**32 - 5
    deliveries = [
        (capture_time(k) + 0.001 * (c + 1), packet(c, (start + k) % 2**32, capture_time(k)))
        for k in range(10)
        for c in (0, 1)
    ]
    sync = FrameSync([0, 1], FPS)
    frames = run(sync, deliveries)
    assert sync.counts.restarts == 0
    assert len(frames) == 10 and all(f.complete for f in frames)


# ---------------------------------------------------------------- deadline and expire


def test_deadline_and_expire() -> None:
    sync = FrameSync([0, 1], FPS, wait_s=0.05, min_cameras=1)
    assert sync.deadline() is None
    assert sync.expire(1e9) == []
    # Capture 1 arrives first (at 10.0), capture 0 later (at 10.03): reordered.
    assert sync.add(packet(0, 1, 5.0 + PERIOD), 10.0) == []
    assert sync.deadline() == pytest.approx(10.05)
    assert sync.add(packet(0, 0, 5.0), 10.03) == []
    assert sync.deadline() == pytest.approx(10.05)
    assert sync.expire(10.049) == []
    # Capture 1's deadline has passed; capture 0 is older, so it goes too, first.
    frames = sync.expire(sync.deadline())
    assert [f.packets[0].sequence for f in frames] == [0, 1]
    assert [f.last_arrival for f in frames] == [10.03, 10.0]
    assert not any(f.complete for f in frames)
    assert sync.deadline() is None
    assert sync.counts.partial == 2


def test_expire_leaves_newer_frames_open() -> None:
    sync = FrameSync([0, 1], FPS, wait_s=0.05, min_cameras=1)
    sync.add(packet(0, 0, 0.0), 10.0)
    sync.add(packet(0, 1, PERIOD), 10.0 + PERIOD)
    frames = sync.expire(10.06)
    assert [f.packets[0].sequence for f in frames] == [0]
    assert sync.deadline() == pytest.approx(10.0 + PERIOD + 0.05)


def test_partial_frames_after_wait() -> None:
    sync = FrameSync([0, 1, 2], FPS, wait_s=0.05, min_cameras=2)
    for c in range(3):
        sync.add(packet(c, 0, 0.0), 10.0)
    t1 = 10.0 + PERIOD
    sync.add(packet(0, 1, PERIOD), t1)
    sync.add(packet(1, 1, PERIOD), t1 + 0.002)
    assert sync.expire(t1 + 0.04) == []
    [frame] = sync.expire(t1 + 0.05)
    assert not frame.complete
    assert list(frame.packets) == [0, 1]
    assert frame.last_arrival == t1 + 0.002
    assert frame.time == pytest.approx(t1)
    # Camera 2's packet for it comes too late.
    assert sync.add(packet(2, 1, PERIOD), t1 + 0.06) == []
    assert sync.counts.late == 1
    # One camera only: skipped, not emitted.
    sync.add(packet(0, 2, 2 * PERIOD), 10.0 + 2 * PERIOD)
    assert sync.expire(11.0) == []
    counts = sync.counts
    assert (counts.complete, counts.partial, counts.skipped, counts.frames) == (1, 1, 1, 2)


def test_a_complete_frame_waits_for_older_open_frames() -> None:
    sync = FrameSync([0, 1, 2], FPS, min_cameras=2, wait_s=0.05)
    sync.add(packet(0, 0, 0.0), 10.0)
    sync.add(packet(1, 0, 0.0), 10.0)
    sync.add(packet(0, 1, PERIOD), 10.0 + PERIOD)  # only camera 0: will be skipped
    for c in range(3):
        assert sync.add(packet(c, 2, 2 * PERIOD), 10.0 + 2 * PERIOD) == []
    assert sync.deadline() == pytest.approx(10.05)
    assert sync.expire(10.049) == []
    frames = sync.expire(10.05)
    assert [(f.complete, sequences(f)) for f in frames] == [(False, [0, 0])]
    assert sync.deadline() == pytest.approx(10.05 + PERIOD)
    frames = sync.expire(10.05 + PERIOD)  # frame 1 has one camera: skipped; frame 2 goes
    assert [(f.complete, sequences(f)) for f in frames] == [(True, [2, 2, 2])]
    assert (sync.counts.partial, sync.counts.skipped, sync.counts.complete) == (1, 1, 1)
    assert sync.deadline() is None


def test_a_late_packet_completes_its_frame_before_the_newer_ones() -> None:
    sync = FrameSync([0, 1], FPS, wait_s=0.05)
    sync.add(packet(0, 0, 0.0), 10.0)
    sync.add(packet(0, 1, PERIOD), 10.0 + PERIOD)
    assert sync.add(packet(1, 1, PERIOD), 10.0 + PERIOD) == []  # frame 1 waits for frame 0
    frames = sync.add(packet(1, 0, 0.0), 10.03)  # 30 ms late, reordered
    assert [(f.complete, sequences(f)) for f in frames] == [(True, [0, 0]), (True, [1, 1])]
    assert frames[0].last_arrival == 10.03


def test_packets_crowding_between_two_frames_keep_times_increasing() -> None:
    """A frame whose members sit nearer the previous frame than `tolerance_s` loses them
    as late when it is resolved, so emitted times never go back."""
    tolerance = 0.4 / FPS
    sync = FrameSync([0, 1, 2], FPS)
    sync.add(packet(0, 0, 0.0), 10.0)
    sync.add(packet(1, 0, 0.0), 10.0)  # both clocks: server = node + 10 s
    sync.add(packet(2, 0, 0.0), 10.0)
    sync.add(packet(0, 1, 1.0), 11.0)  # frame A at 11.0
    sync.add(packet(1, 1, 1.0 + 0.99 * tolerance), 11.01)  # joins A
    sync.add(packet(2, 1, 1.0 + 1.01 * tolerance), 11.011)  # opens frame B
    sync.add(packet(0, 2, 1.0 + 0.05 * tolerance), 11.012)  # A has camera 0: joins B
    assert sync.add(packet(1, 2, 1.0 + 0.04 * tolerance), 11.013) == []  # B waits for A
    frames = sync.expire(11.05)  # A waited wait_s (0.05 s)
    # B's members average earlier than A's: they are late, and B is not emitted.
    assert [sequences(f) for f in frames] == [[1, 1]]
    assert sync.counts.late == 3
    assert_increasing(frames)


# ---------------------------------------------------------------- dropped packets


def test_duplicates_late_conflicts_and_unknown_cameras() -> None:
    sync = FrameSync([0, 1], FPS)
    sync.add(packet(0, 5, 5 * PERIOD), 10.0)
    assert sync.add(packet(0, 5, 5 * PERIOD), 10.001) == []  # duplicate, frame open
    assert sync.add(packet(0, 6, 5 * PERIOD + 0.002), 10.002) == []  # conflict
    assert sync.add(packet(9, 5, 5 * PERIOD), 10.002) == []  # unknown camera
    [frame] = sync.add(packet(1, 5, 5 * PERIOD), 10.003)
    assert frame.packets[0].sequence == 5
    assert sync.add(packet(1, 5, 5 * PERIOD), 10.004) == []  # duplicate, frame emitted
    assert sync.add(packet(1, 4, 4 * PERIOD), 10.005) == []  # late
    # Within tolerance_s after the emitted frame's time (10.0015 s): late, opens no frame.
    assert sync.add(packet(0, 7, 5 * PERIOD + 0.003), 10.006) == []
    assert sync.deadline() is None
    counts = sync.counts
    assert (counts.duplicates, counts.conflicts, counts.unknown_camera, counts.late) == (2, 1, 1, 2)
    assert (counts.packets, counts.frames, counts.restarts) == (8, 1, 0)


def test_duplicates_remembered_for_the_last_256_packets() -> None:
    sync = FrameSync([0], FPS, min_cameras=1)
    for k in range(300):
        sync.add(packet(0, k, k * PERIOD), 10.0 + k * PERIOD)
    now = 10.0 + 300 * PERIOD
    sync.add(packet(0, 300 - RECENT_PACKETS, (300 - RECENT_PACKETS) * PERIOD), now)
    assert (sync.counts.duplicates, sync.counts.late) == (1, 0)
    sync.add(packet(0, 299 - RECENT_PACKETS, (299 - RECENT_PACKETS) * PERIOD), now)
    assert (sync.counts.duplicates, sync.counts.late) == (1, 1)


def test_max_open_resolves_the_oldest_frames() -> None:
    sync = FrameSync([0, 1], FPS, min_cameras=1, max_open=4)
    emitted = sync.add(packet(1, 0, 0.0), 10.0)
    for k in range(10):
        emitted += sync.add(packet(0, k, k * PERIOD), 10.0 + k * PERIOD)
    assert [f.packets[0].sequence for f in emitted] == list(range(6))
    assert (sync.counts.complete, sync.counts.partial) == (1, 5)
    assert sync.deadline() == pytest.approx(10.0 + 6 * PERIOD + 0.05)
    # A packet for a pushed-out frame is late.
    assert sync.add(packet(1, 2, 2 * PERIOD), 10.2) == []
    assert sync.counts.late == 1


# ---------------------------------------------------------------- clock window


@pytest.mark.parametrize(
    ("cameras", "kwargs", "message"),
    [
        ([], {}, "no cameras"),
        ([0, 0], {}, "not unique"),
        ([-1, 0], {}, "camera id -1"),
        ([0, 65536], {}, "camera id 65536"),
        ([0, 1.5], {}, "camera id 1.5"),
        ([True, 0], {}, "camera id True"),
        ([0, 1], {"fps": 0.0}, "fps 0.0"),
        ([0, 1], {"fps": -30.0}, "fps -30.0"),
        ([0, 1], {"fps": math.inf}, "fps inf"),
        ([0, 1], {"fps": math.nan}, "fps nan"),
        ([0, 1], {"wait_s": -0.01}, "wait_s -0.01"),
        ([0, 1], {"wait_s": math.nan}, "wait_s nan"),
        ([0, 1], {"tolerance_s": 0.0}, "tolerance_s 0.0"),
        ([0, 1], {"min_cameras": 0}, "min_cameras 0"),
        ([0, 1], {"min_cameras": 3}, "min_cameras 3"),
        ([0, 1], {"min_cameras": 1.5}, "min_cameras 1.5"),
        ([0, 1], {"clock_window_s": 0.0}, "clock_window_s 0.0"),
        ([0, 1], {"clock_rise": -0.001}, "clock_rise -0.001"),
        ([0, 1], {"clock_rise": math.nan}, "clock_rise nan"),
        ([0, 1], {"max_open": 0}, "max_open 0"),
    ],
)
def test_invalid_arguments(cameras: list, kwargs: dict, message: str) -> None:
    kwargs = {"fps": FPS, **kwargs}
    with pytest.raises(ValueError, match=message):
        FrameSync(cameras, **kwargs)


def test_invalid_arrival() -> None:
    sync = FrameSync([0, 1], FPS)
    with pytest.raises(ValueError, match="arrival nan"):
        sync.add(packet(0, 0, 0.0), math.nan)
    assert sync.counts.packets == 0


@pytest.mark.parametrize("seed", range(5))
def test_misbehaving_cameras_keep_time_order_and_counts(seed: int) -> None:
    """Cameras at other rates than configured, with jitter, duplicates, restarts and an
    unknown camera: emitted times still strictly increase and every packet is counted."""
    rng = np.random.default_rng(seed)
    deliveries: list[Delivery] = []
    for camera, fps in zip((0, 1, 2, 9), rng.uniform(30.0, 240.0, 4), strict=True):
        node = rng.uniform(-100.0, 100.0)
        sequence = int(rng.integers(0, 2**32))
        epoch = 0
        for t in np.arange(0.0, 2.0, 1.0 / fps):
            if rng.random() < 0.02:
                sequence = int(rng.integers(0, 2**32))
                node += rng.uniform(-1.0, 1.0)
                epoch += 1
            pkt = packet(camera, sequence, float(t + node), epoch)
            for _ in range(1 + (rng.random() < 0.1)):
                deliveries.append((float(T0 + t + rng.uniform(0.0, 0.03)), pkt))
            sequence = (sequence + 1) % 2**32
    sync = FrameSync([0, 1, 2], FPS, min_cameras=1, max_open=8)
    frames = run(sync, deliveries)
    assert_increasing(frames)
    counts = sync.counts
    members = sum(len(f.packets) for f in frames)
    assert counts.skipped == 0 and counts.unknown_camera > 0 and counts.restarts > 0
    assert (
        counts.packets
        == len(deliveries)
        == (members + counts.duplicates + counts.late + counts.conflicts + counts.unknown_camera)
    )
    assert counts.frames == counts.complete + counts.partial == len(frames)
    assert counts.complete == sum(f.complete for f in frames)
