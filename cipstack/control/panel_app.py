"""The front panel's transport: its static files (``control/panel/``: plain HTML, CSS and JavaScript,
no build step) and the live stream a panel reads, Server-Sent Events over one request.

The stream adds no behaviour: every half second it sends what the command service answers to
``status``, ``faults`` and ``connections`` (when it changed) and the events after the last one sent.
The panel itself calls the same JSON operations as any client, under the same origin, host and token
rules (``Guard``). Streams are bounded (``MAX_STREAMS``) and end at once when the API closes, so an
open panel never holds up a stop."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Iterator
from importlib import resources
from typing import TYPE_CHECKING, Any

from aiohttp import web

if TYPE_CHECKING:
    from .service import DeviceService

log = logging.getLogger(__name__)

#: Seconds between two looks at the device for a stream (a panel is for eyes, not for timing).
STREAM_INTERVAL_S = 0.5
#: Streams served at once by one API, a fleet's relay included (each is one long request, counted
#: apart from the requests in flight); one more is a 503.
MAX_STREAMS = 8
#: The panel's files and their content types.
_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css", ".svg": "image/svg+xml"}
#: A page that runs only its own scripts, loads nothing from elsewhere, and cannot be framed by another
#: page (a framed panel could be clicked through by the page around it).
_HEADERS = {"Content-Security-Policy": "default-src 'self'; img-src 'self' data:; frame-ancestors 'none'; "
                                       "base-uri 'none'; form-action 'none'",
            "X-Frame-Options": "DENY", "X-Content-Type-Options": "nosniff", "Referrer-Policy": "no-referrer",
            "Cache-Control": "no-cache"}


def _files() -> dict[str, tuple[bytes, str]]:
    folder = resources.files("cipstack.control") / "panel"
    found: dict[str, tuple[bytes, str]] = {}
    for entry in folder.iterdir():
        suffix = "." + entry.name.rsplit(".", 1)[-1]
        if entry.is_file() and suffix in _TYPES:
            found[entry.name] = (entry.read_bytes(), _TYPES[suffix])
    return found


class PanelStreams:
    """The front panel's routes on an app, and its live streams, which ``close`` ends."""

    def __init__(self) -> None:
        self.files = _files()
        self.count = 0
        self.closing = asyncio.Event()

    def add_routes(self, app: web.Application) -> None:
        app.router.add_get("/", self.index)
        app.router.add_get("/panel/{name}", self.file)

    async def index(self, request: web.Request) -> web.Response:
        return self._file("index.html")

    async def file(self, request: web.Request) -> web.Response:
        return self._file(request.match_info["name"])

    def _file(self, name: str) -> web.Response:
        found = self.files.get(name)
        if found is None:
            raise web.HTTPNotFound(reason=f"no panel file {name!r}")
        body, content_type = found
        return web.Response(body=body, content_type=content_type, charset="utf-8" if "text" in content_type
                            else None, headers=_HEADERS)

    def close(self) -> None:
        self.closing.set()

    @contextlib.contextmanager
    def slot(self) -> Iterator[None]:
        """One of the ``MAX_STREAMS`` streams for the block, or ``HTTPServiceUnavailable`` (the guard's 503,
        with when to try again) when they are all open. A fleet's relay takes one for each stream it forwards."""
        if self.count >= MAX_STREAMS:
            raise web.HTTPServiceUnavailable(reason=f"{MAX_STREAMS} panels are open already")
        self.count += 1
        try:
            yield
        finally:
            self.count -= 1

    async def stream(self, request: web.Request, service: DeviceService, since: int = 0) -> web.StreamResponse:
        """Server-Sent Events of ``service``'s device until the client goes or the API closes; ``since``:
        the last event the panel has (one that reconnects says it, ``?since=N``: each event once)."""
        with self.slot():
            return await self._stream(request, service, since)

    async def _stream(self, request: web.Request, service: DeviceService, since: int) -> web.StreamResponse:
        response = web.StreamResponse(headers={"Content-Type": "text/event-stream", "Cache-Control": "no-cache"})
        try:
            await response.prepare(request)
            last: dict[str, str] = {}
            while not self.closing.is_set():
                try:
                    snapshot = (("status", service.status()), ("faults", service.faults_active()),
                                ("connections", service.connections()))
                except Exception:  # a defect must end this stream cleanly, never corrupt it
                    log.exception("front panel stream of %s", request.path)
                    break
                for name, value in snapshot:
                    text = json.dumps(value, separators=(",", ":"))
                    if last.get(name) != text:
                        last[name] = text
                        await response.write(f"event: {name}\ndata: {text}\n\n".encode())
                events: list[dict[str, Any]] = service.events_since(since)
                if events:
                    since = events[-1]["number"]
                    await response.write(f"event: events\ndata: {json.dumps(events)}\n\n".encode())
                await response.write(b": tick\n\n")     # a client that went away is seen here
                with contextlib.suppress(asyncio.TimeoutError):
                    await asyncio.wait_for(self.closing.wait(), STREAM_INTERVAL_S)
        except ConnectionResetError:   # the panel was closed or reloaded
            pass
        return response


__all__ = ["MAX_STREAMS", "STREAM_INTERVAL_S", "PanelStreams"]
