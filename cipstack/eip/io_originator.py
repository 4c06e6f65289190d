"""Class 1 connections, originator side.

``IoOriginator`` is the sans-I/O core shared by every connection of one event loop: it
produces O->T datagrams at each connection's RPI (with the run/idle header), consumes T->O
datagrams (sequence filtering, watchdog) and reports timeouts. ``IoConnectionHandle`` is what
a scanner holds: open it with ``EncapsulationClient.io_connection`` (or the scanner's), set
output fields, read input fields, iterate input updates, switch run/idle, read statistics.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import random
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..cip.epath import LogicalSegment, LogicalType, encode_path
from .cm_messages import ConnectionTriad, ConnectionType, NetworkParameters, TransportTrigger, TriggerType
from .io_core import (
    ConsumerState,
    IoDatagram,
    IoDatagramError,
    IoStatistics,
    ProductionSchedule,
    Reception,
    connection_timeout,
    decode_io_datagram,
    encode_io_datagram,
)
from .io_target import OT_OVERHEAD, TO_OVERHEAD

if TYPE_CHECKING:
    from ..assemblies.schema import AssemblySchema
    from .io_server import IoEndpoint

log = logging.getLogger(__name__)


class IoTimeoutError(ConnectionError):
    """The target's T->O data stopped for longer than the connection timeout."""


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
    heartbeat: bool = False
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


class IoOriginator:
    """All class 1 connections of one originator (an ``IoCore`` for ``IoEndpoint``)."""

    def __init__(self) -> None:
        #: By O->T connection id, which the target makes unique.
        self.connections: dict[int, OriginatorConnection] = {}
        #: By T->O connection id: several connections share one when they listen to the same multicast data.
        self.by_to_id: dict[int, list[OriginatorConnection]] = {}
        self.dropped = 0

    def add(self, connection: OriginatorConnection) -> None:
        self.connections[connection.ot_connection_id] = connection
        self.by_to_id.setdefault(connection.to_connection_id, []).append(connection)

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
        if connection.closed or len(datagram.payload) != connection.input_size:
            self.dropped += 1
            return
        reception = connection.consumer.accept(datagram.encap_sequence, datagram.cip_sequence, now)
        if reception is Reception.STALE:
            return
        if connection.keep_intervals:
            if connection.last_arrival is not None:
                connection.interval_samples.append(now - connection.last_arrival)
            connection.last_arrival = now
        if reception is Reception.NEW:
            changed = datagram.payload != connection.input
            connection.input = datagram.payload
            if changed and connection.updates is not None:
                if connection.updates.full():
                    connection.updates.get_nowait()  # keep the newest: a slow reader sees the latest state
                connection.updates.put_nowait(datagram.payload)

    def poll(self, now: float) -> list[tuple[bytes, tuple[str, int]]]:
        out = []
        for connection in self.connections.values():
            if connection.closed or now < connection.producer.next_due:
                continue
            due, _ = connection.producer.due(now)
            if not due:
                continue
            connection.encap_sequence = (connection.encap_sequence + 1) & 0xFFFFFFFF
            connection.cip_sequence = (connection.cip_sequence + 1) & 0xFFFF
            data = b"" if connection.heartbeat else bytes(connection.output)
            out.append((encode_io_datagram(connection.ot_connection_id, connection.encap_sequence,
                                           connection.cip_sequence, data, 1 if connection.run else 0),
                        (connection.target_host, connection.target_io_port)))
            connection.stats.sent += 1
            if connection.keep_intervals:
                connection.send_times.append(now)
        return out

    def next_deadline(self) -> float | None:
        deadlines = [c.producer.next_due for c in self.connections.values() if not c.closed]
        deadlines += [c.consumer.deadline for c in self.connections.values() if not c.closed and not c.timed_out]
        return min(deadlines, default=None)

    def expire(self, now: float) -> list[OriginatorConnection]:
        expired = [c for c in self.connections.values()
                   if not c.timed_out and not c.closed and c.consumer.expired(now)]
        for connection in expired:
            connection.timed_out = True
            log.warning("class 1 connection 0x%08X: no data from %s for %.3f s: timed out",
                        connection.to_connection_id, connection.target_host, connection.consumer.timeout)
            if connection.updates is not None:
                connection.updates.put_nowait(b"")  # wakes an iterator, which then raises
        return expired


class ProcessImage:
    """Assembly data with field access when the schema is known, raw bytes always."""

    def __init__(self, buffer: bytearray, schema: AssemblySchema | None, writable: bool) -> None:
        object.__setattr__(self, "_buffer", buffer)
        object.__setattr__(self, "_schema", schema)
        object.__setattr__(self, "_writable", writable)

    @property
    def raw(self) -> bytes:
        return bytes(self._buffer)

    @raw.setter
    def raw(self, value: bytes) -> None:
        if not self._writable:
            raise AttributeError("input data is read-only")
        if len(value) != len(self._buffer):
            raise ValueError(f"assembly is {len(self._buffer)} bytes, got {len(value)}")
        self._buffer[:] = value

    def fields(self) -> dict[str, Any]:
        if self._schema is None:
            raise AttributeError("no assembly schema known: use .raw")
        return self._schema.decode(bytes(self._buffer))

    def __getattr__(self, name: str) -> Any:
        schema = self._schema
        if schema is None or name not in schema.field_names:
            raise AttributeError(f"no field {name!r}" + ("" if schema else " (no assembly schema known: use .raw)"))
        return schema.decode(bytes(self._buffer))[name]

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "raw":
            ProcessImage.raw.fset(self, value)  # type: ignore[attr-defined]
            return
        if not self._writable:
            raise AttributeError("input data is read-only")
        if self._schema is None or name not in self._schema.field_names:
            raise AttributeError(f"no field {name!r}")
        self._buffer[:] = self._schema.with_field(bytes(self._buffer), name, value)

    def update(self, **values: Any) -> None:
        for name, value in values.items():
            setattr(self, name, value)


class IoConnectionHandle:
    """An open class 1 connection: ``output``/``input`` process images, updates, run/idle, statistics."""

    def __init__(self, core: IoOriginator, endpoint: IoEndpoint, connection: OriginatorConnection,
                 output_schema: AssemblySchema | None, input_schema: AssemblySchema | None) -> None:
        self._core = core
        self._endpoint = endpoint
        self.connection = connection
        self.output = ProcessImage(connection.output, output_schema, writable=True)
        self._input_schema = input_schema

    @property
    def input(self) -> ProcessImage:
        self._check()
        return ProcessImage(bytearray(self.connection.input or bytes(self.connection.input_size)),
                            self._input_schema, writable=False)

    @property
    def stats(self) -> IoStatistics:
        return self.connection.stats

    @property
    def timed_out(self) -> bool:
        return self.connection.timed_out

    def _check(self) -> None:
        if self.connection.timed_out:
            raise IoTimeoutError(f"class 1 connection to {self.connection.target_host} timed out")

    def set_run(self, run: bool) -> None:
        """Run (True) or idle (False) in the O->T run/idle header."""
        self.connection.run = run

    async def updates(self) -> AsyncIterator[ProcessImage]:
        """Input data each time it changes; raises ``IoTimeoutError`` when the target goes silent."""
        queue = self.connection.updates
        assert queue is not None
        while True:
            self._check()
            data = await queue.get()
            self._check()
            if data:
                yield ProcessImage(bytearray(data), self._input_schema, writable=False)

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


def class1_path(output: int | None, input: int, config: int, heartbeat: int | None = None) -> bytes:
    """``20 04 24 <config> 2C <O->T> 2C <T->O>`` (the O->T point is the heartbeat point when given)."""
    consumed = heartbeat if heartbeat is not None else output
    assert consumed is not None
    return encode_path([
        LogicalSegment(LogicalType.CLASS_ID, 0x04), LogicalSegment(LogicalType.INSTANCE_ID, config),
        LogicalSegment(LogicalType.CONNECTION_POINT, consumed), LogicalSegment(LogicalType.CONNECTION_POINT, input),
    ])


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

    def parameters(self) -> tuple[NetworkParameters, NetworkParameters, TransportTrigger, ConnectionTriad, int]:
        ot_size = (self.output_size + OT_OVERHEAD) if self.output_size is not None else OT_OVERHEAD
        ot = NetworkParameters(ot_size, ConnectionType.POINT_TO_POINT)
        to = NetworkParameters(self.input_size + TO_OVERHEAD,
                               ConnectionType.MULTICAST if self.multicast else ConnectionType.POINT_TO_POINT)
        triad = ConnectionTriad(next(_serials) & 0xFFFF, 0xFFFE, random.randrange(1, 0xFFFFFFFF))
        return ot, to, TransportTrigger(1, TriggerType.CYCLIC), triad, random.randrange(1, 0xFFFFFFFF)


def new_connection(request: Class1Request, target_host: str, target_io_port: int, ot_id: int, to_id: int,
                   ot_api_us: int, to_api_us: int, now: float, keep_intervals: bool = False) -> OriginatorConnection:
    stats = IoStatistics()
    to_timeout = connection_timeout(to_api_us, request.timeout_multiplier)
    return OriginatorConnection(
        target_host=target_host, target_io_port=target_io_port, ot_connection_id=ot_id, to_connection_id=to_id,
        ot_rpi=ot_api_us / 1e6, to_rpi=to_api_us / 1e6,
        output=bytearray(request.output_size or 0), input_size=request.input_size,
        consumer=ConsumerState.opened(to_timeout, now, stats=stats),
        producer=ProductionSchedule(ot_api_us / 1e6, now, stats=stats), stats=stats,
        heartbeat=request.output_size is None, updates=asyncio.Queue(maxsize=64), keep_intervals=keep_intervals)


__all__ = ["Class1Request", "IoConnectionHandle", "IoOriginator", "IoTimeoutError", "OriginatorConnection",
           "ProcessImage", "class1_path", "new_connection"]
