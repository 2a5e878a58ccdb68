"""The control API and viewer against other web pages and bad requests (issue 41, item 4):
a real `LiveServer` on loopback, aiohttp's client for the requests a page could forge,
and headless Chromium for what a page of another origin can actually do."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import stat
import subprocess
import sys
import time
from collections.abc import AsyncIterator
from pathlib import Path

import aiohttp
import pytest
from aiohttp import web
from chromium_page import ChromiumPage, find_chromium
from live_fixtures import WAIT_MS, config, free_udp_port
from live_fixtures import until as until_done

from samba.service.serve import LiveServer
from samba.service.session_config import SessionConfig
from samba.service.session_policy import SessionPolicy
from samba.service.synthetic_capture import SyntheticCapture, play

ROOT = Path(__file__).resolve().parents[1]
EVIL = "http://evil.example"


@contextlib.asynccontextmanager
async def live_server(
    configs: list[SessionConfig], takes: Path, **options: object
) -> AsyncIterator[tuple[LiveServer, aiohttp.ClientSession]]:
    """A `LiveServer` on loopback and a client session on its URL, without the token."""
    async with (
        LiveServer(configs, takes, udp=("127.0.0.1", 0), http=("127.0.0.1", 0), **options) as live,
        aiohttp.ClientSession(str(live.http_url)) as http,
    ):
        yield live, http


def bearer(live: LiveServer, **headers: str) -> dict[str, str]:
    """The token header, with more headers."""
    return {"Authorization": f"Bearer {live.token}", **headers}


async def answer(response: aiohttp.ClientResponse) -> tuple[int, str]:
    """A response's status and its JSON error message ("" when none)."""
    assert response.content_type == "application/json", await response.text()
    body = await response.json()
    return response.status, body.get("error", "") if isinstance(body, dict) else ""


@pytest.mark.slow
def test_other_origins_and_hosts_are_refused(
    live_store: Path, live_calibration: Path, tmp_path: Path
) -> None:
    """Cross-origin POSTs, WebSockets and foreign Host headers are refused even with the
    token; the server's own origin and programs without an Origin work."""

    async def run() -> None:
        async with live_server([config(live_calibration, live_store)], tmp_path) as (live, http):
            assert live.server is not None
            session = live.server.session("stage")
            port = live.http_address[1]
            take = "/api/sessions/stage/takes"
            for headers in (
                {"Origin": EVIL},
                {"Origin": "null"},
                {"Origin": f"http://127.0.0.1:{port + 1}"},
                {"Sec-Fetch-Site": "cross-site"},
                {"Sec-Fetch-Site": "same-site"},
            ):
                async with http.post(
                    take, json={"name": "x"}, headers=bearer(live, **headers)
                ) as r:
                    assert (await answer(r))[0] == 403, headers
                async with http.delete("/api/sessions/stage", headers=bearer(live, **headers)) as r:
                    assert (await answer(r))[0] == 403
            assert session.recording is None and "stage" in live.server.sessions
            for host in ("evil.example", f"evil.example:{port}", f"127.0.0.1:{port + 1}", ""):
                async with http.get("/api/health", headers=bearer(live, Host=host)) as r:
                    status, message = await answer(r)
                    assert status == 403 and "Host" in message, host
            for host in (f"127.0.0.1:{port}", f"localhost:{port}", f"LOCALHOST.:{port}"):
                async with http.get("/api/health", headers=bearer(live, Host=host)) as r:
                    assert r.status == 200, host
            own = {"Origin": f"http://127.0.0.1:{port}", "Sec-Fetch-Site": "same-origin"}
            async with http.post(take, json={"name": "t1"}, headers=bearer(live, **own)) as r:
                assert r.status == 201
            async with http.post(f"{take}/stop", headers=bearer(live)) as r:  # curl: no Origin
                assert r.status == 200
            async with http.post(f"{take}/stop") as r:
                assert (await answer(r))[0] == 401
            ws = f"/ws/stage?token={live.token}"
            with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                await http.ws_connect(ws, origin=EVIL)
            assert refused.value.status == 403
            with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                await http.ws_connect("/ws/stage", origin=f"http://127.0.0.1:{port}")
            assert refused.value.status == 401
            async with http.ws_connect(ws, origin=f"http://127.0.0.1:{port}") as socket:
                assert (await socket.receive_json(timeout=5))["type"] == "hello"

    asyncio.run(run())


def test_session_names_and_paths_stay_inside_the_servers_folders(
    live_store: Path, live_calibration: Path, tmp_path: Path
) -> None:
    """Names `.` and `..` are refused; a session names only the files and VMC receivers
    given at start or allowed, and the answer does not say whether another file exists."""
    allowed = tmp_path / "allowed"
    allowed.mkdir()
    (allowed / "stage.toml").write_bytes(live_calibration.read_bytes())
    outside = tmp_path / "outside.toml"
    outside.write_bytes(live_calibration.read_bytes())
    (allowed / "escape.toml").symlink_to(outside)  # a link out of the folder
    cfg = config(live_calibration, live_store)
    policy = SessionPolicy.of([cfg], [allowed], [("127.0.0.1", 39539)])
    takes = tmp_path / "takes"

    async def run() -> None:
        async with live_server([cfg], takes, policy=policy) as (live, http):
            body = {"calibration": str(live_calibration), "database": str(live_store)}
            for name in (".", "..", ".hidden", "a/b", "-x", ""):
                async with http.post(
                    "/api/sessions", json={**body, "name": name}, headers=bearer(live)
                ) as r:
                    status, message = await answer(r)
                    assert status == 400 and "name" in message, name
            errors = set()
            for calibration in ("/etc/passwd", "/nowhere/x.toml", "../stage.toml", "/etc"):
                bad = {**body, "name": "s2", "calibration": calibration}
                async with http.post("/api/sessions", json=bad, headers=bearer(live)) as r:
                    status, message = await answer(r)
                    assert status == 403, calibration
                    errors.add(message.replace(calibration, "PATH"))
            assert len(errors) == 1  # the same answer whether the file exists or not
            for database in (str(tmp_path), "/"):
                bad = {**body, "name": "s2", "database": database}
                async with http.post("/api/sessions", json=bad, headers=bearer(live)) as r:
                    assert (await answer(r))[0] == 403
            escape = {**body, "name": "s2", "calibration": str(allowed / "escape.toml")}
            async with http.post("/api/sessions", json=escape, headers=bearer(live)) as r:
                assert (await answer(r))[0] == 403
            for vmc in (["10.0.0.9:39539"], ["127.0.0.1:22"]):
                async with http.post(
                    "/api/sessions", json={**body, "name": "s2", "vmc": vmc}, headers=bearer(live)
                ) as r:
                    status, message = await answer(r)
                    assert status == 403 and "vmc" in message
            good = {
                **body,
                "name": "s2",
                "calibration": str(allowed / "stage.toml"),
                "vmc": ["127.0.0.1:39539"],
            }
            async with http.post("/api/sessions", json=good, headers=bearer(live)) as r:
                assert r.status == 201
            async with http.post(
                "/api/sessions/s2/takes", json={"name": ".."}, headers=bearer(live)
            ) as r:
                assert (await answer(r))[0] == 400

    asyncio.run(run())
    written = [p for p in tmp_path.rglob("*") if p.suffix == ".mcap"]
    assert all(p.is_relative_to(takes) for p in written)


def test_sessions_are_capped(live_store: Path, live_calibration: Path, tmp_path: Path) -> None:
    """Two hundred sessions asked for at once: the server runs at most its cap."""
    cfg = config(live_calibration, live_store)
    policy = SessionPolicy.of([cfg], max_sessions=4)

    async def run() -> list[int]:
        async with live_server([cfg], tmp_path, policy=policy) as (live, http):
            assert live.server is not None

            async def create(i: int) -> int:
                body = {
                    "name": f"s{i}",
                    "calibration": str(live_calibration),
                    "database": str(live_store),
                }
                async with http.post("/api/sessions", json=body, headers=bearer(live)) as r:
                    status, message = await answer(r)
                    assert status == 201 or (status == 409 and "at most 4" in message)
                    return status

            statuses = await asyncio.gather(*(create(i) for i in range(200)))
            assert len(live.server.sessions) == 4
            return statuses

    statuses = asyncio.run(run())
    assert statuses.count(201) == 3


def test_bad_requests_get_a_clear_4xx_json_error(
    live_store: Path, live_calibration: Path, tmp_path: Path
) -> None:
    """No bad input gives a 500: deep nesting, other content types, large bodies, odd
    bytes, unknown routes and methods each get one JSON error line."""
    json_type = {"Content-Type": "application/json"}
    cases: list[tuple[str, str, bytes, dict[str, str], int]] = [
        ("POST", "/api/sessions", b"[" * 100_000, json_type, 413),
        ("POST", "/api/sessions", b"[" * 5_000 + b"]" * 5_000, json_type, 400),
        ("POST", "/api/sessions", b'{"name": ' * 1_500 + b"1" + b"}" * 1_500, json_type, 400),
        ("POST", "/api/sessions", b'{"name": "x"}', {"Content-Type": "text/plain"}, 415),
        (
            "POST",
            "/api/sessions",
            b"name=x",
            {"Content-Type": "application/x-www-form-urlencoded"},
            415,
        ),
        ("POST", "/api/sessions", b"\xff\xfe{}", json_type, 400),
        ("POST", "/api/sessions", b'{"name": 1e999999}', json_type, 400),
        ("POST", "/api/sessions", b'{"name": ' + b"9" * 5000 + b"}", json_type, 400),
        ("POST", "/api/sessions", b'{"name": "s", "fps": NaN}', json_type, 400),
        ("POST", "/api/sessions", b'["a list"]', json_type, 400),
        ("POST", "/api/sessions", b"", json_type, 400),
        ("POST", "/api/sessions", b'{"name": {"deep": [1, 2]}}', json_type, 400),
        ("POST", "/api/sessions/stage/takes", b'{"name": 5}', json_type, 400),
        ("POST", "/api/sessions/stage/takes", b'{"name": "a b"}', json_type, 400),
        ("POST", "/api/sessions/nope/takes", b"{}", json_type, 404),
        ("GET", "/api/nothing", b"", {}, 404),
        ("PUT", "/api/sessions", b"{}", json_type, 405),
        ("GET", "/ws/stage", b"", {}, 400),  # not an upgrade
    ]

    async def run() -> None:
        async with live_server([config(live_calibration, live_store)], tmp_path) as (live, http):
            for method, path, data, headers, expected in cases:
                async with http.request(
                    method, path, data=data, headers=bearer(live, **headers)
                ) as r:
                    status, message = await answer(r)
                    assert status == expected, (path, data[:40], status, message)
                    assert message and "\n" not in message and len(message) < 400
            async with http.get("/api/health", headers=bearer(live)) as r:
                assert r.status == 200  # still serving

    asyncio.run(run())


@pytest.mark.slow
def test_the_token_file_is_the_owners_only(
    live_store: Path, live_calibration: Path, tmp_path: Path
) -> None:
    """`--token-file`: the token drawn at start goes to a file of mode 0600 (also when it
    existed with looser rights) and is not printed."""
    token_file = tmp_path / "token"
    token_file.write_text("old")
    token_file.chmod(0o644)
    argv = [sys.executable, "-m", "samba.cli", "serve", "--calib", str(live_calibration)]
    argv += ["--db", str(live_store), "--udp", f"127.0.0.1:{free_udp_port()}"]
    argv += ["--http", "127.0.0.1:0", "--token-file", str(token_file), "--duration", "1"]
    argv += ["--out-dir", str(tmp_path / "takes")]
    env = {k: v for k, v in os.environ.items() if k != "SAMBA_TOKEN"}
    done = subprocess.run(argv, capture_output=True, text=True, cwd=ROOT, timeout=120, env=env)
    assert done.returncode == 0, done.stderr
    token = token_file.read_text().strip()
    assert len(token) >= 32 and token not in done.stdout
    assert stat.S_IMODE(token_file.stat().st_mode) == 0o600
    assert f"the token in {token_file}" in done.stdout
    printed = subprocess.run(
        [*argv[: argv.index("--token-file")], "--duration", "1", "--out-dir", str(tmp_path)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
        env=env,
    )
    assert re.search(
        r"viewer: http://127\.0\.0\.1:\d+/viewer/default\?token=\S{32,}", printed.stdout
    )


# ---- in a browser ----------------------------------------------------------------------

EVIL_PAGE = """<!doctype html><meta charset="utf-8"><title>evil</title><script>
window.results = {};
const target = "TARGET";
const token = "TOKEN";  // even a page that got hold of the token
fetch(`${target}/api/sessions/stage/takes?token=${token}`, {
  method: "POST", mode: "no-cors", headers: {"Content-Type": "text/plain"},
  body: JSON.stringify({name: "evil"}),
}).then(() => { window.results.fetch = "sent"; }, () => { window.results.fetch = "failed"; });
fetch(`${target}/api/sessions?token=${token}`).then(
  () => { window.results.read = "read"; }, () => { window.results.read = "blocked"; });
const ws = new WebSocket(`${target.replace("http", "ws")}/ws/stage?token=${token}`);
ws.onmessage = () => { window.results.ws = "read"; };
ws.onerror = () => { window.results.ws = "refused"; };
</script>
<form id="form" method="post" action="TARGET/api/sessions/stage/takes?token=TOKEN"
      enctype="text/plain"><input name='{"name": "form", "x": "' value='"}'></form>
"""


async def serve_page(html: str) -> tuple[web.AppRunner, str]:
    """A page of another origin: its runner and URL."""

    async def page(_request: web.Request) -> web.Response:
        return web.Response(text=html, content_type="text/html")

    app = web.Application()
    app.router.add_get("/", page)
    app.router.add_post("/", page)
    runner = web.AppRunner(app)
    await runner.setup()
    site = web.TCPSite(runner, "127.0.0.1", 0)
    await site.start()
    return runner, f"http://127.0.0.1:{runner.addresses[0][1]}/"


@pytest.mark.slow
def test_in_chromium_another_origin_can_do_nothing_and_the_viewer_works(
    live_store: Path, live_calibration: Path, live_capture: SyntheticCapture, tmp_path: Path
) -> None:
    """A page of another origin, even one holding the token, cannot start a take (fetch
    or form) or read the WebSocket; a page reached by a rebound DNS name is refused; the
    viewer page itself shows the live frames."""
    find_chromium()

    async def run() -> None:
        cfg = config(live_calibration, live_store, wait_ms=WAIT_MS)
        async with live_server([cfg], tmp_path) as (live, _http):
            assert live.server is not None and live.http_url is not None
            session = live.server.session("stage")
            html = EVIL_PAGE.replace("TARGET", live.http_url).replace("TOKEN", live.token)
            runner, evil = await serve_page(html)
            port = live.http_address[1]
            rules = "--host-resolver-rules=MAP rebound.example 127.0.0.1"
            try:
                async with ChromiumPage(flags=(rules,)) as page:
                    await page.goto(evil)
                    await page.wait_for("Object.keys(window.results).length === 3", 10.0)
                    results = await page.evaluate("window.results")
                    assert results["read"] == "blocked" and results["ws"] == "refused"
                    await page.evaluate("document.getElementById('form').submit()")
                    await asyncio.sleep(1.0)
                    assert session.recording is None and session.takes() == []
                    assert live.hub.clients("stage") == 0

                    await page.goto(
                        f"http://rebound.example:{port}/viewer/stage?token={live.token}"
                    )
                    text = await page.evaluate("document.body.innerText")
                    assert "is not this server's address" in text

                    page.errors.clear()
                    viewer = live.viewer_url("stage")
                    await page.goto(str(viewer))
                    await page.wait_for("document.body.dataset.state === 'connected'")
                    playing = asyncio.create_task(
                        play(live_capture, live.udp_address, time.time() + 0.2, "stage")
                    )
                    await page.wait_for(
                        "parseInt(document.getElementById('frame').textContent) > 10", 10.0
                    )
                    await playing
                    await page.goto(f"{live.http_url}/?token={live.token}")  # lists sessions
                    await page.wait_for("document.body.dataset.state === 'connected'")
                    assert (
                        await page.evaluate("document.getElementById('session').textContent")
                        == "stage"
                    )
                    # the refused page's favicon may be reported after it
                    assert [e for e in page.errors if "rebound.example" not in e] == []
            finally:
                await runner.cleanup()
            await until_done(lambda: session.frames_out == live_capture.frames)
            assert session.takes() == []

    asyncio.run(run())


def test_the_viewer_page_sends_no_referrer_and_cannot_be_framed(
    live_store: Path, live_calibration: Path, tmp_path: Path
) -> None:
    async def run() -> None:
        async with live_server([config(live_calibration, live_store)], tmp_path) as (live, http):
            async with http.get(f"/viewer/stage?token={live.token}") as r:
                assert r.status == 200
                assert r.headers["Referrer-Policy"] == "no-referrer"
                assert "frame-ancestors 'none'" in r.headers["Content-Security-Policy"]
            async with http.get("/viewer/stage") as r:
                assert r.status == 401 and json.loads(await r.text())["error"]

    asyncio.run(run())
