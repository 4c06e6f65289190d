"""Class 1 connections, originator side, without I/O: datagrams and time in, datagrams, events and
the next deadline out.

``IoOriginator`` holds every class 1 connection of one originator endpoint: ``poll(now)`` gives the
O->T datagrams due (with the run/idle header of the connection's format and its sequence counts),
``receive(raw, source, now)`` consumes a T->O datagram (sequence filtering, the watchdog, arrival
figures), ``expire(now)`` the connections whose watchdog ran out, ``next_deadline()`` when to look
again. What a connection reports (new input data, its timeout) goes to the ``Class1Listener`` it was
made with. It never reads a clock, touches a socket or imports asyncio: the asyncio shell
(``io_context``, ``io_originator``) and the blocking one (``blocking_io``) move its bytes.

The Forward_Open of a class 1 connection is written here once too, as plans over the explicit core
(``OriginatorCore``): ``open_plan`` (with the one retry at the size a target asks for) and
``close_plan``; ``reply_addresses`` reads the Sockaddr Info items of the reply.

RPIs are microseconds (``rpi_us``, ``api_us``) from the request to the connection; the clock the
shells give (``now``) is in seconds, and a connection's schedule and watchdog are kept in it.
"""

from __future__ import annotations

import heapq
import ipaddress
import itertools
import logging
import random
from collections import deque
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import TYPE_CHECKING, NamedTuple, Protocol

from ...cip.epath import LogicalSegment, LogicalType, encode_path
from ...cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from ...cip.status import CipError, GeneralStatus
from ...errors import BadRequest, PeerUnreachable
from ..io_core import (
    EARLY_SHARE,
    RECEIVED_NEW,
    RECEIVED_STALE,
    RUN_IDLE_HEADER_SIZE,
    SEQUENCE_COUNT_SIZE,
    TO_OVERHEAD,
    ConsumerState,
    IoDatagram,
    IoDatagramError,
    IoStatistics,
    ProductionGrid,
    ProductionSchedule,
    connection_timeout,
    decode_io_datagram,
    encode_io_datagram,
)
from ..wire.cm_messages import (
    CONNECTION_MANAGER_PATH,
    ConnectionTriad,
    ConnectionType,
    ForwardCloseRequest,
    ForwardOpenReply,
    ForwardOpenRequest,
    NetworkParameters,
    TransportTrigger,
    TriggerType,
)
from ..wire.cpf import Item, ItemType, SockAddr
from ..wire.encapsulation import EncapsulationError
from .replies import decode_reply

if TYPE_CHECKING:
    from .core import OriginatorCore, Plan

log = logging.getLogger(__name__)


class IoTimeoutError(PeerUnreachable):
    """The target's T->O data stopped for longer than the connection timeout."""


class OtFormat(Enum):
    """The O->T real-time format (EDS ``ConnectionN`` field 2, bits 8-10: 0, 3 or 4; eds.md)."""

    #: Sequence count and data, no header (EDS 0).
    MODELESS = "modeless"
    #: Sequence count alone (EDS 3): input-only and listen-only connections of many stacks.
    HEARTBEAT = "heartbeat"
    #: Sequence count, 32-bit run/idle header, data (EDS 4); what an exclusive owner sends.
    RUN_IDLE = "run-idle"

    @classmethod
    def from_eds(cls, code: int) -> OtFormat | None:
        return {0: cls.MODELESS, 3: cls.HEARTBEAT, 4: cls.RUN_IDLE}.get(code)

    @property
    def header_size(self) -> int:
        return RUN_IDLE_HEADER_SIZE if self is OtFormat.RUN_IDLE else 0


@dataclass
class ArrivalStatistics:
    """How the target really produces: T->O inter-arrival times against the granted T->O API.

    ``lost`` (gaps in the sequence numbers) cannot see a target that numbers every packet
    but sends fewer than it was granted; the share of missed production slots does. The last
    ``window`` intervals are kept for the percentiles, so memory stays bounded. ``api`` is in
    seconds, the unit of the arrival times it is compared with."""

    api: float
    window: int = 4096
    count: int = 0
    first: float | None = None
    last: float | None = None
    max_interval: float = 0.0
    #: Input data changes (new data that differs from the previous input).
    changes: int = 0
    #: T->O packets dropped because their data size is not the connection's.
    wrong_size: int = 0
    #: Intervals within half an API of the API (the share of on-time arrivals).
    on_time: int = 0
    slow_warned: bool = False
    intervals: deque[float] = field(init=False)

    def __post_init__(self) -> None:
        self.intervals = deque(maxlen=self.window)

    @classmethod
    def of_api(cls, api_us: int) -> ArrivalStatistics:
        """The figures of a connection whose T->O API is ``api_us`` microseconds."""
        return cls(api_us / 1e6)

    def arrived(self, now: float) -> float | None:
        """Record a packet; returns the mean interval when the producer has proven slower than its API
        (once per connection), else None."""
        last = self.last
        self.count += 1
        self.last = now
        if last is None:
            self.first = now
            return None
        interval = now - last
        self.intervals.append(interval)  # a deque with maxlen ``window``: the oldest falls out
        if abs(interval - self.api) <= self.api / 2:
            self.on_time += 1
        if interval > self.max_interval:
            self.max_interval = interval
        # Judged every 16 packets from the 17th interval on, on the mean (cheap); 1.5 x the API
        # leaves room for jitter.
        if not self.count & 15 and not self.slow_warned and self.first is not None:
            mean = (now - self.first) / (self.count - 1)
            if mean > 1.5 * self.api:
                self.slow_warned = True
                return mean
        return None

    def percentile(self, share: float) -> float | None:
        if not self.intervals:
            return None
        ordered = sorted(self.intervals)
        return ordered[min(len(ordered) - 1, int(share * len(ordered)))]

    @property
    def missed_slot_share(self) -> float | None:
        """Share of the T->O production slots (one per API since the first packet) with no packet."""
        if self.first is None or self.last is None or self.api <= 0:
            return None
        slots = round((self.last - self.first) / self.api) + 1
        return max(0, slots - self.count) / slots

    def as_dict(self) -> dict[str, float | int | None]:
        span = (self.last - self.first) if self.first is not None and self.last is not None else 0.0
        p50, p99, share = self.percentile(0.50), self.percentile(0.99), self.missed_slot_share
        return {
            "api_ms": round(self.api * 1e3, 3),
            "api_rate_hz": round(1 / self.api, 3) if self.api > 0 else None,
            "received_rate_hz": round((self.count - 1) / span, 3) if span > 0 else None,
            "interval_p50_ms": None if p50 is None else round(p50 * 1e3, 3),
            "interval_p99_ms": None if p99 is None else round(p99 * 1e3, 3),
            "interval_max_ms": round(self.max_interval * 1e3, 3) if self.intervals else None,
            "missed_slots": None if share is None else round(share, 4),
            "within_half_api_pct": round(100.0 * self.on_time / (self.count - 1), 2) if self.count > 1 else None,
            "input_changes": self.changes,
            "wrong_size": self.wrong_size,
        }


class Class1Listener(Protocol):
    """What a connection reports, given when it is made (``new_connection``): a shell wakes its
    readers with it. Called from the core's ``receive`` and ``expire``: keep it short."""

    def input_changed(self, data: bytes) -> None:
        """New T->O data that differs from the previous input."""

    def timed_out(self) -> None:
        """The watchdog ran out: no T->O data for the connection timeout."""


@dataclass
class OriginatorConnection:
    """One class 1 connection as the originator sees it. RPIs in microseconds (the granted APIs)."""

    target_host: str
    target_io_port: int
    ot_connection_id: int
    to_connection_id: int
    ot_rpi_us: int
    to_rpi_us: int
    output: bytearray
    input_size: int
    consumer: ConsumerState
    producer: ProductionSchedule
    stats: IoStatistics
    arrivals: ArrivalStatistics
    heartbeat: bool = False
    #: O->T packets carry the 32-bit run/idle header (real-time format RUN_IDLE).
    ot_header: bool = True
    run: bool = True
    input: bytes = b""
    encap_sequence: int = 0
    cip_sequence: int = 0
    timed_out: bool = False
    closed: bool = False
    #: Who hears of new input and of the timeout (None: nobody; the shell reads ``input`` itself).
    listener: Class1Listener | None = None
    interval_samples: list[float] = field(default_factory=list)
    #: Times O->T packets went out (with ``keep_intervals``).
    send_times: list[float] = field(default_factory=list)
    last_arrival: float | None = None
    keep_intervals: bool = False
    #: When the originator's watchdog heap looks at this connection next (its live entry there).
    watch_at: float = 0.0


class IoOriginator:
    """All class 1 connections of one originator endpoint (an ``IoCore`` for ``IoEndpoint``)."""

    def __init__(self) -> None:
        #: By O->T connection id, which the target makes unique.
        self.connections: dict[int, OriginatorConnection] = {}
        #: By T->O connection id: several connections share one when they listen to the same multicast data.
        self.by_to_id: dict[int, list[OriginatorConnection]] = {}
        self.dropped = 0
        # Deadlines in heaps, as the target keeps them (``IoTarget``): a timer firing touches what is
        # due, not every connection. Entries (time, order, connection); those of closed connections
        # are dropped when they come up, a watchdog entry whose deadline has moved on (packets
        # arrived) is pushed again at the new one.
        self._productions: list[tuple[float, int, OriginatorConnection]] = []
        self._watchdogs: list[tuple[float, int, OriginatorConnection]] = []
        self._order = itertools.count()
        self._grid = ProductionGrid()

    def add(self, connection: OriginatorConnection) -> None:
        """Take ``connection`` on; its O->T production starts on this originator's slots (``ProductionGrid``)."""
        producer = connection.producer
        producer.next_due = self._grid.first_due(producer.period, producer.next_due)
        self.connections[connection.ot_connection_id] = connection
        self.by_to_id.setdefault(connection.to_connection_id, []).append(connection)
        heapq.heappush(self._productions, (connection.producer.next_due, next(self._order), connection))
        self._watch(connection)

    def _watch(self, connection: OriginatorConnection) -> None:
        connection.watch_at = connection.consumer.deadline
        heapq.heappush(self._watchdogs, (connection.watch_at, next(self._order), connection))

    def _live(self, connection: OriginatorConnection) -> bool:
        return not connection.closed and self.connections.get(connection.ot_connection_id) is connection

    def remove(self, connection: OriginatorConnection) -> None:
        """Forget ``connection`` (it is closed: nothing is produced or consumed for it any more)."""
        connection.closed = True
        self.connections.pop(connection.ot_connection_id, None)
        sharing = self.by_to_id.get(connection.to_connection_id, [])
        if connection in sharing:
            sharing.remove(connection)
        if not sharing:
            self.by_to_id.pop(connection.to_connection_id, None)

    def receive(self, raw: bytes, source: tuple[str, int], now: float) -> None:
        try:
            datagram = decode_io_datagram(raw)
        except IoDatagramError:
            self.dropped += 1
            return
        sharing = self.by_to_id.get(datagram.connection_id)
        if not sharing:
            self.dropped += 1
            return
        for connection in sharing:
            self._consume(connection, datagram, now)

    def _consume(self, connection: OriginatorConnection, datagram: IoDatagram, now: float) -> None:
        if connection.closed:
            self.dropped += 1
            return
        if len(datagram.payload) != connection.input_size:
            self.dropped += 1
            arrivals = connection.arrivals
            arrivals.wrong_size += 1
            if arrivals.wrong_size == 1:  # once: a target producing another size does so every RPI
                log.warning("class 1 connection 0x%08X: %s sends %d data bytes, the connection carries %d: dropped",
                            connection.to_connection_id, connection.target_host, len(datagram.payload),
                            connection.input_size)
            return
        reception = connection.consumer.accept(datagram.encap_sequence, datagram.cip_sequence, now)
        if reception is RECEIVED_STALE:
            return
        if connection.consumer.deadline < connection.watch_at:
            self._watch(connection)  # the first packet ends the 10 s first-packet allowance
        slow = connection.arrivals.arrived(now)
        if slow is not None:
            log.warning("class 1 connection 0x%08X: %s produces every %.3f ms on average, slower than its API of "
                        "%.3f ms (%.0f%% of the production slots missed)", connection.to_connection_id,
                        connection.target_host, slow * 1e3, connection.to_rpi_us / 1e3,
                        100 * (connection.arrivals.missed_slot_share or 0))
        if connection.keep_intervals:
            if connection.last_arrival is not None:
                connection.interval_samples.append(now - connection.last_arrival)
            connection.last_arrival = now
        if reception is RECEIVED_NEW:
            changed = datagram.payload != connection.input
            if changed and connection.input:
                connection.arrivals.changes += 1
            connection.input = datagram.payload
            listener = connection.listener
            if changed and listener is not None:
                listener.input_changed(datagram.payload)

    def poll(self, now: float, horizon: float = 0.0) -> list[tuple[bytes, tuple[str, int]]]:
        """The O->T datagrams due at ``now`` (and within ``horizon`` after it, as ``IoTarget.poll``)."""
        heap = self._productions
        out: list[tuple[bytes, tuple[str, int]]] = []
        while heap and heap[0][0] <= now + horizon:
            due_at, _order, connection = heap[0]
            producer = connection.producer
            if due_at > now and due_at - now > producer.period * EARLY_SHARE:
                break  # not due, and too far off to send early
            heapq.heappop(heap)
            if not self._live(connection):
                continue  # closed since
            due, _ = producer.due(max(now, due_at))
            heapq.heappush(heap, (producer.next_due, next(self._order), connection))
            if not due:
                continue
            connection.encap_sequence = (connection.encap_sequence + 1) & 0xFFFFFFFF
            connection.cip_sequence = (connection.cip_sequence + 1) & 0xFFFF
            data = b"" if connection.heartbeat else bytes(connection.output)
            run_idle = (1 if connection.run else 0) if connection.ot_header else None
            out.append((encode_io_datagram(connection.ot_connection_id, connection.encap_sequence,
                                           connection.cip_sequence, data, run_idle),
                        (connection.target_host, connection.target_io_port)))
            connection.stats.sent += 1
            if connection.keep_intervals:
                connection.send_times.append(now)
        return out

    def next_deadline(self) -> float | None:
        """The earliest production slot or watchdog deadline (a watchdog may have moved on since:
        firing early costs one look, see ``expire``)."""
        productions, watchdogs = self._productions, self._watchdogs
        while productions and not self._live(productions[0][2]):
            heapq.heappop(productions)
        while watchdogs and not (self._live(watchdogs[0][2]) and not watchdogs[0][2].timed_out
                                 and watchdogs[0][0] == watchdogs[0][2].watch_at):
            heapq.heappop(watchdogs)
        candidates = [heap[0][0] for heap in (productions, watchdogs) if heap]
        return min(candidates, default=None)

    def expire(self, now: float) -> list[OriginatorConnection]:
        """The connections whose watchdog ran out at ``now`` (each once; its listener hears it)."""
        expired = []
        heap = self._watchdogs
        while heap and heap[0][0] <= now:
            at, _order, connection = heapq.heappop(heap)
            if not self._live(connection) or connection.timed_out or at != connection.watch_at:
                continue  # closed or timed out since, or superseded by another entry
            if connection.consumer.expired(now):
                expired.append(connection)
            else:  # packets arrived: watch again at the deadline they set
                self._watch(connection)
        for connection in expired:
            connection.timed_out = True
            log.warning("class 1 connection 0x%08X: no data from %s for %.3f s: timed out",
                        connection.to_connection_id, connection.target_host, connection.consumer.timeout)
            if connection.listener is not None:
                connection.listener.timed_out()
        return expired


_serials = itertools.count(random.randrange(0, 0xFFFF))


#: A simple data segment carries at most 255 words.
MAX_CONFIG_DATA = 510


def class1_path(output: int | None, input: int, config: int, heartbeat: int | None = None,
                config_data: bytes = b"") -> bytes:
    """``20 04 24 <config> 2C <O->T> 2C <T->O>`` (the O->T point is the heartbeat point when given),
    then ``80 <words> <config data>`` when configuration data is given (padded to whole words)."""
    consumed = heartbeat if heartbeat is not None else output
    assert consumed is not None
    path = encode_path([
        LogicalSegment(LogicalType.CLASS_ID, 0x04), LogicalSegment(LogicalType.INSTANCE_ID, config),
        LogicalSegment(LogicalType.CONNECTION_POINT, consumed), LogicalSegment(LogicalType.CONNECTION_POINT, input),
    ])
    if config_data:
        if len(config_data) > MAX_CONFIG_DATA:
            raise BadRequest(f"configuration data is {len(config_data)} bytes, at most {MAX_CONFIG_DATA}")
        padded = config_data + b"\x00" * (len(config_data) & 1)
        path += bytes((0x80, len(padded) // 2)) + padded
    return path


#: The largest connection size a (small) Forward_Open carries: 9 bits of its network parameters.
MAX_FORWARD_OPEN_SIZE = 0x1FF


@dataclass(frozen=True)
class Class1Request:
    """What the originator asks for, before it becomes a Forward_Open (RPIs in microseconds)."""

    output_size: int | None
    input_size: int
    ot_rpi_us: int
    to_rpi_us: int
    path: bytes
    multicast: bool = False
    timeout_multiplier: int = 2
    large: bool = False
    ot_format: OtFormat = OtFormat.RUN_IDLE

    @classmethod
    def asked(cls, output: int | None, input: int, rpi_us: int, *, output_size: int, input_size: int,
              config: int = 1, heartbeat: int | None = None, multicast: bool = False, timeout_multiplier: int = 2,
              config_data: bytes = b"", ot_format: OtFormat | str | None = None) -> Class1Request:
        """The request of an ``io_connection`` call, both shells' (their arguments, the RPI in microseconds):
        ``heartbeat`` replaces the output point for input-only and listen-only connections."""
        fmt = OtFormat(ot_format) if ot_format is not None else OtFormat.RUN_IDLE
        if fmt is OtFormat.HEARTBEAT and heartbeat is None:
            raise BadRequest("the heartbeat format carries no data: give a heartbeat point, not an output")
        return cls(None if heartbeat is not None else output_size, input_size, rpi_us, rpi_us,
                   class1_path(output, input, config, heartbeat, config_data), multicast, timeout_multiplier,
                   ot_format=fmt)

    @property
    def ot_size(self) -> int:
        """O->T connection size: sequence count, header of the format, data."""
        return SEQUENCE_COUNT_SIZE + self.ot_format.header_size + (self.output_size or 0)

    @property
    def to_size(self) -> int:
        return self.input_size + TO_OVERHEAD

    @property
    def large_forward_open(self) -> bool:
        """Whether the connection needs a Large_Forward_Open: asked for, or a connection size past
        the 9 bits (511 bytes) a Forward_Open's network connection parameters hold."""
        return self.large or max(self.ot_size, self.to_size) > MAX_FORWARD_OPEN_SIZE

    def corrected(self, extended: tuple[int, ...]) -> tuple[Class1Request, str] | None:
        """The request a target's 0x0127 (O->T) / 0x0128 (T->O) refusal asks for, when it names the
        size it wants, and a line saying what changed; None when there is nothing to retry with."""
        if len(extended) < 2:
            return None
        status, wanted = extended[0], extended[1]
        if status == 0x0128 and wanted >= TO_OVERHEAD and wanted != self.to_size:
            return (replace(self, input_size=wanted - TO_OVERHEAD),
                    f"T->O size {self.to_size} refused (0x0128), the target wants {wanted}: retrying with {wanted}")
        if status != 0x0127 or wanted == self.ot_size or wanted < SEQUENCE_COUNT_SIZE:
            return None
        data = self.output_size or 0
        if self.output_size is None:  # heartbeat: the format is all that can differ
            fmt = {2: OtFormat.HEARTBEAT, 6: OtFormat.RUN_IDLE}.get(wanted)
            if fmt is None:
                return None
            changed = replace(self, ot_format=fmt)
        elif wanted == SEQUENCE_COUNT_SIZE + data:
            changed = replace(self, ot_format=OtFormat.MODELESS)
        elif wanted == SEQUENCE_COUNT_SIZE + RUN_IDLE_HEADER_SIZE + data:
            changed = replace(self, ot_format=OtFormat.RUN_IDLE)
        else:
            changed = replace(self, output_size=max(0, wanted - SEQUENCE_COUNT_SIZE - self.ot_format.header_size))
        return (changed, f"O->T size {self.ot_size} refused (0x0127), the target wants {wanted}: retrying with "
                         f"{wanted} ({changed.ot_format.value}, {changed.output_size or 0} data bytes)")

    def parameters(self) -> tuple[NetworkParameters, NetworkParameters, TransportTrigger, ConnectionTriad, int]:
        ot = NetworkParameters(self.ot_size, ConnectionType.POINT_TO_POINT)
        to = NetworkParameters(self.to_size,
                               ConnectionType.MULTICAST if self.multicast else ConnectionType.POINT_TO_POINT)
        triad = ConnectionTriad(next(_serials) & 0xFFFF, 0xFFFE, random.randrange(1, 0xFFFFFFFF))
        return ot, to, TransportTrigger(1, TriggerType.CYCLIC), triad, random.randrange(1, 0xFFFFFFFF)

    def forward_open(self, local_io_port: int) -> tuple[bytes, list[Item], ConnectionTriad]:
        """The Forward_Open (or Large_Forward_Open) request to the Connection Manager, the CPF items that
        go with it (a point-to-point T->O asks for data at ``local_io_port``: Sockaddr Info 0.0.0.0), and
        the connection's triad (what its Forward_Close names)."""
        ot, to, transport, triad, to_id = self.parameters()
        large = self.large_forward_open
        fo = ForwardOpenRequest(0x0A, 0x0E, 0, to_id, triad, self.timeout_multiplier, self.ot_rpi_us,
                                ot, self.to_rpi_us, to, transport, self.path, large)
        service = Service.LARGE_FORWARD_OPEN if large else Service.FORWARD_OPEN
        raw = MessageRouterRequest(service, CONNECTION_MANAGER_PATH, fo.encode()).encode()
        sockaddr = Item(ItemType.SOCKADDR_T_O, SockAddr("0.0.0.0", local_io_port).encode())
        return raw, [] if self.multicast else [sockaddr], triad


class Class1Opened(NamedTuple):
    """A Forward_Open the target accepted: the request as finally asked (after a retry at the size
    the target named), its reply and Sockaddr Info items, the triad, and what opening adapted to."""

    request: Class1Request
    reply: ForwardOpenReply
    items: list[Item]
    triad: ConnectionTriad
    notes: list[str]


def _forward_open(core: OriginatorCore, request: Class1Request, local_io_port: int
                  ) -> Plan[tuple[ForwardOpenReply, list[Item], ConnectionTriad]]:
    raw, items, triad = request.forward_open(local_io_port)
    reply_raw, extra = yield core.send_rr_data_items(raw, items)
    response = decode_reply("Forward_Open reply", lambda: MessageRouterResponse.decode(reply_raw))
    response.raise_for_status()
    return decode_reply("Forward_Open reply", lambda: ForwardOpenReply.decode(response.data)), extra, triad


def open_plan(core: OriginatorCore, request: Class1Request, local_io_port: int) -> Plan[Class1Opened]:
    """Forward_Open ``request``; a refusal with 0x0127/0x0128 that names the size the target wants gets
    one retry with it (``Class1Request.corrected``), any other refusal raises its ``CipError``."""
    notes: list[str] = []
    try:
        reply, extra, triad = yield from _forward_open(core, request, local_io_port)
    except CipError as refused:
        corrected = request.corrected(refused.extended) if refused.general == GeneralStatus.CONNECTION_FAILURE \
            else None
        if corrected is None:
            raise
        request, note = corrected
        log.debug("Forward_Open: %s", note)
        notes.append(note)
        reply, extra, triad = yield from _forward_open(core, request, local_io_port)
    return Class1Opened(request, reply, extra, triad, notes)


def close_plan(core: OriginatorCore, triad: ConnectionTriad, path: bytes) -> Plan[None]:
    """Forward_Close of the connection ``triad`` names (unconnected; its error status raises)."""
    fc = ForwardCloseRequest(0x0A, 0x0E, triad, path)
    reply: MessageRouterResponse = yield core.request(Service.FORWARD_CLOSE, CONNECTION_MANAGER_PATH, fc.encode(),
                                                      connected=False)
    reply.raise_for_status()


class ReplyAddresses(NamedTuple):
    """What a Forward_Open reply's Sockaddr Info items say: the UDP port the target consumes O->T data
    on (None: not said), the multicast group T->O data comes from (None: point-to-point) and its port."""

    ot_port: int | None
    group: str | None
    group_port: int


def reply_addresses(items: list[Item]) -> ReplyAddresses:
    """Read a Forward_Open reply's extra items, tolerantly: an item that does not decode, or one of
    another type, is logged at DEBUG and ignored."""
    announced: int | None = None
    group: str | None = None
    group_port = 0
    for item in items:
        if item.type not in (ItemType.SOCKADDR_T_O, ItemType.SOCKADDR_O_T):
            log.debug("Forward_Open reply: item 0x%04X ignored", item.type)
            continue
        try:
            address = SockAddr.decode(item.data)
        except EncapsulationError as exc:
            log.debug("Forward_Open reply: Sockaddr Info 0x%04X ignored: %s", item.type, exc)
            continue
        if item.type == ItemType.SOCKADDR_T_O and ipaddress.IPv4Address(address.host).is_multicast:
            group, group_port = address.host, address.port
        elif item.type == ItemType.SOCKADDR_O_T and address.port:
            # The target consumes O->T data on this port, not 2222 (CIP Vol. 2, 2-6.3.3).
            announced = address.port
            log.debug("Forward_Open reply: the target consumes O->T data on UDP port %d", address.port)
        else:
            # 0.0.0.0:<our port> echoed back on a point-to-point connection, or the target's
            # O->T address: informational; only a 224.0.0.0/4 group is something to join.
            log.debug("Forward_Open reply: Sockaddr Info 0x%04X %s:%d (informational)", item.type,
                      address.host, address.port)
    return ReplyAddresses(announced, group, group_port)


def new_connection(request: Class1Request, target_host: str, target_io_port: int, ot_id: int, to_id: int,
                   ot_api_us: int, to_api_us: int, now: float, keep_intervals: bool = False,
                   listener: Class1Listener | None = None) -> OriginatorConnection:
    """The connection a Forward_Open reply granted (its APIs in microseconds), opened at ``now``: the
    watchdog runs RPI x 4 x 2^multiplier of the T->O API (``connection_timeout``) after each packet,
    at least 10 s before the first."""
    stats = IoStatistics()
    return OriginatorConnection(
        target_host=target_host, target_io_port=target_io_port, ot_connection_id=ot_id, to_connection_id=to_id,
        ot_rpi_us=ot_api_us, to_rpi_us=to_api_us,
        output=bytearray(request.output_size or 0), input_size=request.input_size,
        consumer=ConsumerState.opened(connection_timeout(to_api_us, request.timeout_multiplier), now, stats=stats),
        producer=ProductionSchedule(ot_api_us / 1e6, now, stats=stats), stats=stats,
        arrivals=ArrivalStatistics.of_api(to_api_us),
        heartbeat=request.output_size is None, ot_header=request.ot_format is OtFormat.RUN_IDLE,
        listener=listener, keep_intervals=keep_intervals)


__all__ = ["MAX_CONFIG_DATA", "MAX_FORWARD_OPEN_SIZE", "RUN_IDLE_HEADER_SIZE", "SEQUENCE_COUNT_SIZE",
           "ArrivalStatistics", "Class1Listener", "Class1Opened", "Class1Request", "IoOriginator", "IoTimeoutError",
           "OriginatorConnection", "OtFormat", "ReplyAddresses", "class1_path", "close_plan", "new_connection",
           "open_plan", "reply_addresses"]
