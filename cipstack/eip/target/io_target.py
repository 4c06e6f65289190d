"""Class 1 connections, target side, sans-I/O.

``IoTarget`` validates class 1 Forward_Opens against what the device offers (``IoProfile``),
keeps the open connections, consumes O->T datagrams (sequence filtering, run/idle, watchdog)
and says which T->O datagrams are due when. The asyncio shell (``io_server``) moves its
datagrams; the Connection Manager hands it Forward_Open and Forward_Close.

Connection kinds: exclusive owner (an output assembly and an input assembly), input only
(the O->T "heartbeat" point, no output data) and listen only (heartbeat; needs a live
connection that produces the same input assembly by multicast, and closes with it).
"""

from __future__ import annotations

import heapq
import itertools
import logging
import random
import socket
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

from ...cip.epath import DataSegment, ElectronicKey, LogicalSegment, LogicalType, decode_path
from ...cip.router import RequestContext
from ...cip.status import CipError, ExtendedStatus
from ..io_core import (
    DEFAULT_IO_PORT,
    EARLY_SHARE,
    OT_OVERHEAD,
    RECEIVED_NEW,
    RECEIVED_STALE,
    TO_OVERHEAD,
    ConsumerState,
    IoDatagramError,
    IoStatistics,
    ProductionGrid,
    ProductionSchedule,
    connection_timeout,
    decode_io_datagram,
    encode_io_datagram,
    split_run_idle,
)
from ..wire.cm_messages import (
    ConnectionTriad,
    ConnectionType,
    ForwardCloseRequest,
    ForwardOpenReply,
    ForwardOpenRequest,
    TriggerType,
)
from ..wire.cpf import Item, ItemType, SockAddr
from .connection_manager import connection_failure, origin_host
from .limits import RateLimitedLog

log = logging.getLogger(__name__)

#: CIP default multicast allocation (CIP Vol. 2, TCP/IP object attribute 9): 239.192.1.0 + 32 x host id.
CIP_MULTICAST_BASE = 0xEFC00100


class AssemblyPoint(Protocol):
    """A connection point as class 1 sees it (``objects.assembly.AssemblyPoint`` is one): the
    transport knows no device and no object, only sizes and where data comes from and goes."""

    @property
    def instance_id(self) -> int: ...

    @property
    def size(self) -> int: ...

    @property
    def produce(self) -> Callable[[], bytes] | None: ...

    @property
    def consume(self) -> Callable[[bytes, float], None] | None: ...


class ConnectionKind(Enum):
    EXCLUSIVE_OWNER = "exclusive owner"
    INPUT_ONLY = "input only"
    LISTEN_ONLY = "listen only"


class RpiType:
    """Types of the acceptable RPI values carried with extended status 0x0112."""

    ACCEPTABLE = 0
    UNSPECIFIED = 1
    MINIMUM = 2
    MAXIMUM = 3
    REQUIRED = 4


@dataclass
class IoProfile:
    """What a device offers for class 1, read at each Forward_Open (the offer may change)."""

    consumed: Callable[[], Mapping[int, AssemblyPoint]]
    produced: Callable[[], Mapping[int, AssemblyPoint]]
    config_instances: frozenset[int] = frozenset({1})
    input_only_point: int = 198
    listen_only_point: int = 199
    #: Further heartbeat points (an EDS may declare several of each kind), beyond the two above.
    more_input_only_points: frozenset[int] = frozenset()
    more_listen_only_points: frozenset[int] = frozenset()
    rpi_min_us: int = 1_000
    rpi_max_us: int = 10_000_000
    max_connections: int = 64
    triggers: frozenset[TriggerType] = frozenset({TriggerType.CYCLIC})
    #: Allowed (output, input) pairs for exclusive owners; None allows any pair.
    pairs: Callable[[], set[tuple[int, int]]] | None = None
    #: The configuration instances that take a Forward_Open's configuration data (a data segment
    #: after the connection points), with the size in bytes each takes; data for another instance
    #: is refused with 0x0118, data of another size with 0x0126.
    config_sizes: Callable[[], Mapping[int, int]] | None = None
    #: For a device that offers only some of its assemblies: which pair is offered now and how
    #: to change it, added to the log line of a Forward_Open refused for its path.
    pair_hint: Callable[[], str] | None = None


#: A connection whose first O->T datagram has not come after this many RPIs (and at least this
#: long, for scheduling noise) is reported once in the log; the watchdog waits 10 s before closing it.
SILENT_RPIS = 8
SILENT_MINIMUM_S = 0.5

#: The extended statuses of a connection path that names assemblies the device does not offer.
_PATH_REFUSALS = frozenset({ExtendedStatus.INVALID_CONSUMING_PATH, ExtendedStatus.INVALID_PRODUCING_PATH,
                           ExtendedStatus.INCONSISTENT_PATH_COMBINATION})


class IoEvents(Protocol):
    """What the device is told about its class 1 connections."""

    def io_opened(self, connection: IoConnection) -> None: ...

    def io_closed(self, connection: IoConnection, timed_out: bool) -> None: ...

    def io_run_idle(self, connection: IoConnection, run: bool) -> None: ...


class NoEvents:
    def io_opened(self, connection: IoConnection) -> None:
        pass

    def io_closed(self, connection: IoConnection, timed_out: bool) -> None:
        pass

    def io_run_idle(self, connection: IoConnection, run: bool) -> None:
        pass


@dataclass
class IoConnection:
    kind: ConnectionKind
    triad: ConnectionTriad
    ot_connection_id: int
    to_connection_id: int
    ot_rpi_us: int
    to_rpi_us: int
    consumed: AssemblyPoint | None
    produced: AssemblyPoint
    destination: tuple[str, int]
    multicast: bool
    consumer: ConsumerState
    #: None for a listen-only connection that shares its owner's multicast production.
    producer: ProductionSchedule | None
    stats: IoStatistics
    peer: str = ""
    run: bool | None = None
    encap_sequence: int = 0
    cip_sequence: int = 0
    owner: IoConnection | None = None
    listeners: list[IoConnection] = field(default_factory=list)
    #: When to say so if no O->T datagram has arrived yet (None: said, or no longer needed).
    silence_check: float | None = None
    #: Bytes after the CIP sequence count of every O->T datagram: the run/idle header and the
    #: consumed assembly, or the heartbeat's (0 or the 4-byte header) as the Forward_Open sized it.
    ot_payload_size: int = 4
    #: When the target's watchdog heap looks at this connection next (its live entry there).
    watch_at: float = 0.0
    #: T->O data bytes of a variable-size connection that asked for fewer than its assembly's size.
    to_payload_size: int | None = None
    #: Opened by a Forward_Open over DTLS: its data flows in that DTLS session (``destination`` is
    #: the session's address), and O->T datagrams that come as plain UDP are dropped.
    secured: bool = False

    @property
    def name(self) -> str:
        out = self.consumed.instance_id if self.consumed else "heartbeat"
        return f"{self.kind.value} {out}->{self.produced.instance_id} (0x{self.ot_connection_id:08X})"


def _variable(point: AssemblyPoint | None) -> bool:
    """A point of a variable size (``objects.assembly.AssemblyPoint.variable``)."""
    return bool(getattr(point, "variable", False))


def _nothing_changed() -> None:
    """``IoTarget.changed`` of a target no shell times (a test driving the core by hand)."""


def _no_time(now: float) -> None:
    """``IoTarget.tick`` of a target without a device to move in time."""


class IoTarget:
    def __init__(self, profile: IoProfile, events: IoEvents | None = None,
                 multicast_block: Callable[[], tuple[int, int]] | None = None,
                 io_port: int = DEFAULT_IO_PORT, grid: ProductionGrid | None = None, *,
                 deliver: Callable[[int, bytes, float], None] | None = None,
                 tick: Callable[[float], None] | None = None,
                 changed: Callable[[], None] | None = None) -> None:
        """The hooks are given here by whoever builds the target (the adapter), never set later:
        ``deliver`` takes consumed data (and a Forward_Open's configuration data) to the device, by
        default each point's own ``consume``; ``tick`` moves the device to the time of what it is
        told, by default nothing; ``changed`` says a connection opened (the shell re-arms its timer
        for the new deadlines), by default nothing. Each is held as given, one call on the hot path."""
        self.profile = profile
        self.events = events or NoEvents()
        #: Where consumed data goes: the device's Assembly object (``AssemblyObject.deliver``).
        self.deliver: Callable[[int, bytes, float], None] = deliver or self._deliver_to_point
        #: (first multicast address as an int, number of addresses) for T->O multicast.
        self.multicast_block = multicast_block or (lambda: (CIP_MULTICAST_BASE, 32))
        self.io_port = io_port
        self.connections: dict[int, IoConnection] = {}
        # Deadlines in heaps, so a timer firing touches only what is due (not every connection):
        # production slots and watchdogs, each entry (time, order, connection). Entries of closed
        # connections are dropped when they come up; a watchdog entry whose deadline has moved on
        # (packets arrived) is pushed again at the new deadline.
        self._productions: list[tuple[float, int, IoConnection]] = []
        #: Where productions start; several targets of one process may share one (a fleet's devices).
        self._grid = grid or ProductionGrid()
        self._watchdogs: list[tuple[float, int, IoConnection]] = []
        #: Connections whose O->T data is still awaited, by when to say it has not come (few, briefly).
        self._silences: list[tuple[float, int, IoConnection]] = []
        self._order = itertools.count()
        self._ids = itertools.count(random.randrange(0x10000, 0x7FFF0000))
        self.timeouts = 0
        self.dropped = 0
        #: The packet counts of the connections closed so far, added up when each closes (nothing per
        #: packet): with the open connections' own, what ``/metrics`` reports as totals.
        self.closed_stats = IoStatistics()
        #: Refused Forward_Opens: at most one line per 10 s per originator address and status.
        self.refused_log = RateLimitedLog(log, level=logging.INFO)
        #: Called when a connection opens (the shell re-arms its timer for the new deadlines).
        self.changed: Callable[[], None] = changed or _nothing_changed
        #: Called with the time before data is consumed or produced: the device moves its simulation there.
        self.tick: Callable[[float], None] = tick or _no_time

    # -- Forward_Open -------------------------------------------------------------------------
    def forward_open(self, fo: ForwardOpenRequest, context: RequestContext) -> ForwardOpenReply:
        try:
            return self._forward_open(fo, context)
        except CipError as exc:
            # A line per refusal and reason, so that whoever runs the adapter sees why a scanner gets no
            # I/O; a flood of the same refusal is one line per 10 s with its count (``RateLimitedLog``).
            source = (origin_host(context.origin) if context.origin else None, exc.general, exc.extended)
            reason = str(exc)
            if exc.extended and exc.extended[0] in _PATH_REFUSALS and self.profile.pair_hint is not None:
                reason += f"; {self.profile.pair_hint()}"
            self.refused_log("class 1 Forward_Open from %s refused: %s", context.origin, reason, source=source,
                             now=context.now)
            raise

    def _forward_open(self, fo: ForwardOpenRequest, context: RequestContext) -> ForwardOpenReply:
        triad = fo.triad
        host = origin_host(context.origin) if context.origin else "127.0.0.1"
        for existing in self.connections.values():
            if existing.triad != triad:
                continue
            if existing.peer == host:
                raise connection_failure(ExtendedStatus.CONNECTION_IN_USE, triad, "duplicate Forward_Open")
            # Another originator's triad, from another address: no such connection for this one.
            raise connection_failure(ExtendedStatus.CONNECTION_NOT_FOUND, triad,
                                     "the triad is a connection of another originator address")
        if fo.transport.trigger not in self.profile.triggers:
            raise connection_failure(ExtendedStatus.TRANSPORT_CLASS_NOT_SUPPORTED, triad,
                                     f"{fo.transport.trigger.name.lower()} trigger not offered")
        config, points, config_data = self._parse_path(fo, context)
        if config is not None and config not in self.profile.config_instances:
            raise connection_failure(ExtendedStatus.INVALID_CONFIGURATION_APPLICATION_PATH, triad,
                                     f"configuration instance {config}")
        if config_data:
            config_data = self._configuration(config, config_data, triad)
        if len(points) != 2:
            raise connection_failure(ExtendedStatus.INCONSISTENT_PATH_COMBINATION, triad,
                                     "a connection path needs a consumed and a produced point")
        out_point, in_point = points
        consumed_points = self.profile.consumed()
        produced_points = self.profile.produced()
        profile = self.profile
        if out_point == profile.input_only_point or out_point in profile.more_input_only_points:
            kind, consumed = ConnectionKind.INPUT_ONLY, None
        elif out_point == profile.listen_only_point or out_point in profile.more_listen_only_points:
            kind, consumed = ConnectionKind.LISTEN_ONLY, None
        elif out_point in consumed_points:
            kind, consumed = ConnectionKind.EXCLUSIVE_OWNER, consumed_points[out_point]
        else:
            raise connection_failure(ExtendedStatus.INVALID_CONSUMING_PATH, triad, f"no output assembly {out_point}")
        produced = produced_points.get(in_point)
        if produced is None:
            raise connection_failure(ExtendedStatus.INVALID_PRODUCING_PATH, triad, f"no input assembly {in_point}")
        if kind is ConnectionKind.EXCLUSIVE_OWNER and self.profile.pairs is not None and (
                (out_point, in_point) not in self.profile.pairs()):
            raise connection_failure(ExtendedStatus.INCONSISTENT_PATH_COMBINATION, triad,
                                     f"assemblies {out_point}/{in_point} are not a pair this device offers")
        self._check_network(fo, kind, consumed, produced)
        if context.extras.get("io_path") is not None and fo.to_parameters.type != ConnectionType.POINT_TO_POINT:
            raise connection_failure(ExtendedStatus.INVALID_NETWORK_CONNECTION_PARAMETER, triad,
                                     "a connection opened over DTLS is point-to-point: its data flows in the "
                                     "DTLS session")
        self._check_rpi(fo)
        owner = None
        if kind is ConnectionKind.EXCLUSIVE_OWNER:
            for other in self.connections.values():
                if other.kind is ConnectionKind.EXCLUSIVE_OWNER and other.consumed is consumed:
                    raise connection_failure(ExtendedStatus.OWNERSHIP_CONFLICT, triad,
                                             f"output assembly {out_point} already has an owner")
        if kind is ConnectionKind.LISTEN_ONLY:
            owner = next((c for c in self.connections.values() if c.kind is not ConnectionKind.LISTEN_ONLY
                          and c.produced is produced and c.multicast), None)
            if owner is None:
                raise connection_failure(ExtendedStatus.NON_LISTEN_ONLY_NOT_OPENED, triad,
                                         f"no connection produces input assembly {in_point} to listen to")
        if len(self.connections) >= self.profile.max_connections:
            raise connection_failure(ExtendedStatus.OUT_OF_CONNECTIONS, triad)
        if config_data and config is not None:
            # Only a Forward_Open that succeeds configures: every check above came first.
            self.deliver(config, config_data, context.now)
        return self._open(fo, context, kind, consumed, produced, owner)

    def _configuration(self, config: int | None, data: bytes, triad: ConnectionTriad) -> bytes:
        """The configuration data a Forward_Open carries for ``config``, without the pad byte a
        data segment of whole words adds to an odd size; refused when the instance takes none or
        another size."""
        sizes = self.profile.config_sizes() if self.profile.config_sizes is not None else {}
        size = sizes.get(config) if config is not None else None
        if size is None:
            raise connection_failure(ExtendedStatus.INVALID_CONFIGURATION_PATH, triad,
                                     "this device takes no configuration data" if not sizes else
                                     f"configuration instance {config} takes no configuration data")
        if len(data) != size and not (size % 2 and len(data) == size + 1):
            raise connection_failure(ExtendedStatus.INVALID_CONFIGURATION_SIZE, triad,
                                     f"configuration data of {len(data)} bytes; instance {config} takes {size}")
        return data[:size]

    def _parse_path(self, fo: ForwardOpenRequest, context: RequestContext
                    ) -> tuple[int | None, list[int], bytes]:
        triad = fo.triad
        try:
            segments = decode_path(fo.connection_path)
        except CipError:
            raise connection_failure(ExtendedStatus.INVALID_SEGMENT_IN_CONNECTION_PATH, triad) from None
        config: int | None = None
        points: list[int] = []
        data = b""
        seen_class = False
        for segment in segments:
            if isinstance(segment, ElectronicKey):
                if seen_class:
                    raise connection_failure(ExtendedStatus.INVALID_SEGMENT_IN_CONNECTION_PATH, triad)
                cm = context.router.objects.get(0x06)
                if cm is not None:
                    cm.check_key(segment, triad)  # type: ignore[attr-defined]
            elif isinstance(segment, LogicalSegment):
                if segment.kind == LogicalType.CLASS_ID:
                    if seen_class or segment.value != 0x04:
                        raise connection_failure(ExtendedStatus.INVALID_APPLICATION_PATH, triad,
                                                 "class 1 connections go to assembly instances")
                    seen_class = True
                elif not seen_class:
                    raise connection_failure(ExtendedStatus.INVALID_SEGMENT_IN_CONNECTION_PATH, triad)
                elif segment.kind == LogicalType.INSTANCE_ID and config is None and not points:
                    config = segment.value
                elif segment.kind in (LogicalType.CONNECTION_POINT, LogicalType.INSTANCE_ID):
                    points.append(segment.value)
                else:
                    raise connection_failure(ExtendedStatus.INVALID_SEGMENT_IN_CONNECTION_PATH, triad)
            elif isinstance(segment, DataSegment):
                data += segment.data
            else:
                raise connection_failure(ExtendedStatus.INVALID_SEGMENT_IN_CONNECTION_PATH, triad)
        if not seen_class:
            raise connection_failure(ExtendedStatus.INVALID_APPLICATION_PATH, triad)
        return config, points, data

    def _check_network(self, fo: ForwardOpenRequest, kind: ConnectionKind, consumed: AssemblyPoint | None,
                       produced: AssemblyPoint) -> None:
        triad = fo.triad
        ot, to = fo.ot_parameters, fo.to_parameters
        if ot.type != ConnectionType.POINT_TO_POINT:
            raise connection_failure(ExtendedStatus.INVALID_NETWORK_CONNECTION_PARAMETER, triad,
                                     "O->T must be point-to-point")
        if to.type not in (ConnectionType.POINT_TO_POINT, ConnectionType.MULTICAST):
            raise connection_failure(ExtendedStatus.INVALID_NETWORK_CONNECTION_PARAMETER, triad,
                                     "T->O must be point-to-point or multicast")
        if kind is ConnectionKind.LISTEN_ONLY and to.type != ConnectionType.MULTICAST:
            raise connection_failure(ExtendedStatus.INVALID_NETWORK_CONNECTION_PARAMETER, triad,
                                     "a listen-only connection receives multicast")
        expected_ot = consumed.size + OT_OVERHEAD if consumed is not None else None
        if expected_ot is None:
            # Heartbeat: the sequence count, with or without the run/idle header.
            if ot.size not in (TO_OVERHEAD, OT_OVERHEAD):
                raise connection_failure(ExtendedStatus.INVALID_OT_SIZE, triad, "heartbeat size",
                                         extra_words=(TO_OVERHEAD,))
        elif ot.size != expected_ot and not (ot.variable and ot.size > expected_ot) and not (
                ot.variable and _variable(consumed) and OT_OVERHEAD <= ot.size < expected_ot):
            raise connection_failure(ExtendedStatus.INVALID_OT_SIZE, triad,
                                     f"O->T size {ot.size}, assembly needs {expected_ot}", extra_words=(expected_ot,))
        expected_to = produced.size + TO_OVERHEAD
        if to.size != expected_to and not (to.variable and to.size > expected_to) and not (
                to.variable and _variable(produced) and TO_OVERHEAD <= to.size < expected_to):
            raise connection_failure(ExtendedStatus.INVALID_TO_SIZE, triad,
                                     f"T->O size {to.size}, assembly needs {expected_to}", extra_words=(expected_to,))

    def _check_rpi(self, fo: ForwardOpenRequest) -> None:
        low, high = self.profile.rpi_min_us, self.profile.rpi_max_us

        def verdict(rpi: int) -> tuple[int, int]:
            if rpi < low:
                return RpiType.MINIMUM, low
            if rpi > high:
                return RpiType.MAXIMUM, high
            return RpiType.ACCEPTABLE, rpi

        (ot_type, ot_value), (to_type, to_value) = verdict(fo.ot_rpi_us), verdict(fo.to_rpi_us)
        if ot_type or to_type:
            words = struct.unpack("<5H", struct.pack("<BBII", ot_type, to_type, ot_value, to_value))
            raise connection_failure(ExtendedStatus.RPI_VALUE_NOT_ACCEPTABLE, fo.triad,
                                     f"RPI outside {low}..{high} us", extra_words=words)

    def _open(self, fo: ForwardOpenRequest, context: RequestContext, kind: ConnectionKind,
              consumed: AssemblyPoint | None, produced: AssemblyPoint, owner: IoConnection | None) -> ForwardOpenReply:
        now = context.now
        multicast = fo.to_parameters.type == ConnectionType.MULTICAST
        peer_host = origin_host(context.origin) if context.origin else "127.0.0.1"
        sockaddrs: dict[int, SockAddr] = context.extras.get("sockaddr", {})
        io_path: tuple[str, int] | None = context.extras.get("io_path")
        if io_path is not None:
            # Over DTLS both directions flow in the session the Forward_Open came in (OpENer issue
            # #234; Wireshark dissects class 1 in DTLS on port 2221): T->O goes to its address.
            destination = io_path
            to_id = fo.to_connection_id
        elif owner is not None:
            destination = owner.destination
            to_id = owner.to_connection_id
        elif multicast:
            destination = (self._multicast_address(), self.io_port)
            to_id = self._new_id()
        else:
            # Point-to-point T->O goes to the originator (the host of its TCP connection) at the
            # port of the T->O Sockaddr Info item (0x8001) its Forward_Open carries, else at 2222,
            # the class 1 port (CIP Vol. 2, 2-6.3.3 and 3-3.9.4, as OpENer's
            # OpenProducingPointToPointConnection and Wireshark's packet-enip.c read it), never at
            # this target's own consuming port. The item's sin_addr is not followed: an originator
            # names where it receives, not another host to send this target's production to. Port 0
            # names no port: the default then.
            requested = sockaddrs.get(ItemType.SOCKADDR_T_O)
            destination = (peer_host, requested.port if requested is not None and requested.port else DEFAULT_IO_PORT)
            to_id = fo.to_connection_id
        stats = IoStatistics()
        consumer = ConsumerState.opened(connection_timeout(fo.ot_rpi_us, fo.timeout_multiplier), now, stats=stats)
        period = fo.to_rpi_us / 1e6
        producer = None if owner is not None else ProductionSchedule(period, self._grid.first_due(period, now),
                                                                     stats=stats)
        ot_payload_size = consumed.size + OT_OVERHEAD - TO_OVERHEAD if consumed is not None else (
            fo.ot_parameters.size - TO_OVERHEAD)
        if consumed is not None and _variable(consumed):
            ot_payload_size = min(ot_payload_size, fo.ot_parameters.size - TO_OVERHEAD)
        to_payload_size = None
        if _variable(produced) and fo.to_parameters.size - TO_OVERHEAD < produced.size:
            to_payload_size = fo.to_parameters.size - TO_OVERHEAD
        connection = IoConnection(kind, fo.triad, self._new_id(), to_id, fo.ot_rpi_us, fo.to_rpi_us, consumed,
                                  produced, destination, multicast, consumer, producer, stats, peer_host,
                                  owner=owner, ot_payload_size=ot_payload_size, to_payload_size=to_payload_size,
                                  secured=io_path is not None)
        if owner is not None:
            owner.listeners.append(connection)
        connection.silence_check = now + max(SILENT_RPIS * fo.ot_rpi_us / 1e6, SILENT_MINIMUM_S)
        self.connections[connection.ot_connection_id] = connection
        heapq.heappush(self._silences, (connection.silence_check, next(self._order), connection))
        if producer is not None:
            heapq.heappush(self._productions, (producer.next_due, next(self._order), connection))
        self._watch(connection)
        reply_items = context.extras.setdefault("reply_items", [])
        if self.io_port != DEFAULT_IO_PORT:
            # An originator sends O->T data to 2222 unless the reply's O->T Sockaddr Info item
            # (0x8000) names another port (CIP Vol. 2, 2-6.3.3; OpENer's
            # OpenConsumingPointToPointConnection always answers one): a target consuming elsewhere
            # says so. Its sin_addr is 0, as OpENer's: the originator already knows this target's
            # address, and the port is what the item is for.
            reply_items.append(Item(ItemType.SOCKADDR_O_T, SockAddr("0.0.0.0", self.io_port).encode()))
        if multicast:
            # Multicast T->O: the reply's T->O item (0x8001) names the group and port to receive on.
            host, port = destination
            reply_items.append(Item(ItemType.SOCKADDR_T_O, SockAddr(host, port).encode()))
        log.info("class 1 %s opened by %s (RPI O->T %d us, T->O %d us%s)", connection.name, context.origin,
                 fo.ot_rpi_us, fo.to_rpi_us, ", multicast " + destination[0] if multicast else "")
        self.events.io_opened(connection)
        self.changed()
        return ForwardOpenReply(connection.ot_connection_id, to_id, fo.triad, fo.ot_rpi_us, fo.to_rpi_us)

    def _check_silence(self, now: float) -> None:
        """Say once, well before the watchdog's first timeout, that an opened connection's O->T data
        has not arrived: an originator that sends to another port (or host) otherwise looks connected."""
        heap = self._silences
        while heap and heap[0][0] <= now:
            _at, _order, connection = heapq.heappop(heap)
            if self.connections.get(connection.ot_connection_id) is not connection or connection.silence_check is None:
                continue
            connection.silence_check = None
            if connection.stats.received == 0:
                waited = SILENT_RPIS * connection.ot_rpi_us / 1e6
                log.warning("class 1 %s: no O->T data from %s after %d RPIs (%.3f s); this adapter consumes on "
                            "UDP port %d: is the originator sending there?", connection.name, connection.peer,
                            SILENT_RPIS, max(waited, SILENT_MINIMUM_S), self.io_port)

    def _new_id(self) -> int:
        while True:
            candidate = next(self._ids) & 0xFFFFFFFF
            if candidate and candidate not in self.connections and all(
                    c.to_connection_id != candidate for c in self.connections.values()):
                return candidate

    def _multicast_address(self) -> str:
        start, count = self.multicast_block()
        in_use = {c.destination[0] for c in self.connections.values() if c.multicast}
        for index in range(max(count, 1)):
            address = socket.inet_ntoa(struct.pack(">I", start + index))
            if address not in in_use:
                return address
        return socket.inet_ntoa(struct.pack(">I", start))

    # -- Forward_Close ------------------------------------------------------------------------
    def forward_close(self, fc: ForwardCloseRequest, context: RequestContext) -> bool:
        """Close the connection the requesting address opened with this triad; False when none
        (a connection of another originator address is not found, whatever its triad)."""
        host = origin_host(context.origin) if context.origin else "127.0.0.1"
        for connection in list(self.connections.values()):
            if connection.triad == fc.triad and connection.peer == host:
                self._close(connection, timed_out=False)
                return True
        return False

    def _close(self, connection: IoConnection, timed_out: bool) -> None:
        if self.connections.pop(connection.ot_connection_id, None) is None:
            return
        self.closed_stats.add(connection.stats)
        if connection.owner is not None and connection in connection.owner.listeners:
            connection.owner.listeners.remove(connection)
        log.info("class 1 %s %s", connection.name, "timed out" if timed_out else "closed")
        self.events.io_closed(connection, timed_out)
        for listener in list(connection.listeners):
            # A listen-only connection lives only as long as the connection it listens to.
            self._close(listener, timed_out)

    def close_path(self, path: tuple[str, int]) -> int:
        """Close the connections opened over the DTLS session at ``path`` (it has ended: their data has
        no way left to flow); how many."""
        closing = [c for c in self.connections.values() if c.secured and c.destination == path]
        for connection in closing:
            self._close(connection, timed_out=False)
        return len(closing)

    def close_all(self) -> None:
        for connection in list(self.connections.values()):
            self._close(connection, timed_out=False)
        self._productions.clear()
        self._watchdogs.clear()
        self._silences.clear()

    # -- datagrams ------------------------------------------------------------------------------
    def connection_of(self, raw: bytes) -> IoConnection | None:
        """The open connection an O->T datagram names by its connection id (CIP Vol. 2, 3-2: the
        Sequenced Address item's connection id at offset 6), or None."""
        if len(raw) < 10:
            return None
        return self.connections.get(int.from_bytes(raw[6:10], "little"))

    def receive(self, raw: bytes, source: tuple[str, int], now: float, to_device: bool = True,
                secured: bool = False) -> None:
        """Consume one O->T datagram; anything malformed or unknown is dropped and counted. With
        ``to_device`` false its data is consumed (sequence count, watchdog, run/idle) and not handed
        to the device (a filter withholds it: ``seams.IoSeam.withhold``). ``secured``: it came in a
        DTLS session; a connection opened over DTLS takes no other, one opened over TCP no such."""
        try:
            datagram = decode_io_datagram(raw)
        except IoDatagramError:
            self.dropped += 1
            return
        connection = self.connections.get(datagram.connection_id)
        payload = datagram.payload
        # Refused before anything moves: a datagram of another source or of the wrong size neither
        # advances the sequence window nor feeds the watchdog (DESIGN: state changes only on
        # accepted input), so it can neither keep a dead connection alive nor make later ones stale.
        if (connection is None or connection.peer != source[0] or len(payload) != connection.ot_payload_size
                or connection.secured is not secured or (secured and connection.destination != source)):
            self.dropped += 1
            return
        consumer = connection.consumer
        reception = consumer.accept(datagram.encap_sequence, datagram.cip_sequence, now)
        if reception is RECEIVED_STALE:
            return
        if consumer.deadline < connection.watch_at:
            self._watch(connection)  # the first packet ends the 10 s first-packet allowance
        # The device is moved to ``now`` only when it is told something (run/idle changes, new
        # data): a heartbeat or a repeated packet leaves it alone, so most datagrams cost no tick.
        if connection.consumed is None:
            if payload and connection.run is not bool(payload[0] & 1):
                self.tick(now)
                self._run_idle(connection, bool(payload[0] & 1))
            return
        run, data = split_run_idle(payload)
        deliver = reception is RECEIVED_NEW and run and to_device
        if deliver or connection.run is not run:
            self.tick(now)
        self._run_idle(connection, run)
        if deliver:
            if len(data) < connection.consumed.size:   # a variable-size connection carries the first bytes
                data = data.ljust(connection.consumed.size, b"\0")
            self.deliver(connection.consumed.instance_id, data, now)

    def _deliver_to_point(self, instance_id: int, data: bytes, now: float) -> None:
        for point in self.profile.consumed().values():
            if point.instance_id == instance_id and point.consume is not None:
                point.consume(data, now)

    def _run_idle(self, connection: IoConnection, run: bool) -> None:
        if connection.run is not run:
            connection.run = run
            log.info("class 1 %s: %s", connection.name, "run" if run else "idle")
            self.events.io_run_idle(connection, run)

    def poll(self, now: float, horizon: float = 0.0) -> list[tuple[bytes, tuple[str, int]]]:
        """The T->O datagrams due at ``now``, each with its destination; with ``horizon``, also those
        due within that much after ``now`` and within 1/16 of their RPI (``early_limit``), so that
        one firing sends what would otherwise take several wake-ups a few microseconds apart."""
        heap = self._productions
        if not heap or heap[0][0] > now + horizon:
            return []
        out = []
        connections = self.connections
        # The device does not change within one firing: each input assembly is produced once and
        # its bytes shared by every connection due that reads it.
        produced: dict[int, bytes] = {}
        ticked = False
        while heap and heap[0][0] <= now + horizon:
            due_at, _order, connection = heap[0]
            producer = connection.producer
            if producer is not None and due_at > now and due_at - now > producer.period * EARLY_SHARE:
                break  # not due, and too far off to send early
            heapq.heappop(heap)
            if producer is None or connections.get(connection.ot_connection_id) is not connection:
                continue  # closed since
            if not ticked:
                self.tick(now)
                ticked = True
            due, _ = producer.due(max(now, due_at))
            heapq.heappush(heap, (producer.next_due, next(self._order), connection))
            if not due:
                continue
            point = connection.produced
            data = produced.get(id(point))
            if data is None:
                data = produced[id(point)] = point.produce() if point.produce is not None else bytes(point.size)
            if connection.to_payload_size is not None:
                data = data[:connection.to_payload_size]
            connection.encap_sequence = (connection.encap_sequence + 1) & 0xFFFFFFFF
            connection.cip_sequence = (connection.cip_sequence + 1) & 0xFFFF
            out.append((encode_io_datagram(connection.to_connection_id, connection.encap_sequence,
                                           connection.cip_sequence, data), connection.destination))
            producer.stats.sent += 1
        return out

    def next_deadline(self) -> float | None:
        """The earliest production slot or watchdog deadline (a watchdog may have moved on since:
        firing early costs one look, see ``expire``)."""
        self._drop_closed(self._productions)
        self._drop_closed(self._watchdogs)
        self._drop_closed(self._silences)
        candidates = [heap[0][0] for heap in (self._productions, self._watchdogs, self._silences) if heap]
        return min(candidates, default=None)

    def _drop_closed(self, heap: list[tuple[float, int, IoConnection]]) -> None:
        connections = self.connections
        while heap:
            at, _order, connection = heap[0]
            if connections.get(connection.ot_connection_id) is connection and (
                    (heap is self._productions) or (heap is self._watchdogs and at == connection.watch_at)
                    or (heap is self._silences and connection.silence_check is not None)):
                return
            heapq.heappop(heap)

    def _watch(self, connection: IoConnection) -> None:
        """Put the connection's watchdog deadline in the heap (an earlier entry becomes stale)."""
        connection.watch_at = connection.consumer.deadline
        heapq.heappush(self._watchdogs, (connection.watch_at, next(self._order), connection))

    def expire(self, now: float) -> list[IoConnection]:
        self._check_silence(now)
        expired = []
        heap = self._watchdogs
        connections = self.connections
        while heap and heap[0][0] <= now:
            at, _order, connection = heapq.heappop(heap)
            if connections.get(connection.ot_connection_id) is not connection or at != connection.watch_at:
                continue  # closed since, or superseded by an earlier entry
            if connection.consumer.expired(now):
                expired.append(connection)
            else:  # packets arrived: watch again at the deadline they set
                self._watch(connection)
        for connection in expired:
            if connection.ot_connection_id in self.connections:
                self.timeouts += 1
                self._close(connection, timed_out=True)
        if expired:
            # The device has been told (a lost-command timer may have started): let the shell
            # follow its new deadlines even if no request or datagram ever comes again.
            self.tick(now)
        return expired
