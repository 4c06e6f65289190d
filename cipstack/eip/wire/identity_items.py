"""ListIdentity (item 0x000C) and ListServices (item 0x0100) replies."""

from __future__ import annotations

import struct
from typing import NamedTuple

from ...errors import BadRequest
from .cpf import Item, ItemType, SockAddr, decode_items, encode_items

_IDENTITY_FIXED = struct.Struct("<HHHBBHI")
_SERVICE = struct.Struct("<HH16s")

#: ListServices capability flags: bit 5 CIP encapsulation over TCP, bit 8 class 0/1 over UDP.
CAPABILITY_CIP_TCP = 0x0020
CAPABILITY_CLASS01_UDP = 0x0100


class IdentityRecord(NamedTuple):
    """What a ListIdentity reply says about a device (Identity attributes 1-8)."""

    vendor_id: int
    device_type: int
    product_code: int
    revision: tuple[int, int]
    status: int
    serial_number: int
    product_name: str
    state: int = 0xFF
    #: Where the reply says the device listens (from the sockaddr).
    address: SockAddr | None = None
    protocol_version: int = 1

    def as_dict(self) -> dict[str, object]:
        return {
            "vendor_id": self.vendor_id, "device_type": self.device_type, "product_code": self.product_code,
            # The shape `cipstack get HOST 1/1 --json` gives the Identity object's attributes.
            "revision": {"major": self.revision[0], "minor": self.revision[1]}, "status": self.status,
            "serial_number": self.serial_number, "product_name": self.product_name, "state": self.state,
            "address": f"{self.address.host}:{self.address.port}" if self.address else None,
        }


def encode_identity_item(record: IdentityRecord, local: SockAddr) -> bytes:
    name = record.product_name.encode("latin-1")[:255]
    return (struct.pack("<H", record.protocol_version) + local.encode()
            + _IDENTITY_FIXED.pack(record.vendor_id, record.device_type, record.product_code, record.revision[0],
                                   record.revision[1], record.status, record.serial_number)
            + bytes((len(name),)) + name + bytes((record.state & 0xFF,)))


def encode_list_identity(record: IdentityRecord, local: SockAddr) -> bytes:
    return encode_items([Item(ItemType.LIST_IDENTITY, encode_identity_item(record, local))])


def decode_identity_item(data: bytes) -> IdentityRecord:
    if len(data) < 2 + 16 + _IDENTITY_FIXED.size + 1:
        raise BadRequest("ListIdentity item cut short")
    (version,) = struct.unpack_from("<H", data)
    address = SockAddr.decode(data, 2)
    vendor, device, product, major, minor, status, serial = _IDENTITY_FIXED.unpack_from(data, 18)
    pos = 18 + _IDENTITY_FIXED.size
    name_len = data[pos]
    name = data[pos + 1:pos + 1 + name_len].decode("latin-1")
    state_pos = pos + 1 + name_len
    state = data[state_pos] if state_pos < len(data) else 0xFF
    return IdentityRecord(vendor, device, product, (major, minor), status, serial, name, state, address, version)


def decode_list_identity(body: bytes) -> list[IdentityRecord]:
    return [decode_identity_item(item.data) for item in decode_items(body, strict=False)
            if item.type == ItemType.LIST_IDENTITY]


class ServiceRecord(NamedTuple):
    """One service of a ListServices reply: protocol version, capability flags and name."""

    version: int
    capabilities: int
    name: str

    @property
    def cip_over_tcp(self) -> bool:
        return bool(self.capabilities & CAPABILITY_CIP_TCP)

    @property
    def class01_over_udp(self) -> bool:
        return bool(self.capabilities & CAPABILITY_CLASS01_UDP)


def encode_list_services(capabilities: int = CAPABILITY_CIP_TCP | CAPABILITY_CLASS01_UDP) -> bytes:
    return encode_items([Item(ItemType.LIST_SERVICES, _SERVICE.pack(1, capabilities, b"Communications"))])


def decode_list_services(body: bytes) -> list[ServiceRecord]:
    records = []
    for item in decode_items(body, strict=False):
        if item.type == ItemType.LIST_SERVICES and len(item.data) >= 4:
            version, flags = struct.unpack_from("<HH", item.data)
            name = item.data[4:20].split(b"\x00", 1)[0].decode("latin-1")
            records.append(ServiceRecord(version, flags, name))
    return records
