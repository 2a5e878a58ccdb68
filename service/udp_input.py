"""`UdpInput`: camera-node datagrams read inside an asyncio loop, with their arrival time.

The arrival time of a datagram is the kernel's receive timestamp (`SO_TIMESTAMPNS`,
wall clock, nanoseconds) where the platform has it (Linux), so time a datagram spends
queued in the socket while the server is busy counts towards its frame's latency;
elsewhere it is the time the datagram is read. Every datagram waiting in the socket is
read per wake-up, up to `MAX_BATCH`, and handed to `handle(data, arrival_s, sender)`,
all inside one `burst()` block when one is given (the server computes the frames those
datagrams complete together);
datagrams longer than `max_bytes` arrive cut to `max_bytes + 1` bytes (camera packets:
`decode` then drops them as too long).
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import struct
import sys
import time
from collections.abc import Callable
from contextlib import AbstractContextManager

from samba.service.packet import MAX_PACKET_BYTES

SO_TIMESTAMPNS = 35
"""Linux socket option (and control message type) of nanosecond receive timestamps."""
RECEIVE_BUFFER_BYTES = 4 * 1024 * 1024
"""Requested socket receive buffer: about 40,000 camera packets of burst."""
MAX_BATCH = 256
"""Most datagrams read per wake-up before the loop runs other work."""

_TIMESPEC = struct.Struct("qq")
Handler = Callable[[bytes, float, str], None]


class UdpInput:
    """A bound UDP socket whose datagrams go to `handle`; see the module docstring.

    `port` 0 picks a free port; `address` tells which after `start`.
    """

    def __init__(
        self,
        host: str,
        port: int,
        handle: Handler,
        max_bytes: int = MAX_PACKET_BYTES,
        burst: Callable[[], AbstractContextManager[None]] = contextlib.nullcontext,
    ) -> None:
        self._handle = handle
        self._burst = burst
        self._buffer_bytes = max_bytes + 1
        self._socket = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
            self._kernel_time = sys.platform.startswith("linux")
            if self._kernel_time:
                self._socket.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
            self._socket.setblocking(False)
            self._socket.bind((host, port))
        except OSError:
            self._socket.close()
            raise
        self._loop: asyncio.AbstractEventLoop | None = None

    @property
    def address(self) -> tuple[str, int]:
        """The (host, port) the socket is bound to."""
        host, port = self._socket.getsockname()[:2]
        return host, port

    def start(self) -> None:
        """Start reading in the running event loop."""
        self._loop = asyncio.get_running_loop()
        self._loop.add_reader(self._socket.fileno(), self._read)

    def close(self) -> None:
        """Stop reading and close the socket."""
        if self._loop is not None:
            self._loop.remove_reader(self._socket.fileno())
            self._loop = None
        self._socket.close()

    def _read(self) -> None:
        with self._burst():
            self._read_waiting()

    def _read_waiting(self) -> None:
        ancillary = socket.CMSG_SPACE(_TIMESPEC.size) if self._kernel_time else 0
        for _ in range(MAX_BATCH):
            try:
                data, cmsgs, _flags, sender = self._socket.recvmsg(MAX_PACKET_BYTES + 1, ancillary)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # an ICMP error of an earlier send; the next read goes on
                continue
            arrival = time.time()
            for level, kind, value in cmsgs:
                if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
                    seconds, nanoseconds = _TIMESPEC.unpack(value[: _TIMESPEC.size])
                    arrival = seconds + nanoseconds * 1e-9
            self._handle(data, arrival, f"{sender[0]}:{sender[1]}")
