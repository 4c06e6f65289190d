"""The Common Packet Format: an item count, then typed items (type UINT, length UINT, data)."""

from __future__ import annotations

import socket
import struct
from enum import IntEnum
from typing import NamedTuple

from ...logs import debug
from .encapsulation import EncapsulationError, EncapsulationStatus


class ItemType(IntEnum):
    NULL_ADDRESS = 0x0000
    LIST_IDENTITY = 0x000C
    CONNECTED_ADDRESS = 0x00A1
    CONNECTED_DATA = 0x00B1
    UNCONNECTED_DATA = 0x00B2
    LIST_SERVICES = 0x0100
    SOCKADDR_O_T = 0x8000
    SOCKADDR_T_O = 0x8001
    SEQUENCED_ADDRESS = 0x8002


_ITEM = struct.Struct("<HH")
_COUNT = struct.Struct("<H")
#: Upper bound on items in one packet; real packets carry 1-4.
MAX_ITEMS = 16


class Item(NamedTuple):
    """One item of a Common Packet Format list: its type id and its data."""

    type: int
    data: bytes = b""


def encode_items(items: list[Item] | tuple[Item, ...]) -> bytes:
    out = [_COUNT.pack(len(items))]
    for item in items:
        out.append(_ITEM.pack(item.type, len(item.data)))
        out.append(item.data)
    return b"".join(out)


def decode_items(raw: bytes, offset: int = 0, *, strict: bool = True) -> list[Item]:
    """Decode a CPF; any inconsistency is encapsulation status 0x0003 (poorly formed).

    ``strict=False`` is the originator's reading of a reply: the items the count declares are
    decoded and bytes after the last of them (some targets append an item they did not count)
    are noted at DEBUG, not refused. A target decodes requests strictly."""
    if offset + 2 > len(raw):
        raise EncapsulationError(EncapsulationStatus.INCORRECT_DATA, "CPF item count missing", offset)
    (count,) = _COUNT.unpack_from(raw, offset)
    if count > MAX_ITEMS:
        raise EncapsulationError(EncapsulationStatus.INCORRECT_DATA, f"{count} CPF items", offset)
    pos = offset + 2
    items = []
    for _ in range(count):
        if pos + 4 > len(raw):
            raise EncapsulationError(EncapsulationStatus.INCORRECT_DATA, "CPF item header cut short", pos)
        item_type, length = _ITEM.unpack_from(raw, pos)
        pos += 4
        if pos + length > len(raw):
            raise EncapsulationError(EncapsulationStatus.INCORRECT_DATA, "CPF item runs past the packet", pos - 2)
        items.append(Item(item_type, bytes(raw[pos:pos + length])))
        pos += length
    if pos != len(raw):
        if not strict:
            debug(__name__, "CPF: %d bytes after the %d declared item(s) ignored: %s", len(raw) - pos, count,
                  bytes(raw[pos:pos + 64]).hex())
            return items
        raise EncapsulationError(EncapsulationStatus.INCORRECT_DATA, "bytes after the last CPF item", pos)
    return items


# Sockaddr info (items 0x8000/0x8001, and inside ListIdentity): big-endian, network order.
SOCKADDR = struct.Struct(">hHI8s")


class SockAddr(NamedTuple):
    """The Sockaddr Info of a CPF item or a ListIdentity reply: an IPv4 address and port."""

    host: str
    port: int

    def encode(self) -> bytes:
        address = struct.unpack(">I", socket.inet_aton(self.host))[0]
        return SOCKADDR.pack(socket.AF_INET, self.port, address, b"\x00" * 8)

    @classmethod
    def decode(cls, raw: bytes, offset: int = 0) -> SockAddr:
        if offset + SOCKADDR.size > len(raw):
            raise EncapsulationError(EncapsulationStatus.INCORRECT_DATA, "sockaddr cut short")
        _family, port, address, _zero = SOCKADDR.unpack_from(raw, offset)
        return cls(socket.inet_ntoa(struct.pack(">I", address)), port)
