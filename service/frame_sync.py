"""Frame sync: group the cameras' marker packets into capture frames for the live server.

Pure logic: the server calls `FrameSync.add` with each decoded packet and its arrival time
on the server's clock (seconds; `samba serve` uses the kernel's wall-clock receive
timestamps), `FrameSync.expire` when
`FrameSync.deadline` passes, and gets back `SyncedFrame`s in strictly increasing time.

Clock alignment. Node clocks are not synchronised with the server or with each other, so
each camera's offset (server time = node time + offset) is estimated from the packets
themselves: every packet gives `arrival - timestamp` = true offset + its transport delay,
and the estimate is the minimum of that over the camera's packets that arrived in the last
`clock_window_s` seconds (a sliding minimum over a monotonic deque, amortised O(1) a
packet). The packet with the least delay pins the offset, so jitter does not move it, and
the window lets it follow clock drift. The estimate falls at once to a lower minimum, but
rises towards a higher one by at most `clock_rise` seconds per second of arrivals (default
`CLOCK_RISE`, ten times the drift of a poor crystal clock): when a node falls behind (a
busy machine, a stall) its packets queue and every delay in the window grows, but its
clock has not moved, and a step in the estimate would step its frames' times (a recorded
take would show a gap of dropped frames that were never dropped, and a node catching up
would have its backlog dropped as late). A node clock stepped back within one run is
followed at that rate; a node that restarts is picked up at once (`restart`).
A packet's aligned time is `timestamp + offset`:
its capture time on the server's clock, late by the camera's minimum transport delay.
Cameras whose minimum delays differ by a constant therefore look shifted by that
difference, which must stay well below `tolerance_s` (on a LAN it is well under 1 ms). The
first packets of a camera, and those after a restart, have had no quick packet yet, so
their aligned times are late by up to the jitter until one arrives: with jitter of several
frame periods, a camera's first frames may pair with a neighbouring capture of another
camera (at 50 ms of jitter and 60 fps, for up to about half a second).

Matching. A packet joins the open frame whose reference time (its first packet's aligned
time) is within `tolerance_s` of the packet's aligned time and which has no packet of that
camera yet; if every such frame already has one, the packet is a duplicate (same sequence
and timestamp) or a conflict (another packet) and is dropped. A packet aligned at or
before the last resolved frame's time + `tolerance_s` is late and dropped, unless its
capture is newer than that frame by more than `tolerance_s` on its own node's clock (the
frame's time less the camera's offset estimate when the frame was resolved): then the
estimate has fallen since (a quicker packet showed the first ones were delayed, as when
a node's first packet is late and the next goes out right behind it), and the packet is
a new capture, not a late one. Otherwise it opens a new frame.

Emission. Frames are ordered by reference time ("older" means earlier) and emitted in that
order. A frame that gets every camera is emitted at once when every older open frame has
been resolved; otherwise it waits for them, so a packet delayed past the next frames
still completes its own frame. `expire` resolves each frame whose first packet arrived
`wait_s` ago or earlier, with every older one, and then the complete frames behind them;
the oldest are also resolved when more than `max_open` are open. Resolving emits a
frame with at least `min_cameras` cameras and counts the others as skipped. A member
late by the same rule against the previous resolved frame (possible when the clock
estimate moved, or packets crowded between two frames, while the frame was open) is
removed first; a frame whose time would not come after the previous one's (new captures
aligned early by an estimate that has fallen since) gets that time + `MIN_STEP_S`, which
keeps emitted times strictly increasing.

Duplicates and restarts. The last `RECENT_PACKETS` (sequence, timestamp) pairs of each
camera identify duplicates, even of packets whose frame is already out; a packet with
the sequence of a recent one but another timestamp is a conflict and dropped. Sequence
numbers alone never make a restart: the caller says when a camera restarted
(`restart`: the server's replay guard saw the node's new epoch,
`samba.service.replay_guard`), and its recent pairs and clock window are forgotten, so
its next packet is grouped at once whatever its sequence and clock. A camera that
pauses and continues has not restarted.
"""

from __future__ import annotations

import bisect
import math
from collections import OrderedDict, deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

from samba.service.packet import Packet

RECENT_PACKETS = 256
"""(sequence, timestamp) pairs remembered per camera to spot duplicates and restarts."""
DEFAULT_TOLERANCE_FRAMES = 0.4
"""Default `tolerance_s` in frame periods (0.4 / fps)."""
CLOCK_RISE = 0.001
"""Default `clock_rise`: the fastest a camera's clock offset estimate rises, seconds per
second of arrivals (1000 ppm: ten times a poor crystal clock's drift, twice NTP's largest
slew; 2 ms over the default 2 s window, well inside `tolerance_s` at 60 fps)."""
MIN_STEP_S = 1e-6
"""Least step (s) between the times of two emitted frames."""
_MAX_CAMERA_ID = 0xFFFF


@dataclass(frozen=True)
class SyncedFrame:
    """One capture frame: the packets of the cameras that saw it.

    `time` is the capture time in seconds on the server's monotonic clock (the mean of the
    members' aligned times, or the previous frame's time + `MIN_STEP_S` if that is later),
    `packets` maps camera id to its packet in increasing camera id (read-only), `complete`
    says every expected camera is present, and `last_arrival` is the server time in
    seconds the last member arrived (latency is measured from it).
    """

    time: float
    packets: Mapping[int, Packet]
    complete: bool
    last_arrival: float


@dataclass
class SyncCounts:
    """Running totals of a `FrameSync`: packets, frames and camera restarts.

    Every packet offered is a member of an emitted frame, of a skipped frame or of a
    frame still open, or was dropped as a duplicate, late, a conflict or of an unknown
    camera. `restarts` counts the cameras' restarts (`FrameSync.restart`).
    """

    packets: int = 0
    frames: int = 0
    complete: int = 0
    partial: int = 0
    skipped: int = 0
    duplicates: int = 0
    late: int = 0
    conflicts: int = 0
    unknown_camera: int = 0
    restarts: int = 0


@dataclass
class _Member:
    packet: Packet
    aligned: float
    arrival: float


@dataclass
class _OpenFrame:
    reference: float
    first_arrival: float
    members: dict[int, _Member]


class _Camera:
    """One camera's recent (sequence, timestamp) pairs and clock window."""

    def __init__(self) -> None:
        self.recent: OrderedDict[int, float] = OrderedDict()
        self.clock: deque[tuple[float, float]] = deque()
        self.estimate: float | None = None
        """The clock offset estimate (s) as of the last packet; None before the first."""
        self.estimated_at = -math.inf
        """Arrival time (s) of the packet the estimate was made at."""
        self.resolved = math.inf
        """The last resolved frame's time (s) on this camera's clock, by the estimate
        when it was resolved; inf while unknown (no estimate then, or a restart since)."""

    def forget(self) -> None:
        """Drop the history, clock window and estimate, as after a restart."""
        self.recent.clear()
        self.clock.clear()
        self.estimate = None
        self.resolved = math.inf

    def remember(self, packet: Packet) -> None:
        """Record the packet's (sequence, timestamp)."""
        self.recent[packet.sequence] = packet.timestamp
        if len(self.recent) > RECENT_PACKETS:
            self.recent.popitem(last=False)

    def offset(self, timestamp: float, arrival: float, window_s: float, rise: float) -> float:
        """Add the sample `arrival - timestamp` (s) and return the new estimate (s): the
        window's minimum, or the last estimate raised by `rise` (s per s) times the
        seconds since, whichever is lower."""
        sample = arrival - timestamp
        clock = self.clock
        while clock and clock[-1][1] >= sample:
            clock.pop()
        clock.append((arrival, sample))
        while len(clock) > 1 and clock[0][0] <= arrival - window_s:
            clock.popleft()
        lowest = clock[0][1]
        if self.estimate is not None and lowest > self.estimate:
            lowest = min(lowest, self.estimate + rise * max(0.0, arrival - self.estimated_at))
        self.estimate, self.estimated_at = lowest, arrival
        return lowest


class FrameSync:
    """Groups camera packets into capture frames; see the module docstring for the rules.

    `cameras` are the expected camera ids (unique ints 0..65535), `fps` the capture rate
    in frames per second, `wait_s` how long (s) a frame waits for missing cameras after its
    first packet arrived, `tolerance_s` the largest difference (s) between aligned times
    in one frame (default 0.4 / fps), `min_cameras` the fewest cameras a frame is emitted
    with, `clock_window_s` the span (s) of arrivals the clock offsets are estimated over,
    `clock_rise` the fastest (s per s) an estimate rises, and `max_open` the most frames
    kept open. Invalid values raise `ValueError`.
    """

    def __init__(
        self,
        cameras: Iterable[int],
        fps: float,
        *,
        wait_s: float = 0.05,
        tolerance_s: float | None = None,
        min_cameras: int = 2,
        clock_window_s: float = 2.0,
        clock_rise: float = CLOCK_RISE,
        max_open: int = 64,
    ) -> None:
        ids = list(cameras)
        if not ids:
            raise ValueError("no cameras: give at least one camera id")
        for camera in ids:
            if not _is_int(camera) or not 0 <= camera <= _MAX_CAMERA_ID:
                raise ValueError(f"camera id {camera!r} is not an integer in 0..65535")
        if len(set(ids)) != len(ids):
            raise ValueError(f"camera ids {ids} are not unique")
        _check_positive("fps", fps)
        if not _is_real(wait_s) or not math.isfinite(wait_s) or wait_s < 0:
            raise ValueError(f"wait_s {wait_s!r} is not a finite number of seconds >= 0")
        if tolerance_s is None:
            tolerance_s = DEFAULT_TOLERANCE_FRAMES / fps
        _check_positive("tolerance_s", tolerance_s)
        if not _is_int(min_cameras) or not 1 <= min_cameras <= len(ids):
            raise ValueError(
                f"min_cameras {min_cameras!r} is not an integer in 1..{len(ids)} "
                f"(the number of cameras)"
            )
        _check_positive("clock_window_s", clock_window_s)
        if not _is_real(clock_rise) or not math.isfinite(clock_rise) or clock_rise < 0:
            raise ValueError(f"clock_rise {clock_rise!r} is not a finite number of s per s >= 0")
        if not _is_int(max_open) or max_open < 1:
            raise ValueError(f"max_open {max_open!r} is not an integer >= 1")
        self._cameras = {camera: _Camera() for camera in ids}
        self._wait_s = float(wait_s)
        self._tolerance_s = float(tolerance_s)
        self._min_cameras = min_cameras
        self._clock_window_s = float(clock_window_s)
        self._clock_rise = float(clock_rise)
        self._max_open = max_open
        self._open: list[_OpenFrame] = []
        self._last_time = -math.inf
        self.counts = SyncCounts()

    def add(self, packet: Packet, arrival: float) -> list[SyncedFrame]:
        """Offer one packet that arrived at server time `arrival` (s, monotonic).

        Returns the frames this resolves, oldest first: the frame it completes when no
        older frame is open, with the complete frames that waited behind it, or frames
        pushed out by `max_open`; often none.
        """
        if not _is_real(arrival) or not math.isfinite(arrival):
            raise ValueError(f"arrival {arrival!r} is not a finite time in seconds")
        counts = self.counts
        counts.packets += 1
        camera = self._cameras.get(packet.camera)
        if camera is None:
            counts.unknown_camera += 1
            return []
        seen = camera.recent.get(packet.sequence)
        if seen is not None:
            if seen == packet.timestamp:
                counts.duplicates += 1
            else:
                counts.conflicts += 1
            return []
        camera.remember(packet)
        offset = camera.offset(packet.timestamp, arrival, self._clock_window_s, self._clock_rise)
        aligned = packet.timestamp + offset
        if self._late(camera, packet, aligned):
            counts.late += 1
            return []
        return self._place(_Member(packet, aligned, arrival))

    def restart(self, camera: int) -> None:
        """Camera `camera`'s node has restarted: forget its recent packets and clock
        window (its next packet is grouped at once) and count it. An id that is not one
        of the cameras is ignored (its packets count as unknown)."""
        state = self._cameras.get(camera)
        if state is not None:
            state.forget()
            self.counts.restarts += 1

    def expire(self, now: float) -> list[SyncedFrame]:
        """Resolve the frames whose first packet arrived at or before `now - wait_s`.

        `now` is the server time in seconds; every open frame older than such a frame is
        resolved too, and then the complete frames waiting behind them. Returns the emitted
        frames (at least `min_cameras` cameras), oldest first.
        """
        last = -1
        for index, frame in enumerate(self._open):
            if frame.first_arrival + self._wait_s <= now:
                last = index
        return self._resolve_through(last) + self._release()

    def deadline(self) -> float | None:
        """The earliest server time (s) at which `expire` resolves a frame; None if none is open."""
        if not self._open:
            return None
        return min(frame.first_arrival for frame in self._open) + self._wait_s

    def clock_offset(self, camera: int) -> float | None:
        """Camera `camera`'s clock offset estimate in seconds (server time = node time + it).

        The estimate made at the camera's last packet (the minimum over the window, risen
        at most `clock_rise` per second); None before its first packet. `ValueError` for an
        id that is not one of the cameras.
        """
        state = self._cameras.get(camera)
        if state is None:
            raise ValueError(f"camera {camera!r} is not one of the synced cameras")
        return state.estimate

    def _late(self, camera: _Camera, packet: Packet, aligned: float) -> bool:
        """Whether `camera`'s `packet`, aligned at `aligned` (s), is late: aligned at or
        before the last resolved frame's time + `tolerance_s`, and captured no later than
        that frame + `tolerance_s` on its node's clock (see the module docstring)."""
        tolerance = self._tolerance_s
        return (
            aligned <= self._last_time + tolerance
            and packet.timestamp <= camera.resolved + tolerance
        )

    def _place(self, member: _Member) -> list[SyncedFrame]:
        """Put an aligned, in-time packet into its frame and emit what that resolves."""
        camera = member.packet.camera
        key = _reference
        low = bisect.bisect_left(self._open, member.aligned - self._tolerance_s, key=key)
        high = bisect.bisect_right(self._open, member.aligned + self._tolerance_s, key=key)
        near = self._open[low:high]
        free = [index for index in range(low, high) if camera not in self._open[index].members]
        if free:
            index = min(free, key=lambda i: abs(self._open[i].reference - member.aligned))
            self._open[index].members[camera] = member
        elif near:
            packet = member.packet
            if any(_same(frame.members[camera].packet, packet) for frame in near):
                self.counts.duplicates += 1
            else:
                self.counts.conflicts += 1
            return []
        else:
            index = low
            self._open.insert(index, _OpenFrame(member.aligned, member.arrival, {camera: member}))
        return self._resolve_through(len(self._open) - self._max_open - 1) + self._release()

    def _release(self) -> list[SyncedFrame]:
        """Resolve the complete frames at the head of the open frames: a complete frame
        waits for every older one to be resolved (complete, or out of time)."""
        ready = 0
        while ready < len(self._open) and len(self._open[ready].members) == len(self._cameras):
            ready += 1
        return self._resolve_through(ready - 1)

    def _resolve_through(self, last: int) -> list[SyncedFrame]:
        """Resolve the open frames 0..`last` (oldest first); return those emitted."""
        if last < 0:
            return []
        resolved = self._open[: last + 1]
        del self._open[: last + 1]
        emitted = []
        for frame in resolved:
            synced = self._resolve(frame)
            if synced is not None:
                emitted.append(synced)
        return emitted

    def _resolve(self, frame: _OpenFrame) -> SyncedFrame | None:
        """Emit `frame` or count it skipped, after dropping members now late."""
        counts = self.counts
        cameras = self._cameras
        members = {
            c: m
            for c, m in frame.members.items()
            if not self._late(cameras[c], m.packet, m.aligned)
        }
        counts.late += len(frame.members) - len(members)
        if not members:
            return None
        time = math.fsum(m.aligned for m in members.values()) / len(members)
        time = max(time, self._last_time + MIN_STEP_S)
        self._last_time = time
        for state in cameras.values():
            if state.estimate is not None:
                state.resolved = time - state.estimate
        if len(members) < self._min_cameras:
            counts.skipped += 1
            return None
        complete = len(members) == len(self._cameras)
        counts.frames += 1
        if complete:
            counts.complete += 1
        else:
            counts.partial += 1
        return SyncedFrame(
            time=time,
            packets=MappingProxyType({c: members[c].packet for c in sorted(members)}),
            complete=complete,
            last_arrival=max(m.arrival for m in members.values()),
        )


def _reference(frame: _OpenFrame) -> float:
    return frame.reference


def _same(a: Packet, b: Packet) -> bool:
    return a.sequence == b.sequence and a.timestamp == b.timestamp


def _check_positive(name: str, value: float) -> None:
    if not _is_real(value) or not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} {value!r} is not a finite number > 0")


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_real(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)
