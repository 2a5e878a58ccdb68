"""The live viewer: a self-contained web page drawing each session's skeleton from a WebSocket.

Routes (`add_viewer_routes`): `GET /` and `GET /viewer/{session}` serve `VIEWER_PAGE`, one
offline HTML file (inline CSS and JS, no external resources); `GET /ws/{session}` is the
WebSocket the page reads. `ViewerHub` fans the capture loop's frames out to the sockets.

Messages are JSON text, coordinates in our world frame (right-handed, +Y up, meters):

* `hello` (`hello_message`), sent first on every connection: the joint and marker names,
  which joint each marker sits on and the joint pairs drawn as lines.
* `frame` (`frame_message`), one per captured frame: 13 joints, 8 markers (null when
  missing), the server latency and the reconstruction flags.

A slow client only ever gets the newest frame: each client holds at most one unsent
message, which a newer frame replaces, so publishing never waits on a socket.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from aiohttp import WSCloseCode, web

from samba.body import JOINT_NAMES, MARKER_JOINTS, MARKER_NAMES, N_JOINTS, N_MARKERS
from samba.service.take_recorder import SKELETON_LINES

VIEWER_PAGE: Path = Path(__file__).with_name("viewer_page") / "index.html"
"""The viewer's single HTML file (shipped as package data of `service`)."""

CONTENT_SECURITY_POLICY = (
    "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
    "connect-src 'self'; img-src data:; base-uri 'none'; form-action 'none'; "
    "frame-ancestors 'none'"
)
"""Sent with the page: the browser refuses anything but inline code and same-origin
sockets, and no other page may frame it."""

_WRITER_LIMIT = 64 * 1024
"""Bytes a client socket may buffer in the server before a send waits for it to drain."""

_log = logging.getLogger(__name__)


def frame_message(
    session: str,
    frame: int,
    time_s: float,
    pose: np.ndarray,
    markers: np.ndarray,
    latency_ms: float,
    confident: bool,
    predicted: bool,
) -> dict[str, Any]:
    """The JSON-ready `frame` message of one captured frame of `session`.

    `pose` is (13, 3) finite meters, `markers` (8, 3) meters with NaN rows where a marker is
    missing, `time_s` the frame's capture time in seconds and `latency_ms` the server's
    latency from capture to publication in milliseconds. Joints and markers are rounded to
    0.1 mm; a missing marker (any coordinate not finite) becomes null.
    Raises ValueError on a wrong shape or a non-finite pose, time or latency.
    """
    pose = np.asarray(pose, dtype=np.float64)
    markers = np.asarray(markers, dtype=np.float64)
    if pose.shape != (N_JOINTS, 3) or not np.isfinite(pose).all():
        raise ValueError(f"pose must be finite ({N_JOINTS}, 3) meters, got shape {pose.shape}")
    if markers.shape != (N_MARKERS, 3):
        raise ValueError(f"markers must be ({N_MARKERS}, 3) meters, got shape {markers.shape}")
    if not (np.isfinite(time_s) and np.isfinite(latency_ms)):
        raise ValueError(f"time {time_s} s and latency {latency_ms} ms must be finite")
    return {
        "type": "frame",
        "session": session,
        "frame": int(frame),
        "time": round(float(time_s), 6),
        "joints": [_rounded(joint) for joint in pose],
        "markers": [_rounded(m) if np.isfinite(m).all() else None for m in markers],
        "latency_ms": round(float(latency_ms), 2),
        "confident": bool(confident),
        "predicted": bool(predicted),
    }


def hello_message(session: str) -> dict[str, Any]:
    """The JSON-ready `hello` message a client of `session` gets first: the skeleton layout.

    `joint_names` (13) and `marker_names` (8) in message order, `marker_joints` the joint
    index of each marker and `lines` the joint index pairs drawn as lines (`SKELETON_LINES`).
    """
    return {
        "type": "hello",
        "session": session,
        "joint_names": list(JOINT_NAMES),
        "marker_names": list(MARKER_NAMES),
        "marker_joints": list(MARKER_JOINTS),
        "lines": [list(pair) for pair in SKELETON_LINES],
    }


def _rounded(point: np.ndarray) -> list[float]:
    # round() is exact to 4 decimals (0.1 mm); adding 0.0 turns -0.0 into 0.0
    return [round(float(v), 4) + 0.0 for v in point]


@dataclass(eq=False)
class _Client:
    """One WebSocket client: its newest unsent message and the task sending it."""

    ws: web.WebSocketResponse
    transport: asyncio.Transport | None
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    pending: str | None = None
    closing: bool = False
    sender: asyncio.Task[None] | None = None


class ViewerHub:
    """Fans frames out to the WebSocket clients of each session.

    `publish` may be called from the event loop serving the sockets or from any other
    thread; it never blocks and never raises. Each client has one sender task and a slot
    for one unsent message (the newest wins), so a slow client skips frames instead of
    queueing them. `heartbeat_s` is the interval of WebSocket pings in seconds (a client
    that does not answer one is dropped); `close_timeout_s` bounds, in seconds, how long
    closing one socket may take.
    """

    def __init__(self, heartbeat_s: float = 10.0, close_timeout_s: float = 2.0) -> None:
        self._heartbeat_s = heartbeat_s
        self._close_timeout_s = close_timeout_s
        self._sessions: dict[str, set[_Client]] = {}
        self._loop: asyncio.AbstractEventLoop | None = None

    def publish(self, session: str, message: dict[str, Any]) -> None:
        """Send `message` (JSON-ready, e.g. `frame_message`) to every client of `session`.

        Serialises once; replaces a client's unsent message rather than queueing behind
        it. A message that is not JSON (NaN, unknown types) is logged and dropped.
        """
        loop = self._loop
        if loop is None or not self._sessions.get(session):
            return
        try:
            text = json.dumps(message, separators=(",", ":"), allow_nan=False)
        except (TypeError, ValueError):
            _log.exception("viewer message for session %r is not JSON; dropped", session)
            return
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is loop:
            self._deliver(session, text)
            return
        with contextlib.suppress(RuntimeError):  # the loop has closed: nobody is listening
            loop.call_soon_threadsafe(self._deliver, session, text)

    def clients(self, session: str) -> int:
        """How many WebSocket clients `session` has now."""
        return len(self._sessions.get(session, ()))

    async def handle_websocket(self, request: web.Request) -> web.WebSocketResponse:
        """`GET /ws/{session}`: stream `hello_message` then the session's frames until the
        client leaves or the hub closes."""
        session = request.match_info["session"]
        ws = web.WebSocketResponse(
            heartbeat=self._heartbeat_s,
            timeout=self._close_timeout_s,
            writer_limit=_WRITER_LIMIT,
        )
        await ws.prepare(request)
        self._loop = asyncio.get_running_loop()
        client = _Client(ws, request.transport)
        self._sessions.setdefault(session, set()).add(client)
        hello = json.dumps(hello_message(session), separators=(",", ":"))
        client.sender = asyncio.create_task(self._send(client, hello))
        try:
            async for _ in ws:  # the page sends nothing; reading answers pings and the close
                pass
        finally:
            clients = self._sessions.get(session, set())
            clients.discard(client)
            if not clients:
                self._sessions.pop(session, None)
            client.sender.cancel()
            await asyncio.gather(client.sender, return_exceptions=True)
            _abort_if_stalled(client.transport)
        return ws

    async def close(self) -> None:
        """Close every client socket with 1001 (going away), e.g. at server shutdown; a
        client that does not take its data or answer within `close_timeout_s` is cut off."""
        clients = [client for clients in self._sessions.values() for client in clients]
        await asyncio.gather(*(self._close_client(client) for client in clients))

    def _deliver(self, session: str, text: str) -> None:
        for client in self._sessions.get(session, ()):
            client.pending = text
            client.wake.set()

    async def _send(self, client: _Client, hello: str) -> None:
        try:
            await client.ws.send_str(hello)
            while not client.closing:
                await client.wake.wait()
                client.wake.clear()
                text, client.pending = client.pending, None
                if text is not None and not client.closing:
                    await client.ws.send_str(text)
        except ConnectionError:  # the client left; its handler's read loop ends as well
            pass

    async def _close_client(self, client: _Client) -> None:
        # The sender may wait on a stalled socket; it is not cancelled because aiohttp's
        # drain waiters share one future, so cancelling it would break the close below.
        client.closing = True
        client.wake.set()
        assert client.sender is not None
        sent, _ = await asyncio.wait({client.sender}, timeout=self._close_timeout_s)
        if sent:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(
                    client.ws.close(code=WSCloseCode.GOING_AWAY, message=b"server shutdown"),
                    self._close_timeout_s,
                )
            _abort_if_stalled(client.transport)
        elif client.transport is not None:
            client.transport.abort()


def _abort_if_stalled(transport: asyncio.Transport | None) -> None:
    """Drop a connection whose client left data unread: closing it would wait for ever."""
    if transport is not None and transport.get_write_buffer_size():
        transport.abort()


async def _page(request: web.Request) -> web.FileResponse:
    """`GET /` and `GET /viewer/{session}`: the viewer page (it reads the session from its URL)."""
    return web.FileResponse(
        VIEWER_PAGE,
        headers={
            "Content-Type": "text/html; charset=utf-8",
            "Cache-Control": "no-cache",
            "Content-Security-Policy": CONTENT_SECURITY_POLICY,
            "Referrer-Policy": "no-referrer",  # its URL carries the API token
            "X-Content-Type-Options": "nosniff",
        },
    )


def add_viewer_routes(app: web.Application, hub: ViewerHub) -> None:
    """Add the viewer to `app`: `GET /`, `GET /viewer/{session}` (the page) and
    `GET /ws/{session}` (`hub.handle_websocket`); `hub.close()` runs at app shutdown.

    The page at `/` asks `GET /api/sessions` (the control API's `{"sessions": [{"name":
    ...}, ...]}`) which session to show and falls back to "default" without it.
    """

    async def close_hub(_app: web.Application) -> None:
        await hub.close()

    app.router.add_get("/", _page)
    app.router.add_get("/viewer/{session}", _page)
    app.router.add_get("/ws/{session}", hub.handle_websocket)
    app.on_shutdown.append(close_hub)
