"""A class 1 connection's life on the originator's side: the Forward_Open (with the one retry at
the size a target asks for), the I/O endpoint shared by the connections of one loop, and the
Forward_Close on every way out once the open succeeded."""

from __future__ import annotations

import asyncio
import ipaddress
import logging
from typing import TYPE_CHECKING

from ...cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from ...cip.status import CipError, GeneralStatus
from ..io_core import DEFAULT_IO_PORT
from ..io_server import IoEndpoint
from ..wire.cm_messages import (
    CONNECTION_MANAGER_PATH,
    ConnectionTriad,
    ForwardCloseRequest,
    ForwardOpenReply,
    ForwardOpenRequest,
)
from ..wire.cpf import Item, ItemType, SockAddr
from ..wire.encapsulation import (
    EncapsulationError,
)
from .io_originator import (
    Class1Request,
    IoConnectionHandle,
    IoOriginator,
    new_connection,
)

if TYPE_CHECKING:
    from ...assemblies.schema import AssemblySchema

from .replies import EncapsulationStatusError, decode_reply

if TYPE_CHECKING:
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

    async def _forward_open(self, request: Class1Request, port: int
                            ) -> tuple[ForwardOpenReply, list[Item], ConnectionTriad]:
        ot, to, transport, triad, to_id = request.parameters()
        large = request.large_forward_open
        fo = ForwardOpenRequest(0x0A, 0x0E, 0, to_id, triad, request.timeout_multiplier, request.ot_rpi_us,
                                ot, request.to_rpi_us, to, transport, request.path, large)
        service = Service.LARGE_FORWARD_OPEN if large else Service.FORWARD_OPEN
        raw = MessageRouterRequest(service, CONNECTION_MANAGER_PATH, fo.encode()).encode()
        sockaddr = Item(ItemType.SOCKADDR_T_O, SockAddr("0.0.0.0", port).encode())
        reply_raw, extra = await self.client.send_rr_data_items(raw, [] if request.multicast else [sockaddr])
        response = decode_reply("Forward_Open reply", lambda: MessageRouterResponse.decode(reply_raw))
        response.raise_for_status()
        return decode_reply("Forward_Open reply", lambda: ForwardOpenReply.decode(response.data)), extra, triad

    async def _open_shielded(self, request: Class1Request, port: int
                             ) -> tuple[ForwardOpenReply, list[Item], ConnectionTriad]:
        """``_forward_open``, closing what the target opens even when the caller is cancelled (Ctrl-C)
        while the request is on the wire."""
        opening = asyncio.ensure_future(self._forward_open(request, port))
        try:
            return await asyncio.shield(opening)
        except asyncio.CancelledError:
            try:
                _, _, self._triad = await opening
            except Exception:  # refused or lost: nothing was opened
                self._triad = None
            else:
                await self._forward_close()
            raise

    async def __aenter__(self) -> IoConnectionHandle:
        client = self.client
        core, endpoint = await shared_io_endpoint(client.local_host(), self.local_io_port)
        if self.kernel_arrival_times:
            endpoint.stamp_arrivals()
        request = self.request
        try:
            reply, extra, triad = await self._open_shielded(request, endpoint.port)
        except CipError as refused:
            corrected = request.corrected(refused.extended) if refused.general == GeneralStatus.CONNECTION_FAILURE \
                else None
            if corrected is None:
                raise
            request, note = corrected
            log.debug("Forward_Open to %s: %s", client.host, note)
            self.notes.append(note)
            reply, extra, triad = await self._open_shielded(request, endpoint.port)
        self.request = request
        self._triad = triad
        try:
            self.handle = await self._start(request, reply, extra, core, endpoint)
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

    async def _start(self, request: Class1Request, reply: ForwardOpenReply, extra: list[Item], core: IoOriginator,
                     endpoint: IoEndpoint) -> IoConnectionHandle:
        announced: int | None = None
        group: str | None = None
        for item in extra:
            if item.type not in (ItemType.SOCKADDR_T_O, ItemType.SOCKADDR_O_T):
                log.debug("Forward_Open reply: item 0x%04X ignored", item.type)
                continue
            try:
                address = SockAddr.decode(item.data)
            except EncapsulationError as exc:
                log.debug("Forward_Open reply: Sockaddr Info 0x%04X ignored: %s", item.type, exc)
                continue
            if item.type == ItemType.SOCKADDR_T_O and ipaddress.IPv4Address(address.host).is_multicast:
                await endpoint.join_multicast(address.host, address.port)
                group = address.host
            elif item.type == ItemType.SOCKADDR_O_T and address.port:
                # The target consumes O->T data on this port, not 2222 (CIP Vol. 2, 2-6.3.3).
                announced = address.port
                log.debug("Forward_Open reply: the target consumes O->T data on UDP port %d", address.port)
            else:
                # 0.0.0.0:<our port> echoed back on a point-to-point connection, or the target's
                # O->T address: informational; only a 224.0.0.0/4 group is something to join.
                log.debug("Forward_Open reply: Sockaddr Info 0x%04X %s:%d (informational)", item.type,
                          address.host, address.port)
        # O->T data goes to the port the caller gave, else to the one the reply names, else to 2222.
        ot_port = self.target_io_port if self.target_io_port is not None else announced or DEFAULT_IO_PORT
        connection = new_connection(request, self.client.host_address(), ot_port,
                                    reply.ot_connection_id, reply.to_connection_id, reply.ot_api_us, reply.to_api_us,
                                    asyncio.get_running_loop().time(), self.keep_intervals)
        connection.run = self.run
        output_schema, input_schema = self.output_schema, self.input_schema
        if output_schema is not None and output_schema.size != (request.output_size or 0):
            output_schema = None  # the size the target asked for is not the schema's: raw bytes only
        if input_schema is not None and input_schema.size != request.input_size:
            input_schema = None
        core.add(connection)
        endpoint.wakeup()
        handle = IoConnectionHandle(core, endpoint, connection, output_schema, input_schema)
        handle.multicast_group = group
        return handle

    async def _forward_close(self) -> None:
        if self._triad is None:
            return
        fc = ForwardCloseRequest(0x0A, 0x0E, self._triad, self.request.path)
        self._triad = None
        try:
            if not self.client.is_open and self.client.session:
                # The target closed the session (not the caller, who ends it with a session of 0):
                # the connection is still open there, and a new session can close it.
                log.info("class 1 connection to %s: the session was closed; a new one sends the Forward_Close",
                         self.client.host)
                await self.client.open()
            reply = await self.client.request(Service.FORWARD_CLOSE, CONNECTION_MANAGER_PATH, fc.encode(),
                                              connected=False)
            reply.raise_for_status()
        except (ConnectionError, CipError, EncapsulationStatusError, asyncio.TimeoutError) as exc_close:
            log.info("Forward_Close of class 1 connection failed: %s", exc_close)

    async def __aexit__(self, *exc: object) -> None:
        if self._keepalive is not None:
            self._keepalive.cancel()
            self._keepalive = None
        handle = self.handle
        if handle is not None:
            handle.connection.closed = True
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
