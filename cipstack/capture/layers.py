"""scapy layers for EtherNet/IP and CIP with cipstack's names, bound to TCP/UDP 44818 and UDP 2222.

    >>> from cipstack.capture import ENIP, CPF, CPFItem, CIP
    >>> request = CIP(service="GET_ATTRIBUTE_SINGLE", path=bytes.fromhex("200124013007"))
    >>> frame = ENIP(command_code="SEND_RR_DATA", session=0x11) / CPF(items=[CPFItem(type="NULL_ADDRESS"),
    ...     CPFItem(type="UNCONNECTED_DATA") / request])

The field layouts and the enumerations are the project's (``eip.encapsulation``, ``eip.cpf``,
``cip.messages``, ``eip.io_core``): the header struct, command and status codes, item types and
service codes come from those modules, and ``CIP.describe()`` / ``ENIP_IO.datagram()`` decode with
the project's codecs rather than a second implementation.
"""

from __future__ import annotations

from typing import Any

from scapy.fields import (
    ByteEnumField,
    ConditionalField,
    FieldLenField,
    FieldListField,
    LEIntEnumField,
    LEIntField,
    LEShortEnumField,
    LEShortField,
    PacketListField,
    StrFixedLenField,
    StrLenField,
    XByteField,
)
from scapy.layers.inet import TCP, UDP
from scapy.packet import Packet, bind_layers

from ..cip.messages import REPLY_BIT, Service
from ..eip.io_core import DEFAULT_IO_PORT, IoDatagram, decode_io_datagram
from ..eip.wire.cpf import ItemType
from ..eip.wire.encapsulation import Command, EncapsulationStatus
from .decoding import Declarations, decode_reply, decode_request

ENIP_PORT = 44818

_COMMANDS = {c.value: c.name for c in Command}
_STATUS = {s.value: s.name for s in EncapsulationStatus}
_ITEMS = {i.value: i.name for i in ItemType}
_SERVICES = {s.value: s.name for s in Service} | {s.value | REPLY_BIT: s.name + "_REPLY" for s in Service}


class ENIP(Packet):
    """The 24-byte encapsulation header (eip.encapsulation.HEADER); ``length`` is filled on build.
    The command field is ``command_code``: ``Packet.command()`` is scapy's own method."""

    name = "EtherNet/IP"
    fields_desc = [
        LEShortEnumField("command_code", 0, _COMMANDS),
        LEShortField("length", None),
        LEIntField("session", 0),
        LEIntEnumField("status", 0, _STATUS),
        StrFixedLenField("context", b"\x00" * 8, 8),
        LEIntField("options", 0),
    ]

    def post_build(self, packet: bytes, payload: bytes) -> bytes:
        if self.length is None:
            size = len(payload)
            packet = packet[:2] + size.to_bytes(2, "little") + packet[4:]
        return packet + payload

    def extract_padding(self, s: bytes) -> tuple[bytes, bytes]:
        return s[:self.length], s[self.length:]


class CPFItem(Packet):
    """One Common Packet Format item: type, length, data."""

    name = "CPF item"
    fields_desc = [
        LEShortEnumField("type", 0, _ITEMS),
        LEShortField("length", None),
    ]

    def post_build(self, packet: bytes, payload: bytes) -> bytes:
        if self.length is None:
            packet = packet[:2] + len(payload).to_bytes(2, "little")
        return packet + payload

    def extract_padding(self, s: bytes) -> tuple[bytes, bytes]:
        return s[:self.length], s[self.length:]

    def guess_payload_class(self, payload: bytes) -> Any:
        if self.type == ItemType.UNCONNECTED_DATA and payload:
            return CIP
        if self.type == ItemType.CONNECTED_DATA and len(payload) > 2:
            return CIPConnected
        return Packet.guess_payload_class(self, payload)


class CPF(Packet):
    """SendRRData/SendUnitData body: interface handle, timeout, then the items (eip.cpf)."""

    name = "CPF"
    fields_desc = [
        LEIntField("interface", 0),
        LEShortField("timeout", 0),
        FieldLenField("count", None, count_of="items", fmt="<H"),
        PacketListField("items", [], CPFItem, count_from=lambda p: p.count),
    ]


class CIP(Packet):
    """A message-router request or reply (cip.messages): service, then the path or the status."""

    name = "CIP"
    fields_desc = [
        ByteEnumField("service", 0, _SERVICES),
        ConditionalField(FieldLenField("path_words", None, length_of="path", fmt="B",
                                       adjust=lambda p, n: n // 2), lambda p: not p.service & REPLY_BIT),
        ConditionalField(StrLenField("path", b"", length_from=lambda p: 2 * p.path_words),
                         lambda p: not p.service & REPLY_BIT),
        ConditionalField(XByteField("reserved", 0), lambda p: p.service & REPLY_BIT),
        ConditionalField(XByteField("general_status", 0), lambda p: p.service & REPLY_BIT),
        ConditionalField(FieldLenField("ext_words", None, count_of="extended_status", fmt="B"),
                         lambda p: p.service & REPLY_BIT),
        ConditionalField(FieldListField("extended_status", [], LEShortField("", 0),
                                        count_from=lambda p: p.ext_words), lambda p: p.service & REPLY_BIT),
    ]

    def describe(self, declarations: Declarations | None = None) -> dict[str, Any]:
        """Service, path and status by name, decoded by the project's message-router codecs."""
        raw = bytes(self)
        decl = declarations or Declarations()
        return decode_reply(raw, None, decl) if self.service & REPLY_BIT else decode_request(raw, decl)


class CIPConnected(Packet):
    """Connected Data of a class 3 message: the CIP sequence count, then the message-router message."""

    name = "CIP connected"
    fields_desc = [LEShortField("sequence", 0)]

    def guess_payload_class(self, payload: bytes) -> Any:
        return CIP


class ENIP_IO(Packet):
    """A class 0/1 datagram (eip.io_core): Sequenced Address and Connected Data items."""

    name = "EtherNet/IP class 1"
    fields_desc = [
        LEShortField("count", 2),
        LEShortEnumField("address_type", ItemType.SEQUENCED_ADDRESS, _ITEMS),
        LEShortField("address_length", 8),
        LEIntField("connection_id", 0),
        LEIntField("encap_sequence", 0),
        LEShortEnumField("data_type", ItemType.CONNECTED_DATA, _ITEMS),
        LEShortField("data_length", None),
        LEShortField("cip_sequence", 0),
    ]

    def post_build(self, packet: bytes, payload: bytes) -> bytes:
        if self.data_length is None:
            packet = packet[:16] + (2 + len(payload)).to_bytes(2, "little") + packet[18:]
        return packet + payload

    def datagram(self) -> IoDatagram:
        """The datagram as eip.io_core decodes it (IoDatagramError when it is not a class 1 datagram)."""
        return decode_io_datagram(bytes(self))


def bind_layers_to_ports() -> None:
    """TCP and UDP 44818 carry the encapsulation; UDP 2222 class 0/1 I/O (wire.md, Ports)."""
    for transport in (TCP, UDP):
        bind_layers(transport, ENIP, dport=ENIP_PORT)
        bind_layers(transport, ENIP, sport=ENIP_PORT)
    bind_layers(UDP, ENIP_IO, dport=DEFAULT_IO_PORT)
    bind_layers(UDP, ENIP_IO, sport=DEFAULT_IO_PORT)
    bind_layers(ENIP, CPF, command_code=Command.SEND_RR_DATA)
    bind_layers(ENIP, CPF, command_code=Command.SEND_UNIT_DATA)


bind_layers_to_ports()
