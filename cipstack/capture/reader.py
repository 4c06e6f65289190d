"""Records of a pcap or pcapng file, and the IPv4/TCP/UDP headers under their link layer.

The hot path of ``capture analyze``: a million-frame capture must not go through a full packet
dissection per frame, so records are read with ``struct`` straight from the file (classic pcap
in either byte order and either timestamp resolution; pcapng section, interface and packet
blocks) and only the headers EtherNet/IP needs are unpacked. The scapy layers in
:mod:`cipstack.capture.layers` are for dissecting or building single packets.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import BinaryIO

# Link types (tcpdump.org/linktypes.html).
LINKTYPE_NULL = 0          # BSD loopback: 4-byte address family in host byte order
LINKTYPE_ETHERNET = 1
LINKTYPE_RAW = 101         # raw IPv4/IPv6
LINKTYPE_LOOP = 108        # OpenBSD loopback: family in network byte order
LINKTYPE_LINUX_SLL = 113   # Linux cooked capture v1 (16-byte header)
LINKTYPE_IPV4 = 228
LINKTYPE_LINUX_SLL2 = 276  # Linux cooked capture v2 (20-byte header)
SUPPORTED_LINKTYPES = {LINKTYPE_NULL: "loopback", LINKTYPE_ETHERNET: "Ethernet", LINKTYPE_RAW: "raw IP",
                       LINKTYPE_LOOP: "loopback", LINKTYPE_LINUX_SLL: "Linux cooked",
                       LINKTYPE_IPV4: "raw IPv4", LINKTYPE_LINUX_SLL2: "Linux cooked v2"}

_PCAP_HEADER = struct.Struct("<IHHiIII")
_PCAPNG_SHB = 0x0A0D0D0A
_PCAPNG_BYTE_ORDER = 0x1A2B3C4D


class CaptureFormatError(ValueError):
    """The file is not a pcap/pcapng file, or is cut short inside its header."""


@dataclass(frozen=True, slots=True)
class Record:
    time: float
    linktype: int
    data: bytes


def read_records(stream: BinaryIO) -> Iterator[Record]:
    """Every packet record of a pcap or pcapng stream, in file order; a record cut short at the
    end of the file (a capture still being written) ends the iteration."""
    magic = stream.read(4)
    if len(magic) < 4:
        raise CaptureFormatError("file is shorter than a capture header")
    if magic in (b"\xd4\xc3\xb2\xa1", b"\xa1\xb2\xc3\xd4", b"\x4d\x3c\xb2\xa1", b"\xa1\xb2\x3c\x4d"):
        yield from _pcap(stream, magic)
    elif int.from_bytes(magic, "little") == _PCAPNG_SHB:
        yield from _pcapng(stream)
    else:
        raise CaptureFormatError(f"not a pcap or pcapng file (magic {magic.hex()})")


def _pcap(stream: BinaryIO, magic: bytes) -> Iterator[Record]:
    order = "<" if magic[0] in (0xD4, 0x4D) else ">"
    nano = magic in (b"\x4d\x3c\xb2\xa1", b"\xa1\xb2\x3c\x4d")
    rest = stream.read(20)
    if len(rest) < 20:
        raise CaptureFormatError("pcap header cut short")
    linktype = struct.unpack(order + "I", rest[16:20])[0] & 0x0FFFFFFF
    record = struct.Struct(order + "IIII")
    divisor = 1e9 if nano else 1e6
    read = stream.read
    unpack = record.unpack
    while True:
        head = read(16)
        if len(head) < 16:
            return
        seconds, fraction, caplen, _origlen = unpack(head)
        data = read(caplen)
        if len(data) < caplen:
            return
        yield Record(seconds + fraction / divisor, linktype, data)


def _pcapng(stream: BinaryIO) -> Iterator[Record]:
    # The first 4 bytes (block type of the section header) are read; the rest of the block follows.
    head = stream.read(8)
    if len(head) < 8:
        raise CaptureFormatError("pcapng section header cut short")
    order = "<" if int.from_bytes(head[4:8], "little") == _PCAPNG_BYTE_ORDER else ">"
    length = struct.unpack(order + "I", head[:4])[0]
    stream.read(length - 12)
    interfaces: list[tuple[int, float]] = []
    u32 = struct.Struct(order + "I")
    two = struct.Struct(order + "II")
    epb = struct.Struct(order + "IIIII")
    read = stream.read
    while True:
        head = read(8)
        if len(head) < 8:
            return
        block_type, length = two.unpack(head)
        if length < 12:
            return
        body = read(length - 8)
        if len(body) < length - 8:
            return
        if block_type == 6:  # enhanced packet block
            interface, high, low, caplen, _origlen = epb.unpack_from(body)
            linktype, resolution = interfaces[interface] if interface < len(interfaces) else (LINKTYPE_ETHERNET, 1e-6)
            yield Record(((high << 32) | low) * resolution, linktype, body[20:20 + caplen])
        elif block_type == 1:  # interface description block
            linktype = struct.unpack_from(order + "H", body)[0]
            interfaces.append((linktype, _resolution(body[8:-4], order)))
        elif block_type == 3:  # simple packet block: no timestamp, first interface
            origlen = u32.unpack_from(body)[0]
            linktype = interfaces[0][0] if interfaces else LINKTYPE_ETHERNET
            yield Record(0.0, linktype, body[4:4 + origlen])
        elif block_type == _PCAPNG_SHB:
            order = "<" if int.from_bytes(body[:4], "little") == _PCAPNG_BYTE_ORDER else ">"
            u32, two, epb = struct.Struct(order + "I"), struct.Struct(order + "II"), struct.Struct(order + "IIIII")
            interfaces = []


def _resolution(options: bytes, order: str) -> float:
    """if_tsresol (option 9) of an interface description block; default microseconds."""
    pos = 0
    while pos + 4 <= len(options):
        code, size = struct.unpack_from(order + "HH", options, pos)
        if code == 0:
            break
        if code == 9 and size >= 1:
            value = options[pos + 4]
            return 2.0 ** -(value & 0x7F) if value & 0x80 else 10.0 ** -value
        pos += 4 + (size + 3) // 4 * 4
    return 1e-6


@dataclass(frozen=True, slots=True)
class Segment:
    """An IPv4 datagram's transport part: TCP (with sequence number and flags) or UDP."""

    protocol: int  # 6 TCP, 17 UDP
    src: str
    sport: int
    dst: str
    dport: int
    payload: bytes
    seq: int = 0
    flags: int = 0


_ETHERTYPE_IPV4 = 0x0800
_ETHERTYPE_VLAN = (0x8100, 0x88A8)


def ip_offset(linktype: int, data: bytes) -> int | None:
    """Where the IPv4 header starts under the link layer, or None (not IPv4, unknown link type)."""
    if linktype == LINKTYPE_ETHERNET:
        if len(data) < 14:
            return None
        ethertype = (data[12] << 8) | data[13]
        offset = 14
        while ethertype in _ETHERTYPE_VLAN and len(data) >= offset + 4:
            ethertype = (data[offset + 2] << 8) | data[offset + 3]
            offset += 4
        return offset if ethertype == _ETHERTYPE_IPV4 else None
    if linktype == LINKTYPE_LINUX_SLL:
        return 16 if len(data) >= 16 and data[14:16] == b"\x08\x00" else None
    if linktype == LINKTYPE_LINUX_SLL2:
        return 20 if len(data) >= 20 and data[0:2] == b"\x08\x00" else None
    if linktype in (LINKTYPE_NULL, LINKTYPE_LOOP):
        if len(data) < 4:
            return None
        # AF_INET is 2 everywhere; the byte order is the capturing host's (NULL) or network (LOOP).
        return 4 if data[:4] in (b"\x02\x00\x00\x00", b"\x00\x00\x00\x02") else None
    if linktype in (LINKTYPE_RAW, LINKTYPE_IPV4):
        return 0
    return None


def _addr(raw: bytes) -> str:
    return f"{raw[0]}.{raw[1]}.{raw[2]}.{raw[3]}"


_TCP = struct.Struct(">HHIIBB")
_UDP = struct.Struct(">HHH")


def decode_segment(linktype: int, data: bytes) -> Segment | None:
    """The TCP or UDP segment of an IPv4 frame; None for anything else (or a fragment after the first)."""
    offset = ip_offset(linktype, data)
    if offset is None or len(data) < offset + 20 or data[offset] >> 4 != 4:
        return None
    header = (data[offset] & 0x0F) * 4
    total = (data[offset + 2] << 8) | data[offset + 3]
    protocol = data[offset + 9]
    if (data[offset + 6] & 0x1F) or data[offset + 7]:  # fragment offset != 0
        return None
    end = min(len(data), offset + total) if total else len(data)
    start = offset + header
    src = _addr(data[offset + 12:offset + 16])
    dst = _addr(data[offset + 16:offset + 20])
    if protocol == 17 and end >= start + 8:
        sport, dport, length = _UDP.unpack_from(data, start)
        return Segment(17, src, sport, dst, dport, data[start + 8:min(end, start + length)])
    if protocol == 6 and end >= start + 20:
        sport, dport, seq, _ack, offset_byte, flags = _TCP.unpack_from(data, start)
        return Segment(6, src, sport, dst, dport, data[start + (offset_byte >> 4) * 4:end], seq, flags)
    return None
