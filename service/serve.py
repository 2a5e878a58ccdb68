"""`LiveServer`: `samba serve` as one asyncio object — sessions, UDP input, timer, HTTP.

The camera datagrams are read and assembled into frames in the event loop
(`samba.service.udp_input`, `samba.service.server`); a single timer resolves frames whose wait for
late cameras ran out. The frames are computed in `workers` worker processes
(`samba.service.pipeline_workers.WorkerPipelines`), or in the event loop when `workers` is 0;
results come back to the loop, which records them and feeds the viewer.
The HTTP side (aiohttp) serves the control API (`samba.service.control_api`) and the live
viewer (`samba.service.viewer`) on one port, bound to 127.0.0.1 by default. Every HTTP
request carries the server's token (given, or drawn at start), names this server in
its `Host` header and, when it changes state, comes from the server's own pages
(`samba.service.api_access`); sessions started over the API name only what the
server's `SessionPolicy` allows. Binding the UDP input beyond loopback requires the
nodes' keys (`samba.service.node_keys`), since an unsigned packet could come from anyone
on the network.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import secrets
import signal
import time
import urllib.parse
from collections.abc import Callable, Iterable
from pathlib import Path
from types import TracebackType

from aiohttp import web

from samba.cameras import read_calibration
from samba.service.api_access import (
    MIN_TOKEN_CHARS,
    HostCheck,
    is_loopback,
    json_errors_middleware,
    origin_middleware,
    token_middleware,
)
from samba.service.control_api import MAX_BODY_BYTES, add_control_routes
from samba.service.errors import ServiceError
from samba.service.node_keys import NodeKeys
from samba.service.pipeline_workers import FrameDone, WorkerPipelines
from samba.service.replay_guard import DEFAULT_MAX_SKEW_S
from samba.service.server import CaptureServer
from samba.service.session import CaptureSession
from samba.service.session_config import SessionConfig
from samba.service.session_policy import SessionPolicy
from samba.service.udp_input import UdpInput
from samba.service.viewer import ViewerHub, add_viewer_routes

UDP_PORT = 9870
"""Default UDP port camera nodes send to."""
HTTP_PORT = 8080
"""Default port of the control API and the viewer."""
TIMER_SLACK_S = 0.0005
"""The frame timer fires this long after a deadline, so that a frame is surely due."""
FLUSH_INTERVAL_S = 1.0
"""How often recording takes are flushed to the operating system, seconds."""
CORES = os.cpu_count() or 1
"""Worker processes `samba serve --workers auto` starts when it starts any: one per core."""


def auto_workers(configs: Iterable[SessionConfig]) -> int:
    """Worker processes for `samba serve --workers auto`: none when no session has the
    server find lost labels (`SessionConfig.server_labels`; the frames are computed in
    the event loop, those that arrive together in one batch: four sessions' p99 7.6-10 ms
    against 11.6-16.5 ms in two workers, `bench/bench_service.py`), else one per core
    (the server's labelling costs about 2 ms a frame per session, more than the event
    loop can carry for four). Reads the sessions' calibration files (`InputError`
    naming a bad one)."""
    labelling = (
        config.server_labels(len(read_calibration(config.calibration)))
        for config in configs
        if config.input == "markers" and config.calibration is not None
    )
    return CORES if any(labelling) else 0


def _bind_error(kind: str, address: tuple[str, int], purpose: str, exc: OSError) -> ServiceError:
    """The error for a `kind` ("udp", "http") socket that cannot be bound to `address`
    (host, port): names the address, what it was for, and the system's reason."""
    reason = os.strerror(exc.errno) if exc.errno else str(exc)
    return ServiceError(f"{kind} {address[0]}:{address[1]}", f"cannot {purpose} there: {reason}")


class LiveServer:
    """A capture server with its sockets; use `async with LiveServer(...) as server:`.

    `udp` and `http` are (host, port) to bind (port 0: any free port; `http=None`: no
    HTTP side). `token` protects the HTTP side (None: one is drawn, `token` tells it),
    at least `MIN_TOKEN_CHARS` characters; `allow_hosts` are DNS names the HTTP side is
    reached by besides its address; `policy` what API sessions may name (None: the
    files and VMC receivers of `configs`). `keys` are the camera nodes' keys, required
    unless `udp` is a loopback address; `max_skew_s` how far (s) a packet's timestamp
    may be from the server's clock; `workers` the number of worker processes computing
    frames (0: in the event loop). `ServiceError` for a short token, missing keys or
    more sessions than the policy allows; session files are opened by `start`.
    """

    def __init__(
        self,
        configs: Iterable[SessionConfig],
        takes_dir: str | Path,
        *,
        udp: tuple[str, int] = ("127.0.0.1", UDP_PORT),
        http: tuple[str, int] | None = ("127.0.0.1", HTTP_PORT),
        token: str | None = None,
        allow_hosts: Iterable[str] = (),
        policy: SessionPolicy | None = None,
        keys: NodeKeys | None = None,
        max_skew_s: float = DEFAULT_MAX_SKEW_S,
        workers: int = 0,
    ) -> None:
        if token is not None and len(token) < MIN_TOKEN_CHARS:
            raise ServiceError(
                "--token", f"a token has at least {MIN_TOKEN_CHARS} characters, got {len(token)}"
            )
        self._configs = list(configs)
        self._policy = SessionPolicy.of(self._configs) if policy is None else policy
        if len(self._configs) > self._policy.max_sessions:
            raise ServiceError(
                "--max-sessions",
                f"{len(self._configs)} sessions to start, but the server runs at most "
                f"{self._policy.max_sessions}",
            )
        if keys is None and not is_loopback(udp[0]):
            raise ServiceError(
                f"udp {udp[0]}:{udp[1]}",
                "camera packets are received beyond this machine: give the nodes' keys "
                "(--keys FILE), or bind --udp to 127.0.0.1",
            )
        self._takes_dir = Path(takes_dir)
        self._udp_bind = udp
        self._http_bind = http
        self.token = token or secrets.token_urlsafe(24)
        """The HTTP side's token."""
        self._hosts = None if http is None else HostCheck(http[0], allow_hosts)
        self._keys = keys
        self._max_skew_s = max_skew_s
        self._workers = workers
        self.hub = ViewerHub()
        self.server: CaptureServer | None = None
        self._udp: UdpInput | None = None
        self._runner: web.AppRunner | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._timer_due = float("inf")
        self._flusher: asyncio.Task[None] | None = None
        self.http_address: tuple[str, int] | None = None

    @property
    def workers(self) -> int:
        """The worker processes computing frames (0: the event loop)."""
        return self._workers

    async def start(self) -> None:
        """Open the sessions (in a worker thread) and the sockets, and start serving."""
        loop = asyncio.get_running_loop()

        def deliver(done: FrameDone) -> None:  # called by the workers' reader threads
            with contextlib.suppress(RuntimeError):  # the loop has closed: nobody waits
                loop.call_soon_threadsafe(self._deliver, done)

        pipelines = WorkerPipelines(self._workers, deliver) if self._workers else None
        self.server = await asyncio.to_thread(
            CaptureServer,
            self._configs,
            self._takes_dir,
            self._keys,
            self.hub,
            pipelines,
            self._max_skew_s,
        )
        try:
            try:
                self._udp = UdpInput(*self._udp_bind, self._on_datagram, burst=self.server.together)
            except OSError as exc:
                raise _bind_error("udp", self._udp_bind, "receive camera packets", exc) from exc
            self._udp.start()
            self._flusher = asyncio.create_task(self._flush_takes())
            if self._http_bind is not None:
                await self._start_http(*self._http_bind)
        except BaseException:
            await self.stop()
            raise

    async def _start_http(self, host: str, port: int) -> None:
        assert self.server is not None and self._hosts is not None
        middlewares = [
            json_errors_middleware,
            self._hosts.middleware(),
            origin_middleware,
            token_middleware(self.token),
        ]
        app = web.Application(middlewares=middlewares, client_max_size=MAX_BODY_BYTES)
        add_viewer_routes(app, self.hub)
        add_control_routes(app, self.server, self._policy)
        self._runner = web.AppRunner(app, access_log=None)
        await self._runner.setup()
        site = web.TCPSite(self._runner, host, port)
        try:
            await site.start()
        except OSError as exc:
            raise _bind_error("http", (host, port), "serve the viewer and API", exc) from exc
        bound = self._runner.addresses[0]
        self.http_address = (bound[0], bound[1])
        self._hosts.port = bound[1]

    @property
    def udp_address(self) -> tuple[str, int]:
        """The (host, port) camera nodes send to."""
        if self._udp is None:
            raise RuntimeError("the server is not started")
        return self._udp.address

    @property
    def http_url(self) -> str | None:
        """The base URL of the control API and viewer, None without an HTTP side."""
        if self.http_address is None:
            return None
        return f"http://{self.http_address[0]}:{self.http_address[1]}"

    def viewer_url(self, session: str) -> str | None:
        """The viewer page of `session` with the token in its query (the page passes it
        on), None without an HTTP side."""
        if self.http_url is None:
            return None
        token = urllib.parse.quote(self.token, safe="")
        return f"{self.http_url}/viewer/{urllib.parse.quote(session)}?token={token}"

    async def stop(self) -> None:
        """Stop reading, close the viewer sockets and HTTP side, finish recording takes."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self._flusher is not None:
            self._flusher.cancel()
            self._flusher = None
        if self._udp is not None:
            self._udp.close()
            self._udp = None
        await self.hub.close()
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None
        if self.server is not None:
            self.server.close()

    async def __aenter__(self) -> LiveServer:
        await self.start()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        await self.stop()

    async def _flush_takes(self) -> None:
        while self.server is not None:
            await asyncio.sleep(FLUSH_INTERVAL_S)
            for session in list(self.server.sessions.values()):
                session.flush_take()

    def _deliver(self, done: FrameDone) -> None:
        if self.server is not None:
            self.server.deliver(done)

    def _on_datagram(self, data: bytes, arrival: float, sender: str) -> None:
        assert self.server is not None
        self.server.receive(data, arrival, sender)
        self._schedule()

    def _schedule(self) -> None:
        assert self.server is not None
        deadline = self.server.deadline()
        if deadline is None or deadline >= self._timer_due:
            return
        if self._timer is not None:
            self._timer.cancel()
        delay = max(0.0, deadline + TIMER_SLACK_S - time.time())
        self._timer = asyncio.get_running_loop().call_later(delay, self._on_timer)
        self._timer_due = deadline

    def _on_timer(self) -> None:
        self._timer, self._timer_due = None, float("inf")
        if self.server is not None:
            self.server.tick(time.time())
            self._schedule()


async def serve_until_stopped(
    server: LiveServer,
    record: str | None = None,
    duration: float | None = None,
    started: Callable[[LiveServer, list[CaptureSession]], None] | None = None,
) -> tuple[dict, list]:
    """Run `server` until SIGINT or SIGTERM, or for `duration` seconds. With `record`
    every session records a take from the start (named `record`, or automatically when it
    is ""). `started` is called once the server listens. Returns the server's metrics and
    the takes recorded, once it has stopped and written them."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    async with server:
        assert server.server is not None
        sessions = list(server.server.sessions.values())
        if record is not None:
            for session in sessions:
                session.start_take(record or None)
        if started is not None:
            started(server, sessions)
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), duration)
        takes = [t for s in sessions for t in s.takes()]
        metrics = server.server.metrics()
    return metrics, takes
