"""The EtherNet/IP originator (scanner) client, asyncio.

``EncapsulationClient`` owns one TCP connection and one session. Requests are matched to
replies by sender context, so several may be in flight at once; class 3 requests are
matched by their connection's sequence count. ``discover`` sends ListIdentity over UDP
(unicast or broadcast) and collects replies until its timeout.
"""

from __future__ import annotations

import asyncio
import ipaddress
import itertools
import logging
import random
import socket
import struct
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

from ..cip.epath import Segment, encode_path, request_path
from ..cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from ..cip.status import CipError, GeneralStatus
from .cm_messages import (
    ConnectionTriad,
    ForwardCloseRequest,
    ForwardOpenReply,
    ForwardOpenRequest,
    NetworkParameters,
    TransportTrigger,
    TriggerType,
    UnconnectedSendRequest,
)
from .cpf import Item, ItemType, SockAddr, decode_items, encode_items
from .encapsulation import (
    HEADER,
    HEADER_SIZE,
    PROTOCOL_VERSION,
    REGISTER_SESSION_DATA,
    RR_PREFIX,
    Command,
    EncapsulationError,
    EncapsulationHeader,
    EncapsulationStatus,
)
from .identity_items import IdentityRecord, ServiceRecord, decode_list_identity, decode_list_services
from .interfaces import directed_broadcasts
from .io_core import DEFAULT_IO_PORT
from .io_originator import (
    Class1Request,
    IoConnectionHandle,
    IoOriginator,
    OtFormat,
    class1_path,
    new_connection,
)
from .io_server import IoEndpoint

if TYPE_CHECKING:
    from ..assemblies.schema import AssemblySchema

log = logging.getLogger(__name__)
T = TypeVar("T")

DEFAULT_PORT = 44818
#: Our vendor id as an originator (0xFFFF is not assigned; any value works for tests).
ORIGINATOR_VENDOR_ID = 0xFFFE
CONNECTION_MANAGER_PATH = request_path(0x06, 1)
MESSAGE_ROUTER_PATH = request_path(0x02, 1)

_SEQ = struct.Struct("<H")
_CONN_ID = struct.Struct("<I")


class EncapsulationStatusError(Exception):
    """A reply carried a non-zero encapsulation status."""

    def __init__(self, command: int, status: int) -> None:
        self.command = command
        self.status = status
        try:
            name = EncapsulationStatus(status).name.lower().replace("_", " ")
        except ValueError:
            name = "unknown"
        text = f"encapsulation command 0x{command:04X} failed with status 0x{status:04X} ({name})"
        if command == 0x0065 and status == 0x0002:
            # RegisterSession answered "insufficient memory": what targets answer when every session is taken.
            text += ": the target's session table is full (its session limit is reached)"
        super().__init__(text)


class MalformedReplyError(ConnectionError):
    """A reply that cannot be decoded: one line for the user, never a traceback."""


def _decode_reply(what: str, decode: Callable[[], T]) -> T:
    """Run a client-side decoder; any failure of it is a ``MalformedReplyError`` naming ``what``."""
    try:
        return decode()
    except (ValueError, struct.error, IndexError, CipError, EncapsulationError) as exc:
        raise MalformedReplyError(f"malformed {what}: {exc}") from None


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
        return _decode_reply("ListIdentity reply", lambda: decode_list_identity(body))

    async def list_services(self) -> list[ServiceRecord]:
        _, body = await self.exchange(Command.LIST_SERVICES)
        return _decode_reply("ListServices reply", lambda: decode_list_services(body))

    async def list_interfaces(self) -> list[Item]:
        _, body = await self.exchange(Command.LIST_INTERFACES)
        return _decode_reply("ListInterfaces reply", lambda: decode_items(body, strict=False))

    async def nop(self, data: bytes = b"") -> None:
        self._write(Command.NOP, data, bytes(8))

    # -- explicit messaging ---------------------------------------------------------------------
    async def send_rr_data(self, request: bytes, timeout: float | None = None) -> bytes:
        """Unconnected explicit request (SendRRData); returns the encoded message-router reply."""
        items = (Item(ItemType.NULL_ADDRESS), Item(ItemType.UNCONNECTED_DATA, request))
        body = RR_PREFIX.pack(0, 0) + encode_items(items)
        _, reply = await self.exchange(Command.SEND_RR_DATA, body, timeout=timeout)
        items = _decode_reply("SendRRData reply", lambda: decode_items(reply, RR_PREFIX.size, strict=False))
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
        reply_items = _decode_reply("SendRRData reply", lambda: decode_items(reply, RR_PREFIX.size, strict=False))
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
            route_bytes = route if isinstance(route, bytes) else encode_path(route)
            raw = MessageRouterRequest(Service.UNCONNECTED_SEND, CONNECTION_MANAGER_PATH,
                                       UnconnectedSendRequest(0x0A, 0x0E, raw, route_bytes).encode()).encode()
        reply = await (self.send_unit_data(raw, timeout) if use_connection else self.send_rr_data(raw, timeout))
        return _decode_reply("message router reply", lambda: MessageRouterResponse.decode(reply))

    # -- class 3 connection -----------------------------------------------------------------------
    async def forward_open(self, rpi_us: int = 2_000_000, connection_size: int = 500, large: bool = False,
                           timeout_multiplier: int = 1, route: Sequence[Segment] | bytes = b"",
                           path: bytes = MESSAGE_ROUTER_PATH) -> ExplicitConnectionInfo:
        """Open a class 3 connection to the message router (Forward_Open or Large_Forward_Open)."""
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
        decoded = _decode_reply("Forward_Open reply", lambda: ForwardOpenReply.decode(reply.data))
        self.connection = ExplicitConnectionInfo(decoded.ot_connection_id, decoded.to_connection_id, triad,
                                                 decoded.ot_api_us)
        return self.connection

    async def forward_close(self) -> None:
        connection = self.connection
        if connection is None:
            return
        self.connection = None
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
                      target_io_port: int = DEFAULT_IO_PORT, local_io_port: int = 0, multicast: bool = False,
                      timeout_multiplier: int = 2, output_schema: AssemblySchema | None = None,
                      input_schema: AssemblySchema | None = None, run: bool = True,
                      keep_intervals: bool = False, config_data: bytes = b"",
                      ot_format: OtFormat | str | None = None) -> IoContext:
        """Open a class 1 connection; use as ``async with client.io_connection(...) as io``.

        ``output``/``input`` are the assembly instances (``heartbeat`` replaces the output for
        input-only and listen-only connections); ``rpi`` is in seconds; ``config`` the
        configuration instance and ``config_data`` the data sent with it (a simple data segment).
        ``ot_format`` is the O->T real-time format: run/idle header (default), heartbeat (the
        sequence count alone) or modeless. T->O data comes to this host's UDP ``local_io_port``
        (0: the shared endpoint's port), which the Forward_Open announces in a Sockaddr Info
        item; O->T data goes to ``target_io_port`` on the target. A target that refuses the
        O->T or T->O size with 0x0127/0x0128 and names the size it wants gets one retry with it.
        """
        fmt = OtFormat(ot_format) if ot_format is not None else OtFormat.RUN_IDLE
        if fmt is OtFormat.HEARTBEAT and heartbeat is None:
            raise ValueError("the heartbeat format carries no data: give a heartbeat point, not an output")
        request = Class1Request(None if heartbeat is not None else output_size, input_size, int(rpi * 1e6),
                                int(rpi * 1e6), class1_path(output, input, config, heartbeat, config_data), multicast,
                                timeout_multiplier, ot_format=fmt)
        return IoContext(self, request, target_io_port, local_io_port, output_schema, input_schema, run,
                         keep_intervals)


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

class IoContext:
    """Async context manager of a class 1 connection: Forward_Open on enter, Forward_Close on exit.

    Once the Forward_Open succeeded, every way out closes the connection: an error while
    setting it up (a group that cannot be joined, a socket error), an exception or a
    cancellation (Ctrl-C) in the body, or a normal exit."""

    def __init__(self, client: EncapsulationClient, request: Class1Request, target_io_port: int, local_io_port: int,
                 output_schema: AssemblySchema | None, input_schema: AssemblySchema | None, run: bool,
                 keep_intervals: bool) -> None:
        self.client = client
        self.request = request
        self.target_io_port = target_io_port
        self.local_io_port = local_io_port
        self.output_schema = output_schema
        self.input_schema = input_schema
        self.run = run
        self.keep_intervals = keep_intervals
        self.handle: IoConnectionHandle | None = None
        self._triad: ConnectionTriad | None = None
        #: What the opening had to adapt to (a retry with the size a target asked for), one line each.
        self.notes: list[str] = []

    async def _forward_open(self, request: Class1Request, port: int
                            ) -> tuple[ForwardOpenReply, list[Item], ConnectionTriad]:
        ot, to, transport, triad, to_id = request.parameters()
        fo = ForwardOpenRequest(0x0A, 0x0E, 0, to_id, triad, request.timeout_multiplier, request.ot_rpi_us,
                                ot, request.to_rpi_us, to, transport, request.path, request.large)
        raw = MessageRouterRequest(Service.FORWARD_OPEN, CONNECTION_MANAGER_PATH, fo.encode()).encode()
        sockaddr = Item(ItemType.SOCKADDR_T_O, SockAddr("0.0.0.0", port).encode())
        reply_raw, extra = await self.client.send_rr_data_items(raw, [] if request.multicast else [sockaddr])
        response = _decode_reply("Forward_Open reply", lambda: MessageRouterResponse.decode(reply_raw))
        response.raise_for_status()
        return _decode_reply("Forward_Open reply", lambda: ForwardOpenReply.decode(response.data)), extra, triad

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
        return self.handle

    async def _start(self, request: Class1Request, reply: ForwardOpenReply, extra: list[Item], core: IoOriginator,
                     endpoint: IoEndpoint) -> IoConnectionHandle:
        connection = new_connection(request, self.client.host_address(), self.target_io_port,
                                    reply.ot_connection_id, reply.to_connection_id, reply.ot_api_us, reply.to_api_us,
                                    asyncio.get_running_loop().time(), self.keep_intervals)
        connection.run = self.run
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
            else:
                # 0.0.0.0:<our port> echoed back on a point-to-point connection, or the target's
                # O->T address: informational; only a 224.0.0.0/4 group is something to join.
                log.debug("Forward_Open reply: Sockaddr Info 0x%04X %s:%d (informational)", item.type,
                          address.host, address.port)
        output_schema, input_schema = self.output_schema, self.input_schema
        if output_schema is not None and output_schema.size != (request.output_size or 0):
            output_schema = None  # the size the target asked for is not the schema's: raw bytes only
        if input_schema is not None and input_schema.size != request.input_size:
            input_schema = None
        core.add(connection)
        endpoint.wakeup()
        return IoConnectionHandle(core, endpoint, connection, output_schema, input_schema)

    async def _forward_close(self) -> None:
        if self._triad is None:
            return
        fc = ForwardCloseRequest(0x0A, 0x0E, self._triad, self.request.path)
        self._triad = None
        try:
            reply = await self.client.request(Service.FORWARD_CLOSE, CONNECTION_MANAGER_PATH, fc.encode(),
                                              connected=False)
            reply.raise_for_status()
        except (ConnectionError, CipError, EncapsulationStatusError, asyncio.TimeoutError) as exc_close:
            log.info("Forward_Close of class 1 connection failed: %s", exc_close)

    async def __aexit__(self, *exc: object) -> None:
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
    if found is not None and found[1].transport is not None and getattr(found[1], "loop", None) is loop:
        return found
    core = IoOriginator()
    endpoint = IoEndpoint(core, host, port)
    await endpoint.start()
    _io_endpoints[key] = (core, endpoint)
    return core, endpoint


class _DiscoveryProtocol(asyncio.DatagramProtocol):
    def __init__(self) -> None:
        self.replies: list[tuple[bytes, tuple[str, int]]] = []

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if len(self.replies) < MAX_DISCOVERY_REPLIES:
            self.replies.append((data, addr))

    def error_received(self, exc: Exception) -> None:
        log.debug("discovery: %s", exc)


#: Replies kept from one query: far more devices than one subnet holds; the rest are dropped.
MAX_DISCOVERY_REPLIES = 4096
LIMITED_BROADCAST = "255.255.255.255"


def broadcast_addresses() -> list[str]:
    """Where a broadcast with no address given goes: 255.255.255.255 and the directed broadcast
    address of every IPv4 interface, loopback included (127.255.255.255), so that devices on
    every attached subnet hear it. Linux reads the interfaces; elsewhere the limited broadcast alone."""
    return [LIMITED_BROADCAST, *(address for address in directed_broadcasts() if address != LIMITED_BROADCAST)]


async def udp_query(command: int, address: str | Sequence[str] | None = None, port: int = DEFAULT_PORT,
                    timeout: float = 2.0, max_delay_ms: int | None = None) -> list[tuple[bytes, tuple[str, int]]]:
    """Send a ListIdentity/ListServices datagram and collect the reply bodies for ``timeout`` seconds.

    ``address``: one address (broadcast or unicast), several, or None for every interface's
    broadcast address (see ``broadcast_addresses``)."""
    addresses = [address] if isinstance(address, str) else list(address) if address is not None else []
    addresses = addresses or broadcast_addresses()
    loop = asyncio.get_running_loop()
    transport, protocol = await loop.create_datagram_endpoint(_DiscoveryProtocol, family=socket.AF_INET,
                                                              allow_broadcast=True)
    try:
        delay = max_delay_ms if max_delay_ms is not None else max(500, min(int(timeout * 1000) - 100, 0xFFFF))
        context = _SEQ.pack(delay) + bytes(6)
        for destination in addresses:
            try:
                transport.sendto(HEADER.pack(command, 0, 0, 0, context, 0), (destination, port))
            except OSError as exc:  # an interface without a route: the others still count
                log.debug("discovery: cannot send to %s:%d: %s", destination, port, exc)
        await asyncio.sleep(timeout)
    finally:
        transport.close()
    bodies = []
    for data, addr in protocol.replies:
        if len(data) >= HEADER_SIZE:
            header = EncapsulationHeader.decode(data)
            if header.command == command and header.status == 0 and header.length == len(data) - HEADER_SIZE:
                bodies.append((data[HEADER_SIZE:], addr))
                continue
        log.debug("discovery: reply from %s:%d ignored: %s", addr[0], addr[1], data[:64].hex())
    return bodies


async def discover(address: str | Sequence[str] | None = None, port: int = DEFAULT_PORT,
                   timeout: float = 2.0) -> list[IdentityRecord]:
    """ListIdentity over UDP: every device that answers within ``timeout`` seconds, once each.

    ``address`` None: the broadcast address of every interface (loopback included). A device
    that answers twice (two broadcasts reached it, or it repeated its reply) is listed once:
    replies are told apart by the address they came from and the serial number."""
    records: list[IdentityRecord] = []
    seen: set[tuple[str, int]] = set()
    for body, addr in await udp_query(Command.LIST_IDENTITY, address, port, timeout):
        try:
            found = decode_list_identity(body)
        except (ValueError, struct.error, EncapsulationError) as exc:
            log.debug("discovery: malformed ListIdentity reply from %s ignored: %s", addr[0], exc)
            continue
        for record in found:
            key = (addr[0], record.serial_number)
            if key not in seen:
                seen.add(key)
                records.append(record)
    return records


async def list_services_udp(address: str, port: int = DEFAULT_PORT, timeout: float = 1.0) -> list[ServiceRecord]:
    records: list[ServiceRecord] = []
    for body, addr in await udp_query(Command.LIST_SERVICES, address, port, timeout):
        try:
            records.extend(decode_list_services(body))
        except (ValueError, struct.error, EncapsulationError) as exc:
            log.debug("malformed ListServices reply from %s ignored: %s", addr[0], exc)
    return records


__all__ = ["DEFAULT_PORT", "CipError", "EncapsulationClient", "EncapsulationStatusError", "ExplicitConnectionInfo",
           "GeneralStatus", "MalformedReplyError", "broadcast_addresses", "discover", "list_services_udp", "parse_host",
           "udp_query"]
