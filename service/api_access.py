"""Who may use the HTTP side of `samba serve`: the checks every request passes, in order.

1. **Host** (`HostCheck`): the `Host` header must name this server as it is bound: its
   address, `localhost` and the loopback addresses when bound to loopback, any IP
   address when bound to all interfaces, and the names given with `--allow-host`; with
   the bound port. A web page that rebinds its own DNS name to this machine (DNS
   rebinding) sends its own name and is refused before anything else.
2. **Origin** (`origin_middleware`): a request that changes state (any method but GET,
   HEAD and OPTIONS) and every WebSocket must come from this server's own pages: an
   `Origin` header, when there is one, must be `http://<the Host header>`, and a
   `Sec-Fetch-Site` header, when there is one, `same-origin` or `none`. Programs that
   send neither (curl, scripts) pass on to the token.
3. **Token** (`token_middleware`): every request carries the server's token, as
   `Authorization: Bearer <token>` or a `token` query parameter (the viewer page's URL
   carries it, and the page passes it on to its WebSocket and API requests). A page of
   another origin cannot read it.

Refusals are JSON, like every error of the API (`json_errors_middleware`): `{"error":
message}` with 403 (host, origin), 401 (token), and the status of any other HTTP error
(404 no such route, 405 method); an unexpected exception is logged and answers 500
without details.
"""

from __future__ import annotations

import hmac
import ipaddress
import logging
from collections.abc import Awaitable, Callable, Iterable

from aiohttp import hdrs, web

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]
Middleware = Callable[[web.Request, Handler], Awaitable[web.StreamResponse]]

MIN_TOKEN_CHARS = 16
"""Shortest API token the server accepts."""
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
"""Methods that change nothing: no `Origin` check."""

_LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})
_log = logging.getLogger(__name__)


def json_error(status: int, message: str) -> web.Response:
    """The API's error answer: `{"error": message}` with HTTP status `status`."""
    return web.json_response({"error": message}, status=status)


@web.middleware
async def json_errors_middleware(request: web.Request, handler: Handler) -> web.StreamResponse:
    """Answer aiohttp's HTTP errors (no such route, wrong method, body too large) as JSON
    errors, and an unexpected exception as a 500 JSON error (logged)."""
    try:
        return await handler(request)
    except web.HTTPException as exc:
        if exc.status < 400:
            raise
        return json_error(exc.status, f"{request.method} {request.path}: {exc.reason}")
    except Exception:
        _log.exception("%s %s failed", request.method, request.path)
        return json_error(500, "internal error (logged by the server)")


class HostCheck:
    """The `Host` headers this server answers to (see the module docstring): bound to
    `host`, on `port` (set once the port is known), also reached by the DNS names in
    `names`."""

    def __init__(self, host: str, names: Iterable[str] = ()) -> None:
        self._bound = _normal(host)
        self._any_address = self._bound in ("0.0.0.0", "::", "")
        self._names = {_normal(name) for name in names}
        if is_loopback(self._bound):
            self._names |= _LOOPBACK_NAMES
        self._names.add(self._bound)
        self.port: int | None = None

    def allows(self, header: str) -> bool:
        """Whether a `Host` header value (`name[:port]`, `[v6]:port`) names this server."""
        name, port = _split_host(header)
        if name is None or port != self.port:
            return False
        return name in self._names or (self._any_address and _is_address(name))

    def middleware(self) -> Middleware:
        """Middleware refusing (403) requests whose `Host` is not this server."""

        @web.middleware
        async def check(request: web.Request, handler: Handler) -> web.StreamResponse:
            host = request.headers.get(hdrs.HOST, "")
            if not self.allows(host):
                return json_error(403, f"Host {host[:80]!r} is not this server's address")
            return await handler(request)

        return check


@web.middleware
async def origin_middleware(request: web.Request, handler: Handler) -> web.StreamResponse:
    """Refuse (403) a state-changing request or a WebSocket sent by a page of another
    origin (see the module docstring)."""
    websocket = request.headers.get(hdrs.UPGRADE, "").lower() == "websocket"
    if request.method in SAFE_METHODS and not websocket:
        return await handler(request)
    origin = request.headers.get(hdrs.ORIGIN)
    own = f"http://{request.headers.get(hdrs.HOST, '')}"
    if origin is not None and origin != own:
        return json_error(403, f"Origin {origin[:80]!r} is not this server's pages")
    site = request.headers.get("Sec-Fetch-Site")
    if site is not None and site not in ("same-origin", "none"):
        return json_error(403, f"a {site} request may not change this server")
    return await handler(request)


def token_middleware(token: str) -> Middleware:
    """Middleware refusing (401) requests without `token` (bearer header or `token`
    query parameter), compared in constant time."""
    expected = token.encode()

    @web.middleware
    async def check(request: web.Request, handler: Handler) -> web.StreamResponse:
        given = request.headers.get(hdrs.AUTHORIZATION, "").removeprefix("Bearer ").strip()
        given = given or request.query.get("token", "")
        if not hmac.compare_digest(given.encode(), expected):
            return json_error(401, "missing or wrong token")
        return await handler(request)

    return check


def _split_host(header: str) -> tuple[str | None, int]:
    """(name, port) of a `Host` header value, port 80 when absent; name None when the
    value is not a host."""
    header = header.strip()
    if header.startswith("["):
        name, bracket, rest = header[1:].partition("]")
        if not bracket or (rest and not rest.startswith(":")):
            return None, 0
        port_text = rest[1:]
    else:
        name, _, port_text = header.partition(":")
    if not name:
        return None, 0
    if not port_text:
        return _normal(name), 80
    if not port_text.isdigit() or len(port_text) > 5:
        return None, 0
    return _normal(name), int(port_text)


def _normal(name: str) -> str:
    """A host name or address as compared: lower case, without a final dot."""
    return name.lower().rstrip(".")


def _is_address(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


def is_loopback(host: str) -> bool:
    """True for localhost and loopback addresses (127.0.0.0/8, ::1)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
