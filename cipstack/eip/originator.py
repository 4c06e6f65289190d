"""The EtherNet/IP originator (scanner) client, asyncio.

``EncapsulationClient`` owns one TCP connection and one session. Requests are matched to
replies by sender context, so several may be in flight at once; class 3 requests are
matched by their connection's sequence count. ``discover`` sends ListIdentity over UDP
(unicast or broadcast) and collects replies until its timeout.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import random
import socket
import struct
from collections.abc import Coroutine, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

from ..cip.epath import Segment, encode_path, request_path
from ..cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from ..cip.status import CipError, GeneralStatus
from .cpf import Item, ItemType, decode_items, encode_items
from .discovery import broadcast_addresses, discover, list_services_udp, udp_query
from .encapsulation import (
    DEFAULT_PORT,
    HEADER,
    HEADER_SIZE,
    PROTOCOL_VERSION,
    REGISTER_SESSION_DATA,
    RR_PREFIX,
    Command,
    EncapsulationError,
    EncapsulationHeader,
)
from .identity_items import IdentityRecord, ServiceRecord, decode_list_identity, decode_list_services
from .replies import EncapsulationStatusError, MalformedReplyError, decode_reply

if TYPE_CHECKING:
    # Imported where used: explicit messaging (a one-shot ``cipstack get``) does not load class 1,
    # nor the Connection Manager's messages (their dataclasses cost 8 ms to import).
    from ..assemblies.schema import AssemblySchema
    from .cm_messages import ConnectionTriad
    from .io_context import IoContext
    from .io_originator import OtFormat

log = logging.getLogger(__name__)
T = TypeVar("T")

#: Our vendor id as an originator (0xFFFF is not assigned; any value works for tests).
ORIGINATOR_VENDOR_ID = 0xFFFE
MESSAGE_ROUTER_PATH = request_path(0x02, 1)

_SEQ = struct.Struct("<H")
_CONN_ID = struct.Struct("<I")
_ITEM_LENGTH = struct.Struct("<H")
#: A SendRRData body up to the Unconnected Data item's length: interface handle 0, timeout 0, item
#: count 2, Null Address item (type 0, length 0), Unconnected Data item type 0x00B2.
_RR_TWO_ITEMS = RR_PREFIX.pack(0, 0) + struct.pack("<HHHH", 2, ItemType.NULL_ADDRESS, 0, ItemType.UNCONNECTED_DATA)
_RR_TWO_ITEMS_SIZE = len(_RR_TWO_ITEMS)


def parse_host(text: str, default_port: int = DEFAULT_PORT) -> tuple[str, int]:
    """``HOST[:PORT]`` -> (host, port)."""
    host, sep, port = text.rpartition(":")
    if not sep:
        return text, default_port
    if not host:
        raise ValueError(f"no host in {text!r}")
    try:
        number = int(port, 0)
    except ValueError:
        raise ValueError(f"bad port in {text!r}") from None
    if not 0 < number < 65536:
        raise ValueError(f"port {number} out of range")
    return host, number


class _ClientProtocol(asyncio.Protocol):
    def __init__(self, client: EncapsulationClient) -> None:
        self.client = client
        self.buffer = bytearray()
        self.transport: asyncio.Transport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def data_received(self, data: bytes) -> None:
        buffer = self.buffer
        buffer += data
        while len(buffer) >= HEADER_SIZE:
            length = int.from_bytes(buffer[2:4], "little")
            end = HEADER_SIZE + length
            if len(buffer) < end:
                return
            header = EncapsulationHeader.decode(buffer)
            body = bytes(buffer[HEADER_SIZE:end])
            del buffer[:end]
            self.client._deliver(header, body)

    def connection_lost(self, exc: Exception | None) -> None:
        self.client._lost(exc)


@dataclass
class ExplicitConnectionInfo:
    """A class 3 connection this client opened."""

    ot_connection_id: int
    to_connection_id: int
    triad: ConnectionTriad
    rpi_us: int
    sequence: int = 0


class ExplicitClient:
    """What an originator says on an encapsulation session, whatever moves the bytes.

    Subclasses provide ``exchange`` (a frame and its reply, matched by sender context),
    ``_connected_round_trip`` (a class 3 request and its reply, matched by sequence count),
    ``_write`` and ``close``. The asyncio client awaits replies; the blocking client's
    coroutines never suspend, so a plain call drives them (see ``run_blocking``).
    """

    def __init__(self, host: str, port: int = DEFAULT_PORT, timeout: float = 5.0) -> None:
        self.host = host
        self.port = port
        self.timeout = timeout
        self.session = 0
        self._contexts = itertools.count(1)
        self.connection: ExplicitConnectionInfo | None = None
        self._serials = itertools.count(random.randrange(0, 0xFFFF))

    def _write(self, command: int, data: bytes, context: bytes) -> None:
        raise NotImplementedError

    async def exchange(self, command: int, data: bytes = b"", context: bytes | None = None,
                       timeout: float | None = None) -> tuple[EncapsulationHeader, bytes]:
        raise NotImplementedError

    async def _connected_round_trip(self, sequence: int, body: bytes, timeout: float | None) -> bytes:
        raise NotImplementedError

    @property
    def is_open(self) -> bool:
        raise NotImplementedError

    def _close_transport(self) -> None:
        raise NotImplementedError

    async def close(self) -> None:
        """Forward_Close the class 3 connection, UnRegisterSession, close the socket."""
        if not self.is_open:
            return
        try:
            if self.connection is not None:
                await self.forward_close()
            if self.session:
                self._write(Command.UNREGISTER_SESSION, b"", bytes(8))
        except (ConnectionError, CipError, EncapsulationStatusError, asyncio.TimeoutError):
            pass
        finally:
            self._close_transport()
            self.session = 0

    def _new_context(self) -> bytes:
        return next(self._contexts).to_bytes(8, "little")

    def _timeout_error(self, what: str) -> asyncio.TimeoutError:
        return asyncio.TimeoutError(f"no reply from {self.host}:{self.port} to {what}")

    # -- encapsulation commands -----------------------------------------------------------------
    async def register_session(self) -> int:
        header, _ = await self.exchange(Command.REGISTER_SESSION, REGISTER_SESSION_DATA.pack(PROTOCOL_VERSION, 0))
        self.session = header.session
        return self.session

    async def list_identity(self) -> list[IdentityRecord]:
        _, body = await self.exchange(Command.LIST_IDENTITY)
        return decode_reply("ListIdentity reply", lambda: decode_list_identity(body))

    async def list_services(self) -> list[ServiceRecord]:
        _, body = await self.exchange(Command.LIST_SERVICES)
        return decode_reply("ListServices reply", lambda: decode_list_services(body))

    async def list_interfaces(self) -> list[Item]:
        _, body = await self.exchange(Command.LIST_INTERFACES)
        return decode_reply("ListInterfaces reply", lambda: decode_items(body, strict=False))

    async def nop(self, data: bytes = b"") -> None:
        self._write(Command.NOP, data, bytes(8))

    # -- explicit messaging ---------------------------------------------------------------------
    async def send_rr_data(self, request: bytes, timeout: float | None = None) -> bytes:
        """Unconnected explicit request (SendRRData); returns the encoded message-router reply."""
        # Interface handle 0, timeout 0, two items: Null Address, Unconnected Data (its length, the request).
        body = _RR_TWO_ITEMS + _ITEM_LENGTH.pack(len(request)) + request
        _, reply = await self.exchange(Command.SEND_RR_DATA, body, timeout=timeout)
        # The reply as nearly every target lays it out, read without building items; anything else
        # (items in another order, an extra item, a count that lies) by the general decoder below.
        if reply[:_RR_TWO_ITEMS_SIZE] == _RR_TWO_ITEMS and len(reply) == _RR_TWO_ITEMS_SIZE + 2 + int.from_bytes(
                reply[_RR_TWO_ITEMS_SIZE:_RR_TWO_ITEMS_SIZE + 2], "little"):
            return reply[_RR_TWO_ITEMS_SIZE + 2:]
        items = decode_reply("SendRRData reply", lambda: decode_items(reply, RR_PREFIX.size, strict=False))
        for item in items:
            if item.type == ItemType.UNCONNECTED_DATA:
                return item.data
        raise MalformedReplyError("malformed SendRRData reply: no Unconnected Data item")

    async def send_rr_data_items(self, request: bytes, extra: Sequence[Item] = (),
                                 timeout: float | None = None) -> tuple[bytes, list[Item]]:
        """SendRRData with extra CPF items (Sockaddr Info); returns the reply and its extra items."""
        items = (Item(ItemType.NULL_ADDRESS), Item(ItemType.UNCONNECTED_DATA, request), *extra)
        _, reply = await self.exchange(Command.SEND_RR_DATA, RR_PREFIX.pack(0, 0) + encode_items(items),
                                       timeout=timeout)
        reply_items = decode_reply("SendRRData reply", lambda: decode_items(reply, RR_PREFIX.size, strict=False))
        data = next((i.data for i in reply_items if i.type == ItemType.UNCONNECTED_DATA), None)
        if data is None:
            raise MalformedReplyError("malformed SendRRData reply: no Unconnected Data item")
        return data, [i for i in reply_items if i.type not in (ItemType.NULL_ADDRESS, ItemType.UNCONNECTED_DATA)]

    async def send_unit_data(self, request: bytes, timeout: float | None = None) -> bytes:
        """Class 3 connected request on the open connection; returns the message-router reply."""
        connection = self.connection
        if connection is None:
            raise ConnectionError("no class 3 connection is open")
        connection.sequence = (connection.sequence + 1) & 0xFFFF
        sequence = connection.sequence
        body = RR_PREFIX.pack(0, 0) + encode_items((
            Item(ItemType.CONNECTED_ADDRESS, _CONN_ID.pack(connection.ot_connection_id)),
            Item(ItemType.CONNECTED_DATA, _SEQ.pack(sequence) + request),
        ))
        return await self._connected_round_trip(sequence, body, timeout)

    async def request(self, service: int, path: bytes, data: bytes = b"", *,
                      route: Sequence[Segment] | bytes | None = None, connected: bool | None = None,
                      timeout: float | None = None) -> MessageRouterResponse:
        """Send any service; returns the reply (its status is not checked here).

        ``route``: a route path (port segments): the request is wrapped in Unconnected_Send
        to the Connection Manager. ``connected``: use the class 3 connection (default: when
        one is open).
        """
        raw = MessageRouterRequest(service, path, data).encode()
        use_connection = self.connection is not None if connected is None else connected
        if route is not None and not use_connection:
            # On a class 3 connection the route is already in the connection path.
            from .cm_messages import CONNECTION_MANAGER_PATH, UnconnectedSendRequest

            route_bytes = route if isinstance(route, bytes) else encode_path(route)
            raw = MessageRouterRequest(Service.UNCONNECTED_SEND, CONNECTION_MANAGER_PATH,
                                       UnconnectedSendRequest(0x0A, 0x0E, raw, route_bytes).encode()).encode()
        reply = await (self.send_unit_data(raw, timeout) if use_connection else self.send_rr_data(raw, timeout))
        return decode_reply("message router reply", lambda: MessageRouterResponse.decode(reply))

    # -- class 3 connection -----------------------------------------------------------------------
    async def forward_open(self, rpi_us: int = 2_000_000, connection_size: int = 500, large: bool = False,
                           timeout_multiplier: int = 1, route: Sequence[Segment] | bytes = b"",
                           path: bytes = MESSAGE_ROUTER_PATH) -> ExplicitConnectionInfo:
        """Open a class 3 connection to the message router (Forward_Open or Large_Forward_Open)."""
        from .cm_messages import (
            CONNECTION_MANAGER_PATH,
            ConnectionTriad,
            ForwardOpenReply,
            ForwardOpenRequest,
            NetworkParameters,
            TransportTrigger,
            TriggerType,
        )

        route_bytes = route if isinstance(route, bytes) else encode_path(route)
        triad = ConnectionTriad(next(self._serials) & 0xFFFF, ORIGINATOR_VENDOR_ID, random.randrange(1, 0xFFFFFFFF))
        params = NetworkParameters(connection_size, variable=True)
        fo = ForwardOpenRequest(
            priority_tick=0x0A, timeout_ticks=0x0E, ot_connection_id=0,
            to_connection_id=random.randrange(1, 0xFFFFFFFF), triad=triad, timeout_multiplier=timeout_multiplier,
            ot_rpi_us=rpi_us, ot_parameters=params, to_rpi_us=rpi_us, to_parameters=params,
            transport=TransportTrigger(3, TriggerType.APPLICATION, server=True),
            connection_path=route_bytes + path, large=large)
        service = Service.LARGE_FORWARD_OPEN if large else Service.FORWARD_OPEN
        reply = await self.request(service, CONNECTION_MANAGER_PATH, fo.encode(), connected=False)
        reply.raise_for_status()
        decoded = decode_reply("Forward_Open reply", lambda: ForwardOpenReply.decode(reply.data))
        self.connection = ExplicitConnectionInfo(decoded.ot_connection_id, decoded.to_connection_id, triad,
                                                 decoded.ot_api_us)
        return self.connection

    async def forward_close(self) -> None:
        connection = self.connection
        if connection is None:
            return
        self.connection = None
        from .cm_messages import CONNECTION_MANAGER_PATH, ForwardCloseRequest

        fc = ForwardCloseRequest(0x0A, 0x0E, connection.triad, MESSAGE_ROUTER_PATH)
        reply = await self.request(Service.FORWARD_CLOSE, CONNECTION_MANAGER_PATH, fc.encode(), connected=False)
        reply.raise_for_status()


class EncapsulationClient(ExplicitClient):
    """The asyncio originator: replies are matched to futures, so requests may overlap."""

    def __init__(self, host: str, port: int = DEFAULT_PORT, timeout: float = 5.0) -> None:
        super().__init__(host, port, timeout)
        self._protocol: _ClientProtocol | None = None
        self._pending: dict[bytes, asyncio.Future[tuple[EncapsulationHeader, bytes]]] = {}
        self._connected_pending: dict[int, asyncio.Future[bytes]] = {}
        self._closed_exc: BaseException | None = None

    # -- life cycle -----------------------------------------------------------------------------
    @classmethod
    async def connect(cls, host: str, port: int = DEFAULT_PORT, timeout: float = 5.0,
                      register: bool = True) -> EncapsulationClient:
        client = cls(host, port, timeout)
        await client.open(register)
        return client

    async def open(self, register: bool = True) -> None:
        loop = asyncio.get_running_loop()
        try:
            _, protocol = await asyncio.wait_for(
                loop.create_connection(lambda: _ClientProtocol(self), self.host, self.port), self.timeout)
        except (OSError, asyncio.TimeoutError) as exc:
            raise ConnectionError(f"cannot connect to {self.host}:{self.port}: {exc or 'timed out'}") from None
        self._protocol = protocol
        if register:
            await self.register_session()

    def local_host(self) -> str:
        """The local address of the TCP connection (where T->O data should come)."""
        assert self._protocol is not None and self._protocol.transport is not None
        return str(self._protocol.transport.get_extra_info("sockname")[0])

    def host_address(self) -> str:
        """The target's address as connected (an IP address even if a name was given)."""
        assert self._protocol is not None and self._protocol.transport is not None
        return str(self._protocol.transport.get_extra_info("peername")[0])

    @property
    def is_open(self) -> bool:
        return self._protocol is not None and self._protocol.transport is not None

    def _close_transport(self) -> None:
        if self._protocol is not None and self._protocol.transport is not None:
            self._protocol.transport.close()
        self._protocol = None

    async def __aenter__(self) -> EncapsulationClient:
        if self._protocol is None:
            await self.open()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # -- frames ---------------------------------------------------------------------------------
    def _write(self, command: int, data: bytes, context: bytes) -> None:
        if self._protocol is None or self._protocol.transport is None or self._protocol.transport.is_closing():
            raise ConnectionError(f"connection to {self.host}:{self.port} is closed")
        self._protocol.transport.write(HEADER.pack(command, len(data), self.session, 0, context, 0) + data)

    def _deliver(self, header: EncapsulationHeader, body: bytes) -> None:
        if header.command == Command.SEND_UNIT_DATA and header.status == 0:
            try:
                items = decode_items(body, RR_PREFIX.size, strict=False)
                sequence = _SEQ.unpack_from(items[1].data)[0]
            except Exception:
                return
            future = self._connected_pending.pop(sequence, None)
            if future is not None and not future.done():
                future.set_result(items[1].data[2:])
            return
        future2 = self._pending.pop(header.context, None)
        if future2 is not None and not future2.done():
            future2.set_result((header, body))

    def _lost(self, exc: Exception | None) -> None:
        self._closed_exc = ConnectionError(f"connection to {self.host}:{self.port} lost" + (f": {exc}" if exc else ""))
        for future in [*self._pending.values(), *self._connected_pending.values()]:
            if not future.done():
                future.set_exception(self._closed_exc)
        self._pending.clear()
        self._connected_pending.clear()
        if self._protocol is not None:
            self._protocol = None

    async def exchange(self, command: int, data: bytes = b"", context: bytes | None = None,
                       timeout: float | None = None) -> tuple[EncapsulationHeader, bytes]:
        """Send one encapsulation frame and wait for the reply with the same sender context."""
        if context is None:
            context = self._new_context()
        loop = asyncio.get_running_loop()
        future: asyncio.Future[tuple[EncapsulationHeader, bytes]] = loop.create_future()
        self._pending[context] = future
        # A plain timer, not asyncio.wait_for: no task and no extra waiter per request.
        timer = loop.call_later(timeout or self.timeout, _expire, future)
        try:
            self._write(command, data, context)
            header, body = await future
        except asyncio.TimeoutError:
            raise self._timeout_error(f"command 0x{command:04X}") from None
        finally:
            timer.cancel()
            self._pending.pop(context, None)
        if header.status != 0:
            raise EncapsulationStatusError(command, header.status)
        return header, body

    async def _connected_round_trip(self, sequence: int, body: bytes, timeout: float | None) -> bytes:
        loop = asyncio.get_running_loop()
        future: asyncio.Future[bytes] = loop.create_future()
        self._connected_pending[sequence] = future
        timer = loop.call_later(timeout or self.timeout, _expire, future)
        try:
            self._write(Command.SEND_UNIT_DATA, body, bytes(8))
            return await future
        except asyncio.TimeoutError:
            raise self._timeout_error("a class 3 request") from None
        finally:
            timer.cancel()
            self._connected_pending.pop(sequence, None)

    # -- class 1 -------------------------------------------------------------------------------------
    def io_connection(self, output: int | None, input: int, rpi: float, *, output_size: int,
                      input_size: int, config: int = 1, heartbeat: int | None = None,
                      target_io_port: int | None = None, local_io_port: int = 0, multicast: bool = False,
                      timeout_multiplier: int = 2, output_schema: AssemblySchema | None = None,
                      input_schema: AssemblySchema | None = None, run: bool = True,
                      keep_intervals: bool = False, config_data: bytes = b"",
                      ot_format: OtFormat | str | None = None, kernel_arrival_times: bool = False) -> IoContext:
        """Open a class 1 connection; use as ``async with client.io_connection(...) as io``.

        ``output``/``input`` are the assembly instances (``heartbeat`` replaces the output for
        input-only and listen-only connections); ``rpi`` is in seconds; ``config`` the
        configuration instance and ``config_data`` the data sent with it (a simple data segment).
        ``ot_format`` is the O->T real-time format: run/idle header (default), heartbeat (the
        sequence count alone) or modeless. T->O data comes to this host's UDP ``local_io_port``
        (0: the shared endpoint's port), which the Forward_Open announces in a Sockaddr Info
        item; O->T data goes to ``target_io_port`` on the target (None: the port the reply's O->T
        Sockaddr Info item names, else 2222). A target that refuses the
        O->T or T->O size with 0x0127/0x0128 and names the size it wants gets one retry with it.
        ``kernel_arrival_times``: T->O packets are timed (watchdog, statistics, ``keep_intervals``)
        when the kernel received them, as a capture shows them, not when this process read them;
        on the precise event loop under Linux, for every connection of the shared endpoint
        (``io.kernel_arrival_times`` says whether it is so).
        """
        from .io_context import IoContext
        from .io_originator import Class1Request, OtFormat, class1_path

        fmt = OtFormat(ot_format) if ot_format is not None else OtFormat.RUN_IDLE
        if fmt is OtFormat.HEARTBEAT and heartbeat is None:
            raise ValueError("the heartbeat format carries no data: give a heartbeat point, not an output")
        request = Class1Request(None if heartbeat is not None else output_size, input_size, int(rpi * 1e6),
                                int(rpi * 1e6), class1_path(output, input, config, heartbeat, config_data), multicast,
                                timeout_multiplier, ot_format=fmt)
        return IoContext(self, request, target_io_port, local_io_port, output_schema, input_schema, run,
                         keep_intervals, kernel_arrival_times)


class BlockingEncapsulationClient(ExplicitClient):
    """The same originator over a blocking socket, for scripts: one request at a time, no event
    loop. Its coroutines complete without suspending; drive them with ``run_blocking``."""

    def __init__(self, host: str, port: int = DEFAULT_PORT, timeout: float = 5.0) -> None:
        super().__init__(host, port, timeout)
        self._sock: socket.socket | None = None
        self._sock_timeout: float | None = None
        self._buffer = bytearray()

    @classmethod
    def connect(cls, host: str, port: int = DEFAULT_PORT, timeout: float = 5.0,
                register: bool = True) -> BlockingEncapsulationClient:
        client = cls(host, port, timeout)
        try:
            client._sock = socket.create_connection((host, port), timeout)
        except OSError as exc:
            raise ConnectionError(f"cannot connect to {host}:{port}: {exc}") from None
        client._sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        if register:
            run_blocking(client.register_session())
        return client

    def _write(self, command: int, data: bytes, context: bytes) -> None:
        if self._sock is None:
            raise ConnectionError(f"connection to {self.host}:{self.port} is closed")
        try:
            self._sock.sendall(HEADER.pack(command, len(data), self.session, 0, context, 0) + data)
        except OSError as exc:
            raise ConnectionError(f"connection to {self.host}:{self.port} lost: {exc}") from None

    def _read_frame(self, timeout: float) -> tuple[EncapsulationHeader, bytes]:
        sock = self._sock
        if sock is None:
            raise ConnectionError(f"connection to {self.host}:{self.port} is closed")
        buffer = self._buffer
        if timeout != self._sock_timeout:
            sock.settimeout(timeout)
            self._sock_timeout = timeout
        while True:
            if len(buffer) >= HEADER_SIZE:
                end = HEADER_SIZE + int.from_bytes(buffer[2:4], "little")
                if len(buffer) >= end:
                    header = EncapsulationHeader.decode(buffer)
                    body = bytes(buffer[HEADER_SIZE:end])
                    del buffer[:end]
                    return header, body
            try:
                # A reply is small; a 64 KiB receive buffer would be allocated and shrunk on every call.
                chunk = sock.recv(4096)
            except TimeoutError:
                raise self._timeout_error("a request") from None
            except OSError as exc:
                raise ConnectionError(f"connection to {self.host}:{self.port} lost: {exc}") from None
            if not chunk:
                raise ConnectionError(f"connection to {self.host}:{self.port} closed by the target")
            buffer += chunk

    async def exchange(self, command: int, data: bytes = b"", context: bytes | None = None,
                       timeout: float | None = None) -> tuple[EncapsulationHeader, bytes]:
        context = context or self._new_context()
        self._write(command, data, context)
        while True:
            header, body = self._read_frame(timeout or self.timeout)
            if header.context == context and header.command == command:
                break  # anything else is a late reply to an earlier, timed-out request
        if header.status != 0:
            raise EncapsulationStatusError(command, header.status)
        return header, body

    async def _connected_round_trip(self, sequence: int, body: bytes, timeout: float | None) -> bytes:
        self._write(Command.SEND_UNIT_DATA, body, bytes(8))
        while True:
            header, reply = self._read_frame(timeout or self.timeout)
            if header.command != Command.SEND_UNIT_DATA or header.status != 0:
                continue
            try:
                items = decode_items(reply, RR_PREFIX.size, strict=False)
                matched = len(items) >= 2 and _SEQ.unpack_from(items[1].data)[0] == sequence
            except (EncapsulationError, struct.error):
                log.debug("malformed SendUnitData reply ignored: %s", reply.hex())
                continue
            if matched:
                return items[1].data[2:]

    @property
    def is_open(self) -> bool:
        return self._sock is not None

    def _close_transport(self) -> None:
        if self._sock is not None:
            self._sock.close()
        self._sock = None


def run_blocking(coroutine: Coroutine[Any, Any, T]) -> T:
    """Run a coroutine of a ``BlockingEncapsulationClient`` to completion without an event loop."""
    try:
        coroutine.send(None)
    except StopIteration as done:
        return done.value  # type: ignore[no-any-return]
    coroutine.close()
    raise RuntimeError("this operation needs an event loop (use the async Scanner)")


def _expire(future: asyncio.Future[Any]) -> None:
    if not future.done():
        future.set_exception(asyncio.TimeoutError())

__all__ = ["DEFAULT_PORT", "CipError", "EncapsulationClient", "EncapsulationStatusError", "ExplicitConnectionInfo",
           "GeneralStatus", "MalformedReplyError", "broadcast_addresses", "discover", "list_services_udp", "parse_host",
           "udp_query"]
