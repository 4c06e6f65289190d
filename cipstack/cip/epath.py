"""EPATH: the segment paths that address objects, route messages and describe connections.

Supported segments (CIP Vol. 1 appendix C, as Wireshark's packet-cip.c decodes them):

* logical: class, instance, member, connection point, attribute, in 8-, 16- and 32-bit
  formats (``0x20 | type << 2 | format``); the electronic key ``34 04 ...``;
* port: ``0x0p`` with a one-byte link address, bit 4 set for a longer link address whose
  length follows, port 15 for an extended port number;
* simple data: ``80 ww`` then ``ww`` words.

Both the padded form (a pad byte after the segment type of a 16/32-bit logical segment,
port segments padded to an even length), used in message-router requests and connection
paths, and the packed form are encoded and decoded.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from enum import IntEnum
from typing import NamedTuple

from ..errors import BadRequest, WrongType
from .status import CipError, GeneralStatus


class LogicalType(IntEnum):
    CLASS_ID = 0
    INSTANCE_ID = 1
    MEMBER_ID = 2
    CONNECTION_POINT = 3
    ATTRIBUTE_ID = 4


class LogicalSegment(NamedTuple):
    """A logical segment: a class, instance, member, connection point or attribute number."""

    kind: LogicalType
    value: int
    #: 8, 16 or 32; None picks the smallest that holds the value.
    bits: int | None = None

    def width(self) -> int:
        if self.bits is not None:
            return self.bits
        if self.value <= 0xFF:
            return 8
        if self.value <= 0xFFFF:
            return 16
        return 32


class PortSegment(NamedTuple):
    """A port segment: leave by ``port`` for the node at ``link`` (a slot, a node address, an IP
    address as text)."""

    port: int
    link: bytes

    @classmethod
    def to(cls, port: int, link: int | bytes | str) -> PortSegment:
        if isinstance(link, int):
            return cls(port, bytes([link]))
        if isinstance(link, str):
            return cls(port, link.encode("ascii"))
        return cls(port, bytes(link))


class ElectronicKey(NamedTuple):
    """The electronic key of a connection path: the identity the target must have (zeros match any)."""

    vendor_id: int = 0
    device_type: int = 0
    product_code: int = 0
    major_revision: int = 0
    minor_revision: int = 0
    #: Bit 7 of the major revision byte: accept any compatible revision.
    compatibility: bool = False

    @property
    def is_null(self) -> bool:
        return not (self.vendor_id or self.device_type or self.product_code
                    or self.major_revision or self.minor_revision)


class DataSegment(NamedTuple):
    """Simple data segment: configuration data carried in a connection path."""

    data: bytes


Segment = LogicalSegment | PortSegment | ElectronicKey | DataSegment

_FORMAT_CODE = {8: 0, 16: 1, 32: 2}
_FORMAT_BITS = {0: 8, 1: 16, 2: 32}
_KEY = struct.Struct("<HHHBB")


def _path_error(message: str) -> CipError:
    return CipError(GeneralStatus.PATH_SEGMENT_ERROR, message=message)


def encode_segment(segment: Segment, padded: bool = True) -> bytes:
    if isinstance(segment, LogicalSegment):
        bits = segment.width()
        if bits not in _FORMAT_CODE or segment.value < 0 or segment.value >= 1 << bits:
            raise BadRequest(f"{segment.kind.name} {segment.value} does not fit {bits} bits")
        head = bytes([0x20 | (segment.kind << 2) | _FORMAT_CODE[bits]])
        body = segment.value.to_bytes(bits // 8, "little")
        pad = b"\x00" if padded and bits > 8 else b""
        return head + pad + body
    if isinstance(segment, PortSegment):
        if not 0 < segment.port <= 0xFFFF or not segment.link:
            raise BadRequest("a port segment needs a port 1..65535 and a link address")
        extended_port = segment.port > 14
        long_link = len(segment.link) > 1
        port_head = (0x0F if extended_port else segment.port) | (0x10 if long_link else 0)
        out = bytearray([port_head])
        if long_link:
            if len(segment.link) > 0xFF:
                raise BadRequest("link address longer than 255 bytes")
            out.append(len(segment.link))
        if extended_port:
            out += segment.port.to_bytes(2, "little")
        out += segment.link
        if padded and len(out) % 2:
            out.append(0)
        return bytes(out)
    if isinstance(segment, ElectronicKey):
        major = (segment.major_revision & 0x7F) | (0x80 if segment.compatibility else 0)
        return b"\x34\x04" + _KEY.pack(segment.vendor_id, segment.device_type,
                                       segment.product_code, major, segment.minor_revision)
    if isinstance(segment, DataSegment):
        if len(segment.data) % 2 or len(segment.data) > 510:
            raise BadRequest("simple data segment must be whole words, at most 255")
        return bytes([0x80, len(segment.data) // 2]) + segment.data
    raise WrongType(f"not a segment: {segment!r}")


def encode_path(segments: Iterable[Segment], padded: bool = True) -> bytes:
    return b"".join(encode_segment(s, padded) for s in segments)


def decode_segment(data: bytes, offset: int = 0, padded: bool = True) -> tuple[Segment, int]:
    """Decode one segment at ``offset``; raises ``CipError(0x04)`` on anything malformed."""
    if offset >= len(data):
        raise _path_error("path ends inside a segment")
    head = data[offset]
    kind = head >> 5
    if kind == 1:  # logical
        logical_type = (head >> 2) & 0x07
        fmt = head & 0x03
        if logical_type == 5:  # special: electronic key
            if head != 0x34 or offset + 2 > len(data) or data[offset + 1] != 4:
                raise _path_error("unsupported logical special segment")
            end = offset + 2 + _KEY.size
            if end > len(data):
                raise _path_error("electronic key is cut short")
            vendor, device, product, major, minor = _KEY.unpack_from(data, offset + 2)
            key = ElectronicKey(vendor, device, product, major & 0x7F, minor, bool(major & 0x80))
            return key, end
        if logical_type > 4 or fmt == 3:
            raise _path_error(f"unsupported logical segment 0x{head:02X}")
        bits = _FORMAT_BITS[fmt]
        start = offset + 1 + (1 if padded and bits > 8 else 0)
        end = start + bits // 8
        if end > len(data):
            raise _path_error("logical segment is cut short")
        if padded and bits > 8 and data[offset + 1] != 0:
            raise _path_error("pad byte of a logical segment is not zero")
        value = int.from_bytes(data[start:end], "little")
        return LogicalSegment(LogicalType(logical_type), value, bits), end
    if kind == 0:  # port
        port = head & 0x0F
        pos = offset + 1
        if head & 0x10:
            if pos >= len(data):
                raise _path_error("port segment is cut short")
            link_size = data[pos]
            pos += 1
        else:
            link_size = 1
        if port == 0x0F:
            if pos + 2 > len(data):
                raise _path_error("extended port number is cut short")
            port = int.from_bytes(data[pos:pos + 2], "little")
            pos += 2
        if port == 0 or link_size == 0:
            raise _path_error("port segment with port or link address 0 bytes")
        end = pos + link_size
        if end > len(data):
            raise _path_error("port segment link address is cut short")
        segment = PortSegment(port, bytes(data[pos:end]))
        if padded and (end - offset) % 2:
            end += 1
            if end > len(data):
                raise _path_error("port segment pad byte missing")
        return segment, end
    if head == 0x80:  # simple data segment
        if offset + 2 > len(data):
            raise _path_error("data segment is cut short")
        end = offset + 2 + 2 * data[offset + 1]
        if end > len(data):
            raise _path_error("data segment is cut short")
        return DataSegment(bytes(data[offset + 2:end])), end
    raise _path_error(f"unsupported segment type 0x{head:02X}")


def decode_path(data: bytes, padded: bool = True) -> list[Segment]:
    segments: list[Segment] = []
    offset = 0
    while offset < len(data):
        segment, offset = decode_segment(data, offset, padded)
        segments.append(segment)
    return segments


def logical_path(class_id: int, instance: int | None = None, attribute: int | None = None,
                 member: int | None = None) -> list[LogicalSegment]:
    path = [LogicalSegment(LogicalType.CLASS_ID, class_id)]
    if instance is not None:
        path.append(LogicalSegment(LogicalType.INSTANCE_ID, instance))
    if attribute is not None:
        path.append(LogicalSegment(LogicalType.ATTRIBUTE_ID, attribute))
    if member is not None:
        path.append(LogicalSegment(LogicalType.MEMBER_ID, member))
    return path


def request_path(class_id: int, instance: int | None = None, attribute: int | None = None,
                 member: int | None = None) -> bytes:
    """Padded EPATH for class/instance[/attribute[/member]], e.g. ``20 01 24 01 30 07``."""
    if member is None and 0 <= class_id <= 0xFF and instance is not None and 0 <= instance <= 0xFF and (
            attribute is None or 0 <= attribute <= 0xFF):
        # Every explicit request builds one of these: the 8-bit forms without segment objects.
        if attribute is None:
            return bytes((0x20, class_id, 0x24, instance))
        return bytes((0x20, class_id, 0x24, instance, 0x30, attribute))
    return encode_path(logical_path(class_id, instance, attribute, member))


class ApplicationPath(NamedTuple):
    """What a message-router request addresses: class, instance, attribute, member."""

    class_id: int
    instance: int | None = None
    attribute: int | None = None
    member: int | None = None


def parse_application_path(data: bytes) -> ApplicationPath:
    """Resolve a padded request path to class/instance/attribute/member.

    The common 8-bit form is handled without building segment objects because every
    explicit request passes through here. Anything else that is not class, instance,
    attribute, member in that order answers 0x04 (path segment error).
    """
    n = len(data)
    if n == 6 and data[0] == 0x20 and data[2] == 0x24 and data[4] == 0x30:
        return ApplicationPath(data[1], data[3], data[5])
    if n == 4 and data[0] == 0x20 and data[2] == 0x24:
        return ApplicationPath(data[1], data[3])
    values: dict[LogicalType, int] = {}
    order: list[LogicalType] = []
    for segment in decode_path(data):
        if not isinstance(segment, LogicalSegment) or segment.kind == LogicalType.CONNECTION_POINT:
            raise _path_error("request path must be class/instance/attribute logical segments")
        if segment.kind in values:
            raise _path_error(f"{segment.kind.name} given twice")
        values[segment.kind] = segment.value
        order.append(segment.kind)
    expected = [LogicalType.CLASS_ID, LogicalType.INSTANCE_ID, LogicalType.ATTRIBUTE_ID,
                LogicalType.MEMBER_ID]
    # A member may follow the instance directly (no attribute); anything else is out of order.
    member_of_instance = [LogicalType.CLASS_ID, LogicalType.INSTANCE_ID, LogicalType.MEMBER_ID]
    if order != expected[: len(order)] and order != member_of_instance:
        raise _path_error("request path segments out of order")
    if not order:
        raise _path_error("empty request path")
    return ApplicationPath(
        values[LogicalType.CLASS_ID],
        values.get(LogicalType.INSTANCE_ID),
        values.get(LogicalType.ATTRIBUTE_ID),
        values.get(LogicalType.MEMBER_ID),
    )
