"""Connection Manager service codecs: Forward_Open, Large_Forward_Open, Forward_Close,
Unconnected_Send, and the network connection parameters they carry.

Field layouts as in CIP Vol. 2, chapter 2, as Wireshark's ENIP dissector and OpENer read it; all little-endian.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from enum import IntEnum

from ...cip.epath import request_path
from ...cip.status import CipError, GeneralStatus
from ...errors import BadRequest
from ..io_core import connection_timeout

#: Where an originator sends Forward_Open and Forward_Close: the Connection Manager, instance 1.
CONNECTION_MANAGER_PATH = request_path(0x06, 1)

_FO_HEAD = struct.Struct("<BBIIHHIB3x")
_FO_SMALL_TAIL = struct.Struct("<IHIHBB")
_FO_LARGE_TAIL = struct.Struct("<IIIIBB")
_FO_REPLY = struct.Struct("<IIHHIIIBB")
_FO_FAIL = struct.Struct("<HHIBB")
_FC_REQUEST = struct.Struct("<BBHHIBB")
_FC_REPLY = struct.Struct("<HHIBB")
_US_HEAD = struct.Struct("<BBH")


class ConnectionType(IntEnum):
    NULL = 0
    MULTICAST = 1
    POINT_TO_POINT = 2
    RESERVED = 3


class Priority(IntEnum):
    LOW = 0
    HIGH = 1
    SCHEDULED = 2
    URGENT = 3


class TriggerType(IntEnum):
    CYCLIC = 0
    CHANGE_OF_STATE = 1
    APPLICATION = 2


@dataclass(frozen=True)
class NetworkParameters:
    """Network connection parameters (16-bit form in Forward_Open, 32-bit in Large_Forward_Open)."""

    size: int
    type: ConnectionType = ConnectionType.POINT_TO_POINT
    priority: Priority = Priority.LOW
    variable: bool = False
    redundant_owner: bool = False

    @classmethod
    def decode(cls, raw: int, large: bool) -> NetworkParameters:
        if large:
            flags, size = raw >> 16, raw & 0xFFFF
        else:
            flags, size = raw >> 9 << 9, raw & 0x1FF
        # In both forms: bit 15 redundant owner, 14-13 type, 11-10 priority, 9 variable size.
        return cls(size, ConnectionType((flags >> 13) & 3), Priority((flags >> 10) & 3),
                   bool(flags & 0x0200), bool(flags & 0x8000))

    def encode(self, large: bool) -> int:
        flags = (self.redundant_owner << 15) | (self.type << 13) | (self.priority << 10) | (self.variable << 9)
        if large:
            return (flags << 16) | (self.size & 0xFFFF)
        if self.size > 0x1FF:
            raise BadRequest(f"connection size {self.size} needs a Large_Forward_Open")
        return flags | self.size


@dataclass(frozen=True)
class TransportTrigger:
    transport_class: int
    trigger: TriggerType = TriggerType.CYCLIC
    server: bool = False

    @classmethod
    def decode(cls, raw: int) -> TransportTrigger:
        trigger = (raw >> 4) & 7
        if trigger > 2:
            raise CipError(GeneralStatus.CONNECTION_FAILURE, (0x0103,), message=f"trigger {trigger} not supported")
        return cls(raw & 0x0F, TriggerType(trigger), bool(raw & 0x80))

    def encode(self) -> int:
        return (0x80 if self.server else 0) | (self.trigger << 4) | self.transport_class


def _need(data: bytes, size: int, what: str) -> None:
    if len(data) < size:
        raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message=f"{what} cut short")


@dataclass(frozen=True)
class ConnectionTriad:
    """Connection serial, originator vendor and originator serial: what names a connection."""

    connection_serial: int
    vendor_id: int
    originator_serial: int


@dataclass(frozen=True)
class ForwardOpenRequest:
    priority_tick: int
    timeout_ticks: int
    ot_connection_id: int
    to_connection_id: int
    triad: ConnectionTriad
    timeout_multiplier: int
    ot_rpi_us: int
    ot_parameters: NetworkParameters
    to_rpi_us: int
    to_parameters: NetworkParameters
    transport: TransportTrigger
    connection_path: bytes
    large: bool = False

    @classmethod
    def decode(cls, data: bytes, large: bool) -> ForwardOpenRequest:
        tail = _FO_LARGE_TAIL if large else _FO_SMALL_TAIL
        fixed = _FO_HEAD.size + tail.size
        _need(data, fixed, "Forward_Open")
        tick, ticks, ot_id, to_id, serial, vendor, orig_serial, multiplier = _FO_HEAD.unpack_from(data)
        ot_rpi, ot_par, to_rpi, to_par, transport, path_words = tail.unpack_from(data, _FO_HEAD.size)
        end = fixed + 2 * path_words
        _need(data, end, "Forward_Open connection path")
        if len(data) > end:
            raise CipError(GeneralStatus.TOO_MUCH_DATA, message="bytes after the connection path")
        return cls(tick, ticks, ot_id, to_id, ConnectionTriad(serial, vendor, orig_serial), multiplier,
                   ot_rpi, NetworkParameters.decode(ot_par, large), to_rpi, NetworkParameters.decode(to_par, large),
                   TransportTrigger.decode(transport), bytes(data[fixed:end]), large)

    def encode(self) -> bytes:
        if len(self.connection_path) % 2:
            raise BadRequest("connection path must be whole words")
        for direction, rpi_us in (("O->T", self.ot_rpi_us), ("T->O", self.to_rpi_us)):
            if not 0 <= rpi_us <= 0xFFFFFFFF:   # a UDINT of microseconds: struct's own error names neither
                raise BadRequest(f"{direction} RPI {rpi_us} us is outside 0..4294967295 us")
        if not 0 <= self.timeout_multiplier <= 0xFF:
            raise BadRequest(f"connection timeout multiplier {self.timeout_multiplier} is outside 0..255")
        tail = _FO_LARGE_TAIL if self.large else _FO_SMALL_TAIL
        return _FO_HEAD.pack(self.priority_tick, self.timeout_ticks, self.ot_connection_id, self.to_connection_id,
                             self.triad.connection_serial, self.triad.vendor_id, self.triad.originator_serial,
                             self.timeout_multiplier) + tail.pack(
            self.ot_rpi_us, self.ot_parameters.encode(self.large), self.to_rpi_us,
            self.to_parameters.encode(self.large), self.transport.encode(), len(self.connection_path) // 2,
        ) + self.connection_path

    @property
    def timeout_s(self) -> float:
        """Connection timeout of the O->T direction (``io_core.connection_timeout``, the one rule)."""
        return connection_timeout(self.ot_rpi_us, self.timeout_multiplier)


@dataclass(frozen=True)
class ForwardOpenReply:
    ot_connection_id: int
    to_connection_id: int
    triad: ConnectionTriad
    ot_api_us: int
    to_api_us: int
    application_reply: bytes = b""

    def encode(self) -> bytes:
        return _FO_REPLY.pack(self.ot_connection_id, self.to_connection_id, self.triad.connection_serial,
                              self.triad.vendor_id, self.triad.originator_serial, self.ot_api_us, self.to_api_us,
                              len(self.application_reply) // 2, 0) + self.application_reply

    @classmethod
    def decode(cls, data: bytes) -> ForwardOpenReply:
        if len(data) < _FO_REPLY.size:
            raise BadRequest("Forward_Open reply cut short")
        ot_id, to_id, serial, vendor, orig, ot_api, to_api, words, _ = _FO_REPLY.unpack_from(data)
        return cls(ot_id, to_id, ConnectionTriad(serial, vendor, orig), ot_api, to_api,
                   bytes(data[_FO_REPLY.size:_FO_REPLY.size + 2 * words]))


def forward_open_failure_data(triad: ConnectionTriad, remaining_path_words: int = 0) -> bytes:
    """Data of an unsuccessful Forward_Open/Forward_Close reply: the triad and remaining path size."""
    return _FO_FAIL.pack(triad.connection_serial, triad.vendor_id, triad.originator_serial, remaining_path_words, 0)


@dataclass(frozen=True)
class ForwardCloseRequest:
    priority_tick: int
    timeout_ticks: int
    triad: ConnectionTriad
    connection_path: bytes = b""

    @classmethod
    def decode(cls, data: bytes) -> ForwardCloseRequest:
        _need(data, _FC_REQUEST.size, "Forward_Close")
        tick, ticks, serial, vendor, orig, words, _ = _FC_REQUEST.unpack_from(data)
        end = _FC_REQUEST.size + 2 * words
        _need(data, end, "Forward_Close connection path")
        if len(data) > end:
            raise CipError(GeneralStatus.TOO_MUCH_DATA, message="bytes after the connection path")
        return cls(tick, ticks, ConnectionTriad(serial, vendor, orig), bytes(data[_FC_REQUEST.size:end]))

    def encode(self) -> bytes:
        return _FC_REQUEST.pack(self.priority_tick, self.timeout_ticks, self.triad.connection_serial,
                                self.triad.vendor_id, self.triad.originator_serial,
                                len(self.connection_path) // 2, 0) + self.connection_path


@dataclass(frozen=True)
class ForwardCloseReply:
    triad: ConnectionTriad
    application_reply: bytes = b""

    def encode(self) -> bytes:
        return _FC_REPLY.pack(self.triad.connection_serial, self.triad.vendor_id, self.triad.originator_serial,
                              len(self.application_reply) // 2, 0) + self.application_reply

    @classmethod
    def decode(cls, data: bytes) -> ForwardCloseReply:
        if len(data) < _FC_REPLY.size:
            raise BadRequest("Forward_Close reply cut short")
        serial, vendor, orig, words, _ = _FC_REPLY.unpack_from(data)
        return cls(ConnectionTriad(serial, vendor, orig), bytes(data[_FC_REPLY.size:_FC_REPLY.size + 2 * words]))


@dataclass(frozen=True)
class UnconnectedSendRequest:
    priority_tick: int
    timeout_ticks: int
    message: bytes
    route_path: bytes = field(default=b"")

    @classmethod
    def decode(cls, data: bytes) -> UnconnectedSendRequest:
        _need(data, _US_HEAD.size, "Unconnected_Send")
        tick, ticks, size = _US_HEAD.unpack_from(data)
        start = _US_HEAD.size
        end = start + size
        _need(data, end, "Unconnected_Send embedded message")
        pos = end + (size & 1)  # pad byte after an odd-length message
        _need(data, pos + 2, "Unconnected_Send route path size")
        words = data[pos]
        route_end = pos + 2 + 2 * words
        _need(data, route_end, "Unconnected_Send route path")
        if len(data) > route_end:
            raise CipError(GeneralStatus.TOO_MUCH_DATA, message="bytes after the route path")
        return cls(tick, ticks, bytes(data[start:end]), bytes(data[pos + 2:route_end]))

    def encode(self) -> bytes:
        pad = b"\x00" if len(self.message) % 2 else b""
        return (_US_HEAD.pack(self.priority_tick, self.timeout_ticks, len(self.message)) + self.message + pad
                + bytes((len(self.route_path) // 2, 0)) + self.route_path)
