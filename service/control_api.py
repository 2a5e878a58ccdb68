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

Every request passes the checks of `samba.service.api_access` first (Host, Origin,
token). A request body is a JSON object sent with `Content-Type: application/json`, at
most `MAX_BODY_BYTES`. A session started here may name only the files and VMC
receivers its server's `SessionPolicy` allows, and the server runs at most
`SessionPolicy.max_sessions` (`samba.service.session_policy`).

Errors answer `{"error": message}`, never a traceback: 400 (bad request body or value),
401 (token), 403 (host, origin, a path or VMC receiver not allowed), 404 (no such
session or route), 405 (method), 409 (conflict: name taken, a take already recording or
none, too many sessions), 413 (body too large), 415 (body not JSON).
"""

from __future__ import annotations

import asyncio
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aiohttp import web

from samba.base import SambaError
from samba.service.api_access import json_error
from samba.service.errors import ServiceError
from samba.service.server import CaptureServer
from samba.service.session_config import SessionConfig
from samba.service.session_policy import SessionPolicy

MAX_BODY_BYTES = 16 * 1024
"""Largest request body, bytes: the app is made with it as `client_max_size`."""
JSON_TYPE = "application/json"


@dataclass
class _Sessions:
    """A server's session rules and the sessions being opened (not yet running)."""

    policy: SessionPolicy
    opening: int = 0


SERVER_KEY = web.AppKey("capture_server", CaptureServer)
STARTED_KEY = web.AppKey("started", float)
SESSIONS_KEY = web.AppKey("sessions", _Sessions)


def add_control_routes(app: web.Application, server: CaptureServer, policy: SessionPolicy) -> None:
    """Register the API routes above on `app` (made with `client_max_size=MAX_BODY_BYTES`)
    for `server`, whose API sessions follow `policy`."""
    app[SERVER_KEY] = server
    app[STARTED_KEY] = time.time()
    app[SESSIONS_KEY] = _Sessions(policy)
    app.router.add_get("/api/health", _health)
    app.router.add_get("/api/sessions", _sessions)
    app.router.add_post("/api/sessions", _create_session)
    app.router.add_get("/api/sessions/{name}", _session)
    app.router.add_delete("/api/sessions/{name}", _delete_session)
    app.router.add_post("/api/sessions/{name}/takes", _start_take)
    app.router.add_post("/api/sessions/{name}/takes/stop", _stop_take)
    app.router.add_get("/api/takes", _takes)
    app.router.add_get("/api/metrics", _metrics)


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
        return json_error(404, f"{request.match_info['name']}: no such session")
    return web.json_response({"session": session.status()})


async def _create_session(request: web.Request) -> web.Response:
    server, sessions = _server(request), request.app[SESSIONS_KEY]
    body = await _json_body(request)
    if isinstance(body, web.Response):
        return body
    try:
        config = SessionConfig.from_mapping(body, "request body")
    except SambaError as exc:
        return json_error(400, str(exc))
    try:
        sessions.policy.check(config)
    except ServiceError as exc:
        return json_error(403, str(exc))
    if config.name in server.sessions:
        return json_error(409, f"{config.name}: a session of this name is already running")
    most = sessions.policy.max_sessions
    if len(server.sessions) + sessions.opening >= most:
        return json_error(409, f"{config.name}: this server runs at most {most} sessions")
    sessions.opening += 1
    try:
        session = await asyncio.to_thread(server.open_session, config)
    except (SambaError, OSError, ValueError) as exc:
        return json_error(400, str(exc)[:300])
    finally:
        sessions.opening -= 1
    try:
        server.attach(session)
    except ServiceError as exc:
        return json_error(409, str(exc))
    return web.json_response({"session": session.status()}, status=201)


async def _delete_session(request: web.Request) -> web.Response:
    server, name = _server(request), request.match_info["name"]
    if name not in server.sessions:
        return json_error(404, f"{name}: no such session")
    server.remove_session(name)
    return web.json_response({"stopped": name})


async def _start_take(request: web.Request) -> web.Response:
    session = _server(request).sessions.get(request.match_info["name"])
    if session is None:
        return json_error(404, f"{request.match_info['name']}: no such session")
    body = await _json_body(request, allow_empty=True)
    if isinstance(body, web.Response):
        return body
    name = body.get("name")
    if name is not None and not isinstance(name, str):
        return json_error(400, "request body: name must be a string")
    if session.recording is not None:
        return json_error(409, f"{session.name}: take {session.recording.name!r} is recording")
    try:
        take = session.start_take(name)
    except SambaError as exc:
        return json_error(409 if "exists" in str(exc) else 400, str(exc))
    return web.json_response({"take": take.to_json()}, status=201)


async def _stop_take(request: web.Request) -> web.Response:
    session = _server(request).sessions.get(request.match_info["name"])
    if session is None:
        return json_error(404, f"{request.match_info['name']}: no such session")
    if session.recording is None:
        return json_error(409, f"{session.name}: no take is recording")
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
    """The request's JSON object, or the error answer: 415 unless the body is sent as
    `application/json` (an empty body, where `allow_empty`, is `{}`), 413 beyond
    `MAX_BODY_BYTES` (raised by aiohttp), 400 for what is not a JSON object."""
    data = await request.read()
    if not data.strip() and allow_empty:
        return {}
    if request.content_type != JSON_TYPE:
        return json_error(415, f"request body must be sent as {JSON_TYPE}")
    try:
        body = json.loads(data.decode("utf-8"))
    except UnicodeDecodeError:
        return json_error(400, "request body is not JSON: not UTF-8")
    except RecursionError:
        return json_error(400, "request body is not JSON: nested too deeply")
    except ValueError as exc:
        return json_error(400, f"request body is not JSON: {str(exc)[:80]}")
    if not isinstance(body, dict):
        return json_error(400, "request body must be a JSON object")
    return body


def _size(path: str) -> int | None:
    try:
        return Path(path).stat().st_size
    except OSError:
        return None
