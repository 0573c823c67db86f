"""The console's web server (aiohttp, in the system's own event loop).

Routes:

==========================================  ===================================================
``GET /``                                   the page (``static/index.html``)
``GET /static/<file>``                      the page's JavaScript, CSS and vendored three.js
``GET /ws``                                 the data WebSocket (:mod:`afa.console.frames`)
``GET /api/status``                         the component table and health, as JSON
``POST /api/components/<name>/<action>``    ``start`` | ``stop`` | ``restart`` (control)
``POST /api/vehicle/<action>``              ``stop`` (always) | ``start`` | ``arbiter-on`` |
                                            ``arbiter-off`` (control)
``POST /api/replay/<action>``               ``play`` | ``pause`` | ``step`` | ``seek`` |
                                            ``speed``, body ``{"value": x}``
==========================================  ===================================================

Every response carries a Content-Security-Policy that lets the page load and connect to
nothing but this server. :mod:`afa.console.guard` says who may do what.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Callable
from importlib import resources
from typing import Any

from aiohttp import WSCloseCode, WSMsgType, web
from aiohttp.http_exceptions import HttpProcessingError

from afa.console.frames import encode_frame, finite
from afa.console.guard import TOKEN_HEADER, ControlGuard, Permission
from afa.console.hub import COMPONENT_ACTIONS, VEHICLE_ACTIONS, ConsoleHub
from afa.console.replay import ACTIONS as REPLAY_ACTIONS
from afa.console.streams import POLICIES
from afa.errors import AfaError
from idl import VehicleControl

__all__ = ["ConsoleServer"]

log = logging.getLogger("afa.console")

_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8",
          ".css": "text/css; charset=utf-8", ".svg": "image/svg+xml", ".png": "image/png",
          ".json": "application/json", ".txt": "text/plain; charset=utf-8",
          ".woff2": "font/woff2"}
_CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; "
        "font-src 'self'; connect-src 'self'; base-uri 'none'; form-action 'none'; "
        "frame-ancestors 'none'")
#: Largest message the page may send (subscriptions): small.
_MAX_INCOMING = 64 * 1024
#: Seconds a browser has, at stop, to take its close frame before its connection is cut.
_CLOSE_TIMEOUT = 1.0
#: Log lines per kind of refused, ignored or failed request; further ones are only counted.
_LOG_LIMIT = 5


def _static_files() -> dict[str, tuple[bytes, str]]:
    """Every file of the package's ``static`` folder: path → (content, type)."""
    files: dict[str, tuple[bytes, str]] = {}
    root = resources.files("afa.console") / "static"

    def walk(folder: Any, prefix: str) -> None:
        for entry in folder.iterdir():
            name = f"{prefix}{entry.name}"
            if entry.is_dir():
                walk(entry, name + "/")
            else:
                suffix = "." + entry.name.rpartition(".")[2]
                files[name] = (entry.read_bytes(), _TYPES.get(suffix,
                                                               "application/octet-stream"))

    walk(root, "")
    return files


class ConsoleServer:
    """aiohttp application, runner and site for one :class:`ConsoleHub`."""

    def __init__(self, hub: ConsoleHub, guard: ControlGuard, *, max_pages: int = 16) -> None:
        if max_pages < 1:
            raise ValueError(f"max_pages must be at least 1, got {max_pages}")
        self.hub = hub
        self.max_pages = max_pages
        self._pages = 0  # WebSockets accepted and not yet ended (counted before prepare)
        self.guard = guard
        self.files = _static_files()
        self.app = web.Application(middlewares=[self._headers],
                                   client_max_size=_MAX_INCOMING)
        self.app.add_routes([
            web.get("/", self._index),
            web.get("/static/{path:.+}", self._static),
            web.get("/ws", self._websocket),
            web.get("/api/status", self._status),
            web.post("/api/components/{name}/{action}", self._component),
            web.post("/api/vehicle/{action}", self._vehicle),
            web.post("/api/replay/{action}", self._replay),
        ])
        self._runner: web.AppRunner | None = None
        self._sockets: dict[web.WebSocketResponse, web.Request] = {}
        self.port = guard.port

    async def start(self) -> None:
        """Listen on the guard's host and port (port 0: a free one, then known).
        Raises OSError when the address cannot be used."""
        # the browsers' WebSockets are closed first at stop(); nothing else lingers
        runner = web.AppRunner(self.app, access_log=None, handle_signals=False,
                               shutdown_timeout=2.0, logger=_RequestErrors(self._note))
        await runner.setup()
        site = web.TCPSite(runner, self.guard.host, self.guard.port, reuse_address=True)
        try:
            await site.start()
        except OSError:
            await runner.cleanup()
            raise
        self._runner = runner
        addresses = runner.addresses
        if addresses:
            self.port = int(addresses[0][1])
            self.guard.port = self.port

    async def stop(self) -> None:
        """Close every browser's WebSocket (the page shows 'disconnected' and retries),
        then the server. A browser that does not read gets :data:`_CLOSE_TIMEOUT`
        seconds, then its connection is cut: no client holds the shutdown."""
        await asyncio.gather(*(_close(ws, request) for ws, request in self._sockets.items()))
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None

    def _note(self, kind: str, level: int, message: str, *args: Any,
              exc_info: Any = None) -> None:
        """Count a refused, ignored or failed request or message (``console.rejected`` in
        the status); log only the first :data:`_LOG_LIMIT` of each kind."""
        self.hub.rejected[kind] += 1
        count = self.hub.rejected[kind]
        if count <= _LOG_LIMIT:
            if count == _LOG_LIMIT:
                message += " (further ones are only counted)"
            log.log(level, message, *args, exc_info=exc_info)

    # -- middleware ------------------------------------------------------------------------
    @web.middleware
    async def _headers(self, request: web.Request, handler: Any) -> web.StreamResponse:
        refusal = self.guard.check_request(request.headers.get("Host"),
                                           request.headers.get("Origin"))
        if refusal is not None:
            self._note("request", logging.WARNING, "console: refused %s %s: %s",
                       request.method, request.path, refusal)
            return _error(403, refusal)
        if request.method == "POST" and request.content_type != "application/json":
            return _error(415, "send control requests as application/json")
        response: web.StreamResponse = await handler(request)
        response.headers.setdefault("Content-Security-Policy", _CSP)
        response.headers.setdefault("X-Content-Type-Options", "nosniff")
        response.headers.setdefault("Referrer-Policy", "no-referrer")
        response.headers.setdefault("Cache-Control", "no-cache")
        return response

    # -- page ----------------------------------------------------------------------------
    async def _index(self, request: web.Request) -> web.Response:
        content, kind = self.files["index.html"]
        return web.Response(body=content, content_type=kind.partition(";")[0],
                            charset="utf-8")

    async def _static(self, request: web.Request) -> web.Response:
        found = self.files.get(request.match_info["path"])
        if found is None:
            return _error(404, "no such file")
        content, kind = found
        base, _, charset = kind.partition("; charset=")
        return web.Response(body=content, content_type=base, charset=charset or None)

    # -- data ----------------------------------------------------------------------------
    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        if self._pages >= self.max_pages:
            self._note("page", logging.WARNING, "console: refused a page from %s: %d are "
                       "connected, the most it serves", request.remote, self._pages)
            return _error(503, f"the console serves at most {self.max_pages} pages at once")
        self._pages += 1
        try:
            return await self._page(request)
        finally:
            self._pages -= 1

    async def _page(self, request: web.Request) -> web.StreamResponse:
        ws = web.WebSocketResponse(heartbeat=30.0, max_msg_size=_MAX_INCOMING,
                                   compress=False)
        await ws.prepare(request)
        session = None

        async def send(data: bytes) -> None:
            try:
                await ws.send_bytes(data)
            except (ConnectionError, RuntimeError):
                if session is not None:
                    session.close()

        session = self.hub.open_session(send, name=str(request.remote))
        sender = self.hub.spawn(session.run(), owner="console sender")
        self._sockets[ws] = request
        try:
            await ws.send_bytes(encode_frame(self._hello()))
            async for message in ws:
                if message.type is WSMsgType.TEXT:
                    self._on_message(session, message.data)
                elif message.type is WSMsgType.ERROR:
                    break
        finally:
            self._sockets.pop(ws, None)
            self.hub.close_session(session)
            sender.cancel()
        return ws

    def _hello(self) -> dict[str, Any]:
        system = self.hub.system
        return {"kind": "hello", "robot": system.robot, "control": self.guard.control,
                "replay": self.hub.replay is not None, "truth": self.hub.truth is not None,
                "reference": self.hub.options.reference_frame,
                "policies": {kind: {"rate": p.rate, "max_rate": p.max_rate, "depth": p.depth,
                                    "description": p.description}
                             for kind, p in POLICIES.items()},
                "vehicle_control": self.hub.served_name(VehicleControl)}

    def _on_message(self, session: Any, data: str) -> None:
        try:
            message = json.loads(data)
        except (ValueError, RecursionError):  # not JSON, or nested too deeply to read
            message = None
        kinds = None
        if isinstance(message, dict) and message.get("op") == "subscribe":
            kinds = message.get("kinds")
        if isinstance(kinds, dict):
            session.subscribe(kinds)
        else:
            self._note("message", logging.INFO,
                       "console: ignored a message that is not a subscription")

    async def _status(self, request: web.Request) -> web.Response:
        return web.json_response(self.hub.status(), dumps=_dumps)

    # -- actions ---------------------------------------------------------------------------
    def _refused(self, request: web.Request, permission: Permission) -> web.Response | None:
        refusal = self.guard.check_permission(permission, request.headers.get(TOKEN_HEADER))
        if refusal is None:
            return None
        self._note("command", logging.WARNING, "console: refused %s: %s", request.path,
                   refusal)
        return _error(403, refusal)

    async def _component(self, request: web.Request) -> web.Response:
        refused = self._refused(request, "control")
        if refused is not None:
            return refused
        name, action = request.match_info["name"], request.match_info["action"]
        if action not in COMPONENT_ACTIONS:
            return _error(400, f"unknown action {action!r}; known: {', '.join(COMPONENT_ACTIONS)}")
        try:
            state = await self.hub.component_action(name, action)
        except KeyError:
            return _error(404, f"no component named {name!r}")
        except AfaError as exc:
            return _error(409, str(exc))
        return web.json_response({"ok": True, "component": name, "action": action,
                                  "state": state})

    async def _vehicle(self, request: web.Request) -> web.Response:
        action = request.match_info["action"]
        if action not in VEHICLE_ACTIONS:
            return _error(400, f"unknown action {action!r}; known: {', '.join(VEHICLE_ACTIONS)}")
        refused = self._refused(request, "stop" if action == "stop" else "control")
        if refused is not None:
            return refused
        try:
            name = await self.hub.vehicle_action(action)
        except AfaError as exc:
            return _error(503, f"vehicle {action} failed: {exc}")
        return web.json_response({"ok": True, "action": action, "served_by": name})

    async def _replay(self, request: web.Request) -> web.Response:
        action = request.match_info["action"]
        if action not in REPLAY_ACTIONS:
            return _error(400, f"unknown action {action!r}; known: {', '.join(REPLAY_ACTIONS)}")
        refused = self._refused(request, "replay")
        if refused is not None:
            return refused
        try:
            body = await request.json() if request.can_read_body else {}
        except (ValueError, RecursionError):
            return _error(400, "the body is not JSON (or nests too deeply)")
        value = body.get("value") if isinstance(body, dict) else None
        try:
            status = await self.hub.replay_action(action, value)
        except ValueError as exc:
            return _error(400, str(exc))
        except AfaError as exc:
            return _error(409, str(exc))
        return web.json_response({"ok": True, "action": action, "replay": status})


class _RequestErrors(logging.LoggerAdapter[logging.Logger]):
    """aiohttp's log of the requests it could not handle, through ``note``: a malformed
    request (the client's fault, answered 400) in one line without a traceback, an error
    of ours with it; both counted, the first few of each kind logged."""

    def __init__(self, note: Callable[..., None]) -> None:
        super().__init__(logging.getLogger("aiohttp.server"))
        self.note = note

    def log(self, level: int, msg: Any, *args: Any, exc_info: Any = None,
            **kwargs: Any) -> None:
        if level < logging.WARNING:
            super().log(level, msg, *args, exc_info=exc_info, **kwargs)
        elif isinstance(exc_info, HttpProcessingError):
            self.note("malformed", logging.WARNING, "console: malformed request (%d): %.200s",
                      exc_info.code, exc_info.message)
        else:
            self.note("error", logging.ERROR, f"console: {msg}", *args, exc_info=exc_info)


async def _close(ws: web.WebSocketResponse, request: web.Request) -> None:
    """Close ``ws`` within :data:`_CLOSE_TIMEOUT`, then drop whatever its peer left unread
    (a close frame stuck behind unread data would otherwise keep the socket forever)."""
    with contextlib.suppress(asyncio.TimeoutError):
        await asyncio.wait_for(ws.close(code=WSCloseCode.GOING_AWAY,
                                        message=b"the console is stopping"), _CLOSE_TIMEOUT)
    if request.transport is not None:
        request.transport.abort()


def _dumps(value: Any) -> str:
    return json.dumps(finite(value), allow_nan=False, default=str)


def _error(status: int, message: str) -> web.Response:
    return web.json_response({"ok": False, "error": message}, status=status)
