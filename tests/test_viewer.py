"""The live viewer: its messages, the WebSocket hub and the page in headless Chromium."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import math
import re
import socket
import time
import tracemalloc
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

import aiohttp
import numpy as np
import pytest
from aiohttp import web

from samba.body.skeleton import JOINT_NAMES, MARKER_NAMES, markers_of
from samba.service.take_recorder import SKELETON_LINES
from samba.service.viewer import (
    CONTENT_SECURITY_POLICY,
    VIEWER_PAGE,
    ViewerHub,
    add_viewer_routes,
    frame_message,
    hello_message,
)
from samba.synthetic.motions import generate
from tests.chromium_page import ChromiumPage, find_chromium

FPS = 30.0
Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]
MISSING_MARKER = MARKER_NAMES.index("r_wrist")


@contextlib.asynccontextmanager
async def serve(
    hub: ViewerHub,
    sessions: Callable[[], list[str] | None] = lambda: None,
    token: str | None = None,
) -> AsyncIterator[str]:
    """An app with the viewer routes on 127.0.0.1, a free port; yields its base URL.

    `GET /api/sessions` lists the names `sessions()` returns at the time, or answers 404
    when it returns None, as when the control API is absent. With a `token`, every request
    must carry it, as the control API's token middleware demands (bearer or query).
    """

    async def list_sessions(_request: web.Request) -> web.Response:
        names = sessions()
        if names is None:
            raise web.HTTPNotFound()
        return web.json_response({"sessions": [{"name": name} for name in names]})

    @web.middleware
    async def check_token(request: web.Request, handler: Handler) -> web.StreamResponse:
        given = request.headers.get("Authorization", "").removeprefix("Bearer ")
        if (given or request.query.get("token")) != token:
            raise web.HTTPUnauthorized()
        return await handler(request)

    app = web.Application(middlewares=[check_token] if token else [])
    add_viewer_routes(app, hub)
    app.router.add_get("/api/sessions", list_sessions)
    runner = web.AppRunner(app, shutdown_timeout=2.0)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", 0)
    await site.start()
    try:
        yield f"http://127.0.0.1:{runner.addresses[0][1]}"
    finally:
        await runner.cleanup()


async def eventually(condition: Callable[[], bool], timeout_s: float = 2.0) -> None:
    """Wait until `condition()` holds, polling every 10 ms; fail after `timeout_s` seconds."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "condition not met in time"
        await asyncio.sleep(0.01)


def run(scenario: Callable[[], Awaitable[None]]) -> None:
    """Run an async test scenario on a fresh event loop."""
    asyncio.run(scenario())


class WalkStream:
    """Publishes a synthetic walk to one session at `FPS`, looping; the r_wrist marker is
    missing on every other third of a second. `playing` pauses and resumes it."""

    def __init__(self, hub: ViewerHub, session: str) -> None:
        self.hub = hub
        self.session = session
        self.poses = generate("walk", seconds=4.0, fps=FPS, seed=7).poses
        self.playing = asyncio.Event()
        self.playing.set()

    def message(self, i: int) -> dict[str, Any]:
        """The frame message of frame `i`."""
        pose = self.poses[i % len(self.poses)]
        markers = markers_of(pose).astype(np.float64)
        if (i // 10) % 2:
            markers[MISSING_MARKER] = np.nan
        return frame_message(
            self.session,
            i,
            i / FPS,
            pose,
            markers,
            latency_ms=9.0 + 3.0 * math.sin(i / 7.0),
            confident=i % 45 < 30,
            predicted=i % 90 >= 80,
        )

    async def run(self) -> None:
        """Publish frames until cancelled."""
        for i in itertools.count():
            await self.playing.wait()
            self.hub.publish(self.session, self.message(i))
            await asyncio.sleep(1.0 / FPS)


# ---- messages ------------------------------------------------------------------------


def test_frame_message_rounds_to_a_tenth_of_a_millimetre_and_nulls_missing_markers() -> None:
    pose = generate("walk", seconds=1.0, fps=FPS, seed=1).poses[5].astype(np.float64)
    pose[0] = [0.123456, 1.00004, -0.00001]
    markers = markers_of(pose).copy()
    markers[2] = [np.nan, 0.5, 0.5]
    message = frame_message("s1", 42, 1.25, pose, markers, 12.3456, True, False)
    assert message["type"] == "frame"
    assert (message["session"], message["frame"], message["time"]) == ("s1", 42, 1.25)
    assert len(message["joints"]) == len(JOINT_NAMES)
    assert all(len(joint) == 3 for joint in message["joints"])
    assert message["joints"][0] == [0.1235, 1.0, 0.0]
    np.testing.assert_allclose(message["joints"], pose, atol=0.5e-4)
    assert len(message["markers"]) == len(MARKER_NAMES)
    assert message["markers"][2] is None
    assert message["markers"][0] == message["joints"][1]  # l_shoulder marker on its joint
    assert (message["latency_ms"], message["confident"], message["predicted"]) == (
        12.35,
        True,
        False,
    )
    text = json.dumps(message, allow_nan=False)
    assert "-0.0," not in text
    assert "0.123456" not in text


def test_frame_message_rejects_bad_shapes_and_values() -> None:
    pose = np.zeros((13, 3))
    markers = np.zeros((8, 3))
    with pytest.raises(ValueError, match="pose"):
        frame_message("s", 0, 0.0, pose[:12], markers, 1.0, True, False)
    with pytest.raises(ValueError, match="pose"):
        frame_message("s", 0, 0.0, np.full((13, 3), np.nan), markers, 1.0, True, False)
    with pytest.raises(ValueError, match="markers"):
        frame_message("s", 0, 0.0, pose, markers[:7], 1.0, True, False)
    with pytest.raises(ValueError, match="latency"):
        frame_message("s", 0, 0.0, pose, markers, math.inf, True, False)


def test_hello_message_describes_the_skeleton() -> None:
    hello = hello_message("studio")
    assert hello["type"] == "hello"
    assert hello["session"] == "studio"
    assert hello["joint_names"] == list(JOINT_NAMES)
    assert hello["marker_names"] == list(MARKER_NAMES)
    assert [hello["joint_names"][j] for j in hello["marker_joints"]] == list(MARKER_NAMES)
    assert hello["lines"] == [list(pair) for pair in SKELETON_LINES]
    json.dumps(hello, allow_nan=False)


# ---- the page ------------------------------------------------------------------------


def test_page_works_offline() -> None:
    html = VIEWER_PAGE.read_text(encoding="utf-8")
    assert not re.search(r"https?://", html, re.IGNORECASE)
    assert not re.search(r"url\(|@import|<script[^>]+src", html, re.IGNORECASE)
    links = re.findall(r"\b(?:src|href)\s*=\s*[\"']([^\"']*)", html, re.IGNORECASE)
    assert all(link.startswith("data:") for link in links), links


def test_routes_serve_the_page() -> None:
    async def scenario() -> None:
        async with serve(ViewerHub()) as base, aiohttp.ClientSession() as http:
            for path in ("/", "/viewer/studio%20A"):
                async with http.get(base + path) as response:
                    assert response.status == 200
                    assert response.content_type == "text/html"
                    assert response.headers["Content-Security-Policy"] == CONTENT_SECURITY_POLICY
                    assert await response.read() == VIEWER_PAGE.read_bytes()

    run(scenario)


# ---- the hub -------------------------------------------------------------------------


def test_clients_get_hello_then_the_newest_frame_of_their_session() -> None:
    async def scenario() -> None:
        hub = ViewerHub()
        async with (
            serve(hub) as base,
            aiohttp.ClientSession() as http,
            http.ws_connect(f"{base}/ws/s") as a,
            http.ws_connect(f"{base}/ws/s") as b,
            http.ws_connect(f"{base}/ws/other") as c,
        ):
            for ws, session in ((a, "s"), (b, "s"), (c, "other")):
                assert await ws.receive_json(timeout=2) == hello_message(session)
            assert (hub.clients("s"), hub.clients("other"), hub.clients("none")) == (2, 1, 0)
            for i in range(50):  # no await in between: the senders only see the last
                hub.publish("s", {"type": "frame", "frame": i})
            for ws in (a, b):
                assert (await ws.receive_json(timeout=2))["frame"] == 49
                with pytest.raises(TimeoutError):
                    await ws.receive(timeout=0.2)
            with pytest.raises(TimeoutError):
                await c.receive(timeout=0.05)
            await a.close()
            await eventually(lambda: hub.clients("s") == 1)
            hub.publish("s", {"type": "frame", "frame": 50})
            assert (await b.receive_json(timeout=2))["frame"] == 50

    run(scenario)


def test_publish_from_another_thread_and_bad_messages() -> None:
    async def scenario() -> None:
        hub = ViewerHub()
        hub.publish("s", {"type": "frame"})  # nobody has ever connected: nothing happens
        async with (
            serve(hub) as base,
            aiohttp.ClientSession() as http,
            http.ws_connect(f"{base}/ws/s") as ws,
        ):
            await ws.receive_json(timeout=2)
            hub.publish("s", {"type": "frame", "bad": math.nan})  # not JSON: logged, dropped
            hub.publish("s", {"type": "frame", "bad": object()})
            await asyncio.to_thread(hub.publish, "s", {"type": "frame", "frame": 7})
            assert await ws.receive_json(timeout=2) == {"type": "frame", "frame": 7}

    run(scenario)


def test_a_client_that_never_reads_does_not_hold_up_publish() -> None:
    async def scenario() -> None:
        hub = ViewerHub(close_timeout_s=0.5)
        async with serve(hub) as base:
            port = int(base.rsplit(":", 1)[1])
            loop = asyncio.get_running_loop()
            with socket.socket() as stalled:
                stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
                stalled.setblocking(False)
                await loop.sock_connect(stalled, ("127.0.0.1", port))
                await loop.sock_sendall(
                    stalled,
                    b"GET /ws/slow HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
                    b"Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
                    b"Sec-WebSocket-Version: 13\r\n\r\n",
                )
                await eventually(lambda: hub.clients("slow") == 1)
                pad = "x" * 100_000  # 1000 frames of 100 kB: 100 MB if they were queued
                tracemalloc.start()
                before = tracemalloc.get_traced_memory()[0]
                longest = total = 0.0
                for i in range(1000):
                    start = time.perf_counter()
                    hub.publish("slow", {"type": "frame", "frame": i, "pad": pad})
                    took = time.perf_counter() - start
                    longest, total = max(longest, took), total + took
                    await asyncio.sleep(0)  # let the sender run and stall
                grown = tracemalloc.get_traced_memory()[1] - before
                tracemalloc.stop()
                assert total < 1.0, f"1000 publishes took {total:.3f} s"
                assert longest < 0.05, f"one publish took {longest:.3f} s"
                assert grown < 10_000_000, f"memory grew by {grown} bytes"
                start = time.perf_counter()
                await hub.close()  # the stalled client never answers the close
                assert time.perf_counter() - start < 1.5
                await eventually(lambda: hub.clients("slow") == 0)

    run(scenario)


def test_close_says_going_away_to_every_client() -> None:
    async def scenario() -> None:
        hub = ViewerHub()
        async with (
            serve(hub) as base,
            aiohttp.ClientSession() as http,
            http.ws_connect(f"{base}/ws/a") as a,
            http.ws_connect(f"{base}/ws/b") as b,
        ):
            for ws in (a, b):
                await ws.receive_json(timeout=2)
            await hub.close()
            for ws in (a, b):
                message = await ws.receive(timeout=2)
                assert message.type is aiohttp.WSMsgType.CLOSE
                assert message.data == aiohttp.WSCloseCode.GOING_AWAY
            await eventually(lambda: hub.clients("a") + hub.clients("b") == 0)
            hub.publish("a", {"type": "frame"})  # no clients left: nothing happens

    run(scenario)


def test_app_shutdown_closes_the_viewer_sockets() -> None:
    async def scenario() -> None:
        hub = ViewerHub()
        async with aiohttp.ClientSession() as http:
            async with serve(hub) as base:
                ws = await http.ws_connect(f"{base}/ws/s")
                await ws.receive_json(timeout=2)
            message = await ws.receive(timeout=2)  # the app has shut down by now
            assert message.type is aiohttp.WSMsgType.CLOSE
            assert message.data == aiohttp.WSCloseCode.GOING_AWAY
            assert hub.clients("s") == 0

    run(scenario)


# ---- the page in headless Chromium ---------------------------------------------------


def _changed_pixels(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> int:
    """How many pixels inside `mask` differ by more than 24 levels in some channel."""
    differs = (np.abs(a.astype(np.int16) - b.astype(np.int16)) > 24).any(axis=2)
    return int((differs & mask).sum())


@pytest.mark.slow
def test_page_in_chromium_shows_the_skeleton_moving() -> None:
    find_chromium()
    text = "document.getElementById({!r}).textContent".format

    async def scenario() -> None:
        hub = ViewerHub()
        stream = WalkStream(hub, "test")
        listing: dict[str, list[str] | None] = {"names": ["alpha", "test"]}
        async with (
            serve(hub, lambda: listing["names"], token="s3cret") as base,
            ChromiumPage() as page,
        ):
            publisher = asyncio.create_task(stream.run())
            try:
                await page.goto(f"{base}/viewer/test?token=s3cret")
                await page.wait_for("document.body.dataset.state === 'connected'")
                assert hub.clients("test") == 1
                assert await page.evaluate(text("session")) == "test"
                await page.wait_for(f"parseInt({text('fps')}) > 0")
                await page.wait_for(f"{text('missing')}.includes('r_wrist')", timeout_s=3)
                assert "ms p50" in await page.evaluate(text("latency"))

                hud = await page.evaluate(
                    "(() => { const r = document.getElementById('hud')"
                    ".getBoundingClientRect(); return [r.left, r.top, r.right, r.bottom]; })()"
                )
                scene = np.ones((page.height, page.width), dtype=bool)  # all but the HUD
                scene[: math.ceil(hud[3]) + 1, : math.ceil(hud[2]) + 1] = False
                first = await page.screenshot()
                assert first.shape == (page.height, page.width, 3)
                await asyncio.sleep(0.3)
                second = await page.screenshot()
                assert _changed_pixels(first, second, scene) > 300

                stream.playing.clear()
                await page.wait_for(f"{text('state')} === 'connected, no frames'", 3)
                paused = await page.screenshot()
                await asyncio.sleep(0.3)
                assert np.array_equal(paused, await page.screenshot())
                stream.playing.set()
                await page.wait_for(f"{text('state')} === 'connected'")

                # "/" lists the sessions of the control API and follows the chosen one
                await page.goto(f"{base}/?token=s3cret")
                await page.wait_for("document.querySelector('#session select')")
                await eventually(lambda: hub.clients("alpha") == 1)
                await page.evaluate(
                    "(() => { const s = document.querySelector('#session select');"
                    " s.value = 'test'; s.dispatchEvent(new Event('change')); })()"
                )
                await page.wait_for(f"parseInt({text('frame')}) > 0")
                await eventually(lambda: hub.clients("alpha") == 0 and hub.clients("test") == 1)
                assert page.errors == []

                # without the control API "/" shows the default session; Chromium logs the 404
                listing["names"] = None
                await page.goto(f"{base}/?token=s3cret")
                await eventually(lambda: hub.clients("default") == 1)
                assert await page.evaluate(text("session")) == "default"
                assert len(page.errors) == 1
                assert "404" in page.errors[0] and "/api/sessions" in page.errors[0]
            finally:
                publisher.cancel()
                await asyncio.gather(publisher, return_exceptions=True)

    start = time.monotonic()
    run(scenario)
    assert time.monotonic() - start < 20.0
