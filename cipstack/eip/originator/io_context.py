"""A class 1 connection's life on the originator's side: the Forward_Open (with the one retry at
the size a target asks for), the I/O endpoint shared by the connections of one loop, and the
Forward_Close on every way out once the open succeeded."""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING

from ...cip.status import CipError
from ..io_core import DEFAULT_IO_PORT
from ..io_server import IoEndpoint
from ..wire.cm_messages import ConnectionTriad
from .class1 import (
    Class1Opened,
    Class1Request,
    IoOriginator,
    close_plan,
    new_connection,
    open_plan,
    reply_addresses,
)
from .io_originator import IoConnectionHandle, QueueListener
from .replies import EncapsulationStatusError

if TYPE_CHECKING:
    from ...assemblies.schema import AssemblySchema
    from .asyncio_client import EncapsulationClient

log = logging.getLogger(__name__)

#: How often the TCP session of an open class 1 connection is kept alive with an encapsulation NOP
#: (no reply, by definition). A target closes a session idle for its encapsulation inactivity
#: timeout (TCP/IP attribute 13, 120 s by default); the class 1 connection outlives its session,
#: but its Forward_Close needs one.
SESSION_KEEPALIVE_S = 30.0


class IoContext:
    """Async context manager of a class 1 connection: Forward_Open on enter, Forward_Close on exit.

    Once the Forward_Open succeeded, every way out closes the connection: an error while
    setting it up (a group that cannot be joined, a socket error), an exception or a
    cancellation (Ctrl-C) in the body, or a normal exit."""

    def __init__(self, client: EncapsulationClient, request: Class1Request, target_io_port: int | None,
                 local_io_port: int,
                 output_schema: AssemblySchema | None, input_schema: AssemblySchema | None, run: bool,
                 keep_intervals: bool, kernel_arrival_times: bool = False) -> None:
        self.client = client
        self.request = request
        self.target_io_port = target_io_port
        self.local_io_port = local_io_port
        self.output_schema = output_schema
        self.input_schema = input_schema
        self.run = run
        self.keep_intervals = keep_intervals
        self.kernel_arrival_times = kernel_arrival_times
        self.handle: IoConnectionHandle | None = None
        self._triad: ConnectionTriad | None = None
        self._keepalive: asyncio.Task[None] | None = None
        #: What the opening had to adapt to (a retry with the size a target asked for), one line each.
        self.notes: list[str] = []

    async def _open_shielded(self, request: Class1Request, port: int) -> Class1Opened:
        """The core's ``open_plan`` (with its one retry), closing what the target opens even when the
        caller is cancelled (Ctrl-C) while a request is on the wire."""
        opening = asyncio.ensure_future(self.client.run(open_plan(self.client.core, request, port)))
        try:
            return await asyncio.shield(opening)
        except asyncio.CancelledError:
            try:
                opened = await opening
            except Exception:  # refused or lost: nothing was opened
                self._triad = None
            else:
                self.request, self._triad = opened.request, opened.triad
                await self._forward_close()
            raise

    async def __aenter__(self) -> IoConnectionHandle:
        client = self.client
        link = client.datagram_link
        if link is not None:   # over DTLS: the session's own core, its data in the session both ways
            core, endpoint = await link.io_endpoint(client.local_host())
        else:
            core, endpoint = await shared_io_endpoint(client.local_host(), self.local_io_port)
        if self.kernel_arrival_times:
            endpoint.stamp_arrivals()
        opened = await self._open_shielded(self.request, endpoint.port)
        for note in opened.notes:
            log.debug("Forward_Open to %s: %s", client.host, note)
        self.notes.extend(opened.notes)
        self.request = opened.request
        self._triad = opened.triad
        try:
            self.handle = await self._start(opened, core, endpoint)
            self.handle.notes = self.notes
        except BaseException:
            # Opened but not started: the target would keep producing to a port nobody reads.
            await self._forward_close()
            raise
        self._keepalive = asyncio.ensure_future(self._keep_session_alive())
        return self.handle

    async def _keep_session_alive(self) -> None:
        while True:
            await asyncio.sleep(SESSION_KEEPALIVE_S)
            if not self.client.is_open:
                return  # lost: the Forward_Close opens a session of its own
            try:
                await self.client.nop()
            except (ConnectionError, OSError) as exc:
                log.debug("class 1 session keepalive to %s: %s", self.client.host, exc)
                return

    async def _start(self, opened: Class1Opened, core: IoOriginator, endpoint: IoEndpoint) -> IoConnectionHandle:
        request, reply = opened.request, opened.reply
        addresses = reply_addresses(opened.items)
        if addresses.group is not None:
            await endpoint.join_multicast(addresses.group, addresses.group_port)
        # O->T data goes to the port the caller gave, else to the one the reply names, else to 2222.
        ot_port = self.target_io_port if self.target_io_port is not None else addresses.ot_port or DEFAULT_IO_PORT
        if self.client.datagram_link is not None:
            ot_port = self.client.port   # the route of the DTLS session's address (``DatagramPaths``)
        listener = QueueListener()
        connection = new_connection(request, self.client.host_address(), ot_port,
                                    reply.ot_connection_id, reply.to_connection_id, reply.ot_api_us, reply.to_api_us,
                                    asyncio.get_running_loop().time(), self.keep_intervals, listener)
        connection.run = self.run
        output_schema, input_schema = self.output_schema, self.input_schema
        if output_schema is not None and output_schema.size != (request.output_size or 0):
            output_schema = None  # the size the target asked for is not the schema's: raw bytes only
        if input_schema is not None and input_schema.size != request.input_size:
            input_schema = None
        core.add(connection)
        endpoint.wakeup()
        handle = IoConnectionHandle(core, endpoint, connection, output_schema, input_schema, listener.queue)
        handle.multicast_group = addresses.group
        return handle

    async def _forward_close(self) -> None:
        if self._triad is None:
            return
        triad, self._triad = self._triad, None
        try:
            if not self.client.is_open and self.client.session:
                # The target closed the session (not the caller, who ends it with a session of 0):
                # the connection is still open there, and a new session can close it.
                log.info("class 1 connection to %s: the session was closed; a new one sends the Forward_Close",
                         self.client.host)
                await self.client.open()
            await self.client.run(close_plan(self.client.core, triad, self.request.path))
        except (ConnectionError, CipError, EncapsulationStatusError, asyncio.TimeoutError) as exc_close:
            log.info("Forward_Close of class 1 connection failed: %s", exc_close)

    async def __aexit__(self, *exc: object) -> None:
        if self._keepalive is not None:
            self._keepalive.cancel()
            self._keepalive = None
        handle = self.handle
        if handle is not None:
            handle._core.remove(handle.connection)
        await self._forward_close()


_io_endpoints: dict[tuple[int, str, int], tuple[IoOriginator, IoEndpoint]] = {}


async def shared_io_endpoint(host: str, port: int = 0) -> tuple[IoOriginator, IoEndpoint]:
    """The originator's class 1 endpoint for this event loop and local address (one socket serves every
    connection, as a PLC's one UDP 2222 socket does)."""
    loop = asyncio.get_running_loop()
    for stale in [k for k, (_, e) in _io_endpoints.items() if getattr(e, "loop", loop).is_closed()]:
        del _io_endpoints[stale]  # an earlier asyncio.run's: nothing can use it any more
    key = (id(loop), host, port)
    found = _io_endpoints.get(key)
    # An id can be reused by a later loop once the first is gone: the endpoint must be this loop's.
    if found is not None and found[1].is_open and getattr(found[1], "loop", None) is loop:
        return found
    core = IoOriginator()
    endpoint = IoEndpoint(core, host, port)
    await endpoint.start()
    _io_endpoints[key] = (core, endpoint)
    return core, endpoint


__all__ = ["IoContext", "shared_io_endpoint"]
