"""The originator's protocol without I/O: requests in, frames out; bytes in, replies out.

``OriginatorCore`` is one encapsulation session as an originator sees it, in the shape of the
target side (h11's and aioquic's): it never touches a socket or a clock. A request is built as a
``Transaction`` (the frame to send and how to read its reply); a shell ``start``\\ s it with the
current time, writes the frame, and feeds whatever arrives to ``receive_data``, which returns the
transactions it completes; ``expired(now)`` gives those whose deadline passed. The core owns the
session handle, sender contexts, the class 3 connection and its sequence count, Forward_Open and
Forward_Close, Unconnected_Send routing, Multiple_Service_Packet and the decoding of replies and
errors. The asyncio client, the blocking client and the conformance battery's probe are shells
over it.

Several operations (identify a device, write by declaration) take more than one request: they are
written once as a ``Plan``, a generator that yields each transaction and is sent back its result
(or has the failure thrown in). A plan cannot await anything else, so a shell that performs each
yielded transaction drives it completely; ``run_plan`` is the blocking driver.
"""

from __future__ import annotations

import itertools
import random
import struct
from collections.abc import Callable, Generator, Sequence
from typing import TYPE_CHECKING, Any, Generic, Protocol, TypeVar

from ...cip.epath import Segment, encode_path, request_path
from ...cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from ...errors import BadRequest, CipstackError, NoReply, PeerUnreachable
from ...logs import debug
from ..wire.cpf import Item, ItemType, decode_items, encode_items
from ..wire.encapsulation import (
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
from .replies import EncapsulationStatusError, MalformedReplyError, decode_reply

if TYPE_CHECKING:
    import socket

    # Imported where used: explicit messaging (a one-shot ``cipstack get``) does not load the
    # Connection Manager's messages (their dataclasses cost milliseconds to import).
    from ..wire.cm_messages import ConnectionTriad
    from ..wire.identity_items import IdentityRecord, ServiceRecord

T = TypeVar("T")

#: Our vendor id as an originator (0xFFFF is not assigned; any value works for tests).
ORIGINATOR_VENDOR_ID = 0xFFFE
MESSAGE_ROUTER_PATH = request_path(0x02, 1)
#: Seconds a request waits for its reply unless told otherwise.
DEFAULT_TIMEOUT = 5.0

_SEQ = struct.Struct("<H")
_CONN_ID = struct.Struct("<I")
_ITEM_LENGTH = struct.Struct("<H")
_UINT = struct.Struct("<H")
#: A SendRRData body up to the Unconnected Data item's length: interface handle 0, timeout 0, item
#: count 2, Null Address item (type 0, length 0), Unconnected Data item type 0x00B2.
_RR_TWO_ITEMS = RR_PREFIX.pack(0, 0) + struct.pack("<HHHH", 2, ItemType.NULL_ADDRESS, 0, ItemType.UNCONNECTED_DATA)
_RR_TWO_ITEMS_SIZE = len(_RR_TWO_ITEMS)
_NO_CONTEXT = bytes(8)


def parse_host(text: str, default_port: int = DEFAULT_PORT) -> tuple[str, int]:
    """``HOST[:PORT]`` -> (host, port)."""
    host, sep, port = text.rpartition(":")
    if not sep:
        return text, default_port
    if not host:
        raise BadRequest(f"no host in {text!r}")
    try:
        number = int(port, 0)
    except ValueError:
        raise BadRequest(f"bad port in {text!r}") from None
    if not 0 < number < 65536:
        raise BadRequest(f"port {number} out of range")
    return host, number


class NoReplyError(NoReply):
    """A request whose reply did not come before its deadline: ``PeerUnreachable`` (a
    ``ConnectionError``) and, as before, a ``TimeoutError``."""


class ExplicitConnectionInfo:
    """A class 3 connection this originator opened; ``sequence`` is the count of its last request."""

    __slots__ = ("ot_connection_id", "rpi_us", "sequence", "to_connection_id", "triad")

    def __init__(self, ot_connection_id: int, to_connection_id: int, triad: ConnectionTriad, rpi_us: int,
                 sequence: int = 0) -> None:
        self.ot_connection_id = ot_connection_id
        self.to_connection_id = to_connection_id
        self.triad = triad
        self.rpi_us = rpi_us
        self.sequence = sequence

    def __repr__(self) -> str:
        return (f"ExplicitConnectionInfo(ot_connection_id=0x{self.ot_connection_id:08X}, "
                f"to_connection_id=0x{self.to_connection_id:08X}, triad={self.triad!r}, rpi_us={self.rpi_us}, "
                f"sequence={self.sequence})")


class Transaction(Generic[T]):
    """One request and how to read its reply: ``frame`` goes on the wire, ``result`` reads the reply
    (raising the error it carries). ``key`` matches the reply: the sender context, or for a class 3
    request its sequence count."""

    __slots__ = ("_decode", "command", "deadline", "frame", "key", "timeout", "what")

    def __init__(self, command: int, frame: bytes, key: bytes | int, what: str, timeout: float | None,
                 decode: Callable[[EncapsulationHeader, bytes], T]) -> None:
        self.command = command
        self.frame = frame
        self.key = key
        self.what = what
        #: Seconds to wait for the reply (None: the core's default); ``deadline`` once started.
        self.timeout = timeout
        self.deadline = 0.0
        self._decode = decode

    def result(self, header: EncapsulationHeader, body: bytes) -> T:
        """The reply's meaning; ``EncapsulationStatusError`` for a non-zero status, ``MalformedReplyError``
        for bytes that do not decode."""
        if header.status:
            raise EncapsulationStatusError(self.command, header.status)
        return self._decode(header, body)

    def __repr__(self) -> str:
        return f"<Transaction {self.what}>"


#: A transaction and the reply that completes it (for a class 3 request the body is the message
#: router reply, the sequence count taken off).
Completion = tuple[Transaction[Any], EncapsulationHeader, bytes]
#: An operation of several requests: yields each transaction, is sent each result, returns T.
Plan = Generator[Transaction[Any], Any, T]


class FrameBuffer:
    """Bytes of a TCP stream in, whole encapsulation frames out (the length field says where each ends)."""

    __slots__ = ("_buffer",)

    def __init__(self) -> None:
        self._buffer = bytearray()

    def feed(self, data: bytes) -> list[bytes]:
        """Append ``data``; return every frame now whole, header included, in order."""
        buffer = self._buffer
        buffer += data
        frames = []
        start = 0
        size = len(buffer)
        while size - start >= HEADER_SIZE:
            end = start + HEADER_SIZE + (buffer[start + 2] | buffer[start + 3] << 8)
            if end > size:
                break
            frames.append(bytes(buffer[start:end]))
            start = end
        if start:
            del buffer[:start]
        return frames

    def __len__(self) -> int:
        return len(self._buffer)


def rr_reply_data(body: bytes) -> bytes:
    """The message-router reply a SendRRData reply carries (its Unconnected Data item)."""
    # The reply as nearly every target lays it out, read without building items; anything else
    # (items in another order, an extra item, a count that lies) by the general decoder.
    if body[:_RR_TWO_ITEMS_SIZE] == _RR_TWO_ITEMS and len(body) == _RR_TWO_ITEMS_SIZE + 2 + int.from_bytes(
            body[_RR_TWO_ITEMS_SIZE:_RR_TWO_ITEMS_SIZE + 2], "little"):
        return body[_RR_TWO_ITEMS_SIZE + 2:]
    return rr_reply_items(body)[0]


def rr_reply_items(body: bytes) -> tuple[bytes, list[Item]]:
    """A SendRRData reply read item by item: its Unconnected Data and every item."""
    items = decode_reply("SendRRData reply", lambda: decode_items(body, RR_PREFIX.size, strict=False))
    for item in items:
        if item.type == ItemType.UNCONNECTED_DATA:
            return item.data, items
    raise MalformedReplyError("malformed SendRRData reply: no Unconnected Data item")


def rr_request_body(request: bytes, extra: Sequence[Item] = ()) -> bytes:
    """SendRRData data: interface handle 0, timeout 0, Null Address and Unconnected Data (+ ``extra`` items)."""
    if not extra:
        return _RR_TWO_ITEMS + _ITEM_LENGTH.pack(len(request)) + request
    return RR_PREFIX.pack(0, 0) + encode_items((Item(ItemType.NULL_ADDRESS), Item(ItemType.UNCONNECTED_DATA, request),
                                                *extra))


def decode_message_reply(data: bytes) -> MessageRouterResponse:
    return decode_reply("message router reply", lambda: MessageRouterResponse.decode(data))


def encode_multiple_service(requests: Sequence[MessageRouterRequest]) -> bytes:
    """Multiple_Service_Packet data: the count, each request's offset, the requests."""
    encoded = [r.encode() for r in requests]
    table = bytearray(_UINT.pack(len(encoded)))
    offset = 2 + 2 * len(encoded)
    for item in encoded:
        table += _UINT.pack(offset)
        offset += len(item)
    return bytes(table) + b"".join(encoded)


def decode_multiple_service(body: bytes) -> list[MessageRouterResponse]:
    """Each reply of a Multiple_Service_Packet reply's data, by its offset."""
    def decode() -> list[MessageRouterResponse]:
        (count,) = _UINT.unpack_from(body, 0)
        offsets = [_UINT.unpack_from(body, 2 + 2 * i)[0] for i in range(count)] + [len(body)]
        return [MessageRouterResponse.decode(body[offsets[i]:offsets[i + 1]]) for i in range(count)]

    return decode_reply("Multiple_Service_Packet reply", decode)


class OriginatorCore:
    """One encapsulation session of an originator, sans I/O (see the module docstring).

    ``random`` draws connection serial numbers and ids (give a seeded one for reproducible frames);
    ``timeout`` is the default seconds a request waits for its reply.
    """

    def __init__(self, timeout: float = DEFAULT_TIMEOUT, rng: random.Random | None = None) -> None:
        self.timeout = timeout
        #: The session handle RegisterSession gave (0: none).
        self.session = 0
        #: The open class 3 connection, if any: connected requests travel on it.
        self.connection: ExplicitConnectionInfo | None = None
        self._random = rng or random.Random()
        self._contexts = itertools.count(1)
        self._serials = itertools.count(self._random.randrange(0, 0xFFFF))
        self._frames = FrameBuffer()
        self._pending: dict[bytes, Transaction[Any]] = {}
        self._connected: dict[int, Transaction[Any]] = {}

    # -- the shell's side -------------------------------------------------------------------------------
    def start(self, transaction: Transaction[Any], now: float) -> bytes:
        """Register ``transaction`` as sent at ``now``; returns its frame to write."""
        transaction.deadline = now + (transaction.timeout or self.timeout)
        if isinstance(transaction.key, int):
            self._connected[transaction.key] = transaction
        else:
            self._pending[transaction.key] = transaction
        return transaction.frame

    def receive_data(self, data: bytes) -> list[Completion]:
        """Feed bytes received; returns the transactions they complete, with their replies. A frame
        no pending request waits for (a late reply to one that timed out, a duplicate) is dropped."""
        completed: list[Completion] = []
        for frame in self._frames.feed(data):
            header = EncapsulationHeader.decode(frame)
            body = frame[HEADER_SIZE:]
            if header.command == Command.SEND_UNIT_DATA and header.status == 0:
                found = self._connected_reply(body)
                if found is not None:
                    completed.append((found[0], header, found[1]))
                continue
            transaction = self._pending.get(header.context)
            if transaction is None or transaction.command != header.command:
                debug(__name__, "reply nothing waits for dropped: command 0x%04X context %s", header.command,
                      header.context.hex())
                continue
            del self._pending[header.context]
            completed.append((transaction, header, body))
        return completed

    def _connected_reply(self, body: bytes) -> tuple[Transaction[Any], bytes] | None:
        try:
            items = decode_items(body, RR_PREFIX.size, strict=False)
            data = items[1].data
            (sequence,) = _SEQ.unpack_from(data)
        except (EncapsulationError, struct.error, IndexError):
            debug(__name__, "malformed SendUnitData reply dropped: %s", body.hex())
            return None
        transaction = self._connected.pop(sequence, None)
        if transaction is None:
            debug(__name__, "SendUnitData reply to no pending sequence count %d dropped", sequence)
            return None
        return transaction, data[2:]

    def forget(self, transaction: Transaction[Any]) -> None:
        """Stop waiting for ``transaction`` (abandoned by its caller); a late reply is then dropped."""
        table: dict[Any, Transaction[Any]] = self._connected if isinstance(transaction.key, int) else self._pending
        if table.get(transaction.key) is transaction:
            del table[transaction.key]

    def expired(self, now: float) -> list[Transaction[Any]]:
        """The transactions whose deadline is past at ``now``, no longer waited for."""
        late = [t for t in (*self._pending.values(), *self._connected.values()) if t.deadline <= now]
        for transaction in late:
            self.forget(transaction)
        return late

    def next_deadline(self) -> float | None:
        """When the earliest pending request times out (None: nothing pending)."""
        deadlines = [t.deadline for t in (*self._pending.values(), *self._connected.values())]
        return min(deadlines) if deadlines else None

    def lost(self) -> list[Transaction[Any]]:
        """The connection is gone: every pending transaction, no longer waited for."""
        pending = [*self._pending.values(), *self._connected.values()]
        self._pending.clear()
        self._connected.clear()
        self._frames = FrameBuffer()
        return pending

    @property
    def pending(self) -> int:
        """How many requests wait for their reply."""
        return len(self._pending) + len(self._connected)

    # -- frames ------------------------------------------------------------------------------------------
    def _frame(self, command: int, data: bytes, context: bytes) -> bytes:
        return HEADER.pack(command, len(data), self.session, 0, context, 0) + data

    def _new_context(self) -> bytes:
        return next(self._contexts).to_bytes(8, "little")

    def _transaction(self, command: int, data: bytes, what: str, decode: Callable[[EncapsulationHeader, bytes], T],
                     timeout: float | None = None, context: bytes | None = None) -> Transaction[T]:
        context = context or self._new_context()
        return Transaction(command, self._frame(command, data, context), context, what, timeout, decode)

    def command(self, command: int, data: bytes = b"", context: bytes | None = None,
                timeout: float | None = None) -> Transaction[tuple[EncapsulationHeader, bytes]]:
        """Any encapsulation command; its reply header and data (matched by sender context)."""
        return self._transaction(command, data, f"command 0x{command:04X}", _header_and_body, timeout, context)

    def unregister_session(self) -> bytes:
        """The UnRegisterSession frame (no reply comes); the session is over."""
        frame = self._frame(Command.UNREGISTER_SESSION, b"", _NO_CONTEXT)
        self.session = 0
        return frame

    def nop(self, data: bytes = b"") -> bytes:
        """A NOP frame (no reply comes): keeps an idle session alive."""
        return self._frame(Command.NOP, data, _NO_CONTEXT)

    # -- encapsulation commands ----------------------------------------------------------------------------
    def register_session(self) -> Transaction[int]:
        def registered(header: EncapsulationHeader, _: bytes) -> int:
            self.session = header.session
            return header.session

        return self._transaction(Command.REGISTER_SESSION, REGISTER_SESSION_DATA.pack(PROTOCOL_VERSION, 0),
                                 "RegisterSession", registered)

    def list_identity(self) -> Transaction[list[IdentityRecord]]:
        from ..wire.identity_items import decode_list_identity  # here: a one-shot ``get`` lists nothing

        return self._transaction(Command.LIST_IDENTITY, b"", "ListIdentity", lambda _, body: decode_reply(
            "ListIdentity reply", lambda: decode_list_identity(body)))

    def list_services(self) -> Transaction[list[ServiceRecord]]:
        from ..wire.identity_items import decode_list_services

        return self._transaction(Command.LIST_SERVICES, b"", "ListServices", lambda _, body: decode_reply(
            "ListServices reply", lambda: decode_list_services(body)))

    def list_interfaces(self) -> Transaction[list[Item]]:
        return self._transaction(Command.LIST_INTERFACES, b"", "ListInterfaces", lambda _, body: decode_reply(
            "ListInterfaces reply", lambda: decode_items(body, strict=False)))

    # -- explicit messaging -----------------------------------------------------------------------------
    def send_rr_data(self, request: bytes, timeout: float | None = None) -> Transaction[bytes]:
        """An unconnected request (SendRRData); its reply is the encoded message-router reply."""
        return self._transaction(Command.SEND_RR_DATA, rr_request_body(request), "SendRRData",
                                 lambda _, body: rr_reply_data(body), timeout)

    def send_rr_data_items(self, request: bytes, extra: Sequence[Item] = (), timeout: float | None = None
                           ) -> Transaction[tuple[bytes, list[Item]]]:
        """SendRRData with extra CPF items (Sockaddr Info); its reply and the reply's extra items."""
        def decode(_: EncapsulationHeader, body: bytes) -> tuple[bytes, list[Item]]:
            data, items = rr_reply_items(body)
            return data, [i for i in items if i.type not in (ItemType.NULL_ADDRESS, ItemType.UNCONNECTED_DATA)]

        return self._transaction(Command.SEND_RR_DATA, rr_request_body(request, extra), "SendRRData", decode, timeout)

    def send_unit_data(self, request: bytes, timeout: float | None = None) -> Transaction[bytes]:
        """A class 3 request on the open connection, numbered by its sequence count; its reply is
        the encoded message-router reply."""
        connection = self.connection
        if connection is None:
            raise PeerUnreachable("no class 3 connection is open")
        connection.sequence = sequence = (connection.sequence + 1) & 0xFFFF
        body = RR_PREFIX.pack(0, 0) + encode_items((
            Item(ItemType.CONNECTED_ADDRESS, _CONN_ID.pack(connection.ot_connection_id)),
            Item(ItemType.CONNECTED_DATA, _SEQ.pack(sequence) + request),
        ))
        return Transaction(Command.SEND_UNIT_DATA, self._frame(Command.SEND_UNIT_DATA, body, _NO_CONTEXT), sequence,
                           "a class 3 request", timeout, _body)

    def request(self, service: int, path: bytes, data: bytes = b"", *,
                route: Sequence[Segment] | bytes | None = None, connected: bool | None = None,
                timeout: float | None = None) -> Transaction[MessageRouterResponse]:
        """Any service; its reply, status unchecked.

        ``route``: a route path (port segments): the request is wrapped in Unconnected_Send to the
        Connection Manager. ``connected``: on the class 3 connection (default: when one is open),
        whose path already holds the route.
        """
        raw = MessageRouterRequest(service, path, data).encode()
        use_connection = self.connection is not None if connected is None else connected
        if route is not None and not use_connection:
            from ..wire.cm_messages import CONNECTION_MANAGER_PATH, UnconnectedSendRequest

            route_bytes = route if isinstance(route, bytes) else encode_path(route)
            raw = MessageRouterRequest(Service.UNCONNECTED_SEND, CONNECTION_MANAGER_PATH,
                                       UnconnectedSendRequest(0x0A, 0x0E, raw, route_bytes).encode()).encode()
        inner = self.send_unit_data(raw, timeout) if use_connection else self.send_rr_data(raw, timeout)
        return _then(inner, decode_message_reply)

    # -- class 3 connection -------------------------------------------------------------------------------
    def forward_open(self, rpi_us: int = 2_000_000, connection_size: int = 500, large: bool = False,
                     timeout_multiplier: int = 1, route: Sequence[Segment] | bytes = b"",
                     path: bytes = MESSAGE_ROUTER_PATH) -> Transaction[ExplicitConnectionInfo]:
        """Open a class 3 connection to the message router (Forward_Open or Large_Forward_Open); once
        its reply is read, later requests travel on it."""
        from ..wire.cm_messages import (
            CONNECTION_MANAGER_PATH,
            ConnectionTriad,
            ForwardOpenReply,
            ForwardOpenRequest,
            NetworkParameters,
            TransportTrigger,
            TriggerType,
        )

        route_bytes = route if isinstance(route, bytes) else encode_path(route)
        triad = ConnectionTriad(next(self._serials) & 0xFFFF, ORIGINATOR_VENDOR_ID,
                                self._random.randrange(1, 0xFFFFFFFF))
        params = NetworkParameters(connection_size, variable=True)
        request = ForwardOpenRequest(
            priority_tick=0x0A, timeout_ticks=0x0E, ot_connection_id=0,
            to_connection_id=self._random.randrange(1, 0xFFFFFFFF), triad=triad, timeout_multiplier=timeout_multiplier,
            ot_rpi_us=rpi_us, ot_parameters=params, to_rpi_us=rpi_us, to_parameters=params,
            transport=TransportTrigger(3, TriggerType.APPLICATION, server=True),
            connection_path=route_bytes + path, large=large)
        service = Service.LARGE_FORWARD_OPEN if large else Service.FORWARD_OPEN

        def opened(reply: MessageRouterResponse) -> ExplicitConnectionInfo:
            reply.raise_for_status()
            decoded = decode_reply("Forward_Open reply", lambda: ForwardOpenReply.decode(reply.data))
            self.connection = ExplicitConnectionInfo(decoded.ot_connection_id, decoded.to_connection_id, triad,
                                                     decoded.ot_api_us)
            return self.connection

        return _then(self.request(service, CONNECTION_MANAGER_PATH, request.encode(), connected=False), opened)

    def forward_close(self) -> Transaction[None] | None:
        """Close the class 3 connection (None: none is open); later requests go unconnected."""
        connection = self.connection
        if connection is None:
            return None
        self.connection = None
        from ..wire.cm_messages import CONNECTION_MANAGER_PATH, ForwardCloseRequest

        request = ForwardCloseRequest(0x0A, 0x0E, connection.triad, MESSAGE_ROUTER_PATH)

        def closed(reply: MessageRouterResponse) -> None:
            reply.raise_for_status()

        return _then(self.request(Service.FORWARD_CLOSE, CONNECTION_MANAGER_PATH, request.encode(), connected=False),
                     closed)


class SecureChannel(Protocol):
    """What secures an originator's connection (CIP Security: ``cipstack.security.Credentials``)."""

    def client_context(self) -> Any:
        """The TLS context of the originator's side (an asyncio client connects with it): an
        ``ssl.SSLContext``, or with a pre-shared key an object with its ``wrap_bio``
        (``security.tls_psk.PskTlsContext``, what asyncio's TLS transport calls)."""

    def wrap_client(self, sock: socket.socket, host: str, port: int) -> Any:
        """``sock`` after a TLS handshake as the originator (a blocking client); a ``SecurityError``
        naming the cause if it fails."""

    def refusal(self, failure: BaseException, host: str, port: int) -> CipstackError | None:
        """The error to raise for a TLS failure (a handshake refused, or with TLS 1.3 an alert after it,
        when the device judges the client's certificate); None for a failure that is not TLS's."""

    def unanswered(self, host: str, port: int, waited: float | None) -> CipstackError:
        """The error of a TCP port that took the connection and did not answer the ClientHello within
        ``waited`` seconds (a plain EtherNet/IP port does that)."""

    async def open_datagram_link(self, host: str, port: int, timeout: float,
                                 protocol_factory: Any) -> tuple[Any, Any]:
        """A DTLS session with the device's UDP ``port`` on the running loop after its handshake
        (``security.dtls_client.AsyncDtlsLink``), with the protocol ``protocol_factory`` makes
        connected to it as to a stream transport: (the link, the protocol)."""

    def datagram_link(self, host: str, port: int, timeout: float) -> Any:
        """A DTLS session with the device's UDP ``port`` after its handshake, blocking
        (``security.dtls_link.DtlsLink``): what a blocking client and its class 1 connections use in
        place of their sockets; ``SecurityError`` or ``PeerUnreachable`` naming the cause."""


class CoreClient:
    """What every shell over the core holds: the target's address, the default reply timeout and
    the core itself, whose session and class 3 connection it shows."""

    def __init__(self, host: str, port: int = DEFAULT_PORT, timeout: float = DEFAULT_TIMEOUT,
                 core: OriginatorCore | None = None) -> None:
        if not 0 < port < 65536:   # the socket's own OverflowError is no CipstackError
            raise BadRequest(f"port {port} out of range")
        self.host = host
        self.port = port
        self.timeout = timeout
        self.core = core or OriginatorCore(timeout)

    @property
    def session(self) -> int:
        """The session handle RegisterSession gave (0: none)."""
        return self.core.session

    @property
    def connection(self) -> ExplicitConnectionInfo | None:
        """The open class 3 connection, if any: requests travel on it."""
        return self.core.connection

    def no_reply(self, transaction: Transaction[Any]) -> NoReplyError:
        """The error of ``transaction`` whose reply did not come in time."""
        return NoReplyError(f"no reply from {self.host}:{self.port} to {transaction.what}")


def _header_and_body(header: EncapsulationHeader, body: bytes) -> tuple[EncapsulationHeader, bytes]:
    return header, body


def _body(_: EncapsulationHeader, body: bytes) -> bytes:
    return body


U = TypeVar("U")


def _then(transaction: Transaction[T], after: Callable[[T], U]) -> Transaction[U]:
    """``transaction`` whose result goes through ``after``: the same frame, a further reading."""
    first = transaction.result

    def decode(header: EncapsulationHeader, body: bytes) -> U:
        return after(first(header, body))

    return Transaction(transaction.command, transaction.frame, transaction.key, transaction.what, transaction.timeout,
                       decode)


def run_plan(plan: Plan[T], perform: Callable[[Transaction[Any]], Any]) -> T:
    """Drive ``plan`` to its result with a blocking ``perform`` (a transaction in, its result out)."""
    try:
        step = next(plan)
        while True:
            try:
                result = perform(step)
            except Exception as exc:  # the plan may handle the failure (a device that does not answer)
                step = plan.throw(exc)
            else:
                step = plan.send(result)
    except StopIteration as done:
        return done.value  # type: ignore[no-any-return]  # StopIteration.value is Any; the plan returns T


def one(transaction: Transaction[T]) -> Plan[T]:
    """A plan of one transaction."""
    return (yield transaction)  # type: ignore[no-any-return]  # what the shell sends back is T


__all__ = [
    "DEFAULT_TIMEOUT",
    "MESSAGE_ROUTER_PATH",
    "ORIGINATOR_VENDOR_ID",
    "Completion",
    "CoreClient",
    "ExplicitConnectionInfo",
    "FrameBuffer",
    "NoReplyError",
    "OriginatorCore",
    "Plan",
    "SecureChannel",
    "Transaction",
    "decode_message_reply",
    "decode_multiple_service",
    "encode_multiple_service",
    "one",
    "parse_host",
    "rr_reply_data",
    "rr_reply_items",
    "rr_request_body",
    "run_plan",
]
