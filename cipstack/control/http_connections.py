"""The HTTP API's connections: how many are served at once, shared between addresses by the one
policy of every listener here (``ConnectionLimiter``: a newcomer takes the place of the idlest
connection of the address holding the most), what a refused or evicted one is told (a 503 with a JSON
body, never a bare close), and how long one may wait before it sends a request head."""

from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Callable, Mapping
from typing import Any

from ..eip.target.limits import ConnectionLimiter, RateLimitedLog

#: The API's one logger (``http.one_line_records`` makes its records one line, credentials redacted).
log = logging.getLogger("cipstack.control.http")

#: Headers of every answer, whatever it is (JSON, an error, ``/metrics``, a stream, a refusal at the
#: connection limit), as on the front panel's files: a browser takes the type given and never guesses
#: another (an error that quotes a client's text is never read as a page or a script).
ALWAYS_HEADERS: Mapping[str, str] = {"X-Content-Type-Options": "nosniff"}
#: Seconds a client refused for want of room (503: connections, requests or streams) is told to wait
#: before it tries again (``Retry-After``).
RETRY_AFTER_S = 1



#: HTTP connections served at once. Far below the process's open-file limit, so that no number of HTTP
#: clients can keep EtherNet/IP and Modbus TCP from accepting theirs.
MAX_CONNECTIONS = 64
#: Seconds a connection has to send a whole request head after it is accepted, or after its last
#: request (idle keep-alive); then it is closed.
HEADER_TIMEOUT = 10.0
#: Refused connections kept open at once while their 503 goes out; past that, one is closed as soon
#: as its 503 is written.
MAX_LINGERING_REFUSALS = 64
#: Seconds a refused connection stays open after its 503, reading (and dropping) what the client still
#: sends: closed with unread bytes, a connection ends in a reset, which can destroy the 503 before the
#: client reads it.
REFUSAL_LINGER_S = 2.0
#: The most a refused connection's client may send while its 503 goes out.
REFUSAL_READ_LIMIT = 64 * 1024


class HttpConnections:
    """The protocol factory of the HTTP listener, in front of aiohttp's: at most ``limit`` connections
    at once, shared between addresses by the one policy of every listener here (``ConnectionLimiter``,
    as EtherNet/IP and Modbus TCP): when every slot is taken, a new address takes the place of the
    idlest connection of the address holding the most, while that one holds more than the newcomer
    would; else the newcomer is answered 503 (JSON, ``Retry-After``) and closed. A connection that has
    not sent a whole request head ``header_timeout`` seconds after it was accepted is closed (an idle
    keep-alive connection is aiohttp's, after the same time).

    The count is of the connections open now: each is counted in when asyncio says it is made, and out
    when it says it is lost (or when it is closed to make room), whatever aiohttp still does with it.
    What aiohttp cannot parse is answered 400 with a JSON body, and logged one line per source per
    10 s (``RequestHandler``)."""

    def __init__(self, limit: int = MAX_CONNECTIONS, header_timeout: float = HEADER_TIMEOUT) -> None:
        #: One address may hold every slot while it is alone: a newcomer takes one of them.
        self.limiter = ConnectionLimiter(limit, per_host=limit)
        self.header_timeout = header_timeout
        #: The connections served, by aiohttp's protocol of each (``request.protocol``).
        self.served: dict[Any, _Connection] = {}
        self.refused_log = RateLimitedLog(log)
        self.evicted_log = RateLimitedLog(log, level=logging.INFO)
        #: Requests aiohttp could not parse.
        self.malformed_log = RateLimitedLog(log)
        #: Refused connections still open while their 503 goes out.
        self.lingering = 0

    @property
    def limit(self) -> int:
        return self.limiter.total

    @property
    def refused(self) -> int:
        """Connections refused since the start."""
        return self.limiter.refused

    def admit(self, connection: _Connection) -> bool:
        """Count ``connection`` in (making room when every slot is taken), or say why not in the log."""
        if self.limiter.admit_making_room(connection.host, self._close_idlest):
            return True
        self.refused_log("HTTP connection from %s refused (503): all %d connections are open, %d of them from "
                         "%s, and no address holds more than it would", connection.host, self.limit,
                         self.limiter.by_host.get(connection.host, 0), connection.host, source=connection.host)
        return False

    def _close_idlest(self, victim: str, host: str) -> bool:
        """Every slot taken: close the idlest connection of ``victim`` (none in a request first, then the
        longest since its last request began or ended, or since it came) to make room for ``host``."""
        idlest = min((c for c in self.served.values() if c.host == victim and not c.evicted),
                     key=lambda c: (c.busy > 0, c.since), default=None)
        if idlest is None:
            return False
        self.evicted_log("HTTP connection from %s closed to make room for %s: %s held %d of the %d connections",
                         victim, host, victim, self.limiter.by_host.get(victim, 0), self.limit, source=victim)
        idlest.evict()
        return True

    def started(self, handler: Any) -> None:
        """``handler``'s connection sent a whole request head: it is in a request until ``finished``."""
        connection = self.served.get(handler)
        if connection is not None:
            connection.began()

    def finished(self, handler: Any) -> None:
        connection = self.served.get(handler)
        if connection is not None:
            connection.ended()

    def malformed(self, host: str | None, status: int, reason: str) -> None:
        self.malformed_log("HTTP request from %s refused (%d): %s", host or "?", status, reason, source=host)


class HttpListener:
    """The protocol factory of one served listener: each connection it accepts goes through
    ``connections`` (admitted or refused), and admitted to the aiohttp protocol ``make_handler`` makes."""

    def __init__(self, connections: HttpConnections,
                 make_handler: Callable[[HttpConnections], asyncio.Protocol]) -> None:
        self.connections = connections
        self.make_handler = make_handler

    def __call__(self) -> asyncio.Protocol:
        return _Connection(self.connections, self.make_handler)


class _Connection(asyncio.Protocol):
    """One accepted connection: admitted, it hands everything to aiohttp's protocol (``handler``);
    refused, it answers 503 and reads what comes until the client closes (``REFUSAL_LINGER_S``)."""

    def __init__(self, connections: HttpConnections,
                 make_handler: Callable[[HttpConnections], asyncio.Protocol]) -> None:
        self.connections = connections
        self.make_handler = make_handler
        self.transport: asyncio.Transport | None = None
        self.handler: Any = None
        self.host = ""
        #: When its last request began or ended, or when it came (loop time): its idleness.
        self.since = 0.0
        #: Requests in progress on it.
        self.busy = 0
        self.evicted = False
        self.admitted = False
        self.head_came = False
        self.timer: asyncio.TimerHandle | None = None
        self.dropped = 0

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        loop = asyncio.get_running_loop()
        self.since = loop.time()
        peer = transport.get_extra_info("peername")
        self.host = str(peer[0]) if isinstance(peer, tuple) and peer else "?"
        connections = self.connections
        if not connections.admit(self):
            self._refuse(loop)
            return
        self.admitted = True
        self.handler = self.make_handler(connections)
        connections.served[self.handler] = self
        self.timer = loop.call_later(connections.header_timeout, self._no_head)
        self.handler.connection_made(transport)

    def data_received(self, data: bytes) -> None:
        if self.handler is not None:
            self.handler.data_received(data)
            return
        self.dropped += len(data)           # a refused connection's request: read, never parsed
        if self.dropped > REFUSAL_READ_LIMIT and self.transport is not None:
            self.transport.close()

    def eof_received(self) -> bool | None:
        if self.handler is not None:
            return self.handler.eof_received()  # type: ignore[no-any-return]  # aiohttp's protocol, untyped here
        return False                         # a refused connection's client has read its 503: close

    def pause_writing(self) -> None:
        if self.handler is not None:
            self.handler.pause_writing()

    def resume_writing(self) -> None:
        if self.handler is not None:
            self.handler.resume_writing()

    def connection_lost(self, exc: Exception | None) -> None:
        if self.timer is not None:
            self.timer.cancel()
            self.timer = None
        if self.admitted:
            self.connections.served.pop(self.handler, None)
            if not self.evicted:
                self.connections.limiter.release(self.host)
            self.handler.connection_lost(exc)
        else:
            self.connections.lingering -= 1

    def began(self) -> None:
        self.head_came = True
        self.busy += 1
        self.since = asyncio.get_running_loop().time()

    def ended(self) -> None:
        self.busy = max(0, self.busy - 1)
        self.since = asyncio.get_running_loop().time()

    def evict(self) -> None:
        """Closed to make room for a newcomer: its slot is free at once. One in no request is told so (a
        503, as a refusal: never a bare close); one in a request is cut."""
        self.evicted = True
        self.connections.limiter.release(self.host)
        transport = self.transport
        if transport is None:
            return
        if self.busy:
            transport.abort()
            return
        try:
            transport.write(_refusal_bytes(self.connections.limit))
        except OSError:          # the client is gone already (reset)
            transport.abort()
            return
        transport.close()

    def _no_head(self) -> None:
        self.timer = None
        if not self.head_came and self.transport is not None:
            self.transport.close()

    def _refuse(self, loop: asyncio.AbstractEventLoop) -> None:
        """A 503 with a JSON body, then the end: at once when too many refusals are open already, else
        once the client has closed or after ``REFUSAL_LINGER_S``."""
        transport = self.transport
        assert transport is not None
        self.connections.lingering += 1
        try:
            transport.write(_refusal_bytes(self.connections.limit))
            if self.connections.lingering > MAX_LINGERING_REFUSALS:
                transport.close()
                return
            transport.write_eof()
        except OSError:          # the client is gone already (reset): nobody to answer
            transport.abort()
            return
        self.timer = loop.call_later(REFUSAL_LINGER_S, transport.close)


def _refusal_bytes(limit: int) -> bytes:
    """The answer to a connection over the limit, written before its request is read (there is no
    room to parse it): 503, a JSON body, when to try again, and the end of the connection."""
    body = json.dumps({"error": f"{limit} HTTP connections are open; try again"}).encode()
    head = ["HTTP/1.1 503 Service Unavailable", "Content-Type: application/json; charset=utf-8",
            f"Content-Length: {len(body)}", f"Retry-After: {RETRY_AFTER_S}",
            *(f"{name}: {value}" for name, value in ALWAYS_HEADERS.items()), "Connection: close"]
    return ("\r\n".join(head) + "\r\n\r\n").encode() + body
