"""The HTTP control API: status, faults, events and keypad parameters of running emulated devices,
as JSON, for a test rig in any language (LabVIEW, TestStand, curl).

It is aiohttp's server on the emulator's own event loop, a shell over the in-process API
(``Adapter.control``, ``Adapter.faults``, ``Adapter.events``): it adds transport, no behaviour. One
API serves every device of a process: ``/devices/{address}/...`` by the device's address (its host,
or ``host:port``), and the same routes at the top for a process that runs one device. A fleet spread
over worker processes has one API in its parent, which forwards each device's routes to the worker
that holds it (``http_relay``); each worker serves this API on a Unix socket only the parent reaches.

Limits (never trust the wire): it listens on loopback unless ``allow_remote`` is given, and then only
with a bearer token, which every request must carry; a request from an address that is not loopback
is refused (403) unless ``allow_remote``; bodies above ``MAX_BODY`` bytes are refused (413); at most
``MAX_IN_FLIGHT`` requests are served at once (503 beyond); a malformed body is a 400 with a JSON
body; nothing a client sends raises out of a handler. The description of every route is at
``/openapi.json``.
"""

from __future__ import annotations

import asyncio
import hmac
import ipaddress
import json
import logging
from collections.abc import Awaitable, Callable
from typing import TYPE_CHECKING, Any

from aiohttp import web

from ..faults import FaultError, FaultStateError, NoSuchConnection

if TYPE_CHECKING:
    from ..adapter import Adapter

log = logging.getLogger(__name__)

MAX_BODY = 16 * 1024
MAX_IN_FLIGHT = 32
#: Events one ``GET .../events`` returns at most (the oldest after ``since`` first).
MAX_EVENTS = 1000

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]

#: The routes of one device: method, path, and the ``HttpApi`` method that serves it. Each answers at
#: the top (a process of one device) and under ``/devices/{device}``; a fleet's relay
#: (``cipstack.control.http_relay``) forwards the same routes, so the API is declared here once.
DEVICE_ROUTES: tuple[tuple[str, str, str], ...] = (
    ("GET", "/status", "status"),
    ("GET", "/faults", "list_faults"),
    ("POST", "/faults", "apply_fault"),
    ("DELETE", "/faults", "clear_faults"),
    ("DELETE", "/faults/{fault}", "clear_faults"),
    ("GET", "/events", "list_events"),
    ("GET", "/parameters/{code}", "get_parameter"),
    ("PUT", "/parameters/{code}", "put_parameter"),
    ("POST", "/trip", "trip"),
)
#: Where a device's routes answer by its address.
DEVICE_PREFIX = "/devices/{device}"


class HttpApiError(ValueError):
    """A setting of the HTTP API that cannot be served (one line)."""


def parse_listen(text: str) -> tuple[str, int]:
    """``HOST:PORT`` of ``--http``."""
    host, sep, port_text = text.rpartition(":")
    if not sep or not host:
        raise HttpApiError(f"--http {text!r} is not HOST:PORT (e.g. 127.0.0.1:8080)")
    try:
        port = int(port_text)
        ipaddress.ip_address(host)
    except ValueError:
        raise HttpApiError(f"--http {text!r} is not HOST:PORT with an IPv4 address and a port number") from None
    if not 0 <= port < 65536:
        raise HttpApiError(f"--http port {port} out of range")
    return host, port


def check_settings(listen: str, token: str | None, allow_remote: bool) -> tuple[str, int]:
    """``--http``, ``--http-token``, ``--http-allow-remote`` checked together; ``HttpApiError`` says why not."""
    host, port = parse_listen(listen)
    if not _is_loopback(host) and not allow_remote:
        raise HttpApiError(f"--http {host}: not a loopback address; another address needs "
                           "--http-allow-remote and --http-token")
    if allow_remote and not token:
        raise HttpApiError("--http-allow-remote needs --http-token (every request must carry it)")
    return host, port


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def json_error(status: int, message: str, **extra: Any) -> web.Response:
    return web.json_response({"error": message, **extra}, status=status)


def no_device(name: str | None, names: list[str]) -> web.Response:
    """404 for a device the API does not serve (``name``), or for a route without an address where
    the API serves more than one device (``name`` None)."""
    if name is None:
        return json_error(404, f"this API serves {len(names)} devices: use /devices/ADDRESS/...", devices=sorted(names))
    return json_error(404, f"no device {name!r}", devices=sorted(names))


class Guard:
    """What every request passes before its handler (an aiohttp middleware): loopback peers only unless
    ``allow_remote``, the bearer ``token`` when one is set, at most ``MAX_IN_FLIGHT`` at once; an error
    of aiohttp's (unknown route, body too large) as a JSON body; nothing a handler raises escapes.
    ``local``: the API listens on a Unix socket (a worker's, reached by its fleet's relay only), where
    the socket's directory is the access control and there is no peer address to check."""

    def __init__(self, token: str | None, allow_remote: bool, local: bool = False) -> None:
        self.token = token
        self.allow_remote = allow_remote
        self.local = local
        self.in_flight = 0

    @web.middleware
    async def middleware(self, request: web.Request, handler: Handler) -> web.StreamResponse:
        peer = request.remote or ""
        if not self.local and not self.allow_remote and not _is_loopback(peer):
            return json_error(403, f"{peer} is not loopback: this API serves loopback only (--http-allow-remote)")
        if self.token is not None:
            given = request.headers.get("Authorization", "")
            if not hmac.compare_digest(given.encode(), f"Bearer {self.token}".encode()):
                return json_error(401, "a request needs the header Authorization: Bearer TOKEN (--http-token)")
        if self.in_flight >= MAX_IN_FLIGHT:
            return json_error(503, f"{MAX_IN_FLIGHT} requests in progress; try again")
        self.in_flight += 1
        try:
            return await handler(request)
        except web.HTTPException as exc:
            if exc.status < 400:
                raise
            return json_error(exc.status, exc.reason)
        except Exception:  # a request must never take the API down
            log.exception("HTTP %s %s", request.method, request.path)
            return json_error(500, "internal error (logged)")
        finally:
            self.in_flight -= 1


async def serve_app(app: web.Application, host: str, port: int, path: str | None = None) -> tuple[web.AppRunner, int]:
    """``app`` served on ``host:port`` (TCP), or on the Unix socket ``path``; the runner and the TCP
    port it got (``port`` 0: the OS's choice). A port or path it cannot take raises ``OSError``."""
    runner = web.AppRunner(app, access_log=None, handle_signals=False)
    await runner.setup()
    site: web.BaseSite = web.UnixSite(runner, path) if path is not None else \
        web.TCPSite(runner, host, port, backlog=64, reuse_address=True)
    try:
        await site.start()
    except OSError:
        await runner.cleanup()
        raise
    server = site._server
    if path is None and server is not None and server.sockets:  # type: ignore[union-attr]
        port = server.sockets[0].getsockname()[1]  # type: ignore[union-attr]
    return runner, port


class HttpApi:
    def __init__(self, devices: dict[str, Adapter], host: str = "127.0.0.1", port: int = 0, *,
                 token: str | None = None, allow_remote: bool = False, path: str | None = None) -> None:
        """``devices``: by address (the host of each, or ``host:port`` when several share a host).
        ``path``: listen on this Unix socket instead of ``host:port`` (a fleet worker's API, which the
        fleet's relay forwards to; its directory is what keeps others out)."""
        if path is None:
            check_settings(f"{host}:{port}", token, allow_remote)
        self.devices = devices
        self.host = host
        self.port = port
        self.path = path
        self.token = token
        self.allow_remote = allow_remote
        self.guard = Guard(token, allow_remote, local=path is not None)
        self._runner: web.AppRunner | None = None
        self.app = self._build()

    # -- serving -----------------------------------------------------------------------------------------
    async def start(self) -> None:
        for adapter in self.devices.values():
            adapter.events.start()  # from now on every event is kept for GET .../events
        self._runner, self.port = await serve_app(self.app, self.host, self.port, self.path)
        if self.path is None:
            log.info("HTTP control API on http://%s:%d/ (openapi.json)", self.host, self.port)

    async def close(self) -> None:
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None

    def _build(self) -> web.Application:
        app = web.Application(client_max_size=MAX_BODY, middlewares=[self.guard.middleware])
        for method, path, name in DEVICE_ROUTES:
            handler = getattr(self, name)
            app.router.add_route(method, path, handler)
            app.router.add_route(method, DEVICE_PREFIX + path, handler)
        app.router.add_get("/devices", self.list_devices)
        app.router.add_get("/openapi.json", openapi)
        return app

    # -- helpers ----------------------------------------------------------------------------------------
    def _device(self, request: web.Request) -> Adapter:
        name = request.match_info.get("device")
        adapter = self.devices.get(name) if name is not None else \
            next(iter(self.devices.values())) if len(self.devices) == 1 else None
        if adapter is None:
            raise _NoDevice(name)
        return adapter

    async def _body(self, request: web.Request) -> dict[str, Any]:
        try:
            body = await request.json(loads=json.loads) if request.can_read_body else {}
        except (ValueError, UnicodeDecodeError):
            raise _BadRequest("the body is not JSON") from None
        if not isinstance(body, dict):
            raise _BadRequest("the body is a JSON object")
        return body

    # -- handlers ---------------------------------------------------------------------------------------
    async def list_devices(self, request: web.Request) -> web.Response:
        return web.json_response([{"address": name, "port": adapter.port,
                                   "product_name": adapter.device.identity_info.product_name}
                                  for name, adapter in sorted(self.devices.items())])

    @staticmethod
    def _handled(handler: Callable[[HttpApi, web.Request], Awaitable[web.Response]]) -> Any:
        async def wrapped(self: HttpApi, request: web.Request) -> web.Response:
            try:
                return await handler(self, request)
            except _NoDevice as exc:
                return no_device(exc.name, list(self.devices))
            except _NotFound as exc:
                return json_error(404, str(exc))
            except (_BadRequest, FaultError) as exc:
                return json_error(400, str(exc))
            except NoSuchConnection as exc:
                return json_error(404, str(exc))
            except (FaultStateError, _Conflict) as exc:
                return json_error(409, str(exc))
        wrapped.__doc__ = handler.__doc__
        return wrapped

    @_handled
    async def status(self, request: web.Request) -> web.Response:
        adapter = self._device(request)
        reply = adapter.control({"command": "status"})
        # "power": "off" while a power-cycle's --off lasts: the device's state is then what it comes back to.
        faults = adapter.faults
        power = "off" if faults.powered_off else "on"
        return web.json_response({**reply, "faults": len(faults.active), "power": power})

    @_handled
    async def list_faults(self, request: web.Request) -> web.Response:
        adapter = self._device(request)
        now = asyncio.get_running_loop().time()
        return web.json_response([f.as_json(now) for f in adapter.faults.faults()])

    @_handled
    async def apply_fault(self, request: web.Request) -> web.Response:
        adapter = self._device(request)
        body = await self._body(request)
        name, options = body.get("name"), body.get("options", {})
        stray = sorted(set(body) - {"name", "options"})
        if stray:
            # {"name": "drop", "share": 0.1} would otherwise read as a drop with no option at all.
            raise _BadRequest(f"unknown key {', '.join(map(repr, stray))}: the body is "
                              "{\"name\": FAULT, \"options\": {...}}, a fault's options go in \"options\"")
        if not isinstance(name, str):
            raise _BadRequest("the body names a fault: {\"name\": \"stop-producing\", \"options\": {...}}")
        if not isinstance(options, dict):
            raise _BadRequest("options are a JSON object")
        fault = adapter.faults.apply(name, **options)
        await adapter.faults.settle()
        return web.json_response(fault.as_json(asyncio.get_running_loop().time()), status=201)

    @_handled
    async def clear_faults(self, request: web.Request) -> web.Response:
        adapter = self._device(request)
        which: int | str | None = request.match_info.get("fault")
        if isinstance(which, str) and which.isdigit():
            which = int(which)
        try:
            cleared = adapter.faults.clear(which)
        except FaultError as exc:
            raise _NotFound(str(exc)) from None
        await adapter.faults.settle()
        return web.json_response([f.as_json() for f in cleared])

    @_handled
    async def list_events(self, request: web.Request) -> web.Response:
        adapter = self._device(request)
        try:
            since = int(request.query.get("since", "0"))
        except ValueError:
            raise _BadRequest("since is an event number") from None
        events = adapter.events.since(since)[:MAX_EVENTS]
        return web.json_response([e.as_json() for e in events])

    @_handled
    async def get_parameter(self, request: web.Request) -> web.Response:
        adapter = self._device(request)
        return web.json_response(_keypad_call(lambda: adapter.keypad_parameter(request.match_info["code"])))

    @_handled
    async def put_parameter(self, request: web.Request) -> web.Response:
        adapter = self._device(request)
        body = await self._body(request)
        code = request.match_info["code"]
        value = body.get("value")
        if set(body) != {"value"} or isinstance(value, (dict, list, bool)) or value is None:
            raise _BadRequest("the body is {\"value\": VALUE}, in the keypad's unit (\"2.5\", 60, or an "
                              "enumeration's name)")
        # The client's host:port; none behind a fleet's relay (a worker's API is on a Unix socket).
        peer = request.transport.get_extra_info("peername") if request.transport is not None else None
        where = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) and len(peer) >= 2 else None
        return web.json_response(_keypad_call(
            lambda: adapter.set_keypad_parameter(code, value, origin="http", peer=where)))

    @_handled
    async def trip(self, request: web.Request) -> web.Response:
        adapter = self._device(request)
        body = await self._body(request)
        from . import ControlDenied, ControlError

        try:
            return web.json_response(adapter.control({"command": "trip", "code": body.get("code")}))
        except ControlDenied as exc:
            return json_error(409, str(exc))
        except (ControlError, KeyError, TypeError) as exc:
            raise _BadRequest(str(exc)) from None

async def openapi(request: web.Request) -> web.Response:
    return web.json_response(openapi_document())


class _NoDevice(LookupError):
    def __init__(self, name: str | None) -> None:
        super().__init__(name)
        self.name = name


def _keypad_call(call: Callable[[], dict[str, Any]]) -> dict[str, Any]:
    """A keypad read or write (``cipstack.devices.keypad``): a code the keypad lacks or a device without
    one (a ``LookupError``) is 404, a write the device refuses (a ``ValueError`` with ``conflict``) 409,
    a value the keypad does not take (another ``ValueError``) 400, each with its reason."""
    try:
        return call()
    except LookupError as exc:
        raise _NotFound(str(exc)) from None
    except ValueError as exc:
        if getattr(exc, "conflict", False):
            raise _Conflict(str(exc)) from None
        raise _BadRequest(str(exc)) from None


class _NotFound(LookupError):
    def __str__(self) -> str:
        return str(self.args[0])


class _BadRequest(ValueError):
    pass


class _Conflict(Exception):
    """The request was understood and the device's state refuses it (409)."""


def openapi_document() -> dict[str, Any]:
    """The OpenAPI 3.0 description of the API (``/openapi.json``)."""
    from ..faults import FAULTS

    error = {"description": "an error",
             "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}}
    ok = {"description": "JSON", "content": {"application/json": {"schema": {"type": "object"}}}}
    device = {"name": "device", "in": "path", "required": True, "schema": {"type": "string"},
              "description": "the device's address (its host, or host:port)"}
    paths: dict[str, Any] = {}

    def route(path: str, method: str, summary: str, body: dict[str, Any] | None = None,
              params: list[dict[str, Any]] | None = None, codes: tuple[str, ...] = ("400", "404", "503")) -> None:
        operation: dict[str, Any] = {"summary": summary, "responses": {"200": ok, **{c: error for c in codes}}}
        if body is not None:
            operation["requestBody"] = {"required": True, "content": {"application/json": {"schema": body}}}
        for prefix, extra in (("", []), (DEVICE_PREFIX, [device])):
            entry = dict(operation)
            if params or extra:
                entry["parameters"] = [*extra, *(params or [])]
            paths.setdefault(prefix + path, {})[method] = entry

    fault_body = {"type": "object", "required": ["name"], "additionalProperties": False, "properties": {
        "name": {"type": "string", "enum": list(FAULTS)},
        "options": {"type": "object", "description": "the fault's options, as `cipstack drive fault` names them "
                                                     "(share, every, by, jitter, connection, for, ...)"}}}
    code = {"name": "code", "in": "path", "required": True, "schema": {"type": "string"},
            "description": "keypad code: the ACG's (drv, Frq, ACC, CM.23, ...), an MX2/RX function code "
                           "(F001, A004, P044, ...); 404 for a code the keypad lacks or a device without one"}
    fault_id = {"name": "fault", "in": "path", "required": True, "schema": {"type": "string"},
                "description": "a fault's id, or a fault name (all of that name)"}
    route("/status", "get", "the drive's state, sessions and connections, active faults, power on or off")
    route("/faults", "get", "the faults active")
    route("/faults", "post", "apply a fault", fault_body, codes=("400", "404", "409", "503"))
    route("/faults", "delete", "clear every active fault")
    route("/faults/{fault}", "delete", "clear one fault", params=[fault_id])
    route("/events", "get", "the events after number `since`", params=[
        {"name": "since", "in": "query", "schema": {"type": "integer", "minimum": 0}}])
    route("/parameters/{code}", "get", "a keypad parameter: code, name, value in the keypad's unit, raw, unit, "
          "address", params=[code])
    route("/parameters/{code}", "put", "set a keypad parameter (not saved): 400 for a value the keypad does not "
          "take, 409 for a write the device refuses (read-only, not while running), with its reason",
          {"type": "object", "required": ["value"], "additionalProperties": False,
           "properties": {"value": {"type": ["string", "number"]}}},
          params=[code], codes=("400", "404", "409"))
    route("/trip", "post", "trip the drive", {"type": "object", "required": ["code"],
                                              "properties": {"code": {"type": ["string", "integer"]}}},
          codes=("400", "404", "409", "503"))
    paths["/devices"] = {"get": {"summary": "the devices this API serves (in a fleet of workers, each with its "
                                            "worker's number, and `error` where that worker is lost)",
                                 "responses": {"200": ok}}}
    return {"openapi": "3.0.3",
            "info": {"title": "cipstack emulator control", "version": "1"},
            "paths": paths,
            "components": {"schemas": {"Error": {"type": "object", "required": ["error"],
                                                 "properties": {"error": {"type": "string"}}}},
                           "securitySchemes": {"token": {"type": "http", "scheme": "bearer"}}}}
