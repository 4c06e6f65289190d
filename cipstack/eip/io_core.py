"""Class 1 (implicit I/O) building blocks, sans-I/O: the datagram, sequence arithmetic,
the production schedule and the consumer's watchdog.

A class 1 datagram on UDP 2222 is a CPF of two items: Sequenced Address (0x8002: connection
id UDINT, encapsulation sequence number UDINT) and Connected Data (0x00B1: CIP sequence
count UINT, then on O->T the 32-bit run/idle header, then the application data).

Sequence numbers compare with serial-number arithmetic (RFC 1982), so wrap-around is a
non-event: 0x0000 is newer than 0xFFFF.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from enum import Enum
from typing import NamedTuple

from ..errors import BadRequest, ProtocolError
from .wire.cpf import ItemType
from .wire.encapsulation import DEFAULT_IO_PORT

#: CPF count 2, Sequenced Address item (type, length 8, connection id, sequence), Connected Data header.
_IO_HEAD = struct.Struct("<HHHIIHHH")
IO_HEAD_SIZE = _IO_HEAD.size  # 22 bytes before the run/idle header or data
_RUN_IDLE = struct.Struct("<I")
#: The item type codes as plain ints: compared and packed for every datagram, where an enum
#: member's lookup costs more than the comparison.
_SEQUENCED_ADDRESS = int(ItemType.SEQUENCED_ADDRESS)
_CONNECTED_DATA = int(ItemType.CONNECTED_DATA)


def seq16_newer(new: int, old: int) -> bool:
    """True when 16-bit sequence ``new`` follows ``old`` (serial-number arithmetic)."""
    return 0 < ((new - old) & 0xFFFF) < 0x8000


def seq32_newer(new: int, old: int) -> bool:
    return 0 < ((new - old) & 0xFFFFFFFF) < 0x80000000


def encode_io_datagram(connection_id: int, encap_sequence: int, cip_sequence: int, data: bytes,
                       run_idle: int | None = None) -> bytes:
    if run_idle is None:
        return _IO_HEAD.pack(2, _SEQUENCED_ADDRESS, 8, connection_id, encap_sequence & 0xFFFFFFFF,
                             _CONNECTED_DATA, 2 + len(data), cip_sequence & 0xFFFF) + data
    return _IO_HEAD.pack(2, _SEQUENCED_ADDRESS, 8, connection_id, encap_sequence & 0xFFFFFFFF,
                         _CONNECTED_DATA, 6 + len(data), cip_sequence & 0xFFFF) + _RUN_IDLE.pack(run_idle) + data


class IoDatagram(NamedTuple):
    """One decoded class 1 datagram (a tuple: made for every datagram received)."""

    connection_id: int
    encap_sequence: int
    cip_sequence: int
    #: Everything after the CIP sequence count: run/idle header (O->T) and data.
    payload: bytes


class IoDatagramError(ProtocolError, ValueError):
    def __init__(self, message: str, offset: int | None = None) -> None:
        super().__init__(message)
        #: Where in the datagram the problem is (capture analysis reports it).
        self.offset = offset


def decode_io_datagram(raw: bytes) -> IoDatagram:
    """Decode a class 1 datagram; anything else raises ``IoDatagramError`` (the caller drops it)."""
    if len(raw) < IO_HEAD_SIZE:
        raise IoDatagramError("shorter than a class 1 datagram", len(raw))
    count, addr_type, addr_len, connection_id, sequence, data_type, data_len, cip_sequence = _IO_HEAD.unpack_from(raw)
    if count != 2 or addr_type != _SEQUENCED_ADDRESS or addr_len != 8:
        raise IoDatagramError("not a Sequenced Address item", 0 if count != 2 else 2)
    if data_type != _CONNECTED_DATA or data_len < 2 or IO_HEAD_SIZE - 2 + data_len != len(raw):
        raise IoDatagramError("Connected Data item length does not match the datagram", 14)
    return IoDatagram(connection_id, sequence, cip_sequence, raw[IO_HEAD_SIZE:])


def split_run_idle(payload: bytes) -> tuple[bool, bytes]:
    """(run, data) of an O->T payload that carries the 32-bit run/idle header (bit 0: 1 run, 0 idle)."""
    if len(payload) < 4:
        raise IoDatagramError("run/idle header missing")
    return bool(payload[0] & 1), payload[4:]


@dataclass
class IoStatistics:
    sent: int = 0
    received: int = 0
    #: Productions that went out later than the tolerance after their slot.
    late: int = 0
    #: Packets the consumer never saw (gaps in the encapsulation sequence), and skipped send slots.
    lost: int = 0
    duplicates: int = 0
    #: Packets older than the newest seen (out of order), dropped.
    stale: int = 0
    skipped_slots: int = 0
    max_lateness: float = 0.0

    def add(self, other: IoStatistics) -> None:
        """Add ``other``'s counts to these (the largest lateness is the larger one)."""
        self.sent += other.sent
        self.received += other.received
        self.late += other.late
        self.lost += other.lost
        self.duplicates += other.duplicates
        self.stale += other.stale
        self.skipped_slots += other.skipped_slots
        self.max_lateness = max(self.max_lateness, other.max_lateness)

    def as_dict(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in ("sent", "received", "late", "lost", "duplicates", "stale",
                                              "skipped_slots", "max_lateness")}


@dataclass
class ProductionSchedule:
    """Cyclic production at a fixed period.

    ``due(now)`` says whether a packet is due and how late it is; a slot missed entirely is
    skipped (counted), never made up with a burst.
    """

    period: float
    next_due: float
    #: Lateness beyond which a production counts as late (default: half the period, at most 0.5 ms).
    tolerance: float = -1.0
    stats: IoStatistics = field(default_factory=IoStatistics)

    def __post_init__(self) -> None:
        if self.period <= 0:
            raise BadRequest("production period must be positive")
        if self.tolerance < 0:
            self.tolerance = min(self.period / 2, 0.0005)

    def due(self, now: float) -> tuple[bool, float]:
        if now < self.next_due:
            return False, 0.0
        lateness = now - self.next_due
        self.next_due += self.period
        if now >= self.next_due:
            missed = int((now - self.next_due) // self.period) + 1
            self.next_due += missed * self.period
            self.stats.skipped_slots += missed
        if lateness > self.tolerance:
            self.stats.late += 1
        if lateness > self.stats.max_lateness:
            self.stats.max_lateness = lateness
        return True, lateness


class ProductionGrid:
    """Where a new connection's production starts: on the slots the core's first connection set, a
    whole number of periods after its first production. Connections of one RPI then fall due
    together and one wake-up sends them all, back to back, as a device producing on its own timer
    tick does; RPIs that are multiples of one another share slots too. Without it, connections
    opened one after another were due at as many phases as there were Forward_Opens, and each phase
    cost a wake-up: at 10 ms, most of what a packet cost. The first packet waits at most one period;
    one moment is kept, whatever the RPIs a peer asks for."""

    def __init__(self) -> None:
        self._anchor: float | None = None

    def first_due(self, period: float, now: float) -> float:
        anchor = self._anchor
        if anchor is None:
            self._anchor = anchor = now
        if anchor >= now:
            return anchor
        return anchor + math.ceil((now - anchor) / period) * period


class Reception(Enum):
    NEW = "new"
    DUPLICATE = "duplicate"
    STALE = "stale"


#: The members under plain module names for the per-packet path: naming an enum member
#: (``Reception.NEW``) is an attribute lookup on the class each time, about 0.1 µs.
RECEIVED_NEW, RECEIVED_DUPLICATE, RECEIVED_STALE = Reception.NEW, Reception.DUPLICATE, Reception.STALE


@dataclass
class ConsumerState:
    """The receiving end of a connection: sequence filtering and the watchdog.

    The watchdog runs out ``timeout`` seconds after the last accepted packet, or
    ``first_timeout`` (at least 10 s) after opening while nothing has arrived yet.
    """

    timeout: float
    deadline: float
    last_encap_sequence: int | None = None
    last_cip_sequence: int | None = None
    stats: IoStatistics = field(default_factory=IoStatistics)

    @classmethod
    def opened(cls, timeout: float, now: float, first_timeout: float = 10.0,
               stats: IoStatistics | None = None) -> ConsumerState:
        return cls(timeout, now + max(timeout, first_timeout), stats=stats or IoStatistics())

    def accept(self, encap_sequence: int, cip_sequence: int, now: float) -> Reception:
        last = self.last_encap_sequence
        if last is not None:
            if not seq32_newer(encap_sequence, last):
                self.stats.stale += 1
                return RECEIVED_STALE
            self.stats.lost += ((encap_sequence - last) & 0xFFFFFFFF) - 1
        self.last_encap_sequence = encap_sequence
        self.deadline = now + self.timeout
        self.stats.received += 1
        if self.last_cip_sequence is not None and cip_sequence == self.last_cip_sequence:
            self.stats.duplicates += 1
            return RECEIVED_DUPLICATE
        self.last_cip_sequence = cip_sequence
        return RECEIVED_NEW

    def expired(self, now: float) -> bool:
        return now >= self.deadline


#: A production may leave up to this share of its RPI early, to go with others in one firing (both
#: roles: the target's ``IoTarget.poll`` and the originator's ``IoOriginator.poll``).
EARLY_SHARE = 1 / 16

#: The 2-byte CIP sequence count that opens every class 1 packet, and the 32-bit run/idle header.
SEQUENCE_COUNT_SIZE = 2
RUN_IDLE_HEADER_SIZE = 4
#: Sequence count + 32-bit run/idle header in front of O->T data.
OT_OVERHEAD = SEQUENCE_COUNT_SIZE + RUN_IDLE_HEADER_SIZE
#: Sequence count in front of T->O data (modeless).
TO_OVERHEAD = SEQUENCE_COUNT_SIZE


def connection_timeout(rpi_us: int, multiplier: int) -> float:
    """The connection timeout, the one rule both roles apply: RPI x 4 x 2^multiplier (multiplier field
    0..7, a larger value counts as 7), in seconds, the unit of the cores' clock (``now``)."""
    return rpi_us * (4 << min(multiplier, 7)) / 1e6


def rpi_us_of(seconds: float) -> int:
    """An RPI given in seconds (the public API's ``rpi=0.010``) in microseconds, the one unit RPIs have
    inside: rounded, not truncated (``int(0.0029 * 1e6)`` is 2899)."""
    return round(seconds * 1e6)


__all__ = [
    "DEFAULT_IO_PORT",
    "EARLY_SHARE",
    "IO_HEAD_SIZE",
    "OT_OVERHEAD",
    "RUN_IDLE_HEADER_SIZE",
    "SEQUENCE_COUNT_SIZE",
    "TO_OVERHEAD",
    "ConsumerState",
    "IoDatagram",
    "IoDatagramError",
    "IoStatistics",
    "ProductionGrid",
    "ProductionSchedule",
    "Reception",
    "connection_timeout",
    "decode_io_datagram",
    "encode_io_datagram",
    "rpi_us_of",
    "seq16_newer",
    "seq32_newer",
    "split_run_idle"
]
