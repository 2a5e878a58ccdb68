"""`LiveServer`: `samba serve` as one asyncio object — sessions, UDP input, timer, HTTP.

The camera datagrams are read and assembled into frames in the event loop
(`samba.service.udp_input`, `samba.service.server`); a single timer resolves frames whose wait for
late cameras ran out. The frames are computed in `workers` worker processes
(`samba.service.pipeline_workers.WorkerPipelines`), or in the event loop when `workers` is 0;
results come back to the loop, which records them and feeds the viewer.
The HTTP side (aiohttp) serves the control API (`samba.service.control_api`) and the live
viewer (`samba.service.viewer`) on one port. The API is bound to 127.0.0.1 by default;
binding it to any other address requires a token. Likewise the UDP input: binding it
beyond loopback requires the nodes' keys (`samba.service.node_keys`), since an
unsigned packet could come from anyone on the network.
"""

from __future__ import annotations

import asyncio
import contextlib
import ipaddress
import os
import signal
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from types import TracebackType

from aiohttp import web

from samba.cameras import read_calibration
from samba.service.control_api import add_control_routes, token_middleware
from samba.service.errors import ServiceError
from samba.service.node_keys import NodeKeys
from samba.service.pipeline_workers import FrameDone, WorkerPipelines
from samba.service.replay_guard import DEFAULT_MAX_SKEW_S
from samba.service.server import CaptureServer
from samba.service.session import CaptureSession
from samba.service.session_config import SessionConfig
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


def is_loopback(host: str) -> bool:
    """True for localhost and loopback addresses (127.0.0.0/8, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _bind_error(kind: str, address: tuple[str, int], purpose: str, exc: OSError) -> ServiceError:
    """The error for a `kind` ("udp", "http") socket that cannot be bound to `address`
    (host, port): names the address, what it was for, and the system's reason."""
    reason = os.strerror(exc.errno) if exc.errno else str(exc)
    return ServiceError(f"{kind} {address[0]}:{address[1]}", f"cannot {purpose} there: {reason}")


class LiveServer:
    """A capture server with its sockets; use `async with LiveServer(...) as server:`.

    `udp` and `http` are (host, port) to bind (port 0: any free port; `http=None`: no
    HTTP side). `token` protects the HTTP side and is required unless `http` is a
    loopback address; `keys` are the camera nodes' keys, required unless `udp` is a
    loopback address; `max_skew_s` how far (s) a packet's timestamp may be from the
    server's clock; `workers` the number of worker processes computing frames (0: in the
    event loop). `ServiceError` for a missing token or keys; session files are opened
    by `start`.
    """

    def __init__(
        self,
        configs: Iterable[SessionConfig],
        takes_dir: str | Path,
        *,
        udp: tuple[str, int] = ("127.0.0.1", UDP_PORT),
        http: tuple[str, int] | None = ("127.0.0.1", HTTP_PORT),
        token: str | None = None,
        keys: NodeKeys | None = None,
        max_skew_s: float = DEFAULT_MAX_SKEW_S,
        workers: int = 0,
    ) -> None:
        if http is not None and token is None and not is_loopback(http[0]):
            raise ServiceError(
                f"{http[0]}:{http[1]}",
                "the control API is bound beyond this machine: give a token (--token or "
                "$SAMBA_TOKEN), or bind it to 127.0.0.1",
            )
        if keys is None and not is_loopback(udp[0]):
            raise ServiceError(
                f"udp {udp[0]}:{udp[1]}",
                "camera packets are received beyond this machine: give the nodes' keys "
                "(--keys FILE), or bind --udp to 127.0.0.1",
            )
        self._configs = list(configs)
        self._takes_dir = Path(takes_dir)
        self._udp_bind = udp
        self._http_bind = http
        self._token = token
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
        middlewares = [token_middleware(self._token)] if self._token else []
        app = web.Application(middlewares=middlewares)
        add_viewer_routes(app, self.hub)
        assert self.server is not None
        add_control_routes(app, self.server)
        self._runner = web.AppRunner(app, access_log=None)
        await self._runner.setup()
        site = web.TCPSite(self._runner, host, port)
        try:
            await site.start()
        except OSError as exc:
            raise _bind_error("http", (host, port), "serve the viewer and API", exc) from exc
        bound = self._runner.addresses[0]
        self.http_address = (bound[0], bound[1])

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
