"""A headless Chromium page for tests, driven over the Chrome DevTools Protocol (CDP).

Only aiohttp's client WebSocket is used (no playwright or pyppeteer). `ChromiumPage`
starts Debian's `chromium` with a throw-away profile, opens one page, records what the page
reports as errors (console errors and warnings, uncaught exceptions, browser log errors and
warnings) and takes screenshots. `find_chromium` skips the calling test when no Chromium
is installed.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import itertools
import json
import os
import shutil
import signal
import tempfile
from collections import deque
from types import TracebackType
from typing import Any

import aiohttp
import cv2
import numpy as np
import pytest

_LISTENING = "DevTools listening on "
_FLAGS = (
    "--headless=new",
    "--remote-debugging-port=0",
    "--no-sandbox",
    "--disable-gpu",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-extensions",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-breakpad",
    "--disable-dev-shm-usage",
    "--disable-background-timer-throttling",
    "--disable-renderer-backgrounding",
    "--disable-backgrounding-occluded-windows",
    "--hide-scrollbars",
    "--mute-audio",
)


class CdpError(RuntimeError):
    """Chromium answered a DevTools command with an error, or a script threw."""


def find_chromium() -> str:
    """The path of `chromium` or `chromium-browser` on PATH; skips the test when neither is."""
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    pytest.skip("headless browser test: no `chromium` or `chromium-browser` on PATH")


class ChromiumPage:
    """One page of a headless Chromium of its own; use it as an async context manager.

    `width` x `height` is the viewport in CSS pixels (device scale 1, so screenshots have
    that many pixels); `timeout_s` bounds, in seconds, the start, every command and every
    page load; `flags` are passed to Chromium besides its own (e.g.
    `--host-resolver-rules=MAP name 127.0.0.1`). `errors` lists what the page reported as
    an error or warning, one string each, prefixed by where it came from
    ("console.error:", "exception:", "log warning:").
    """

    def __init__(
        self,
        width: int = 960,
        height: int = 600,
        timeout_s: float = 20.0,
        flags: tuple[str, ...] = (),
    ) -> None:
        self.width = width
        self.flags = flags
        self.height = height
        self.timeout_s = timeout_s
        self.errors: list[str] = []
        self._binary = find_chromium()
        self._profile: tempfile.TemporaryDirectory[str] | None = None
        self._process: asyncio.subprocess.Process | None = None
        self._stderr: deque[str] = deque(maxlen=40)
        self._stderr_task: asyncio.Task[None] | None = None
        self._http: aiohttp.ClientSession | None = None
        self._ws: aiohttp.ClientWebSocketResponse | None = None
        self._reader: asyncio.Task[None] | None = None
        self._ids = itertools.count(1)
        self._pending: dict[int, asyncio.Future[dict[str, Any]]] = {}
        self._loaded: asyncio.Future[None] | None = None
        self._session_id: str | None = None

    async def __aenter__(self) -> ChromiumPage:
        try:
            await self.start()
        except BaseException:
            await self.close()
            raise
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.close()

    async def start(self) -> None:
        """Launch Chromium, connect to its DevTools socket and open a blank page."""
        self._profile = tempfile.TemporaryDirectory(
            prefix="samba-chromium-", ignore_cleanup_errors=True
        )
        self._process = await asyncio.create_subprocess_exec(
            self._binary,
            *_FLAGS,
            *self.flags,
            f"--user-data-dir={self._profile.name}",
            f"--window-size={self.width},{self.height}",
            "about:blank",
            stdin=asyncio.subprocess.DEVNULL,
            stdout=asyncio.subprocess.DEVNULL,
            stderr=asyncio.subprocess.PIPE,
            start_new_session=True,  # its own process group, so a kill reaches the renderers
        )
        url = await asyncio.wait_for(self._devtools_url(), self.timeout_s)
        self._stderr_task = asyncio.create_task(self._drain_stderr())
        self._http = aiohttp.ClientSession()
        self._ws = await self._http.ws_connect(url, max_msg_size=0)
        self._reader = asyncio.create_task(self._read())
        target = await self.send("Target.createTarget", {"url": "about:blank"}, page=False)
        attached = await self.send(
            "Target.attachToTarget", {"targetId": target["targetId"], "flatten": True}, page=False
        )
        self._session_id = attached["sessionId"]
        for domain in ("Page", "Runtime", "Log"):
            await self.send(f"{domain}.enable")
        await self.send(
            "Emulation.setDeviceMetricsOverride",
            {"width": self.width, "height": self.height, "deviceScaleFactor": 1, "mobile": False},
        )

    async def send(
        self, method: str, params: dict[str, Any] | None = None, page: bool = True
    ) -> dict[str, Any]:
        """Run one DevTools command, on the page (`page`) or the browser; returns its result.

        Raises CdpError when Chromium answers with an error, TimeoutError after `timeout_s`.
        """
        if self._ws is None:
            raise CdpError(f"{method}: the browser is not connected")
        command_id = next(self._ids)
        command: dict[str, Any] = {"id": command_id, "method": method, "params": params or {}}
        if page:
            command["sessionId"] = self._session_id
        future = asyncio.get_running_loop().create_future()
        self._pending[command_id] = future
        try:
            await self._ws.send_str(json.dumps(command))
            return await asyncio.wait_for(future, self.timeout_s)
        finally:
            self._pending.pop(command_id, None)

    async def goto(self, url: str) -> None:
        """Navigate to `url` and wait for its load event."""
        self._loaded = asyncio.get_running_loop().create_future()
        result = await self.send("Page.navigate", {"url": url})
        if result.get("errorText"):
            raise CdpError(f"{url}: {result['errorText']}")
        await asyncio.wait_for(self._loaded, self.timeout_s)

    async def evaluate(self, expression: str) -> Any:
        """The JSON value of a JavaScript expression in the page (promises are awaited).

        Raises CdpError when the expression throws.
        """
        result = await self.send(
            "Runtime.evaluate",
            {"expression": expression, "returnByValue": True, "awaitPromise": True},
        )
        if "exceptionDetails" in result:
            raise CdpError(f"{expression}: {_exception_text(result['exceptionDetails'])}")
        return result["result"].get("value")

    async def wait_for(self, expression: str, timeout_s: float = 5.0) -> Any:
        """Poll a JavaScript expression every 50 ms until its value is truthy; return it.

        Raises TimeoutError naming the expression and its last value after `timeout_s`.
        """
        deadline = asyncio.get_running_loop().time() + timeout_s
        while True:
            value = await self.evaluate(expression)
            if value:
                return value
            if asyncio.get_running_loop().time() > deadline:
                raise TimeoutError(f"{expression} still {value!r} after {timeout_s} s")
            await asyncio.sleep(0.05)

    async def screenshot(self) -> np.ndarray:
        """The viewport as a (height, width, 3) uint8 BGR image."""
        result = await self.send("Page.captureScreenshot", {"format": "png"})
        png = np.frombuffer(base64.b64decode(result["data"]), dtype=np.uint8)
        return cv2.imdecode(png, cv2.IMREAD_COLOR)

    async def close(self) -> None:
        """Ask Chromium to quit, kill it if it has not within 5 s and delete its profile."""
        if self._ws is not None and not self._ws.closed:
            with contextlib.suppress(CdpError, TimeoutError, ConnectionError):
                await asyncio.wait_for(self.send("Browser.close", page=False), 5.0)
            await self._ws.close()
        self._ws = None
        if self._http is not None:
            await self._http.close()
            self._http = None
        if self._process is not None:
            try:
                await asyncio.wait_for(self._process.wait(), 5.0)
            except TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(self._process.pid, signal.SIGKILL)
                await self._process.wait()
            self._process = None
        for task in (self._reader, self._stderr_task):
            if task is not None:
                task.cancel()
                await asyncio.gather(task, return_exceptions=True)
        if self._profile is not None:
            self._profile.cleanup()
            self._profile = None

    async def _devtools_url(self) -> str:
        assert self._process is not None and self._process.stderr is not None
        while line := await self._process.stderr.readline():
            text = line.decode(errors="replace").strip()
            self._stderr.append(text)
            if text.startswith(_LISTENING):
                return text.removeprefix(_LISTENING)
        tail = " | ".join(self._stderr)
        raise CdpError(f"{self._binary} exited before opening DevTools: {tail}")

    async def _drain_stderr(self) -> None:
        assert self._process is not None and self._process.stderr is not None
        while line := await self._process.stderr.readline():
            self._stderr.append(line.decode(errors="replace").rstrip())

    async def _read(self) -> None:
        assert self._ws is not None
        try:
            async for message in self._ws:
                if message.type is not aiohttp.WSMsgType.TEXT:
                    break
                data = json.loads(message.data)
                if "id" in data:
                    self._answer(data)
                else:
                    self._event(data["method"], data.get("params", {}))
        finally:
            for future in self._pending.values():
                if not future.done():
                    future.set_exception(CdpError("the browser closed the DevTools connection"))

    def _answer(self, data: dict[str, Any]) -> None:
        future = self._pending.get(data["id"])
        if future is None or future.done():
            return
        if "error" in data:
            future.set_exception(CdpError(f"{data['error'].get('message')}: {data['error']}"))
        else:
            future.set_result(data.get("result", {}))

    def _event(self, method: str, params: dict[str, Any]) -> None:
        if method == "Page.loadEventFired" and self._loaded is not None:
            if not self._loaded.done():
                self._loaded.set_result(None)
        elif method == "Runtime.consoleAPICalled" and params["type"] in ("error", "warning"):
            text = " ".join(
                str(arg.get("value", arg.get("description", ""))) for arg in params["args"]
            )
            self.errors.append(f"console.{params['type']}: {text}")
        elif method == "Runtime.exceptionThrown":
            self.errors.append(f"exception: {_exception_text(params['exceptionDetails'])}")
        elif method == "Log.entryAdded" and params["entry"]["level"] in ("error", "warning"):
            entry = params["entry"]
            url = f" ({entry['url']})" if entry.get("url") else ""
            self.errors.append(f"log {entry['level']}: {entry['text']}{url}")


def _exception_text(details: dict[str, Any]) -> str:
    exception = details.get("exception", {})
    return str(exception.get("description") or details.get("text", "unknown exception"))
