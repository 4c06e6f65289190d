"""Class 1 connections, originator side.

``IoOriginator`` is the sans-I/O core shared by every connection of one event loop: it
produces O->T datagrams at each connection's RPI (with the run/idle header), consumes T->O
datagrams (sequence filtering, watchdog) and reports timeouts. ``IoConnectionHandle`` is what
a scanner holds: open it with ``EncapsulationClient.io_connection`` (or the scanner's), set
output fields, read input fields, iterate input updates, switch run/idle, read statistics.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import logging
import random
from collections import deque
from collections.abc import AsyncIterator
from dataclasses import dataclass, field, replace
from enum import Enum
from typing import TYPE_CHECKING, Any

from ...cip.epath import LogicalSegment, LogicalType, encode_path
from ...errors import BadRequest, PeerUnreachable, ReadOnlyField, UnknownField
from ..io_core import (
    RECEIVED_NEW,
    RECEIVED_STALE,
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
from ..target.io_target import EARLY_SHARE, TO_OVERHEAD
from ..wire.cm_messages import ConnectionTriad, ConnectionType, NetworkParameters, TransportTrigger, TriggerType

if TYPE_CHECKING:
    from ...assemblies.schema import AssemblySchema
    from ..io_server import IoEndpoint

log = logging.getLogger(__name__)


class IoTimeoutError(PeerUnreachable):
    """The target's T->O data stopped for longer than the connection timeout."""


#: The 2-byte CIP sequence count that opens every class 1 packet, and the 32-bit run/idle header.
SEQUENCE_COUNT_SIZE = 2
RUN_IDLE_HEADER_SIZE = 4


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
    ``window`` intervals are kept for the percentiles, so memory stays bounded."""

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


@dataclass
class OriginatorConnection:
    """One class 1 connection as the originator sees it."""

    target_host: str
    target_io_port: int
    ot_connection_id: int
    to_connection_id: int
    ot_rpi: float
    to_rpi: float
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
    updates: asyncio.Queue[bytes] | None = None
    interval_samples: list[float] = field(default_factory=list)
    #: Times O->T packets went out (with ``keep_intervals``).
    send_times: list[float] = field(default_factory=list)
    last_arrival: float | None = None
    keep_intervals: bool = False
    #: When the originator's watchdog heap looks at this connection next (its live entry there).
    watch_at: float = 0.0


class IoOriginator:
    """All class 1 connections of one originator (an ``IoCore`` for ``IoEndpoint``)."""

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
                        connection.target_host, slow * 1e3, connection.arrivals.api * 1e3,
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
            if changed and connection.updates is not None:
                if connection.updates.full():
                    connection.updates.get_nowait()  # keep the newest: a slow reader sees the latest state
                connection.updates.put_nowait(datagram.payload)

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
            if connection.updates is not None:
                connection.updates.put_nowait(b"")  # wakes an iterator, which then raises
        return expired


class ProcessImage:
    """Assembly data with field access when the schema is known, raw bytes always.

    ``image.speed_reference`` reads a field, ``image.speed_reference = 900`` writes one (outputs
    only), ``image.fields()`` decodes them all, ``image.raw`` is the bytes. A field the schema
    does not have raises ``AttributeError`` naming the schema and its fields, or why none is known.
    """

    _buffer: bytearray
    _schema: AssemblySchema | None
    _writable: bool
    _where: str

    def __init__(self, buffer: bytearray, schema: AssemblySchema | None, writable: bool, where: str = "") -> None:
        object.__setattr__(self, "_buffer", buffer)
        object.__setattr__(self, "_schema", schema)
        object.__setattr__(self, "_writable", writable)
        object.__setattr__(self, "_where", where)

    @property
    def raw(self) -> bytes:
        return bytes(self._buffer)

    @raw.setter
    def raw(self, value: bytes) -> None:
        if not self._writable:
            raise ReadOnlyField("input data is read-only")
        if len(value) != len(self._buffer):
            raise BadRequest(f"assembly is {len(self._buffer)} bytes, got {len(value)}")
        self._buffer[:] = value

    @property
    def schema(self) -> AssemblySchema | None:
        """The assembly's declaration (None: raw bytes only)."""
        return self._schema

    @property
    def field_names(self) -> frozenset[str]:
        """The fields this image has by name (empty when no schema is known)."""
        return self._schema.field_names if self._schema is not None else frozenset()

    def fields(self) -> dict[str, Any]:
        """Every field's value by name."""
        if self._schema is None:
            raise UnknownField(self._no_field(None))
        return self._schema.decode(bytes(self._buffer))

    def _no_field(self, name: str | None) -> str:
        what = f"no field {name!r}" if name is not None else "no field names"
        schema = self._schema
        if schema is None:
            why = self._where or "no assembly schema known"
            return f"{what}: {why} (use .raw)"
        where = self._where or f"assembly {schema.instance} {schema.name!r}"
        return f"{what} in {where}; its fields: {', '.join(f.name for f in schema.fields)}"

    def __getattr__(self, name: str) -> Any:
        schema = self._schema
        if name.startswith("__") or schema is None or name not in schema.field_names:
            if name.startswith("__"):
                raise AttributeError(name)
            raise UnknownField(self._no_field(name))
        return schema.decode(bytes(self._buffer))[name]

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "raw":
            ProcessImage.raw.fset(self, value)  # type: ignore[attr-defined]
            return
        if not self._writable:
            raise ReadOnlyField("input data is read-only")
        if self._schema is None or name not in self._schema.field_names:
            raise UnknownField(self._no_field(name))
        self._buffer[:] = self._schema.with_field(bytes(self._buffer), name, value)

    def update(self, **values: Any) -> None:
        """Set several fields at once (``io.output.update(run_forward=True, speed_reference=900)``)."""
        if not self._writable:
            raise ReadOnlyField("input data is read-only")
        schema = self._schema
        for name in values:
            if schema is None or name not in schema.field_names:
                raise UnknownField(self._no_field(name))
        data = bytes(self._buffer)
        for name, value in values.items():
            assert schema is not None   # every name was checked above
            data = schema.with_field(data, name, value)
        self._buffer[:] = data  # one assignment: a production sees all the fields or none

    def __repr__(self) -> str:
        if self._schema is None:
            return f"ProcessImage(raw={self.raw.hex()!r})"
        return "ProcessImage(" + ", ".join(f"{k}={v!r}" for k, v in self.fields().items()) + ")"


class IoConnectionHandle:
    """An open class 1 connection: ``output``/``input`` process images, updates, run/idle, statistics."""

    def __init__(self, core: IoOriginator, endpoint: IoEndpoint, connection: OriginatorConnection,
                 output_schema: AssemblySchema | None, input_schema: AssemblySchema | None) -> None:
        self._core = core
        self._endpoint = endpoint
        self.connection = connection
        self.output = ProcessImage(connection.output, output_schema, writable=True)
        self._input_schema = input_schema
        self._input_where = ""
        #: What opening had to adapt to, one line each (e.g. a retry with the size the target asked for).
        self.notes: list[str] = []
        #: The multicast group T->O data comes from (the target's Sockaddr Info), None for point-to-point.
        self.multicast_group: str | None = None

    def describe_schemas(self, output: str, input: str) -> None:
        """Say where the output and input schemas come from (or why there is none), for the
        message of a field name they do not have."""
        object.__setattr__(self.output, "_where", output)
        self._input_where = input

    @property
    def kernel_arrival_times(self) -> bool:
        """Whether T->O packets are timed when the kernel received them (``io_connection``)."""
        return self._endpoint.kernel_arrival_times

    @property
    def input(self) -> ProcessImage:
        self._check()
        return ProcessImage(bytearray(self.connection.input or bytes(self.connection.input_size)),
                            self._input_schema, writable=False, where=self._input_where)

    @property
    def stats(self) -> IoStatistics:
        return self.connection.stats

    @property
    def arrivals(self) -> ArrivalStatistics:
        """T->O inter-arrival times, received rate against the API, missed production slots."""
        return self.connection.arrivals

    def statistics(self) -> dict[str, Any]:
        """Counters and arrival figures in one dictionary."""
        return {**self.connection.stats.as_dict(), **self.connection.arrivals.as_dict()}

    @property
    def timed_out(self) -> bool:
        return self.connection.timed_out

    def _check(self) -> None:
        if self.connection.timed_out:
            raise IoTimeoutError(f"class 1 connection to {self.connection.target_host} timed out")

    def set_run(self, run: bool) -> None:
        """Run (True) or idle (False) in the O->T run/idle header."""
        self.connection.run = run

    def stop_producing(self) -> None:
        """Stop sending O->T data, with no Forward_Close: what the target sees of a scanner that lost
        power or its cable. The target's connection times out and its timeout action runs; T->O data
        is no longer taken. Leaving the ``io_connection`` block still sends the Forward_Close."""
        self._core.remove(self.connection)

    async def updates(self) -> AsyncIterator[ProcessImage]:
        """Input data each time it changes; raises ``IoTimeoutError`` when the target goes silent."""
        queue = self.connection.updates
        assert queue is not None
        while True:
            self._check()
            data = await queue.get()
            self._check()
            if data:
                yield ProcessImage(bytearray(data), self._input_schema, writable=False, where=self._input_where)

    async def wait_input(self, predicate: Any, timeout: float) -> ProcessImage:
        """Wait until ``predicate(input_image)`` is true (or raise ``asyncio.TimeoutError``)."""
        async def wait() -> ProcessImage:
            if self.connection.input and predicate(self.input):
                return self.input
            async for image in self.updates():
                if predicate(image):
                    return image
            raise IoTimeoutError("input updates ended")

        return await asyncio.wait_for(wait(), timeout)


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
    """What the originator asks for, before it becomes a Forward_Open."""

    output_size: int | None
    input_size: int
    ot_rpi_us: int
    to_rpi_us: int
    path: bytes
    multicast: bool = False
    timeout_multiplier: int = 2
    large: bool = False
    ot_format: OtFormat = OtFormat.RUN_IDLE

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


def new_connection(request: Class1Request, target_host: str, target_io_port: int, ot_id: int, to_id: int,
                   ot_api_us: int, to_api_us: int, now: float, keep_intervals: bool = False) -> OriginatorConnection:
    stats = IoStatistics()
    arrivals = ArrivalStatistics(to_api_us / 1e6)
    to_timeout = connection_timeout(to_api_us, request.timeout_multiplier)
    return OriginatorConnection(
        target_host=target_host, target_io_port=target_io_port, ot_connection_id=ot_id, to_connection_id=to_id,
        ot_rpi=ot_api_us / 1e6, to_rpi=to_api_us / 1e6,
        output=bytearray(request.output_size or 0), input_size=request.input_size,
        consumer=ConsumerState.opened(to_timeout, now, stats=stats),
        producer=ProductionSchedule(ot_api_us / 1e6, now, stats=stats), stats=stats, arrivals=arrivals,
        heartbeat=request.output_size is None, ot_header=request.ot_format is OtFormat.RUN_IDLE,
        updates=asyncio.Queue(maxsize=64), keep_intervals=keep_intervals)


__all__ = ["ArrivalStatistics", "Class1Request", "IoConnectionHandle", "IoOriginator", "IoTimeoutError",
           "OriginatorConnection", "OtFormat", "ProcessImage", "class1_path", "new_connection"]
