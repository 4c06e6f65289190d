"""The HTTP control API: status, faults, events and keypad parameters of running emulated devices,
as JSON, for a test rig in any language (LabVIEW, TestStand, curl).

It is aiohttp's server on the emulator's own event loop, a shell over the command service
(``cipstack.control.service``): it adds transport, no behaviour, and its routes and ``/openapi.json``
are generated from the service's operations (``operations.OPERATIONS``). One
API serves every device of a process: ``/devices/{address}/...`` by the device's address (its host,
or ``host:port``), and the same routes at the top for a process that runs one device. A fleet spread
over worker processes has one API in its parent, which forwards each device's routes to the worker
that holds it (``http_relay``); each worker serves this API on a Unix socket only the parent reaches.

Limits (never trust the wire): it listens on loopback unless ``allow_remote`` is given, and then only
with a bearer token, which every request must carry; a request from an address that is not loopback
is refused (403) unless ``allow_remote``; bodies above ``MAX_BODY`` bytes are refused (413); at most
``MAX_IN_FLIGHT`` requests are served at once (503 beyond), the front panel's streams apart
(``panel_app.MAX_STREAMS``); at most ``MAX_CONNECTIONS`` connections, shared between addresses by the
listeners' one policy (``HttpConnections``); a malformed request, target, query or body is a 400 with
a JSON body; every answer says ``X-Content-Type-Options: nosniff``; nothing a client sends raises out
of a handler, and what it sends is logged one line per source per 10 s, never a traceback, never a
credential (``redact``). The description of every route is at ``/openapi.json``.
"""

from __future__ import annotations

import asyncio
import hmac
import ipaddress
import json
import logging
import re
import traceback
from collections.abc import Awaitable, Callable, Mapping
from functools import partial
from typing import TYPE_CHECKING, Any

from aiohttp import web

from ..eip.target.limits import RateLimitedLog, guarded_listener, quiet_accept_errors
from ..errors import BadRequest, CipstackError
from .http_connections import (
    ALWAYS_HEADERS,
    HEADER_TIMEOUT,
    RETRY_AFTER_S,
    HttpConnections,
    HttpListener,
)
from .metrics import ShardGauges, add_metrics_route
from .operations import OPERATIONS, Operation
from .panel_app import PanelStreams
from .panel_app import log as panel_log
from .plant_grid import SharedRows, plant_rows
from .service import outcome, whole_number
from .tokens import weak_token_reason

if TYPE_CHECKING:
    from .service import DeviceService

log = logging.getLogger(__name__)

MAX_BODY = 16 * 1024
MAX_IN_FLIGHT = 32

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]

def _routes(operation: Operation) -> list[str]:
    """The paths an operation answers on (``DELETE /faults`` and ``DELETE /faults/{which}``)."""
    if operation.optional_path:
        return [operation.path.split("/{", 1)[0], operation.path]
    return [operation.path]


#: The routes of one device, generated from the command service's operations: method, path, operation.
#: Each answers at the top (a process of one device) and under ``/devices/{device}``; a fleet's relay
#: (``cipstack.control.http_relay``) forwards the same routes.
DEVICE_ROUTES: tuple[tuple[str, str, Operation], ...] = tuple(
    (operation.method, path, operation) for operation in OPERATIONS for path in _routes(operation))
#: Where a device's routes answer by its address.
DEVICE_PREFIX = "/devices/{device}"
#: The front panel's live stream of a device (``panel_app``), at the top and under ``DEVICE_PREFIX``.
STREAM_PATH = "/stream"
#: The routes of the streams: bounded by ``panel_app.MAX_STREAMS``, never counted as requests in flight
#: (a panel left open must not take a request's place).
STREAM_ROUTES = frozenset({STREAM_PATH, DEVICE_PREFIX + STREAM_PATH})


class HttpApiError(BadRequest):
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
    if allow_remote and token:   # the token is then the only lock: one that can be guessed is none
        reason = weak_token_reason(token)
        if reason is not None:
            raise HttpApiError(f"--http-allow-remote: {reason}")
    return host, port


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def json_error(status: int, message: str, *, headers: Mapping[str, str] | None = None, **extra: Any) -> web.Response:
    return web.json_response({"error": message, **extra}, status=status, headers={**ALWAYS_HEADERS, **(headers or {})})


def busy(message: str) -> web.Response:
    """503 for want of room, with when to try again."""
    return json_error(503, message, headers={"Retry-After": str(RETRY_AFTER_S)})


def check_target(raw: str) -> str | None:
    """Why a request's target (``raw``, as the request line gave it) is not served, or None: only an
    origin-form target (a path from ``/``, then its query). An absolute-form target
    (``http://host/path``, for proxies) would give the path, the host and the URL that a relay
    forwards other values than the ``Host`` header that the guard checks; ``*`` and ``//name`` are
    no path of this API either."""
    if not raw.startswith("/") or raw.startswith("//"):
        shown = raw if len(raw) <= 60 else raw[:60] + "..."
        return f"the request target {shown!r} is not a path: send GET /devices/... with a Host header"
    return None


# -- logs: one line each, no credential --------------------------------------------------------------------
#: What stands for a credential in a log line.
REDACTED = "[redacted]"
#: The tokens of this process's APIs (each ``Guard`` adds its own), never written in a log line.
_SECRETS: set[str] = set()
#: Credentials as a client sends them, whatever the token: a header with its value (to the end of the
#: line or quote), an authorization scheme with its credentials, a secret in a query.
_CREDENTIALS = re.compile(
    r"(?i)\b((?:proxy-)?authorization|cookie|x-api-key)\b(\s*:?\s*)[^\r\n'\"]*"
    r"|\b(bearer|basic|digest)(\s+)[^\s'\",;]+"
    r"|\b(access_token|token|password|secret)(=)[^\s'\"&;]+")
#: The longest a client's text quoted in a log line may be.
_MAX_QUOTED = 160


def redact(text: str) -> str:
    """``text`` with every credential in it replaced by ``REDACTED``: the tokens of this process's
    APIs, and whatever a client sends as one (``Authorization: ...``, ``Bearer ...``, ``token=...``)."""
    for secret in _SECRETS:
        text = text.replace(secret, REDACTED)

    def hide(match: re.Match[str]) -> str:
        name, separator = (match.group(1), match.group(2)) if match.group(1) else \
            (match.group(3), match.group(4)) if match.group(3) else (match.group(5), match.group(6))
        return f"{name}{separator}{REDACTED}"

    return _CREDENTIALS.sub(hide, text)


def _one_line(text: str) -> str:
    """``text`` on one line: line breaks and other control characters escaped."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def describe_exception(exc: BaseException) -> str:
    """An exception in one line: its type, its message's first line (bounded), where it was raised."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    if len(text) > _MAX_QUOTED:
        text = text[:_MAX_QUOTED] + "..."
    where = ""
    frames = traceback.extract_tb(exc.__traceback__) if exc.__traceback__ is not None else []
    if frames:
        where = f" (at {frames[-1].filename.rsplit('/', 1)[-1]}:{frames[-1].lineno})"
    return f"{type(exc).__name__}{': ' + text if text else ''}{where}"


class OneLineRecords(logging.Filter):
    """Each record of a logger of the HTTP API as one line and with no credential: a traceback becomes
    its exception in one line (``describe_exception``), and ``redact`` runs over the whole. A client
    can neither fill the log with tracebacks nor have a token written in clear."""

    def filter(self, record: logging.LogRecord) -> bool:
        text = record.getMessage()
        if record.exc_info and record.exc_info[1] is not None:
            text += ": " + describe_exception(record.exc_info[1])
        record.msg = redact(_one_line(text))
        record.args = ()
        record.exc_info = None
        record.exc_text = None
        record.stack_info = None
        return True


def one_line_records(logger: logging.Logger) -> None:
    """``OneLineRecords`` on ``logger`` (once)."""
    if not any(isinstance(f, OneLineRecords) for f in logger.filters):
        logger.addFilter(OneLineRecords())


#: aiohttp's own records of the servers here (what it cannot parse, what escapes a handler).
server_log = logging.getLogger(__name__ + ".server")
for _logger in (log, server_log, panel_log):
    one_line_records(_logger)


def no_device(name: str | None, names: list[str]) -> web.Response:
    """404 for a device the API does not serve (``name``), or for a route without an address where
    the API serves more than one device (``name`` None)."""
    if name is None:
        return json_error(404, f"this API serves {len(names)} devices: use /devices/ADDRESS/...", devices=sorted(names))
    return json_error(404, f"no device {name!r}", devices=sorted(names))


#: Methods that change something: from a browser, only the API's own page may send them.
_CHANGING = frozenset({"POST", "PUT", "DELETE", "PATCH"})
#: What ``Sec-Fetch-Site`` says of a request a browser sent from the API's own page, or not from a page.
_SAME_SITE = frozenset({"same-origin", "none"})


def _host_name(host_header: str) -> str:
    """The name or address of a ``Host`` header, without its port (``[::1]:8080`` -> ``::1``)."""
    host = host_header.strip()
    if host.startswith("["):
        return host[1:].split("]", 1)[0]
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


def _is_address(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


def _public(request: web.Request) -> bool:
    """The front panel's own files: the same for everyone, no secret in them, so a browser loads them
    without the token (the page then asks for it, and sends it with every call of the API)."""
    return request.method == "GET" and (request.path == "/" or request.path.startswith("/panel/"))


class Guard:
    """What every request passes before its handler (an aiohttp middleware): loopback peers only unless
    ``allow_remote``, the bearer ``token`` when one is set, at most ``MAX_IN_FLIGHT`` at once; an error
    of aiohttp's (unknown route, body too large) as a JSON body; nothing a handler raises escapes.

    Browsers: a web page of another origin that the test engineer opens must not drive the emulator.
    A ``Host`` that is not an address, ``localhost`` or one of ``hosts`` is refused (a DNS-rebinding
    page names the API by a name of its own); a request that changes something is refused when its
    ``Origin`` is not the API's own (``null`` included: a sandboxed or ``file://`` page) or, without
    ``Origin``, when ``Sec-Fetch-Site`` says another site sent it; and its body must be JSON
    (``Content-Type: application/json``), which no page of another origin can send without the API's
    consent (a CORS preflight, which it never gives). curl and scripts send none of these headers but
    the content type. ``local``: the API listens on a Unix socket (a worker's, reached by its fleet's
    relay only, which has checked all this), where the socket's directory is the access control."""

    def __init__(self, token: str | None, allow_remote: bool, local: bool = False,
                 hosts: tuple[str, ...] = ()) -> None:
        self.token = token
        self.allow_remote = allow_remote
        self.local = local
        #: Host names the API answers to besides addresses and localhost (``--http-allow-host``).
        self.hosts = frozenset(h.lower() for h in hosts)
        self.in_flight = 0
        #: What escapes a handler (a defect of ours, never a client's): one line per source per 10 s.
        self.defects = RateLimitedLog(log, level=logging.ERROR)
        if token:
            _SECRETS.add(token)

    def refusal(self, request: web.Request) -> tuple[int, str] | None:
        """The status and the reason ``request`` is refused for before its handler, or None."""
        peer = request.remote or ""
        if not self.allow_remote and not _is_loopback(peer):
            return 403, f"{peer} is not loopback: this API serves loopback only (--http-allow-remote)"
        name = _host_name(request.headers.get("Host", "")).lower()
        if not (_is_address(name) or name == "localhost" or name.endswith(".localhost") or name in self.hosts):
            return 403, (f"Host {name!r} is not this API's: use its address, localhost, or name it with "
                         "--http-allow-host")
        if request.method in _CHANGING:
            origin = request.headers.get("Origin")
            if origin is not None:
                own = f"{request.scheme}://{request.headers.get('Host', '')}".lower()
                if origin.strip().lower() != own:
                    return 403, (f"Origin {origin!r} is not this API's own: a page of another origin "
                                 "cannot change the emulator")
            elif request.headers.get("Sec-Fetch-Site", "none").lower() not in _SAME_SITE:
                return 403, ("a request a browser sent from another site cannot change the emulator "
                             "(Sec-Fetch-Site)")
            if request.can_read_body and request.content_type != "application/json":
                return 415, "a body is JSON: send it with Content-Type: application/json"
        return None

    @web.middleware
    async def middleware(self, request: web.Request, handler: Handler) -> web.StreamResponse:
        connections = request.app.get(CONNECTIONS)
        if connections is not None:
            connections.started(request.protocol)    # its head came in time: busy until its answer
        try:
            return await self._guarded(request, handler, connections)
        finally:
            if connections is not None:
                connections.finished(request.protocol)

    async def _guarded(self, request: web.Request, handler: Handler,
                       connections: HttpConnections | None) -> web.StreamResponse:
        wrong_target = check_target(request.raw_path)
        if wrong_target is not None:   # a malformed request, logged as those aiohttp cannot parse are
            if connections is not None:
                connections.malformed(request.remote, 400, wrong_target)
            else:
                log.info("HTTP request refused (400): %s", wrong_target)
            return json_error(400, wrong_target)
        if not self.local:
            refused = self.refusal(request)
            if refused is not None:
                # Said once per request, so that whoever wonders why a page or a script is refused reads it.
                log.info("HTTP %s %s refused (%d): %s", request.method, request.path, *refused)
                return json_error(*refused)
        if self.token is not None and not _public(request):
            given = request.headers.get("Authorization", "")
            # A header aiohttp decoded with surrogates (bytes that are not UTF-8) compares as what it is.
            if not hmac.compare_digest(given.encode("utf-8", "surrogateescape"), f"Bearer {self.token}".encode()):
                return json_error(401, "a request needs the header Authorization: Bearer TOKEN (--http-token)")
        # A stream is bounded by the streams' own limit (``panel_app.MAX_STREAMS``), never by this one:
        # panels left open must not leave the API without room for requests.
        stream = request.match_info.route.resource is not None and \
            request.match_info.route.resource.canonical in STREAM_ROUTES
        if not stream and self.in_flight >= MAX_IN_FLIGHT:
            return busy(f"{MAX_IN_FLIGHT} requests in progress; try again")
        self.in_flight += not stream
        try:
            return await handler(request)
        except web.HTTPException as exc:
            if exc.status < 400:
                raise
            # 503: no room (the streams' bound), which is said with when to try again.
            return busy(exc.reason) if exc.status == 503 else json_error(exc.status, exc.reason)
        except Exception as exc:  # a request must never take the API down
            self.defects("HTTP %s %s from %s: internal error, a defect: %s", request.method, request.path,
                         request.remote, describe_exception(exc), source=request.remote)
            return json_error(500, "internal error (logged)")
        finally:
            self.in_flight -= not stream


#: Seconds a request's body has to arrive whole once its head has.
BODY_TIMEOUT = 10.0


class QuietRequestHandler(web.RequestHandler):
    """aiohttp's protocol of a connection, but a request it cannot parse (a bad request line or header)
    is answered with a JSON body and logged one line per source per 10 s with the reason, never a
    traceback, never the bytes of a header (a token in a malformed ``Authorization`` header)."""

    __slots__ = ("connections",)

    def __init__(self, manager: web.Server, connections: HttpConnections, **kwargs: Any) -> None:
        super().__init__(manager, **kwargs)
        self.connections = connections

    def handle_error(self, request: Any, status: int = 500, exc: BaseException | None = None,
                     message: str | None = None) -> web.StreamResponse:
        if status >= 500:
            reason = "internal error (logged)"
            self.connections.malformed(request.remote, status, "internal error, a defect: "
                                       + (describe_exception(exc) if exc is not None else "unknown"))
        else:
            reason = _parse_error(exc, message)
            self.connections.malformed(request.remote, status, reason)
        if request.writer.output_size > 0:   # an answer began: there is none to give but the close
            raise ConnectionError("an answer began already: the connection ends here")
        response = json_error(status, reason)
        response.force_close()
        return response


def _parse_error(exc: BaseException | None, message: str | None) -> str:
    """What aiohttp found wrong with a request, in one line without the client's bytes: the first line
    of its message (``Invalid header value char``), redacted and bounded."""
    text = getattr(exc, "message", None) or message or str(exc or "")
    first = str(text).strip().splitlines()[0].rstrip(":") if str(text).strip() else "malformed request"
    first = redact(_one_line(first))
    return "malformed request: " + (first if len(first) <= _MAX_QUOTED else first[:_MAX_QUOTED] + "...")


class ServedApp:
    """An app being served: aiohttp's runner and, on TCP, the listener of ``HttpConnections``."""

    def __init__(self, runner: web.AppRunner, port: int, server: asyncio.AbstractServer | None = None) -> None:
        self.runner = runner
        self.port = port
        self.server = server

    async def close(self) -> None:
        """Stop accepting, then close every connection (aiohttp's cleanup ends the requests in flight)."""
        if self.server is not None:
            self.server.close()
        await self.runner.cleanup()
        if self.server is not None:
            await self.server.wait_closed()


#: Seconds closing an API waits for a request in progress (then for its cancellation) before it goes
#: on: an answer that never ends (a stream whose source went silent) cannot hold a stop.
STOP_WAIT_S = 0.5


async def serve_app(app: web.Application, host: str, port: int, path: str | None = None) -> ServedApp:
    """``app`` served on ``host:port`` (TCP, through ``HttpConnections``), or on the Unix socket ``path``
    (``port`` 0: the OS's choice). A port or path it cannot take raises ``OSError``."""
    connections = app.get(CONNECTIONS)
    # What aiohttp's protocol of each connection takes: its own records go to a logger of ours, one line each.
    options: dict[str, Any] = {"access_log": None, "logger": server_log,
                               "keepalive_timeout": connections.header_timeout if connections else HEADER_TIMEOUT}
    runner = web.AppRunner(app, handle_signals=False, shutdown_timeout=STOP_WAIT_S, **options)
    await runner.setup()
    if path is not None:
        site = web.UnixSite(runner, path)
        try:
            await site.start()
        except OSError:
            await runner.cleanup()
            raise
        return ServedApp(runner, port)
    loop = asyncio.get_running_loop()
    quiet_accept_errors(loop)
    try:
        listener = guarded_listener(host, port)
    except OSError:
        await runner.cleanup()
        raise
    server = runner.server
    assert server is not None  # made by runner.setup()
    factory: Callable[[], asyncio.BaseProtocol] = server
    if connections is not None:
        factory = HttpListener(connections, partial(QuietRequestHandler, server, loop=loop, **options))
    try:
        listening = await loop.create_server(factory, sock=listener)
    except BaseException:
        listener.close()
        await runner.cleanup()
        raise
    return ServedApp(runner, int(listener.getsockname()[1]), listening)


#: Where an app keeps its ``HttpConnections`` (the guard marks the connections that began a request).
CONNECTIONS: web.AppKey[HttpConnections] = web.AppKey("cipstack_http_connections", HttpConnections)


async def _always_headers(request: web.Request, response: web.StreamResponse) -> None:
    response.headers.update(ALWAYS_HEADERS)


def guarded_app(guard: Guard) -> web.Application:
    """An application of the API (one process's, or a relay's): ``guard`` before every handler, bodies
    within ``MAX_BODY``, its connections bounded (``HttpConnections``), ``ALWAYS_HEADERS`` on every
    answer, aiohttp's records one line each."""
    app = web.Application(client_max_size=MAX_BODY, middlewares=[guard.middleware], logger=server_log)
    app[CONNECTIONS] = HttpConnections()
    app.on_response_prepare.append(_always_headers)
    return app


class HttpApi:
    def __init__(self, devices: dict[str, DeviceService], host: str = "127.0.0.1", port: int = 0, *,
                 token: str | None = None, allow_remote: bool = False, path: str | None = None,
                 hosts: tuple[str, ...] = (), shard: ShardGauges | None = None) -> None:
        """``devices``: the command service of each device, by address (its host, or ``host:port`` when
        several share a host). ``path``: listen on this Unix socket instead of ``host:port`` (a fleet
        worker's API, which the fleet's relay forwards to; its directory is what keeps others out).
        ``shard``: a fleet's gauges of itself on ``/metrics``."""
        if path is None:
            check_settings(f"{host}:{port}", token, allow_remote)
        self.devices = devices
        self.host = host
        self.port = port
        self.path = path
        self.token = token
        self.allow_remote = allow_remote
        self.guard = Guard(token, allow_remote, local=path is not None, hosts=hosts)
        self.shard = shard
        self.panel = PanelStreams()
        self._served: ServedApp | None = None
        self._plant = SharedRows(lambda: plant_rows(self.devices))
        self.app = self._build()

    # -- serving -----------------------------------------------------------------------------------------
    async def start(self) -> None:
        for service in self.devices.values():
            service.events.start()  # from now on every event is kept for GET .../events
        self._served = await serve_app(self.app, self.host, self.port, self.path)
        self.port = self._served.port
        if self.path is None:
            log.info("HTTP control API on http://%s:%d/ (the front panel; openapi.json)", self.host, self.port)

    async def close(self) -> None:
        self.panel.close()
        if self._served is not None:
            await self._served.close()
            self._served = None

    def _build(self) -> web.Application:
        app = guarded_app(self.guard)
        for method, path, operation in DEVICE_ROUTES:
            handler = self._handler(operation)
            app.router.add_route(method, path, handler)
            app.router.add_route(method, DEVICE_PREFIX + path, handler)
        app.router.add_get("/devices", self.list_devices)
        app.router.add_get("/plant", self.plant)
        app.router.add_get("/openapi.json", openapi)
        add_metrics_route(app, self.devices, self.shard)
        app.router.add_get(STREAM_PATH, self.stream)
        app.router.add_get(DEVICE_PREFIX + STREAM_PATH, self.stream)
        self.panel.add_routes(app)
        return app

    def _service(self, request: web.Request) -> DeviceService | web.Response:
        """The device a request's route names (the only one where it names none), or the 404 saying so."""
        name = request.match_info.get("device")
        service = self.devices.get(name) if name is not None else \
            next(iter(self.devices.values())) if len(self.devices) == 1 else None
        return service if service is not None else no_device(name, list(self.devices))

    async def stream(self, request: web.Request) -> web.StreamResponse:
        service = self._service(request)
        if isinstance(service, web.Response):
            return service
        try:   # before any answer begins: a stream, once its head is out, can only end
            since = whole_number("since", request.query.get("since", "0"))
        except BadRequest as exc:
            return json_error(400, str(exc))
        return await self.panel.stream(request, service, since)

    async def list_devices(self, request: web.Request) -> web.Response:
        return web.json_response([{"address": name, **service.describe()}
                                  for name, service in sorted(self.devices.items())])

    async def plant(self, request: web.Request) -> web.Response:
        """Every device's row of the plant grid (``plant_grid``), one reading shared by the grids open."""
        return web.json_response(await self._plant.get())

    def _handler(self, operation: Operation) -> Callable[[web.Request], Awaitable[web.Response]]:
        async def handle(request: web.Request) -> web.Response:
            service = self._service(request)
            if isinstance(service, web.Response):
                return service
            try:
                arguments = await _arguments(operation, request)
                # The client's host:port; none behind a fleet's relay (a worker's API is on a Unix socket).
                peer = request.transport.get_extra_info("peername") if request.transport is not None else None
                where = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) and len(peer) >= 2 else None
                result = await service.call_async(operation.name, arguments, origin="http", peer=where)
            except CipstackError as exc:
                found = outcome(exc)
                return json_error(found.http_status if found is not None else 500, str(exc))
            return web.json_response(result, status=201 if operation.created else 200)
        handle.__doc__ = operation.summary
        return handle


#: The deepest JSON a body may nest (an operation's body is two levels deep: a fault's options).
MAX_JSON_DEPTH = 8
#: The most digits a JSON number may have (a duration, a count, a connection id have far fewer).
MAX_NUMBER_DIGITS = 20


def _bounded_number(text: str) -> int | float:
    if len(text.lstrip("-").replace(".", "").split("e")[0].split("E")[0]) > MAX_NUMBER_DIGITS:
        raise BadRequest(f"a number of the body has more than {MAX_NUMBER_DIGITS} digits")
    return float(text) if any(c in text for c in ".eE") else int(text)


def _depth(value: Any, limit: int) -> None:
    """Raise ``BadRequest`` when ``value`` nests deeper than ``limit``."""
    if limit < 0:
        raise BadRequest(f"the body nests deeper than {MAX_JSON_DEPTH} levels")
    children = value.values() if isinstance(value, dict) else value if isinstance(value, list) else ()
    for child in children:
        _depth(child, limit - 1)


def parse_body(text: str) -> Any:
    """A request body as JSON, bounded: nesting, number sizes; anything else a 400 naming the problem."""
    try:
        loaded = json.loads(text, parse_int=_bounded_number, parse_float=_bounded_number,
                            parse_constant=_no_constant)
    except RecursionError:
        raise BadRequest(f"the body nests deeper than {MAX_JSON_DEPTH} levels") from None
    except ValueError as exc:
        if isinstance(exc, BadRequest):
            raise
        raise BadRequest("the body is not JSON") from None
    _depth(loaded, MAX_JSON_DEPTH)
    return loaded


def _no_constant(name: str) -> Any:
    raise BadRequest(f"{name} is not a JSON number")


async def _arguments(operation: Operation, request: web.Request) -> dict[str, Any]:
    """An operation's arguments from its route (path), its query and its JSON body, by their JSON keys;
    a key the operation does not take is a 400 naming the keys it takes."""
    arguments: dict[str, Any] = {}
    body: dict[str, Any] = {}
    if request.can_read_body:
        try:
            text = await asyncio.wait_for(request.text(), BODY_TIMEOUT)
        except UnicodeDecodeError:
            raise BadRequest("the body is not JSON (not UTF-8)") from None
        except asyncio.TimeoutError:
            raise web.HTTPRequestTimeout(reason=f"the body did not arrive within {BODY_TIMEOUT:g} s") from None
        loaded = parse_body(text) if text.strip() else {}
        if not isinstance(loaded, dict):
            raise BadRequest("the body is a JSON object")
        body = loaded
    takes = {a.key for a in operation.arguments if a.where == "body"}
    stray = sorted(set(body) - takes)
    if stray:
        keys = ", ".join(f'"{k}"' for k in sorted(takes)) or "none"
        raise BadRequest(f"unknown key {', '.join(map(repr, stray))}: the body is {{{keys}}}{operation.body_hint}")
    for argument in operation.arguments:
        if argument.where == "path":
            value: Any = request.match_info.get(argument.key)
        elif argument.where == "query":
            value = request.query.get(argument.key)
        else:
            value = body.get(argument.key)
        if isinstance(value, str) and argument.where != "body" and argument.json_type == "integer":
            value = whole_number(argument.key, value)
        if value is not None:
            arguments[argument.key] = value
    return arguments


async def openapi(request: web.Request) -> web.Response:
    return web.json_response(openapi_document())


_JSON_TYPES: dict[str, dict[str, Any]] = {
    "string": {"type": "string"}, "integer": {"type": "integer"}, "number": {"type": "number"},
    "object": {"type": "object"}, "string|integer": {"type": ["string", "integer"]},
    "string|number": {"type": ["string", "number"]}}


def openapi_document() -> dict[str, Any]:
    """The OpenAPI 3.0 description of the API (``/openapi.json``), generated from the operations: each
    route's parameters and body by their JSON keys, and the statuses of the outcome table."""
    from .service import OUTCOMES

    error = {"description": "an error",
             "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Error"}}}}
    ok = {"description": "JSON", "content": {"application/json": {"schema": {}}}}
    device = {"name": "device", "in": "path", "required": True, "schema": {"type": "string"},
              "description": "the device's address (its host, or host:port)"}
    errors = {str(result.http_status): {**error, "description": f"{result.name}"} for _, result in OUTCOMES}
    paths: dict[str, Any] = {}
    for method, path, operation in DEVICE_ROUTES:
        params: list[dict[str, Any]] = []
        body: dict[str, Any] = {}
        for argument in operation.arguments:
            schema = dict(_JSON_TYPES[argument.json_type])
            if argument.choices is not None:
                schema["enum"] = argument.choices()
            if argument.where == "body":
                body[argument.key] = {**schema, "description": argument.help}
            elif f"{{{argument.key}}}" in path or argument.where == "query":
                params.append({"name": argument.key, "in": argument.where, "required": argument.where == "path",
                               "schema": schema, "description": argument.help})
        entry: dict[str, Any] = {"summary": operation.summary, "operationId": operation.name,
                                 "responses": {"201" if operation.created else "200": ok, **errors}}
        if body:
            required = [a.key for a in operation.arguments if a.where == "body" and a.required]
            entry["requestBody"] = {"required": bool(required), "content": {"application/json": {"schema": {
                "type": "object", "additionalProperties": False, "properties": body,
                **({"required": required} if required else {})}}}}
        for prefix, extra in (("", []), (DEVICE_PREFIX, [device])):
            routed = dict(entry)
            if params or extra:
                routed["parameters"] = [*extra, *params]
            if prefix:
                routed["operationId"] = operation.name + "-by-address"
            paths.setdefault(prefix + path, {})[method.lower()] = routed
    stream: dict[str, Any] = {
        "summary": "the front panel's live feed: Server-Sent Events `status`, `faults` and `connections` when "
                   "they change and the new `events`, twice a second",
        "operationId": "stream",
        "parameters": [{"name": "since", "in": "query", "required": False, "schema": {"type": "integer"},
                        "description": "the last event the client has (0: every event kept)"}],
        "responses": {"200": {"description": "a stream of events",
                              "content": {"text/event-stream": {"schema": {"type": "string"}}}}, **errors}}
    paths[STREAM_PATH] = {"get": stream}
    paths[DEVICE_PREFIX + STREAM_PATH] = {"get": {**stream, "operationId": "stream-by-address",
                                                  "parameters": [device, *stream["parameters"]]}}
    paths["/devices"] = {"get": {"summary": "the devices this API serves (in a fleet of workers, each with its "
                                            "worker's number, and `error` where that worker is lost)",
                                 "operationId": "devices", "responses": {"200": ok}}}
    paths["/plant"] = {"get": {"summary": "one row of every device for the plant grid: state, output, power and "
                                          "link, connections, faults, class 1 productions late and missed",
                               "operationId": "plant", "responses": {"200": ok}}}
    paths["/metrics"] = {"get": {"summary": "the devices' counters in the Prometheus text format",
                                 "operationId": "metrics", "responses": {"200": {
                                     "description": "Prometheus text", "content": {"text/plain": {"schema": {}}}}}}}
    return {"openapi": "3.0.3",
            "info": {"title": "cipstack emulator control", "version": "2"},
            "paths": paths,
            "components": {"schemas": {"Error": {"type": "object", "required": ["error"],
                                                 "properties": {"error": {"type": "string"}}}},
                           "securitySchemes": {"token": {"type": "http", "scheme": "bearer"}}}}
