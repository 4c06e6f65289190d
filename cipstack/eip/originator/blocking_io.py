"""Class 1 for blocking code: a thin shell over ``class1.IoOriginator`` on a plain UDP socket, with no
event loop and no thread of its own.

The connection is served by the thread that calls it: each call (``input``, ``update``,
``statistics``, ...) first sends the productions that fell due, reads what arrived and runs the
watchdog; ``wait_input`` and ``sleep`` serve it for as long as they wait, in a ``select`` on the
socket until the core's next deadline. A script that waits for something else keeps the connection
alive with ``io.sleep(seconds)`` rather than ``time.sleep``. Given ``on_input``, a callback for each
input change, the connection is served by a thread of its own instead, which calls it. It imports
nothing of asyncio.
"""

from __future__ import annotations

import logging
import select
import socket
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ...errors import CipstackError, PeerUnreachable, TimedOut
from ..io_core import DEFAULT_IO_PORT, IoStatistics, rpi_us_of
from .class1 import (
    ArrivalStatistics,
    Class1Request,
    IoOriginator,
    IoTimeoutError,
    OriginatorConnection,
    OtFormat,
    close_plan,
    new_connection,
    open_plan,
    reply_addresses,
)
from .process_image import ProcessImage

if TYPE_CHECKING:
    from ...assemblies.schema import AssemblySchema
    from ..wire.cm_messages import ConnectionTriad
    from .blocking import BlockingEncapsulationClient

log = logging.getLogger(__name__)

#: What one wake-up also sends ahead of its time (the asyncio shell's ``io_server.COALESCE_S``).
COALESCE_S = 0.0002
#: The receive buffer asked for the class 1 socket (``io_server.RECEIVE_BUFFER``): what arrives while
#: the caller does something else waits there.
RECEIVE_BUFFER = 1 << 20
#: The largest UDP payload.
MAX_DATAGRAM = 65535
#: How often the connection's TCP session is kept alive with an encapsulation NOP while it is served
#: (``io_context.SESSION_KEEPALIVE_S``).
SESSION_KEEPALIVE_S = 30.0


class SyncIoConnection:
    """An open class 1 connection for synchronous code (``SyncScanner.io_connection``).

    ``io.update(run_forward=True, speed_reference=900)`` sets output fields (all at once, between two
    productions); ``io.input.speed_actual`` reads the latest input; ``io.wait_input(lambda i:
    i.at_reference, timeout=5)`` blocks until the input says so; ``io.sleep(1.0)`` waits while the
    connection runs; ``io.statistics()`` gives the counters. Use it in a ``with`` block, or call
    ``close()``: either sends the Forward_Close. Without ``on_input`` the connection runs while this
    object is called (see the module's docstring); with it, on a thread of its own.
    """

    def __init__(self, client: BlockingEncapsulationClient, request: Class1Request, *,
                 target_io_port: int | None = None, local_io_port: int = 0,
                 output_schema: AssemblySchema | None = None, input_schema: AssemblySchema | None = None,
                 run: bool = True, keep_intervals: bool = False,
                 on_input: Callable[[ProcessImage], Any] | None = None,
                 on_close: Callable[[SyncIoConnection], None] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._client = client
        self._clock = clock
        self._on_close = on_close
        self._on_input = on_input
        self._closed = False
        self._triad: ConnectionTriad | None = None
        self._core = IoOriginator()
        self._sockets: list[socket.socket] = []
        self._thread: threading.Thread | None = None
        self._changed = threading.Condition()
        #: What opening had to adapt to (a retry with the size the target asked for), one line each.
        self.notes: list[str] = []
        #: The multicast group T->O data comes from (the target's Sockaddr Info), None for point-to-point.
        self.multicast_group: str | None = None
        self.request = request
        #: Over DTLS: the client's session, which carries this connection's data both ways.
        self._link = client.datagram_link
        try:
            if self._link is not None:
                self._sockets.append(self._link.sock)   # the link's, closed with the client
                local_port = self._link.getsockname()[1]
            else:
                local_port = self._bind(client.local_host(), local_io_port).getsockname()[1]
            opened = client.run(open_plan(client.core, request, local_port))
            self.request, self._triad, self.notes = opened.request, opened.triad, opened.notes
            addresses = reply_addresses(opened.items)
            if addresses.group is not None:
                self._join(addresses.group, addresses.group_port, client.local_host())
                self.multicast_group = addresses.group
            ot_port = target_io_port if target_io_port is not None else addresses.ot_port or DEFAULT_IO_PORT
            reply, request = opened.reply, opened.request
            self.connection: OriginatorConnection = new_connection(
                request, client.host_address(), ot_port, reply.ot_connection_id, reply.to_connection_id,
                reply.ot_api_us, reply.to_api_us, clock(), keep_intervals,
                _CallbackListener(self) if on_input is not None else None)
        except BaseException:
            self._abandon()
            raise
        self.connection.run = run
        if output_schema is not None and output_schema.size != (request.output_size or 0):
            output_schema = None  # the size the target asked for is not the schema's: raw bytes only
        if input_schema is not None and input_schema.size != request.input_size:
            input_schema = None
        self._input_schema = input_schema
        self._input_where = ""
        self.output = ProcessImage(self.connection.output, output_schema, writable=True)
        self._core.add(self.connection)
        self._keepalive_at = clock() + SESSION_KEEPALIVE_S
        if on_input is not None:
            self._thread = threading.Thread(target=self._serve_forever, name="cipstack-io", daemon=True)
            self._thread.start()
        else:
            self._serve(clock())   # the first production goes out now

    # -- sockets -----------------------------------------------------------------------------------
    def _bind(self, host: str, port: int) -> socket.socket:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sockets.append(sock)
        sock.bind((host, port))
        sock.setblocking(False)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
        return sock

    def _join(self, group: str, port: int, interface: str) -> None:
        """Also receive what is sent to ``group:port`` (multicast T->O data), on a socket of its own."""
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sockets.append(sock)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((group, port))
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, socket.inet_aton(group) + socket.inet_aton(
            interface if interface not in ("", "0.0.0.0") else "0.0.0.0"))
        sock.setblocking(False)

    def _abandon(self) -> None:
        """Opening failed: the Forward_Close if the target opened it, the sockets, the session."""
        try:
            self._forward_close()
        finally:
            for sock in self._sockets:
                if self._link is None or sock is not self._link.sock:
                    sock.close()
            self._sockets.clear()
            self._client.close()

    # -- serving the core --------------------------------------------------------------------------
    def _drain(self, sock: socket.socket) -> None:
        if self._link is not None:
            self._link.drain(self._core.receive)
            return
        receive, clock = self._core.receive, self._clock
        while True:
            try:
                data, source = sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # an ICMP error reported on the socket
                log.debug("class 1 UDP error: %s", exc)
                return
            try:
                receive(data, source, clock())
            except Exception:  # a datagram must never take the connection down
                log.exception("class 1 datagram from %s", source)

    def _serve(self, until: float, stop_on_input: bool = False) -> None:
        """Run the connection until ``until`` (the clock's time): send what falls due, read what arrives,
        run the watchdog; at least one pass. With ``stop_on_input``, return as soon as input arrived."""
        core, clock, sockets, connection = self._core, self._clock, self._sockets, self.connection
        sock = sockets[0]
        while True:
            before = connection.input
            for each in sockets:
                self._drain(each)
            now = clock()
            for datagram, destination in core.poll(now, COALESCE_S):
                try:
                    if self._link is not None:
                        self._link.send_io(datagram)
                    else:
                        sock.sendto(datagram, destination)
                except OSError as exc:   # a full buffer or an ICMP error: the next production carries newer data
                    log.debug("class 1 send to %s failed: %s", destination, exc)
            core.expire(now)
            if now >= self._keepalive_at:
                self._keep_session_alive(now)
            if now >= until or connection.timed_out or (stop_on_input and connection.input is not before):
                return
            deadline = core.next_deadline()
            wait = (until if deadline is None else min(deadline, until)) - clock()
            if wait > 0:
                select.select(sockets, [], [], wait)

    def _keep_session_alive(self, now: float) -> None:
        self._keepalive_at = now + SESSION_KEEPALIVE_S
        try:
            self._client.nop()
        except (OSError, CipstackError) as exc:
            log.debug("class 1 session keepalive to %s: %s", self._client.host, exc)

    def _serve_forever(self) -> None:
        """The connection's own thread (with ``on_input``): serve until closed or timed out."""
        while not self._closed and not self.connection.timed_out:
            self._serve(self._clock() + 0.1)
        self._wake()

    def _input_changed(self, data: bytes) -> None:
        """With ``on_input`` (on the connection's thread): the callback, then wake ``wait_input``."""
        assert self._on_input is not None
        try:
            self._on_input(ProcessImage(bytearray(data), self._input_schema, writable=False,
                                        where=self._input_where))
        except Exception:
            log.exception("class 1 on_input callback")
        self._wake()

    def _wake(self) -> None:
        with self._changed:
            self._changed.notify_all()

    def _serve_now(self) -> None:
        if self._thread is None and not self._closed:
            self._serve(self._clock())

    # -- data ----------------------------------------------------------------------------------------
    def describe_schemas(self, output: str, input: str) -> None:
        """Say where the output and input schemas come from (or why there is none), for the message of a
        field name they do not have."""
        object.__setattr__(self.output, "_where", output)
        self._input_where = input

    @property
    def input_schema(self) -> AssemblySchema | None:
        """The input assembly's declaration (None: raw bytes only)."""
        return self._input_schema

    @property
    def handle(self) -> SyncIoConnection:
        """This connection (it was the async handle on a background loop: ``handle.connection``,
        ``handle.stats`` read the same)."""
        return self

    @property
    def input(self) -> ProcessImage:
        """The latest input data: fields by name and ``raw``; ``IoTimeoutError`` once the target went silent."""
        self._serve_now()
        self._check()
        connection = self.connection
        return ProcessImage(bytearray(connection.input or bytes(connection.input_size)), self._input_schema,
                            writable=False, where=self._input_where)

    def _check(self) -> None:
        if self.connection.timed_out:
            raise IoTimeoutError(f"class 1 connection to {self.connection.target_host} timed out")

    def update(self, **fields: Any) -> None:
        """Set output fields by name, all in the same production."""
        self.output.update(**fields)
        self._serve_now()

    def set_run(self, run: bool) -> None:
        """Run (True) or idle (False) in the O->T run/idle header."""
        self.connection.run = run
        self._serve_now()

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` while the connection runs (``time.sleep`` would stop its productions, and the
        target would close it after its timeout)."""
        if self._thread is not None:
            time.sleep(seconds)
        else:
            self._serve(self._clock() + seconds)
        self._check()

    def wait_input(self, predicate: Callable[[ProcessImage], Any], timeout: float) -> ProcessImage:
        """Serve the connection until ``predicate(input)`` is true and return that input; ``TimeoutError``
        after ``timeout`` seconds, ``IoTimeoutError`` if the target goes silent."""
        clock = self._clock
        end = clock() + timeout
        while True:
            if self.connection.input:
                image = self.input
                if predicate(image):
                    return image
            self._check()
            if clock() >= end:
                raise TimedOut(f"input did not satisfy the condition within {timeout} s")
            if self._thread is None:
                self._serve(end, stop_on_input=True)
            else:
                with self._changed:
                    self._changed.wait(max(0.0, end - clock()))

    @property
    def stats(self) -> IoStatistics:
        return self.connection.stats

    @property
    def arrivals(self) -> ArrivalStatistics:
        """T->O inter-arrival times, received rate against the API, missed production slots."""
        return self.connection.arrivals

    def statistics(self) -> dict[str, Any]:
        """Counters and T->O arrival figures in one dictionary."""
        self._serve_now()
        return {**self.connection.stats.as_dict(), **self.connection.arrivals.as_dict()}

    @property
    def timed_out(self) -> bool:
        return self.connection.timed_out

    @property
    def kernel_arrival_times(self) -> bool:
        """T->O packets are timed when this process reads them (the asyncio shell's precise loop can take
        the kernel's time stamps instead)."""
        return False

    # -- life cycle ---------------------------------------------------------------------------------
    @property
    def closed(self) -> bool:
        return self._closed

    def _forward_close(self) -> None:
        """The Forward_Close, on the connection's session, or on a new one when that session is gone
        (the class 1 connection outlives it at the target)."""
        if self._triad is None:
            return
        triad, self._triad = self._triad, None
        client = self._client
        try:
            if not client.is_open:
                raise PeerUnreachable("the session is closed")
            client.run(close_plan(client.core, triad, self.request.path))
            return
        except OSError as lost:
            if self._link is not None:   # over DTLS the connection closes with its session at the device
                log.info("class 1 connection to %s: the DTLS session was lost (%s)", client.host, lost)
                return
            log.info("class 1 connection to %s: the session was lost (%s); a new one sends the Forward_Close",
                     client.host, lost)
        except CipstackError as exc:
            log.info("Forward_Close of class 1 connection failed: %s", exc)
            return
        from .blocking import BlockingEncapsulationClient

        try:
            with BlockingEncapsulationClient.connect(client.host, client.port, client.timeout) as fresh:
                fresh.run(close_plan(fresh.core, triad, self.request.path))
        except (OSError, CipstackError) as exc:
            log.info("Forward_Close of class 1 connection failed: %s", exc)

    def close(self) -> None:
        """Send the Forward_Close and close the connection's session (once; later calls do nothing)."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._thread is not None:
                self._thread.join()
            self._core.remove(self.connection)
            self._abandon()
        finally:
            if self._on_close is not None:
                self._on_close(self)

    def __enter__(self) -> SyncIoConnection:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def io_connection(client: BlockingEncapsulationClient, output: int | None, input: int, rpi: float, *,
                  output_size: int, input_size: int, config: int = 1, heartbeat: int | None = None,
                  target_io_port: int | None = None, local_io_port: int = 0, multicast: bool = False,
                  timeout_multiplier: int = 2, output_schema: AssemblySchema | None = None,
                  input_schema: AssemblySchema | None = None, run: bool = True, keep_intervals: bool = False,
                  config_data: bytes = b"", ot_format: OtFormat | str | None = None,
                  kernel_arrival_times: bool = False, on_input: Callable[[ProcessImage], Any] | None = None,
                  on_close: Callable[[SyncIoConnection], None] | None = None) -> SyncIoConnection:
    """Open a class 1 connection over ``client``'s session, as ``EncapsulationClient.io_connection``
    does on asyncio (the same arguments; ``rpi`` in seconds). ``kernel_arrival_times`` is not
    available here: packets are timed when read."""
    request = Class1Request.asked(output, input, rpi_us_of(rpi), output_size=output_size, input_size=input_size,
                                  config=config, heartbeat=heartbeat, multicast=multicast,
                                  timeout_multiplier=timeout_multiplier, config_data=config_data, ot_format=ot_format)
    return SyncIoConnection(client, request, target_io_port=target_io_port, local_io_port=local_io_port,
                            output_schema=output_schema, input_schema=input_schema, run=run,
                            keep_intervals=keep_intervals, on_input=on_input, on_close=on_close)


class _CallbackListener:
    """The core's listener of a connection served by its own thread (``on_input``)."""

    __slots__ = ("_io",)

    def __init__(self, io: SyncIoConnection) -> None:
        self._io = io

    def input_changed(self, data: bytes) -> None:
        self._io._input_changed(data)

    def timed_out(self) -> None:
        self._io._wake()


__all__ = ["SyncIoConnection", "io_connection"]
