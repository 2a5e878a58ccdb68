"""`CaptureServer`: the capture sessions of one server and the routing of datagrams to them.

No sockets here (`samba.service.udp_input` reads them, `samba.service.serve` runs everything):
`receive` takes one datagram with the wall-clock time it arrived, decodes it
(`samba.service.packet.decode`; with node keys, checked with the key listed for the
packet's session and camera) and hands the packet to the session its session id names
— or, when the id is empty, to the only session — whose replay guard admits it or not
(`samba.service.replay_guard`). A datagram that is dropped is counted by reason: a
`PacketError` reason, "unknown session", "wrong input" (marker packets to a poses
session, or the other way round), or the replay guard's ("duplicate", "replayed", "off
clock"). Nothing a sender does raises out of `receive`.

The sessions' frames are computed by `pipelines` (`samba.service.pipeline_workers`; by
default `InlinePipelines`, in the caller's thread); whatever runs them hands each
result to `deliver`, which passes it to its session.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

from samba.service.errors import PacketError, ServiceError
from samba.service.node_keys import NodeKeys
from samba.service.packet import decode
from samba.service.pipeline_workers import FrameDone, InlinePipelines
from samba.service.replay_guard import DEFAULT_MAX_SKEW_S
from samba.service.session import CaptureSession, Pipelines
from samba.service.session_config import SessionConfig
from samba.service.viewer import ViewerHub

UNKNOWN_SESSION = "unknown session"
"""Drop reason of a valid packet whose session id names no session."""
WRONG_INPUT = "wrong input"
"""Drop reason of a marker packet sent to a poses session, or the other way round."""


class CaptureServer:
    """The sessions of a server; see the module docstring.

    `takes_dir`: folder of recorded takes (a sub-folder per session). `keys`: the keys
    camera nodes sign packets with, by session and camera (None: packets must be
    unsigned). `viewer`: where sessions send frames for the live viewer. `pipelines`:
    where the frames are computed, created with `deliver` as its callback (None:
    inline). `max_skew_s`: how far (s) a packet's timestamp may be from its arrival.
    """

    def __init__(
        self,
        configs: Iterable[SessionConfig],
        takes_dir: str | Path,
        keys: NodeKeys | None = None,
        viewer: ViewerHub | None = None,
        pipelines: Pipelines | None = None,
        max_skew_s: float = DEFAULT_MAX_SKEW_S,
    ) -> None:
        self.takes_dir = Path(takes_dir)
        self.keys = keys
        self.max_skew_s = max_skew_s
        self._viewer = viewer
        self.pipelines = InlinePipelines(self.deliver) if pipelines is None else pipelines
        self.sessions: dict[str, CaptureSession] = {}
        self.datagrams = 0
        self.drops: Counter[str] = Counter()
        try:
            for config in configs:
                self.add_session(config)
        except BaseException:
            self.close()
            raise

    def add_session(self, config: SessionConfig) -> CaptureSession:
        """Open a session and start routing packets to it (`open_session`, `attach`)."""
        return self.attach(self.open_session(config))

    def open_session(self, config: SessionConfig) -> CaptureSession:
        """A new session of this server, not yet receiving packets. It only reads files,
        so a caller may run it in a worker thread (loading a large database takes a
        while). `ServiceError` if the name is taken, or as `CaptureSession` raises."""
        self._check_free(config.name)
        return CaptureSession(
            config, self.takes_dir / config.name, self.pipelines, self._viewer, self.max_skew_s
        )

    def attach(self, session: CaptureSession) -> CaptureSession:
        """Start routing packets to an opened session; `ServiceError` (and the session is
        closed) if a session of its name appeared meanwhile."""
        try:
            self._check_free(session.name)
        except ServiceError:
            session.close()
            raise
        self.sessions[session.name] = session
        return session

    def _check_free(self, name: str) -> None:
        if name in self.sessions:
            raise ServiceError(name, "a session of this name is already running")

    def remove_session(self, name: str) -> None:
        """Stop a session (closing its take); `ServiceError` if there is none."""
        self.session(name).close()
        del self.sessions[name]

    def session(self, name: str) -> CaptureSession:
        """The session called `name`; `ServiceError` if there is none."""
        try:
            return self.sessions[name]
        except KeyError:
            raise ServiceError(name, "no such session") from None

    def receive(self, data: bytes, arrival: float, sender: str = "packet") -> None:
        """Handle one datagram from `sender` that arrived at `arrival` (s, wall clock)."""
        self.datagrams += 1
        key_for = None if self.keys is None else self._key_for
        try:
            packet = decode(data, source=sender, key_for=key_for)
        except PacketError as exc:
            self.drops[exc.reason] += 1
            return
        session = self._route(packet.session)
        if session is None:
            self.drops[UNKNOWN_SESSION] += 1
            return
        if not session.accepts(packet):
            self.drops[WRONG_INPUT] += 1
            return
        verdict = session.on_packet(packet, arrival)
        if not verdict.accepted:
            self.drops[verdict.value] += 1

    def _route(self, session_id: str) -> CaptureSession | None:
        """The session a packet's session id names; an empty id names the only session."""
        session = self.sessions.get(session_id)
        if session is None and session_id == "" and len(self.sessions) == 1:
            session = next(iter(self.sessions.values()))
        return session

    def _key_for(self, session_id: str, camera: int) -> bytes | None:
        """The key that may speak for `camera` of the session a packet's id routes to."""
        assert self.keys is not None
        session = self._route(session_id)
        return None if session is None else self.keys.key_for(session.name, camera)

    def together(self) -> AbstractContextManager[None]:
        """A block whose completed frames are computed together at its end (frames of
        sessions that search one database in one batch, `pipelines.together`); wrap the
        datagrams that arrived at once in it."""
        return self.pipelines.together()

    def tick(self, now: float) -> None:
        """Submit every session's frames whose wait ran out at `now` (s), together."""
        with self.together():
            for session in list(self.sessions.values()):
                session.on_timer(now)

    def deliver(self, done: FrameDone) -> None:
        """Pass a computed (or failed) frame to its session; a session that has been
        removed meanwhile is ignored."""
        session = self.sessions.get(done.session)
        if session is None:
            return
        if done.output is not None:
            session.complete(done.sequence, done.output)
        else:
            session.fail(done.sequence, done.error or "unknown error")

    def deadline(self) -> float | None:
        """The earliest time (s) `tick` has work, None if no frame waits."""
        deadlines = [d for s in self.sessions.values() if (d := s.deadline()) is not None]
        return min(deadlines, default=None)

    def metrics(self) -> dict[str, Any]:
        """A JSON-ready snapshot: datagrams in, drops by reason, and per-session metrics."""
        return {
            "datagrams": self.datagrams,
            "workers": self.pipelines.worker_pids(),
            "dropped": {"total": self.drops.total(), **dict(sorted(self.drops.items()))},
            "sessions": {name: s.metrics() for name, s in self.sessions.items()},
        }

    def close(self) -> None:
        """Close every session (recording takes are finished, not lost) and stop the
        pipelines' workers."""
        for session in self.sessions.values():
            session.close()
        self.pipelines.shutdown()
