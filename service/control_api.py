"""The control API of `samba serve`: HTTP + JSON on aiohttp.

| method and path | body | answer |
|---|---|---|
| `GET /api/health` | | `{"status": "ok", "sessions": n, "uptime_s": s}` |
| `GET /api/sessions` | | `{"sessions": [session, ...]}` |
| `POST /api/sessions` | a session config (`session_config`) | 201 `{"session": session}` |
| `GET /api/sessions/{name}` | | `{"session": session}` |
| `DELETE /api/sessions/{name}` | | `{"stopped": name}` (a recording take is finished) |
| `POST /api/sessions/{name}/takes` | optional `{"name": take}` | 201 `{"take": take}` |
| `POST /api/sessions/{name}/takes/stop` | | `{"take": take}` with its frame count |
| `GET /api/takes` | | `{"takes": [take, ...]}`: this run's takes, then older files |
| `GET /api/metrics` | | datagrams, drops by reason; per session frames, sync counts, latency |

Errors answer `{"error": message}` with 400 (bad request body or value), 401 (token),
404 (no such session), 409 (conflict: name taken, a take already recording or none).

With a token, every request must carry it, as `Authorization: Bearer <token>` or as a
`token` query parameter (which the viewer page passes on to its WebSocket); the server
refuses to bind the API anywhere but loopback without one (`samba.service.serve`).
"""

from __future__ import annotations

import asyncio
import hmac
import json
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from aiohttp import web

from samba.base import SambaError
from samba.service.errors import ServiceError
from samba.service.server import CaptureServer
from samba.service.session_config import SessionConfig

SERVER_KEY = web.AppKey("capture_server", CaptureServer)
STARTED_KEY = web.AppKey("started", float)

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]


def add_control_routes(app: web.Application, server: CaptureServer) -> None:
    """Register the API routes above on `app` for `server`."""
    app[SERVER_KEY] = server
    app[STARTED_KEY] = time.time()
    app.router.add_get("/api/health", _health)
    app.router.add_get("/api/sessions", _sessions)
    app.router.add_post("/api/sessions", _create_session)
    app.router.add_get("/api/sessions/{name}", _session)
    app.router.add_delete("/api/sessions/{name}", _delete_session)
    app.router.add_post("/api/sessions/{name}/takes", _start_take)
    app.router.add_post("/api/sessions/{name}/takes/stop", _stop_take)
    app.router.add_get("/api/takes", _takes)
    app.router.add_get("/api/metrics", _metrics)


def token_middleware(token: str) -> Callable[[web.Request, Handler], Awaitable[web.StreamResponse]]:
    """Middleware refusing (401) requests without `token` (header or query parameter)."""
    expected = token.encode()

    @web.middleware
    async def check(request: web.Request, handler: Handler) -> web.StreamResponse:
        given = request.headers.get("Authorization", "").removeprefix("Bearer ").strip()
        given = given or request.query.get("token", "")
        if not hmac.compare_digest(given.encode(), expected):
            return _error(401, "missing or wrong token")
        return await handler(request)

    return check


def _error(status: int, message: str) -> web.Response:
    return web.json_response({"error": message}, status=status)


def _server(request: web.Request) -> CaptureServer:
    return request.app[SERVER_KEY]


async def _health(request: web.Request) -> web.Response:
    server = _server(request)
    uptime = round(time.time() - request.app[STARTED_KEY], 3)
    return web.json_response({"status": "ok", "sessions": len(server.sessions), "uptime_s": uptime})


async def _sessions(request: web.Request) -> web.Response:
    sessions = [s.status() for s in _server(request).sessions.values()]
    return web.json_response({"sessions": sessions})


async def _session(request: web.Request) -> web.Response:
    session = _server(request).sessions.get(request.match_info["name"])
    if session is None:
        return _error(404, f"{request.match_info['name']}: no such session")
    return web.json_response({"session": session.status()})


async def _create_session(request: web.Request) -> web.Response:
    server = _server(request)
    body = await _json_body(request)
    if isinstance(body, web.Response):
        return body
    try:
        config = SessionConfig.from_mapping(body, "request body")
    except SambaError as exc:
        return _error(400, str(exc))
    if config.name in server.sessions:
        return _error(409, f"{config.name}: a session of this name is already running")
    try:
        session = await asyncio.to_thread(server.open_session, config)
    except SambaError as exc:
        return _error(400, str(exc))
    try:
        server.attach(session)
    except ServiceError as exc:
        return _error(409, str(exc))
    return web.json_response({"session": session.status()}, status=201)


async def _delete_session(request: web.Request) -> web.Response:
    server, name = _server(request), request.match_info["name"]
    if name not in server.sessions:
        return _error(404, f"{name}: no such session")
    server.remove_session(name)
    return web.json_response({"stopped": name})


async def _start_take(request: web.Request) -> web.Response:
    session = _server(request).sessions.get(request.match_info["name"])
    if session is None:
        return _error(404, f"{request.match_info['name']}: no such session")
    body = await _json_body(request, allow_empty=True)
    if isinstance(body, web.Response):
        return body
    name = body.get("name")
    if name is not None and not isinstance(name, str):
        return _error(400, "request body: name must be a string")
    if session.recording is not None:
        return _error(409, f"{session.name}: take {session.recording.name!r} is recording")
    try:
        take = session.start_take(name)
    except SambaError as exc:
        return _error(409 if "exists" in str(exc) else 400, str(exc))
    return web.json_response({"take": take.to_json()}, status=201)


async def _stop_take(request: web.Request) -> web.Response:
    session = _server(request).sessions.get(request.match_info["name"])
    if session is None:
        return _error(404, f"{request.match_info['name']}: no such session")
    if session.recording is None:
        return _error(409, f"{session.name}: no take is recording")
    return web.json_response({"take": session.stop_take().to_json()})


async def _takes(request: web.Request) -> web.Response:
    server = _server(request)
    takes: list[dict[str, Any]] = []
    for session in server.sessions.values():
        takes += [{"session": session.name, **t.to_json()} for t in session.takes()]
    known = {t["path"] for t in takes}
    for path in sorted(server.takes_dir.glob("*/*.mcap")):
        if str(path) not in known:
            takes.append({"session": path.parent.name, "name": path.stem, "path": str(path)})
    for take in takes:
        take["bytes"] = _size(take["path"])
    return web.json_response({"takes": takes})


async def _metrics(request: web.Request) -> web.Response:
    return web.json_response(_server(request).metrics())


async def _json_body(request: web.Request, allow_empty: bool = False) -> dict | web.Response:
    text = await request.text()
    if not text.strip() and allow_empty:
        return {}
    try:
        body = json.loads(text)
    except ValueError as exc:
        return _error(400, f"request body is not JSON: {exc}")
    if not isinstance(body, dict):
        return _error(400, "request body must be a JSON object")
    return body


def _size(path: str) -> int | None:
    try:
        return Path(path).stat().st_size
    except OSError:
        return None
