"""Records of a pcap or pcapng file, and the IPv4/TCP/UDP headers under their link layer.

The hot path of ``capture analyze``: records come from scapy's raw readers (both formats, either
byte order, any timestamp resolution) without a dissection per frame, which would limit a
million-frame capture to scapy's dissection rate (about 50,000 packets/s here, against 370,000
raw records/s); only the headers EtherNet/IP needs are then unpacked with ``struct``. The scapy
layers in :mod:`cipstack.capture.layers` dissect or build single packets.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass
from typing import BinaryIO, cast

from ..errors import BadRequest

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

class CaptureFormatError(BadRequest):
    """The file is not a pcap/pcapng file, or is cut short inside its header."""


@dataclass(frozen=True, slots=True)
class Record:
    time: float
    linktype: int
    data: bytes


def read_records(stream: BinaryIO) -> Iterator[Record]:
    """Every packet record of a pcap or pcapng stream, in file order, read by scapy's raw readers
    (``RawPcapReader`` opens either format; records are not dissected). A record cut short at the
    end of the file (a capture still being written) ends the iteration."""
    from scapy.error import Scapy_Exception
    from scapy.utils import RawPcapNgReader, RawPcapReader

    try:
        # scapy opens a file object as well as a name (utils.open_file); its annotation names only str.
        reader = RawPcapReader(stream)  # type: ignore[arg-type]
    except (Scapy_Exception, EOFError, struct.error) as exc:
        raise CaptureFormatError(f"not a pcap or pcapng file ({exc})") from None
    if isinstance(reader, RawPcapNgReader):
        for data, pcap_meta in reader:
            # A pcapng reader's records carry its own metadata; scapy types iteration by the pcap reader's.
            ng_meta = cast("RawPcapNgReader.PacketMetadata", pcap_meta)
            # tsresol: timestamp units per second of the packet's interface (if_tsresol).
            yield Record(((ng_meta.tshigh << 32) | ng_meta.tslow) / ng_meta.tsresol, ng_meta.linktype, data)
        return
    divisor = 1e9 if getattr(reader, "nano", False) else 1e6
    linktype = reader.linktype
    for data, meta in reader:
        yield Record(meta.sec + meta.usec / divisor, linktype, data)


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
