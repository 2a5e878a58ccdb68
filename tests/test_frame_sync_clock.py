"""A camera's clock offset in `samba.service.frame_sync.FrameSync`: the minimum delay over
the window, risen at most `CLOCK_RISE` a second, so a node falling behind or catching up
keeps its frames on its own clock, and a first packet sent late costs no frame.

Arrival times are passed explicitly (server seconds), with the helpers of test_frame_sync.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_frame_sync import FPS, PERIOD, capture_time, packet, run, sequences

from samba.service.frame_sync import CLOCK_RISE, FrameSync


@pytest.mark.parametrize("rise", [CLOCK_RISE, 1e9], ids=["default rise", "unbounded rise"])
def test_clock_offset_is_the_minimum_over_the_window_risen_at_most_clock_rise(
    rise: float,
) -> None:
    rng = np.random.default_rng(7)
    sync = FrameSync([0, 1], FPS, clock_window_s=0.5, clock_rise=rise, min_cameras=1)
    assert sync.clock_offset(0) is None
    k = np.arange(400)
    timestamps = 50.0 + k * PERIOD
    arrivals = 10.0 + k * PERIOD + rng.uniform(0.0, 0.05, k.size) + 0.001 * np.sin(k / 30)
    order = np.argsort(arrivals)
    expected, at, rose = math.inf, 0.0, 0
    for i, j in enumerate(order):
        sync.add(packet(0, int(k[j]), float(timestamps[j])), float(arrivals[j]))
        now = arrivals[j]
        seen = order[: i + 1]
        window = seen[arrivals[seen] > now - 0.5]
        lowest = min(arrivals[window] - timestamps[window])
        rose += lowest > expected + rise * (now - at)
        expected = min(lowest, expected + rise * (now - at))
        at = now
        assert sync.clock_offset(0) == expected
    assert rose > 0 if rise == CLOCK_RISE else rose == 0  # the bound held the estimate
    assert sync.clock_offset(1) is None
    with pytest.raises(ValueError, match="camera 7"):
        sync.clock_offset(7)


def test_a_node_falling_behind_keeps_its_frames_on_its_clock() -> None:
    # A node on a busy machine takes 3 frame periods a frame: its packets queue, each
    # 2 periods later than the one before (10 s behind after 300 frames). Its clock has
    # not moved: the frames keep their capture times one period apart, none is late. (The
    # window's minimum alone rose 2 periods a packet once the first left the window: a
    # recorded take showed gaps of frames never dropped.)
    sync = FrameSync([0], FPS, min_cameras=1)
    deliveries = [
        (capture_time(0) + 0.002 + 3 * k * PERIOD, packet(0, k, k * PERIOD)) for k in range(300)
    ]
    frames = run(sync, deliveries)
    assert [sequences(f)[0] for f in frames] == list(range(300))
    assert sync.counts.late == 0
    steps = np.diff([f.time for f in frames])
    assert steps == pytest.approx(PERIOD, abs=CLOCK_RISE * 3 * PERIOD + 1e-9)


def test_a_node_catching_up_after_a_3_s_stall_loses_no_frame() -> None:
    # The node sends captures 0..119 at once, stalls for 3 s (longer than the clock
    # window), sends the 180 captures of the stall in a burst 1 ms apart and goes on
    # 0.2 s behind. (The window's minimum alone was the burst's first delay, about 3 s,
    # then fell with each packet of the burst: their frames were a millisecond apart and
    # dropped as late.)
    burst = capture_time(300)
    deliveries = [
        (
            capture_time(k) + 0.002
            if k < 120
            else burst + 0.001 * (k - 120)
            if k < 300
            else capture_time(k) + 0.2,
            packet(0, k, k * PERIOD),
        )
        for k in range(360)
    ]
    sync = FrameSync([0], FPS, min_cameras=1)
    frames = run(sync, deliveries)
    assert [sequences(f)[0] for f in frames] == list(range(360))
    assert sync.counts.late == 0
    steps = np.diff([f.time for f in frames])
    assert steps == pytest.approx(PERIOD, abs=CLOCK_RISE * 3.5 + 1e-9)


def test_a_first_packet_sent_late_does_not_make_the_next_frame_late() -> None:
    # The nodes' first packets go out 17.6 ms late (a busy machine) and the second
    # capture's right behind them, 1 ms after it: the offset estimates fall by 16.6 ms
    # and capture 1 aligns 0.1 ms after frame 0, which was emitted with the first
    # estimates. It is a new capture on the nodes' clocks, not a late packet. (It was
    # dropped as late: a live take lost its second frame.) Camera 1's packet of capture
    # 50, delayed 0.2 s past its frame (skipped with camera 0 alone), is still late.
    deliveries = [
        (capture_time(0) + 0.0176 + 0.0001 * k if k < 2 else capture_time(k) + 0.001, pkt)
        for k in range(120)
        for pkt in (packet(0, k, k * PERIOD), packet(1, k, k * PERIOD))
    ]
    deliveries = [(t + 0.2 if p.camera == 1 and p.sequence == 50 else t, p) for t, p in deliveries]
    sync = FrameSync([0, 1], FPS)
    frames = run(sync, deliveries)
    assert [sequences(f) for f in frames] == [[k, k] for k in range(120) if k != 50]
    assert all(f.complete for f in frames)
    assert (sync.counts.late, sync.counts.skipped) == (1, 1)
    steps = np.diff([f.time for f in frames])
    assert np.all(steps > 0) and np.all(steps < 2 * PERIOD + 1e-9)  # 2: across capture 50


# ---------------------------------------------------------------- validation
