"""`ReplayGuard`: which packets of a session are new, by epoch, sequence and server clock.

A signed packet proves which node sent it, not that it is new: a copy sent again later
carries the same valid tag. The guard admits a packet only when all of these hold:

1. **Server clock.** Its timestamp is within `max_skew_s` of its arrival on the
   server's clock ("off clock" otherwise). Nodes keep their clocks within that of the
   server's (NTP does milliseconds); a packet captured longer ago, or stamped far in
   the future, is dropped before it can move the frame sync's clock estimate.
2. **Epoch.** Each node run draws a random 64-bit epoch (`samba.service.packet`). The
   first packet of a camera starts its epoch. A packet of another epoch is a restart
   only when that epoch was never retired and its timestamp is newer than every packet
   of the current epoch; the current epoch is then retired ("restart", the packet is
   used). A packet of a retired epoch, or of a new one whose timestamp is not newer, is
   "replayed". A restart is picked up with the new run's first packet.
3. **Counter.** Within an epoch the sequence only increases. Each sequence number is
   accepted once: one already accepted is a "duplicate" (a network duplicate or a
   replay, which look the same), and one more than `REPLAY_WINDOW` behind the highest
   accepted is "replayed"; those in between, not yet seen, are reordered packets and are
   accepted (the anti-replay window of IPsec, RFC 4303).

A retired epoch is remembered until its packets are too old for rule 1 whatever they
carry (`2 max_skew_s` after it was retired, and at most `RETIRED_EPOCHS` per camera). A
replay therefore needs a copy of packets the server has never seen, sent within
`max_skew_s` of their capture. Without keys anyone who can reach the socket can make
new epochs; with a key per node (`samba.service.node_keys`) only that node can.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass
from enum import StrEnum

from samba.service.packet import Packet

REPLAY_WINDOW = 256
"""Sequence numbers behind the highest accepted that may still arrive (reordering)."""
DEFAULT_MAX_SKEW_S = 5.0
"""Default largest difference, seconds, between a packet's timestamp and its arrival."""
RETIRED_EPOCHS = 64
"""Most retired epochs remembered per camera."""
_WINDOW_MASK = (1 << REPLAY_WINDOW) - 1


class Verdict(StrEnum):
    """What the guard made of a packet: used (`NEW`, `RESTART`) or dropped (the others,
    whose values are the drop reasons the server counts)."""

    NEW = "new"
    RESTART = "restart"
    DUPLICATE = "duplicate"
    REPLAYED = "replayed"
    OFF_CLOCK = "off clock"

    @property
    def accepted(self) -> bool:
        """Whether the packet is used."""
        return self in (Verdict.NEW, Verdict.RESTART)


@dataclass
class _Epoch:
    """One camera's current epoch: its id, highest sequence, the window of sequences
    accepted below it (bit i: highest - i) and the newest timestamp (s)."""

    epoch: int
    highest: int
    seen: int
    newest: float


class ReplayGuard:
    """Admits each camera's new packets; see the module docstring. `max_skew_s` is the
    largest difference (s) between a packet's timestamp and its arrival time, both
    UNIX seconds; `ValueError` unless it is a finite number > 0."""

    def __init__(self, max_skew_s: float = DEFAULT_MAX_SKEW_S) -> None:
        if (
            isinstance(max_skew_s, bool)
            or not isinstance(max_skew_s, int | float)
            or not math.isfinite(max_skew_s)
            or max_skew_s <= 0
        ):
            raise ValueError(f"max_skew_s {max_skew_s!r} is not a finite number of seconds > 0")
        self.max_skew_s = float(max_skew_s)
        self._current: dict[int, _Epoch] = {}
        self._retired: dict[int, OrderedDict[int, float]] = {}

    def check(self, packet: Packet, arrival: float) -> Verdict:
        """The verdict on `packet`, which arrived at `arrival` (UNIX seconds); an accepted
        packet is remembered, a dropped one changes nothing."""
        if not abs(packet.timestamp - arrival) <= self.max_skew_s:
            return Verdict.OFF_CLOCK
        current = self._current.get(packet.camera)
        if current is None:
            if packet.epoch in self._retired_of(packet.camera, arrival):
                return Verdict.REPLAYED
            self._current[packet.camera] = _first(packet)
            return Verdict.NEW
        if packet.epoch != current.epoch:
            retired = self._retired_of(packet.camera, arrival)
            if packet.epoch in retired or packet.timestamp <= current.newest:
                return Verdict.REPLAYED
            retired[current.epoch] = arrival
            if len(retired) > RETIRED_EPOCHS:
                retired.popitem(last=False)
            self._current[packet.camera] = _first(packet)
            return Verdict.RESTART
        verdict = _count(current, packet.sequence)
        if verdict.accepted:
            current.newest = max(current.newest, packet.timestamp)
        return verdict

    def _retired_of(self, camera: int, now: float) -> OrderedDict[int, float]:
        """Camera `camera`'s retired epochs (epoch -> when retired, s), those older than
        `2 max_skew_s` at `now` forgotten."""
        retired = self._retired.setdefault(camera, OrderedDict())
        while retired and next(iter(retired.values())) < now - 2 * self.max_skew_s:
            retired.popitem(last=False)
        return retired


def _first(packet: Packet) -> _Epoch:
    """The epoch `packet` starts, holding it alone."""
    return _Epoch(packet.epoch, packet.sequence, 1, packet.timestamp)


def _count(epoch: _Epoch, sequence: int) -> Verdict:
    """Accept `sequence` into `epoch`'s window (`NEW`), or say why not."""
    if sequence > epoch.highest:
        epoch.seen = ((epoch.seen << (sequence - epoch.highest)) | 1) & _WINDOW_MASK
        epoch.highest = sequence
        return Verdict.NEW
    behind = epoch.highest - sequence
    if behind >= REPLAY_WINDOW:
        return Verdict.REPLAYED
    if epoch.seen >> behind & 1:
        return Verdict.DUPLICATE
    epoch.seen |= 1 << behind
    return Verdict.NEW
