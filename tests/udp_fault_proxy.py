"""A UDP proxy for tests that loses, duplicates, delays and so reorders datagrams.

Runs in the test's asyncio loop between the camera-node side and the server: each datagram
it receives is dropped with probability `loss`, else forwarded after a delay drawn
uniformly from 0..`jitter_s` (so later datagrams overtake earlier ones), and forwarded a
second time, after its own delay, with probability `duplicate`. Seeded, so a run's faults
are reproducible up to scheduling.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field

import numpy as np


@dataclass
class FaultCounts:
    """Datagrams received, dropped, duplicated and forwarded (duplicates included)."""

    received: int = 0
    dropped: int = 0
    duplicated: int = 0
    forwarded: int = 0


@dataclass
class UdpFaultProxy(asyncio.DatagramProtocol):
    """Forwards datagrams to `target` with faults; `start()` binds it on 127.0.0.1."""

    target: tuple[str, int]
    loss: float = 0.1
    duplicate: float = 0.1
    jitter_s: float = 0.05
    seed: int = 0
    counts: FaultCounts = field(default_factory=FaultCounts)
    lost: list[bytes] = field(default_factory=list)
    """The datagrams dropped."""

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng(self.seed)
        self._transport: asyncio.DatagramTransport | None = None

    async def start(self) -> tuple[str, int]:
        """Bind to a free loopback port; returns the address senders should use."""
        loop = asyncio.get_running_loop()
        transport, _ = await loop.create_datagram_endpoint(
            lambda: self, local_addr=("127.0.0.1", 0)
        )
        self._transport = transport
        return transport.get_extra_info("sockname")[:2]

    def close(self) -> None:
        """Stop forwarding (datagrams still delayed are not sent)."""
        if self._transport is not None:
            self._transport.close()
            self._transport = None

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        self.counts.received += 1
        if self._rng.random() < self.loss:
            self.counts.dropped += 1
            self.lost.append(data)
            return
        copies = 2 if self._rng.random() < self.duplicate else 1
        self.counts.duplicated += copies - 1
        loop = asyncio.get_running_loop()
        for _ in range(copies):
            loop.call_later(self._rng.uniform(0.0, self.jitter_s), self._forward, data)

    def _forward(self, data: bytes) -> None:
        if self._transport is not None:
            self._transport.sendto(data, self.target)
            self.counts.forwarded += 1
