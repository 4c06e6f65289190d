"""One HTTP control API for a fleet spread over worker processes: the parent's, which forwards each
device's routes to the worker that holds the device.

Each worker serves the API of its own devices (``HttpApi``) on a Unix socket in a directory only the
fleet's user reaches; the relay listens on ``--http`` and answers what the API of one process
answers, for every device of every worker, by the same addresses: it declares no route of its own
beyond ``DEVICE_ROUTES`` (the same table ``HttpApi`` serves), ``/devices`` (the workers' own listings,
joined) and ``/openapi.json`` (the same document). The same ``Guard`` bounds its clients, bodies and
peers, and checks the token; the worker's answer (status, JSON body, a streamed body as it comes) goes
back as it is.

A worker that no longer serves (ended, or stopped answering its parent) makes its devices answer 503
with a JSON body naming the device and why; the other workers' devices answer as before.

The same relay serves a plant spread over machines or pods (``cipstack.control.plant``): there each
backend is a fleet's own HTTP API over TCP (``Backend.url``, its token in ``Backend.headers``), and
backends come and go while it serves (``RelayApi.add``).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import aiohttp
from aiohttp import web
from yarl import URL

from ..errors import PeerUnreachable, connect_failure
from .http import (
    DEVICE_PREFIX,
    DEVICE_ROUTES,
    STREAM_PATH,
    Guard,
    ServedApp,
    check_settings,
    guarded_app,
    json_error,
    no_device,
    one_line_records,
    openapi,
    serve_app,
)
from .metrics import ShardGauges, WorkerGauges, merge_families, metrics_response, powered_devices, render
from .panel_app import PanelStreams
from .plant_grid import SharedRows, down_rows

log = logging.getLogger(__name__)
one_line_records(log)

#: A worker's API by its Unix socket: the socket has no host name, aiohttp's client needs one.
_WORKER_URL = URL("http://cipstack-worker")

#: How long the relay waits for a worker's socket to accept; its event loop accepts in microseconds,
#: so a worker that takes longer is stopped or stuck (its parent's heartbeat says so, and ends it).
CONNECT_TIMEOUT = 5.0
#: How long the grid's rows of one backend may take: a worker whose loop is that far behind is shown
#: as not answering for this refresh, the others' rows still come (the grid asks again in a second).
PLANT_TIMEOUT = 5.0
#: Headers of a request the worker's API reads (the token stays with the relay, which checked it).
_FORWARDED = ("Content-Type", "Accept")


@dataclass
class Backend:
    """A worker's API as the relay reaches it (or a fleet's, for a plant: ``url``)."""

    #: How the worker is named in messages: ``worker 2 (127.0.0.12-127.0.0.13)``.
    name: str
    #: The Unix socket its ``HttpApi`` listens on; None: TCP to ``url``.
    path: str | None
    #: Why it serves no more (``worker 2 (...) ended: killed by SIGKILL``), or None while it serves.
    down: Callable[[], str | None] = lambda: None
    #: Its number among the fleet's workers (1, 2, ...), shown in ``/devices``.
    number: int = 0
    #: Its devices as its own ``GET /devices`` lists them (read when it is added: they do not change).
    devices: list[dict[str, Any]] = field(default_factory=list)
    session: aiohttp.ClientSession | None = None
    #: Where its API is.
    url: URL = field(default_factory=lambda: _WORKER_URL)
    #: Headers of every request to it (a fleet's token).
    headers: dict[str, str] = field(default_factory=dict)
    #: What ``/devices`` adds to each of its devices (default: its worker number).
    shown: dict[str, Any] | None = None
    #: Its load as its heartbeat last told (``WorkerGauges``), or None: not known (a plant's fleets).
    load: Callable[[], Mapping[str, float] | None] = lambda: None

    def open(self) -> None:
        """Its client session (call once, on the relay's loop)."""
        connector = aiohttp.UnixConnector(path=self.path) if self.path is not None else None
        self.session = aiohttp.ClientSession(connector=connector, headers=self.headers,
                                             timeout=aiohttp.ClientTimeout(total=None, sock_connect=CONNECT_TIMEOUT))

    def at(self, path: str) -> URL:
        """The URL of ``path`` (already encoded, with its query) on its API."""
        return URL(f"{self.url}{path}", encoded=True)

    async def close(self) -> None:
        if self.session is not None:
            session, self.session = self.session, None
            await session.close()


def _failure(backend: Backend, exc: BaseException) -> str:
    """Why ``backend`` did not answer; a refused connection in the words every command uses for one
    (aiohttp's own, ``Cannot connect to host ... [Connect call failed ...]``, are asyncio's)."""
    if isinstance(exc, aiohttp.ClientConnectorError):
        where = backend.path or f"{backend.url.host}:{backend.url.port}"
        return f"cannot connect to {where}: {connect_failure(exc.os_error)}"
    return str(exc) or type(exc).__name__


class RelayApi:
    """The fleet's HTTP API on ``host:port`` over the APIs of ``backends`` (see the module docstring)."""

    def __init__(self, backends: list[Backend], host: str = "127.0.0.1", port: int = 0, *,
                 token: str | None = None, allow_remote: bool = False, hosts: tuple[str, ...] = (),
                 shard: str | None = "0/1") -> None:
        """``shard``: the fleet's name on ``/metrics`` (``--shard``; 0/1 for a whole plant); None: its
        backends' gauges only (a plant's fleets say their own)."""
        check_settings(f"{host}:{port}", token, allow_remote)
        self.backends = backends
        self.host = host
        self.port = port
        self.guard = Guard(token, allow_remote, hosts=hosts)
        self.shard = shard
        #: The front panel's files (the plant view and each device's panel); its streams are the workers'.
        self.panel = PanelStreams()
        #: Each device's worker, by the address the worker's API gives it.
        self.routes: dict[str, Backend] = {}
        self._served: ServedApp | None = None
        self._plant = SharedRows(self._read_plant)
        self.app = self._build()

    async def start(self) -> None:
        """Read each worker's devices, then listen. A worker whose API does not answer raises
        ``ConnectionError`` naming it; a port that is taken raises ``OSError``."""
        try:
            for backend in self.backends:
                await self.add(backend, listed=True)
            self._served = await serve_app(self.app, self.host, self.port)
            self.port = self._served.port
        except BaseException:
            await self.close()
            raise
        log.info("HTTP control API on http://%s:%d/ (the plant; openapi.json), for %d devices in %d workers", self.host,
                 self.port, len(self.routes), len(self.backends))

    async def close(self) -> None:
        self.panel.close()
        if self._served is not None:
            await self._served.close()
            self._served = None
        for backend in self.backends:
            await backend.close()

    async def add(self, backend: Backend, listed: bool = False) -> None:
        """Open ``backend``, read its devices and route them to it (from another backend that listed them
        before: a fleet that came back elsewhere). ``listed``: it is in ``backends`` already. A backend
        that does not answer raises ``ConnectionError`` naming it, and is closed."""
        backend.open()
        try:
            backend.devices = await self.listing(backend)
        except BaseException:
            await backend.close()
            raise
        if not listed:
            self.backends.append(backend)
        self.routes.update((entry["address"], backend) for entry in backend.devices)

    @staticmethod
    async def listing(backend: Backend) -> list[dict[str, Any]]:
        """The devices ``backend``'s ``GET /devices`` lists; ``PeerUnreachable`` naming it when it does not answer."""
        assert backend.session is not None
        try:
            async with backend.session.get(backend.at("/devices")) as reply:
                listed = await reply.json()
                if reply.status != 200 or not isinstance(listed, list):
                    raise PeerUnreachable(f"{backend.name}: its HTTP API answered {reply.status} to GET /devices")
                return listed
        except (aiohttp.ClientError, asyncio.TimeoutError, ValueError) as exc:
            raise PeerUnreachable(f"{backend.name}: its HTTP API does not answer ({_failure(backend, exc)})") \
                from None

    def _build(self) -> web.Application:
        app = guarded_app(self.guard)
        for method, path, _operation in DEVICE_ROUTES:
            app.router.add_route(method, path, self.unaddressed)
            app.router.add_route(method, DEVICE_PREFIX + path, self.forward)
        app.router.add_get("/devices", self.list_devices)
        app.router.add_get("/plant", self.plant)
        app.router.add_get("/openapi.json", openapi)
        app.router.add_get("/metrics", self.metrics)
        app.router.add_get(STREAM_PATH, self.unaddressed)
        app.router.add_get(DEVICE_PREFIX + STREAM_PATH, self.forward_stream)
        self.panel.add_routes(app)
        return app

    # -- handlers ---------------------------------------------------------------------------------------
    async def list_devices(self, request: web.Request) -> web.Response:
        """Every device of every worker, as its worker lists it, with the worker's number; a device
        whose worker no longer serves carries ``error``, why."""
        listed = []
        for backend in self.backends:
            down = backend.down()
            shown = backend.shown if backend.shown is not None else {"worker": backend.number}
            for entry in backend.devices:
                if self.routes.get(entry["address"]) is backend:   # not one another backend serves now
                    listed.append({**entry, **shown, **({"error": down} if down else {})})
        return web.json_response(sorted(listed, key=lambda entry: str(entry["address"])))

    async def plant(self, request: web.Request) -> web.Response:
        """Every device's row of the plant grid, one reading shared by the grids open (``SharedRows``)."""
        return web.json_response(await self._plant.get())

    async def _read_plant(self) -> list[dict[str, Any]]:
        """Each serving backend asked once, all at once; the devices of one that no longer serves (or
        does not answer now) listed with why."""
        rows = await asyncio.gather(*(self._plant_rows(backend) for backend in self.backends))
        return sorted((row for part in rows for row in part), key=lambda row: str(row["address"]))

    async def _plant_rows(self, backend: Backend) -> list[dict[str, Any]]:
        shown = backend.shown if backend.shown is not None else {"worker": backend.number}
        mine = [entry for entry in backend.devices if self.routes.get(entry["address"]) is backend]
        down = backend.down()
        if down is None and backend.session is not None:
            try:
                async with backend.session.get(backend.at("/plant"),
                                               timeout=aiohttp.ClientTimeout(total=PLANT_TIMEOUT)) as reply:
                    if reply.status == 200:
                        addresses = {entry["address"] for entry in mine}
                        return [{**row, **shown} for row in await reply.json() if row.get("address") in addresses]
                    down = f"{backend.name} answered {reply.status}"
            except asyncio.TimeoutError:
                down = f"{backend.name} did not answer in {PLANT_TIMEOUT:g} s (its event loop is behind: overloaded)"
            except (aiohttp.ClientError, ValueError) as exc:
                down = f"{backend.name} did not answer: {_failure(backend, exc)}"
        return down_rows(mine, shown, down or f"{backend.name} is not connected")

    async def metrics(self, request: web.Request) -> web.Response:
        """Every serving worker's ``/metrics`` in one, with the fleet's gauges: a lost worker's devices
        are not up, and their counters are gone with it."""
        texts = []
        for backend in self.backends:
            if backend.down() is not None or backend.session is None:
                continue
            try:
                async with backend.session.get(backend.at("/metrics")) as reply:
                    if reply.status == 200:
                        texts.append(await reply.text())
            except (aiohttp.ClientError, asyncio.TimeoutError):
                continue   # gone since: its devices count as not up
        families = merge_families(texts)
        up = powered_devices(families)
        gauges = ShardGauges(self.shard, lambda: (len(self.routes), up)) if self.shard is not None else None
        loads = [(backend.number, load) for backend in self.backends
                 if backend.down() is None and (load := backend.load()) is not None]
        workers = WorkerGauges(lambda: loads).families() if loads else []
        return metrics_response(await render([*families.values(), *(gauges.families() if gauges else []),
                                              *workers]))

    async def unaddressed(self, request: web.Request) -> web.Response:
        """A device's route without its address: a fleet has more than one device."""
        return no_device(None, list(self.routes))

    async def forward_stream(self, request: web.Request) -> web.StreamResponse:
        """A panel's stream, forwarded as any route, in one of the relay's own ``MAX_STREAMS`` slots: the
        relay bounds the streams of all its workers together, apart from the requests in flight, so
        that open panels never leave the API without room."""
        with self.panel.slot():
            return await self.forward(request)

    async def forward(self, request: web.Request) -> web.StreamResponse:
        """The request, as it came, to the API of the worker that holds the device; its answer back."""
        name = request.match_info["device"]
        backend = self.routes.get(name)
        if backend is None:
            return no_device(name, list(self.routes))
        down = backend.down()
        if down is not None or backend.session is None:
            return self._unserved(name, down or f"{backend.name} is stopping")
        body = await request.read()   # within MAX_BODY (413 beyond), as the worker's own limit
        headers = {key: request.headers[key] for key in _FORWARDED if key in request.headers}
        url = backend.at(request.raw_path)
        response: web.StreamResponse | None = None
        try:
            async with backend.session.request(request.method, url, data=body or None, headers=headers,
                                               allow_redirects=False) as reply:
                kept = {key: reply.headers[key] for key in ("Content-Type",) if key in reply.headers}
                if reply.content_length is not None:
                    return web.Response(status=reply.status, body=await reply.read(), headers=kept)
                # A body of no announced length (a stream of events) goes on as it comes.
                response = web.StreamResponse(status=reply.status, headers=kept)
                await response.prepare(request)
                while (chunk := await self._next_chunk(reply)) is not None:
                    await response.write(chunk)
                await response.write_eof()
                return response
        except (aiohttp.ClientError, asyncio.TimeoutError) as exc:
            if response is not None:   # the worker went away in mid-stream: the stream ends there
                return response
            return self._unserved(name, backend.down() or f"{backend.name} does not answer "
                                                          f"({_failure(backend, exc)})")

    async def _next_chunk(self, reply: aiohttp.ClientResponse) -> bytes | None:
        """What the worker sends next of a body of no announced length; None at its end, or as soon as the
        relay stops (a panel's stream ends there, whether or not the worker still sends)."""
        if self.panel.closing.is_set():
            return None
        reading = asyncio.ensure_future(reply.content.readany())
        closing = asyncio.ensure_future(self.panel.closing.wait())
        try:
            await asyncio.wait((reading, closing), return_when=asyncio.FIRST_COMPLETED)
        finally:
            closing.cancel()
            if not reading.done():
                reading.cancel()
        if reading.cancelled() or not reading.done():
            return None
        chunk = reading.result()
        return chunk if chunk else None

    @staticmethod
    def _unserved(name: str, why: str) -> web.Response:
        return json_error(503, f"device {name} is not served: {why}", device=name)


__all__ = ["Backend", "RelayApi"]
