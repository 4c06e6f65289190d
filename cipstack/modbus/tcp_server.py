"""The asyncio shell of a drive's Modbus TCP: accepts connections, frames their streams, answers each
request in order, and keeps a timer at the drive's next deadline. The sans-I/O core is the family's
(``ModbusDrive.tcp``, the ACG-ET2's ``ModbusTcpCore``): the shell knows no register map."""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass
from typing import Any, Protocol

from ..devices.state import StateFileError, StateWriter
from ..eip.target.limits import (
    DEFAULT_MAX_TCP_CONNECTIONS,
    ConnectionLimiter,
    RateLimitedLog,
    guarded_listener,
    quiet_accept_errors,
)
from ..eip.wire.encapsulation import DEFAULT_FRAME_TIMEOUT
from ..errors import ProtocolError

log = logging.getLogger(__name__)

#: Modbus exception code 04, Slave Device Failure (Modbus Application Protocol, section 7): a save the
#: state file did not take.
SLAVE_DEVICE_FAILURE = 0x04


class Framer(Protocol):
    """Splits one connection's stream into frames; an impossible length raises ``ProtocolError`` with the
    ``frames`` completed before it."""

    @property
    def pending(self) -> int: ...

    def feed(self, data: bytes) -> list[bytes]: ...


class TcpCore(Protocol):
    """A drive's Modbus TCP, sans I/O (``ModbusDrive.tcp``)."""

    @property
    def drive(self) -> Any: ...

    def framer(self) -> Framer: ...

    def handle_adu(self, adu: bytes, now: float, source: object = None) -> bytes | None: ...

    def exception_adu(self, adu: bytes, code: Any) -> bytes: ...


@dataclass(eq=False)
class _Served:
    """An admitted connection: its host, when it last completed a frame, whether it was evicted."""

    host: str
    writer: asyncio.StreamWriter
    last_activity: float
    evicted: bool = False
    #: ``host:port`` of the peer, as the requests' source.
    peer: str = ""


class ModbusTcpServer:
    """Modbus TCP server of an emulated drive (port 502 on a real card; here any port, 0 = chosen by the
    OS). ``core``: the drive's sans-I/O Modbus TCP, as its family makes it (``ModbusDrive.tcp``). It keeps
    a loop timer at the drive's next deadline, so the Modbus silence timer fires even when nothing else
    moves the drive.

    ``saves``: the state writer of the drive's saves. A request that saves is answered once the
    file is written, on the writer's thread: the event loop (and every class 1 connection) runs
    on meanwhile, and a save the file did not take is answered with exception 0x04.
    Each connection serves its requests in order; ``_accept`` is the one place a connection
    is accepted, and refused (closed at once, one log line per 10 s) past ``max_connections`` in
    total or ``max_connections_per_host`` from one address, as on the EtherNet/IP port; as there, a new
    host finding every slot taken closes the idlest connection of the host holding the most
    (``ConnectionLimiter.victim``), and a frame once begun has ``frame_timeout`` seconds to arrive."""

    def __init__(self, core: TcpCore, host: str = "127.0.0.1", port: int = 0, *,
                 saves: StateWriter | None = None, max_connections: int = DEFAULT_MAX_TCP_CONNECTIONS,
                 max_connections_per_host: int | None = None, frame_timeout: float = DEFAULT_FRAME_TIMEOUT) -> None:
        self.core = core
        self.frame_timeout = frame_timeout
        self.limiter = ConnectionLimiter(max_connections, max_connections_per_host)
        self._refused_log = RateLimitedLog(log)
        self._unframed_log = RateLimitedLog(log, level=logging.INFO)
        self._late_log = RateLimitedLog(log, level=logging.INFO)
        self._evicted_log = RateLimitedLog(log, level=logging.INFO)
        self._served: set[_Served] = set()
        self.host = host
        self.saves = saves
        self._requested_port = port
        self._server: asyncio.Server | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        self._timer: asyncio.TimerHandle | None = None
        self.loop: asyncio.AbstractEventLoop | None = None

    @property
    def port(self) -> int:
        if self._server is None or not self._server.sockets:
            return self._requested_port
        return int(self._server.sockets[0].getsockname()[1])

    async def start(self) -> None:
        self.loop = asyncio.get_running_loop()
        quiet_accept_errors(self.loop)
        listener = guarded_listener(self.host, self._requested_port)
        try:
            self._server = await asyncio.start_server(self._accept, sock=listener)
        except BaseException:
            listener.close()
            raise
        log.info("Modbus TCP on %s:%d", self.host, self.port)

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        host = str(peer[0]) if peer else "?"
        if not self.limiter.admit_making_room(host, self._close_idlest):
            self._refused_log("Modbus TCP connection from %s refused: %s", host, self.limiter.reason(host),
                              source=host)
            writer.transport.abort()
            return
        assert self.loop is not None
        served = _Served(host, writer, self.loop.time(), peer=f"{host}:{peer[1]}" if peer else host)
        self._served.add(served)
        self._writers.add(writer)
        try:
            await self._serve(reader, writer, served)
        except (ConnectionError, OSError) as exc:
            log.debug("Modbus TCP connection ended: %s", exc)
        finally:
            if not served.evicted:
                self.limiter.release(host)
            self._served.discard(served)
            self._writers.discard(writer)
            writer.close()

    def _close_idlest(self, victim: str, host: str) -> bool:
        """Every slot taken: close the idlest connection of ``victim`` to make room for ``host``
        (``ConnectionLimiter.victim``); False if it has none."""
        idlest = min((s for s in self._served if s.host == victim and not s.evicted),
                     key=lambda s: s.last_activity, default=None)
        if idlest is None:
            return False
        self._evicted_log("Modbus TCP connection from %s closed to make room for %s: it held %d of the %d "
                          "connections", victim, host, self.limiter.by_host.get(victim, 0), self.limiter.total,
                          source=victim)
        idlest.evicted = True
        self.limiter.release(idlest.host)
        idlest.writer.transport.abort()
        return True

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, served: _Served) -> None:
        assert self.loop is not None
        buffer = self.core.framer()
        frame_started: float | None = None
        while True:
            if frame_started is None:
                data = await reader.read(4096)
            else:
                # A frame has begun: the rest has what is left of the frame timeout to come.
                try:
                    data = await asyncio.wait_for(reader.read(4096),
                                                  frame_started + self.frame_timeout - self.loop.time())
                except asyncio.TimeoutError:   # not TimeoutError before Python 3.11
                    self._late_log("Modbus TCP connection from %s closed: a frame begun %g s ago is still "
                                   "incomplete (the frame timeout)", served.host, self.frame_timeout,
                                   source=served.host)
                    return
            if not data:
                return
            unframed: ProtocolError | None = None
            try:
                frames = buffer.feed(data)
            except ProtocolError as exc:
                # The requests complete before the impossible length came are served and answered;
                # nothing after it can be framed, so the connection then closes.
                frames, unframed = list(getattr(exc, "frames", [])), exc
            now = self.loop.time()
            if frames:
                served.last_activity = now
            if not buffer.pending:
                frame_started = None
            elif frames or frame_started is None:
                frame_started = now
            for frame in frames:
                reply = await self.handle_frame(frame, served.peer)
                if reply is not None:
                    writer.write(reply)
            self.rearm()
            await writer.drain()
            if unframed is not None:
                self._unframed_log("Modbus TCP connection from %s closed: %s", served.host, unframed,
                                   source=served.host)
                return

    async def handle_frame(self, frame: bytes, peer: str | None = None) -> bytes | None:
        """One frame's reply; a request that saved waits (off the loop) for the file to take the save.
        ``peer``: the client's ``host:port``, the requests' source (``ModbusCore.store``)."""
        assert self.loop is not None
        saves = self.saves
        submitted = saves.submitted if saves is not None else 0
        reply = self.core.handle_adu(frame, self.loop.time(), peer)
        if saves is None or reply is None or saves.submitted == submitted or saves.last is None:
            return reply
        try:
            await asyncio.wrap_future(saves.last)
        except StateFileError as exc:
            log.debug("Modbus TCP: %s", exc)
            return self.core.exception_adu(frame, SLAVE_DEVICE_FAILURE)
        return reply

    def rearm(self) -> None:
        """Keep a timer at the drive's next deadline."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        deadline = self.core.drive.next_deadline()
        if deadline is not None and self.loop is not None:
            self._timer = self.loop.call_at(deadline, self._on_timer)

    def _on_timer(self) -> None:
        self._timer = None
        assert self.loop is not None
        drive = self.core.drive
        drive.advance(max(self.loop.time(), drive.time))
        self.rearm()

    @property
    def is_open(self) -> bool:
        return self._server is not None

    async def close(self) -> None:
        """Close the port and every connection; a later ``start`` opens it again on the same port
        number, also one the OS chose (port 0)."""
        self._requested_port = self.port
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self._server is not None:
            self._server.close()
        for writer in list(self._writers):
            writer.close()
        if self._server is not None:
            await self._server.wait_closed()
            self._server = None

    async def __aenter__(self) -> ModbusTcpServer:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()


__all__ = ["ModbusTcpServer"]
