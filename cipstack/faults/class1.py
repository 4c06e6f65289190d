"""Class 1 faults: filters of the datagrams that enter or leave the device, in its class 1 seam
(``cipstack.eip.target.seams.IoSeam``). Each fault is one filter, installed while the fault is active; with
none, the seam is a direct call to the core and costs nothing.

Datagrams are read and changed by their bytes (CIP Vol. 2, 3-2: a Sequenced Address item, the
connection id at offset 6 and the encapsulation sequence number at 10, a Connected Data item whose
length is at 16, the CIP sequence count at 18, then O->T the 32-bit run/idle header at 20 and the
data). The core's own counters never see a fault: after ``clear`` it produces what it would have.
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING

from .effect import FaultContext

if TYPE_CHECKING:
    from ..eip.target.io_target import IoConnection
    from ..eip.target.seams import Datagram, IoSeam

_CONNECTION_ID = struct.Struct("<I")
_UINT = struct.Struct("<H")
#: Bytes before the data of a class 1 datagram: CPF count, Sequenced Address item, Connected Data
#: item header and the CIP sequence count (``io_core.IO_HEAD_SIZE``).
HEAD = 20
DEFAULT_DELAY = 0.010


class Class1Filter:
    """A class 1 fault in force: which connections it acts on (``--connection``, ``--originator``, or
    all), installed in the class 1 seam from ``start`` (an ``OutboundFilter`` or an ``InboundFilter``)
    to ``stop``."""

    def __init__(self, context: FaultContext) -> None:
        self.context = context
        options = context.options
        self.connection = options.connection
        self.originator = options.originator
        self.rng = context.rng
        self.count = 0
        assert context.runtime.class1 is not None   # checked by the controller: the device has class 1
        self.seam: IoSeam = context.runtime.class1

    def stop(self) -> None:
        self.seam.remove(self)

    def matches(self, connection: IoConnection | None) -> bool:
        if connection is None:
            return self.connection is None and self.originator is None
        if self.connection is not None and self.connection not in (connection.ot_connection_id,
                                                                   connection.to_connection_id):
            return False
        return self.originator is None or connection.peer == self.originator

    def every_nth(self, every: int) -> bool:
        self.count += 1
        return self.count % every == 0


class OutboundFilter(Class1Filter):
    """A filter of T->O datagrams: ``change`` each one of a matching connection."""

    def start(self) -> None:
        self.seam.add(self)

    def outbound(self, datagrams: list[Datagram], now: float, seam: IoSeam) -> list[Datagram]:
        by_to_id = {c.to_connection_id: c for c in self.context.runtime.class1_connections()}
        out: list[Datagram] = []
        for datagram in datagrams:
            to_id = _CONNECTION_ID.unpack_from(datagram[0], 6)[0]
            if self.matches(by_to_id.get(to_id)):
                out += self.change(datagram, to_id, now)
            else:
                out.append(datagram)
        return out

    def change(self, datagram: Datagram, to_id: int, now: float) -> list[Datagram]:
        raise NotImplementedError


class StopProducing(OutboundFilter):
    def change(self, datagram: Datagram, to_id: int, now: float) -> list[Datagram]:
        return []


class Drop(OutboundFilter):
    def __init__(self, context: FaultContext) -> None:
        super().__init__(context)
        self.share = context.options.share
        # The fault model requires one of the two: without a share, every Nth.
        self.every = context.options.every or 1

    def change(self, datagram: Datagram, to_id: int, now: float) -> list[Datagram]:
        share = self.share
        dropped = self.rng.random() < share if share is not None else self.every_nth(self.every)
        return [] if dropped else [datagram]


class Duplicate(OutboundFilter):
    def __init__(self, context: FaultContext) -> None:
        super().__init__(context)
        self.every = context.options.every or 1

    def change(self, datagram: Datagram, to_id: int, now: float) -> list[Datagram]:
        return [datagram, datagram] if self.every_nth(self.every) else [datagram]


class Reorder(OutboundFilter):
    def __init__(self, context: FaultContext) -> None:
        super().__init__(context)
        #: Per connection, the datagram held back until the next one passes it.
        self.held: dict[int, Datagram] = {}

    def change(self, datagram: Datagram, to_id: int, now: float) -> list[Datagram]:
        held = self.held.pop(to_id, None)
        if held is None:
            self.held[to_id] = datagram
            return []
        return [datagram, held]


class Delay(OutboundFilter):
    def __init__(self, context: FaultContext) -> None:
        super().__init__(context)
        options = context.options
        self.by = DEFAULT_DELAY if options.by is None else options.by
        self.jitter = options.jitter or 0.0

    def change(self, datagram: Datagram, to_id: int, now: float) -> list[Datagram]:
        by, jitter = self.by, self.jitter
        at = now + max(0.0, by + (self.rng.uniform(-jitter, jitter) if jitter else 0.0))
        self.seam.send_later(at, [datagram])
        return []


class FreezeSequence(OutboundFilter):
    def __init__(self, context: FaultContext) -> None:
        super().__init__(context)
        #: Per connection, the CIP sequence count it keeps.
        self.frozen: dict[int, bytes] = {}

    def change(self, datagram: Datagram, to_id: int, now: float) -> list[Datagram]:
        raw = datagram[0]
        frozen = self.frozen.setdefault(to_id, raw[HEAD - 2:HEAD])
        return [(raw[:HEAD - 2] + frozen + raw[HEAD:], datagram[1])]


class WrongSize(OutboundFilter):
    def __init__(self, context: FaultContext) -> None:
        super().__init__(context)
        self.size = context.options.size

    def change(self, datagram: Datagram, to_id: int, now: float) -> list[Datagram]:
        raw = datagram[0]
        data = raw[HEAD:]
        wanted = self.size
        size = len(data) - 1 if wanted is None else wanted
        data = data[:size] if size <= len(data) else data + bytes(size - len(data))
        return [(raw[:16] + _UINT.pack(2 + len(data)) + raw[18:HEAD] + data, datagram[1])]


class InboundFilter(Class1Filter):
    """A filter of O->T datagrams (``inbound``)."""

    def start(self) -> None:
        self.seam.add(self)

    def inbound(self, raw: bytes, source: tuple[str, int], now: float, connection: IoConnection | None,
                seam: IoSeam) -> bytes | None:
        raise NotImplementedError


class IgnoreOutput(InboundFilter):
    """O->T data of a matching connection is consumed (its sequence count, its watchdog, run/idle) and
    not handed to the device, which keeps its last command."""

    def inbound(self, raw: bytes, source: tuple[str, int], now: float, connection: IoConnection | None,
                seam: IoSeam) -> bytes | None:
        if not self.matches(connection):
            return raw
        seam.withhold(raw, source, now)
        return None


class Idle(InboundFilter):
    """O->T data of a matching connection reaches the device with its run/idle header's run bit clear."""

    def inbound(self, raw: bytes, source: tuple[str, int], now: float, connection: IoConnection | None,
                seam: IoSeam) -> bytes | None:
        if connection is None or not self.matches(connection) or connection.ot_payload_size < 4 or len(raw) <= HEAD:
            return raw
        return raw[:HEAD] + bytes((raw[HEAD] & 0xFE,)) + raw[HEAD + 1:]


__all__ = [
    "Class1Filter",
    "Delay",
    "Drop",
    "Duplicate",
    "FreezeSequence",
    "Idle",
    "IgnoreOutput",
    "Reorder",
    "StopProducing",
    "WrongSize",
]
