"""The EtherNet/IP target (adapter), sans-I/O.

``EncapsulationTarget`` holds what all TCP connections share: the message router, the
session registry, the class 3 connection table and the limits. Each TCP connection is an
``EncapsulationConnection`` that takes received bytes and the current time, and leaves
bytes to send and whether to close. UDP datagrams go through ``datagram``, which returns
the reply and how long to delay it. Nothing here touches a socket or a clock.

Limits that keep a target bounded on any input: sessions (in total and per originator
address, so one host cannot lock every other out), class 3 connections, the largest
encapsulation frame (a larger announced length is answered with 0x0065 and the connection
closed, so the receive buffer never exceeds header + limit), the encapsulation inactivity
timeout (TCP/IP attribute 13), and the delayed UDP ListIdentity replies (``DelayedReplies``:
a bounded number in total and per source, each held at most ``LIST_IDENTITY_MAX_DELAY``).
"""

from __future__ import annotations

import heapq
import itertools
import logging
import random
import struct
from collections.abc import Callable
from dataclasses import dataclass, field

from ...cip.router import MessageRouter, RequestContext
from ...cip.status import GeneralStatus
from ..wire.cpf import Item, ItemType, SockAddr, decode_items, encode_items
from ..wire.encapsulation import (
    DEFAULT_FRAME_TIMEOUT,
    HEADER,
    HEADER_SIZE,
    PROTOCOL_VERSION,
    REGISTER_SESSION_DATA,
    RR_PREFIX,
    UDP_COMMANDS,
    Command,
    EncapsulationError,
    EncapsulationStatus,
)
from ..wire.identity_items import CAPABILITY_CIP_TCP, IdentityRecord, encode_list_identity, encode_list_services
from .connection_manager import ConnectionTable, ExplicitConnection, IoConnectionHandler, origin_host
from .limits import RateLimitedLog
from .seams import RequestSeam
from .trailing_bytes import is_too_much_data, too_much_data_hint

log = logging.getLogger(__name__)

_SEQ = struct.Struct("<H")
_CONN_ID = struct.Struct("<I")
#: Requests whose reply may carry a Sockaddr Info item (a class 1 Forward_Open, possibly routed).
_MAY_CARRY_SOCKADDR = frozenset({0x54, 0x5B, 0x52})

# Plain ints for the request path: an enum member costs an attribute lookup each time it is named.
_SEND_RR_DATA = int(Command.SEND_RR_DATA)
_TOO_MUCH_DATA = int(GeneralStatus.TOO_MUCH_DATA)
_NULL_ADDRESS = int(ItemType.NULL_ADDRESS)
_UNCONNECTED_DATA = int(ItemType.UNCONNECTED_DATA)

#: The common SendRRData: interface handle 0, timeout, 2 items, Null Address (0x0000, length 0),
#: Unconnected Data (0x00B2, length), then the request; served without building Item objects.
_RR_TWO_ITEMS = struct.Struct("<IHHHHHH")
_RR_TWO_ITEMS_SIZE = _RR_TWO_ITEMS.size
#: Its reply frame up to the reply's bytes: the encapsulation header and the same two items.
_RR_REPLY_FRAME = struct.Struct(HEADER.format + _RR_TWO_ITEMS.format.lstrip("<"))

#: UDP ListIdentity reply delay (CIP Vol. 2, 2-4.2.3): random between 0 and the MaxResponseDelay of
#: the request (the first UINT of the sender context, in ms); 0 means 2000 ms, 1..500 mean 500 ms.
LIST_IDENTITY_DEFAULT_DELAY_MS = 2000
LIST_IDENTITY_MIN_DELAY_MS = 500
#: The field allows up to 65,535 ms; a reply at any time within 0..2000 ms is also within every
#: larger maximum, so the target holds no reply longer than this (bounding how long a slot is taken).
LIST_IDENTITY_MAX_DELAY = 2.0


@dataclass
class TargetSettings:
    max_sessions: int = 32
    #: Sessions one originator address may hold; None: half of ``max_sessions`` (rounded up).
    max_sessions_per_host: int | None = None
    max_connections: int = 32
    #: Largest encapsulation data length accepted (bytes after the 24-byte header).
    max_frame_length: int = 4200
    #: Encapsulation inactivity timeout in seconds (0 disables); read live from TCP/IP attribute 13.
    #: Only a complete frame is activity: bytes that do not finish one keep no connection open.
    inactivity_timeout: Callable[[], float] = lambda: 120.0
    #: Seconds a frame, once its first byte has come, has to arrive whole; past that the connection
    #: closes (a peer trickling bytes holds no slot). A frame is at most 24 + 4,200 bytes, which any
    #: live peer sends in milliseconds.
    frame_timeout: float = DEFAULT_FRAME_TIMEOUT
    #: ListServices capability flags; class 0/1 over UDP is added when the device offers class 1 I/O.
    capabilities: int = CAPABILITY_CIP_TCP
    #: Randomness of the UDP ListIdentity reply delay (seedable for tests).
    rng: random.Random = field(default_factory=random.Random)
    #: Delayed UDP ListIdentity replies held at once, in total and per source address; the excess is dropped.
    max_delayed_replies: int = 64
    max_delayed_replies_per_host: int = 4

    @property
    def sessions_per_host(self) -> int:
        if self.max_sessions_per_host is not None:
            return self.max_sessions_per_host
        return max(1, (self.max_sessions + 1) // 2)


@dataclass
class TargetStatistics:
    frames: int = 0
    dropped: int = 0
    errors: int = 0
    sessions_opened: int = 0
    #: Delayed ListIdentity replies not sent because their source or the target had too many pending.
    replies_dropped: int = 0


class DelayedReplies:
    """UDP replies waiting for their time, bounded in total and per source address.

    ``push`` refuses a reply (False, nothing kept) when ``total`` are pending or its source host
    has ``per_host`` pending; ``due(now)`` hands out the replies whose time has come, in order.
    Memory is therefore at most ``total`` replies, whatever the rate of requests.
    """

    def __init__(self, total: int = 64, per_host: int = 4) -> None:
        self.total = total
        self.per_host = per_host
        self._heap: list[tuple[float, int, bytes, tuple[str, int]]] = []
        self._by_host: dict[str, int] = {}
        self._order = itertools.count()

    def __len__(self) -> int:
        return len(self._heap)

    def push(self, reply: bytes, destination: tuple[str, int], at: float) -> bool:
        host = destination[0]
        held = self._by_host.get(host, 0)
        if len(self._heap) >= self.total or held >= self.per_host:
            return False
        self._by_host[host] = held + 1
        heapq.heappush(self._heap, (at, next(self._order), reply, destination))
        return True

    def next_deadline(self) -> float | None:
        return self._heap[0][0] if self._heap else None

    def due(self, now: float) -> list[tuple[bytes, tuple[str, int]]]:
        out = []
        heap = self._heap
        while heap and heap[0][0] <= now:
            _at, _order, reply, destination = heapq.heappop(heap)
            host = destination[0]
            held = self._by_host[host] - 1
            if held:
                self._by_host[host] = held
            else:
                del self._by_host[host]
            out.append((reply, destination))
        return out

    def clear(self) -> None:
        self._heap.clear()
        self._by_host.clear()


class EncapsulationTarget:
    def __init__(self, router: MessageRouter, identity: Callable[[], IdentityRecord],
                 settings: TargetSettings | None = None, table: ConnectionTable | None = None,
                 requests: RequestSeam | None = None, tick: Callable[[float], None] | None = None,
                 class1: IoConnectionHandler | None = None) -> None:
        """``requests``: the seam explicit requests reach the router through (``seams.RequestSeam``); by
        default one of its own, with nothing in it. ``tick``: called with the time before a request is
        served (the device moves its simulation there). ``class1``: the class 1 I/O connections this
        target offers over UDP (``io_target.IoTarget``), which the Connection Manager hands class 1
        Forward_Opens and Forward_Closes (``RequestContext.class1``); None: refused, 0x0103."""
        self.router = router
        self.class1 = class1
        self.requests = requests or RequestSeam(router)
        self.identity = identity
        self.settings = settings or TargetSettings()
        self.table = table or ConnectionTable(self.settings.max_connections)
        self.sessions: dict[int, EncapsulationConnection] = {}
        self.stats = TargetStatistics()
        self.delayed = DelayedReplies(self.settings.max_delayed_replies, self.settings.max_delayed_replies_per_host)
        self.tick: Callable[[float], None] = tick or (lambda now: None)
        self._handles = itertools.count(random.randrange(1, 0x7FFF0000))
        # Refusals, each kind logged at most once per 10 s per originator address (``RateLimitedLog``).
        self.sessions_refused_log = RateLimitedLog(log, level=logging.WARNING)
        self.sessions_per_host_refused_log = RateLimitedLog(log, level=logging.INFO)
        self.frames_refused_log = RateLimitedLog(log, level=logging.INFO)
        self.frames_late_log = RateLimitedLog(log, level=logging.INFO)
        self.idle_log = RateLimitedLog(log, level=logging.INFO)
        self.too_much_data_log = RateLimitedLog(log, level=logging.INFO)

    # -- TCP ------------------------------------------------------------------------------------
    def connection(self, peer: str, local: SockAddr, now: float,
                   io_path: tuple[str, int] | None = None) -> EncapsulationConnection:
        """A connection's core; ``io_path``: the address of the DTLS session it arrives in, where the
        class 1 data of the Forward_Opens it carries then flows (None: a TCP connection, plain UDP)."""
        return EncapsulationConnection(self, peer, local, now, io_path)

    def _new_session(self, owner: EncapsulationConnection) -> int:
        while True:
            handle = next(self._handles) & 0xFFFFFFFF
            if handle and handle not in self.sessions:
                self.sessions[handle] = owner
                self.stats.sessions_opened += 1
                return handle

    def drop_sessions(self) -> int:
        """Forget every session, as a restarted target would; their TCP connections stay open, and a
        request in one of them is answered 0x0064 (invalid session handle). Class 3 connections go
        with their sessions. Returns how many sessions there were."""
        owners = list(self.sessions.values())
        self.sessions.clear()
        for owner in owners:
            owner.end_session()
        return len(owners)

    # -- UDP ------------------------------------------------------------------------------------
    def datagram(self, data: bytes, local: SockAddr) -> tuple[bytes, float] | None:
        """Answer a UDP datagram: (reply, delay in seconds), or None to drop it."""
        if len(data) < HEADER_SIZE:
            self.stats.dropped += 1
            return None
        command, length, session, _status, context, options = HEADER.unpack_from(data)
        if options != 0 or length != len(data) - HEADER_SIZE:
            self.stats.dropped += 1
            return None
        if command not in UDP_COMMANDS:
            reply = HEADER.pack(command, 0, session, EncapsulationStatus.INVALID_COMMAND, context, 0)
            return reply, 0.0
        body = self._list_reply(command, local)
        reply = HEADER.pack(command, len(body), session, 0, context, 0) + body
        if command == Command.LIST_IDENTITY:
            return reply, self.list_identity_delay(context)
        return reply, 0.0

    def list_identity_delay(self, context: bytes) -> float:
        """Random delay up to the maximum in the sender context's first UINT (0: 2000 ms, 1..499: 500 ms),
        never more than ``LIST_IDENTITY_MAX_DELAY``."""
        (max_ms,) = _SEQ.unpack_from(context)
        if max_ms == 0:
            max_ms = LIST_IDENTITY_DEFAULT_DELAY_MS
        elif max_ms < LIST_IDENTITY_MIN_DELAY_MS:
            max_ms = LIST_IDENTITY_MIN_DELAY_MS
        return self.settings.rng.uniform(0, min(max_ms / 1000.0, LIST_IDENTITY_MAX_DELAY))

    def datagram_from(self, data: bytes, source: tuple[str, int], local: SockAddr,
                      now: float) -> bytes | None:
        """Answer a UDP datagram from ``source`` at ``now``: the reply to send at once, or None. A
        delayed reply is queued in ``delayed`` (or dropped and counted when its source or the target
        has too many pending); the shell sends ``delayed.due(now)`` at ``delayed.next_deadline()``."""
        result = self.datagram(data, local)
        if result is None:
            return None
        reply, delay = result
        if delay <= 0:
            return reply
        if not self.delayed.push(reply, source, now + delay):
            self.stats.replies_dropped += 1
        return None

    def _list_reply(self, command: int, local: SockAddr) -> bytes:
        if command == Command.LIST_IDENTITY:
            return encode_list_identity(self.identity(), local)
        if command == Command.LIST_SERVICES:
            return encode_list_services(self.settings.capabilities)
        return encode_items([])  # ListInterfaces: no items

    # -- timers ---------------------------------------------------------------------------------
    def expire(self, now: float) -> list[ExplicitConnection]:
        return self.table.expire(now)


class EncapsulationConnection:
    """One TCP connection to the target."""

    def __init__(self, target: EncapsulationTarget, peer: str, local: SockAddr, now: float,
                 io_path: tuple[str, int] | None = None) -> None:
        self.target = target
        self.peer = peer
        self.host = origin_host(peer)
        self.local = local
        self.session: int | None = None
        self.closing = False
        #: When the last complete frame came (or the connection opened): the inactivity timeout and
        #: the choice of the idlest connection to close for a new host count from it.
        self.last_activity = now
        #: When the first byte of the frame still incomplete came (None: no frame under way).
        self.frame_started: float | None = None
        self._inbox = bytearray()
        self._outbox: list[bytes] = []
        self._context = RequestContext(target.router, now, peer, self, class1=target.class1)
        if io_path is not None:
            # A Forward_Open over DTLS opens a connection whose data flows in that DTLS session
            # (``IoTarget``); one over TCP or TLS opens plain UDP.
            self._context.extras["io_path"] = io_path
        #: The last common SendRRData that was a read of its own (``_frame``): its bytes, its CIP
        #: request and its sender context, for a client that sends it again (``receive``).
        self._repeat = b""
        self._repeat_request = b""
        self._repeat_context = b""

    @property
    def buffered_bytes(self) -> int:
        """Bytes held of a frame still incomplete (0 between whole frames): never more than a header
        and the frame limit, whatever the peer sends, since a larger announced length closes."""
        return len(self._inbox)

    # -- bytes in, bytes out ------------------------------------------------------------------------
    def receive(self, data: bytes, now: float) -> None:
        if self.closing:
            return
        inbox = self._inbox
        if data == self._repeat and not inbox and self.session is not None:
            # The same frame again, byte for byte and alone (a client polling one attribute): what
            # its header and items were found to say still holds, since the session cannot change
            # while the connection is open, so the frame goes straight to its request.
            self.last_activity = now
            target = self.target
            target.stats.frames += 1
            target.tick(now)
            self._unconnected(self._repeat_request, self.session, self._repeat_context, now)
            return
        if inbox:  # the rest of a frame cut short by the last read comes first
            inbox += data
            data = bytes(inbox)
            inbox.clear()
        # Frames are taken from ``data`` in place; only an incomplete last frame is kept, and it is
        # never longer than the header and the frame limit (a larger announced length closes).
        size = len(data)
        offset = 0
        target = self.target
        limit, stats = target.settings.max_frame_length, target.stats
        while size - offset >= HEADER_SIZE and not self.closing:
            command, length, session, _status, context, options = HEADER.unpack_from(data, offset)
            if length > limit:
                stats.errors += 1
                target.frames_refused_log("%s: frame of %d bytes exceeds the %d-byte limit; closing", self.peer,
                                          length, limit, source=self.host, now=now)
                self._reply(command, session, context, status=EncapsulationStatus.INVALID_LENGTH)
                self.closing = True
                return
            start = offset + HEADER_SIZE
            end = start + length
            if end > size:
                break
            offset = end
            stats.frames += 1
            if options != 0:
                stats.dropped += 1  # the specification says: discard
                continue
            try:
                self._frame(command, session, context, data, start, end, now)
            except EncapsulationError as exc:
                stats.errors += 1
                self._reply(command, session, context, status=exc.status)
            if offset == size:
                self.last_activity = now
                self.frame_started = None
                return  # the common end: the read held whole frames
        if offset:
            self.last_activity = now
        if offset < size and not self.closing:
            inbox += memoryview(data)[offset:]
            if offset or self.frame_started is None:
                self.frame_started = now   # a new frame has begun: its bytes have frame_timeout to come
        elif offset == size:
            self.frame_started = None

    def data_to_send(self) -> bytes:
        outbox = self._outbox
        if len(outbox) == 1:  # the common case: one request read, one reply
            return outbox.pop()
        out = b"".join(outbox)
        outbox.clear()
        return out

    def frame_deadline(self) -> float | None:
        """When the frame under way must be complete (None: none under way)."""
        started = self.frame_started
        return None if started is None else started + self.target.settings.frame_timeout

    def next_deadline(self) -> float | None:
        deadlines = []
        timeout = self.target.settings.inactivity_timeout()
        if timeout:
            deadlines.append(self.last_activity + timeout)
        frame_deadline = self.frame_deadline()
        if frame_deadline is not None:
            deadlines.append(frame_deadline)
        table_deadline = self.target.table.next_deadline(self)
        if table_deadline is not None:
            deadlines.append(table_deadline)
        return min(deadlines, default=None)

    def on_timer(self, now: float) -> None:
        self.target.table.expire(now, self)
        timeout = self.target.settings.inactivity_timeout()
        if self.closing:
            return
        frame_deadline = self.frame_deadline()
        if frame_deadline is not None and now >= frame_deadline:
            self.target.frames_late_log("%s: a frame begun %g s ago is still incomplete (the frame timeout, "
                                        "--frame-timeout); closing", self.peer, now - (self.frame_started or now),
                                        source=self.host, now=now)
            self.closing = True
        elif timeout and now >= self.last_activity + timeout:
            self.target.idle_log("%s: no complete frame for %g s (encapsulation inactivity timeout); closing",
                                 self.peer, timeout, source=self.host, now=now)
            self.closing = True

    def end_session(self) -> None:
        """The target has forgotten this connection's session: its class 3 connections go, and the
        repeated-frame shortcut (``receive``), which assumes the session, is forgotten too."""
        self.session = None
        self._repeat = self._repeat_request = self._repeat_context = b""
        self.target.table.drop_owner(self)

    def connection_lost(self) -> None:
        """The TCP connection is gone: its session and class 3 connections go with it."""
        self.closing = True
        if self.session is not None:
            self.target.sessions.pop(self.session, None)
            log.info("%s: session 0x%08X ended", self.peer, self.session)
            self.session = None
        dropped = self.target.table.drop_owner(self)
        if dropped:
            log.info("%s: %d class 3 connection(s) closed with their TCP connection", self.peer, dropped)

    # -- frames -----------------------------------------------------------------------------------------
    def _reply(self, command: int, session: int, context: bytes, data: bytes = b"", status: int = 0) -> None:
        self._outbox.append(HEADER.pack(command, len(data), session, status, context, 0) + data)

    def _frame(self, command: int, session: int, context: bytes, data: bytes, start: int, end: int,
               now: float) -> None:
        """Serve a frame: its header's fields and its body, ``data[start:end]``, cut out only where
        needed (the common SendRRData reads its items and request straight from ``data``)."""
        if command == _SEND_RR_DATA:
            if session != self.session:  # also when none is registered: no header carries None
                raise EncapsulationError(EncapsulationStatus.INVALID_SESSION)
            target = self.target
            target.tick(now)
            # The common SendRRData (see ``_RR_TWO_ITEMS``) is served without building items; any
            # other shape by ``_send_rr_data``.
            request_at = start + _RR_TWO_ITEMS_SIZE
            if end > request_at:
                interface, _timeout, count, null_type, null_length, data_type, length = _RR_TWO_ITEMS.unpack_from(
                    data, start)
                if (interface == 0 and count == 2 and null_type == _NULL_ADDRESS and null_length == 0
                        and data_type == _UNCONNECTED_DATA and end == request_at + length
                        and data[request_at] not in _MAY_CARRY_SOCKADDR):
                    request = data[request_at:end]
                    if start == HEADER_SIZE and end == len(data) and data.__class__ is bytes:
                        # The read was this frame alone (and bytes, which no caller can change).
                        self._repeat, self._repeat_request, self._repeat_context = data, request, context
                    self._unconnected(request, session, context, now)
                    return
            self._reply(command, session, context, self._send_rr_data(data[start:end], now))
            return
        body = data[start:end]
        if command == Command.SEND_UNIT_DATA:
            self._check_session(session)
            self.target.tick(now)
            reply = self._send_unit_data(body, now)
            if reply is not None:
                self._reply(command, session, context, reply)
        elif command == Command.REGISTER_SESSION:
            self._register_session(session, context, body, now)
        elif command == Command.UNREGISTER_SESSION:
            self._check_session(session)
            self.closing = True  # no reply; the TCP connection closes
        elif command == Command.NOP:
            pass  # no reply by definition
        elif command in UDP_COMMANDS:
            self._reply(command, session, context, self.target._list_reply(command, self.local))
        else:
            raise EncapsulationError(EncapsulationStatus.INVALID_COMMAND, f"command 0x{command:04X}")

    def _unconnected(self, request: bytes, session: int, context: bytes, now: float) -> None:
        """Serve the CIP ``request`` of a common SendRRData; the reply goes out in the same two items."""
        request_context = self._context
        request_context.now = now
        request_context.connected = False
        reply = self.target.requests.entry.handle(request, request_context)  # the router, or the seam's chain
        if reply[2] == _TOO_MUCH_DATA:
            self._too_much_data(request, now)
        self._outbox.append(_RR_REPLY_FRAME.pack(
            _SEND_RR_DATA, _RR_TWO_ITEMS_SIZE + len(reply), session, 0, context, 0, 0, 0, 2,
            _NULL_ADDRESS, 0, _UNCONNECTED_DATA, len(reply)) + reply)

    def _too_much_data(self, request: bytes, now: float) -> None:
        """A request answered 0x15: the log says what it carried beyond what its service takes, and the
        likely cause (a route path appended by the client), so that a client author sees more than
        "Too much data"."""
        self.target.too_much_data_log("%s: %s", self.peer, too_much_data_hint(request), source=self.host, now=now)

    def _check_session(self, session: int) -> None:
        if self.session is None or session != self.session:
            raise EncapsulationError(EncapsulationStatus.INVALID_SESSION)

    def _register_session(self, session: int, context: bytes, body: bytes, now: float) -> None:
        if len(body) != REGISTER_SESSION_DATA.size:
            raise EncapsulationError(EncapsulationStatus.INVALID_LENGTH)
        version, options = REGISTER_SESSION_DATA.unpack(body)
        if self.session is not None:
            raise EncapsulationError(EncapsulationStatus.INVALID_COMMAND, "second RegisterSession")
        if version != PROTOCOL_VERSION or options != 0:
            self._reply(Command.REGISTER_SESSION, 0, context, REGISTER_SESSION_DATA.pack(PROTOCOL_VERSION, 0),
                        status=EncapsulationStatus.UNSUPPORTED_PROTOCOL)
            return
        settings = self.target.settings
        if len(self.target.sessions) >= settings.max_sessions:
            limit = settings.max_sessions
            self.target.sessions_refused_log(
                "%s: RegisterSession refused (0x0002): all %d sessions in use (the session limit, --max-sessions)",
                self.peer, limit, source=self.host, now=now)
            raise EncapsulationError(EncapsulationStatus.INSUFFICIENT_MEMORY, f"all {limit} sessions in use")
        held = sum(1 for owner in self.target.sessions.values() if owner.host == self.host)
        if held >= settings.sessions_per_host:
            self.target.sessions_per_host_refused_log(
                "%s: RegisterSession refused (0x0002): %s holds %d sessions (the per-host limit, "
                "--max-sessions-per-host)", self.peer, self.host, held, source=self.host, now=now)
            raise EncapsulationError(EncapsulationStatus.INSUFFICIENT_MEMORY,
                                     f"{self.host} holds {held} sessions (the per-host limit)")
        self.session = self.target._new_session(self)
        log.info("%s: session 0x%08X registered", self.peer, self.session)
        self._reply(Command.REGISTER_SESSION, self.session, context, body)

    def _send_rr_data(self, body: bytes, now: float) -> bytes:
        if len(body) < RR_PREFIX.size:
            raise EncapsulationError(EncapsulationStatus.INVALID_LENGTH)
        interface, _timeout = RR_PREFIX.unpack_from(body)
        items = decode_items(body, RR_PREFIX.size)
        if (interface != 0 or len(items) < 2 or items[0].type != ItemType.NULL_ADDRESS or items[0].data
                or items[1].type != ItemType.UNCONNECTED_DATA or not items[1].data):
            raise EncapsulationError(EncapsulationStatus.INCORRECT_DATA,
                                     "SendRRData needs Null Address + Unconnected Data")
        context = self._context
        context.now = now
        context.connected = False
        if len(items) == 2 and items[1].data[0] not in _MAY_CARRY_SOCKADDR:
            reply = self.target.requests.entry.handle(items[1].data, context)
            if is_too_much_data(reply):
                self._too_much_data(items[1].data, now)
            return RR_PREFIX.pack(0, 0) + encode_items((Item(ItemType.NULL_ADDRESS), Item(ItemType.UNCONNECTED_DATA,
                                                                                          reply)))
        # A Forward_Open may carry Sockaddr Info items (where the originator wants T->O data), and
        # its reply may carry one (the multicast group of T->O data).
        sockaddrs: dict[int, SockAddr] = {}
        for item in items[2:]:
            if item.type not in (ItemType.SOCKADDR_O_T, ItemType.SOCKADDR_T_O) or len(item.data) != 16:
                raise EncapsulationError(EncapsulationStatus.INCORRECT_DATA, f"unexpected CPF item 0x{item.type:04X}")
            sockaddrs[item.type] = SockAddr.decode(item.data)
        context.extras["sockaddr"] = sockaddrs
        reply_items: list[Item] = []
        context.extras["reply_items"] = reply_items
        try:
            reply = self.target.requests.entry.handle(items[1].data, context)
        finally:
            del context.extras["sockaddr"], context.extras["reply_items"]
        if is_too_much_data(reply):
            self._too_much_data(items[1].data, now)
        return RR_PREFIX.pack(0, 0) + encode_items((Item(ItemType.NULL_ADDRESS), Item(ItemType.UNCONNECTED_DATA, reply),
                                                    *reply_items))

    def _send_unit_data(self, body: bytes, now: float) -> bytes | None:
        if len(body) < RR_PREFIX.size:
            raise EncapsulationError(EncapsulationStatus.INVALID_LENGTH)
        interface, _timeout = RR_PREFIX.unpack_from(body)
        items = decode_items(body, RR_PREFIX.size)
        if (interface != 0 or len(items) != 2 or items[0].type != ItemType.CONNECTED_ADDRESS or len(items[0].data) != 4
                or items[1].type != ItemType.CONNECTED_DATA or len(items[1].data) < 2):
            raise EncapsulationError(EncapsulationStatus.INCORRECT_DATA,
                                     "SendUnitData needs Connected Address + Connected Data")
        (connection_id,) = _CONN_ID.unpack(items[0].data)
        connection = self.target.table.connections.get(connection_id)
        if connection is None or connection.owner is not self:
            # No CIP-level way to answer a packet for an unknown connection: drop and count.
            self.target.stats.dropped += 1
            log.debug("%s: SendUnitData for unknown connection 0x%08X dropped", self.peer, connection_id)
            return None
        connection.deadline = now + connection.timeout_s
        (sequence,) = _SEQ.unpack_from(items[1].data)
        if sequence == connection.last_sequence:
            reply = connection.last_reply  # a retransmission: answer again, do not execute twice
        else:
            context = self._context
            context.now = now
            context.connected = True
            reply = self.target.requests.entry.handle(items[1].data[2:], context)
            context.connected = False
            if is_too_much_data(reply):
                self._too_much_data(items[1].data[2:], now)
            connection.last_sequence = sequence
            connection.last_reply = reply
            connection.requests += 1
        return RR_PREFIX.pack(0, 0) + encode_items((
            Item(ItemType.CONNECTED_ADDRESS, _CONN_ID.pack(connection.to_connection_id)),
            Item(ItemType.CONNECTED_DATA, _SEQ.pack(sequence) + reply),
        ))
