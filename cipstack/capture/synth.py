"""Writing captures: a plain pcap writer and Ethernet/IPv4/TCP/UDP framing around EtherNet/IP bytes.

For tests that reproduce a wire exchange byte for byte and for the benchmark's synthetic
million-frame capture; the EtherNet/IP and CIP bytes inside come from the project's codecs.
"""

from __future__ import annotations

import socket
import struct
from typing import BinaryIO

from .reader import LINKTYPE_ETHERNET

_PCAP_HEADER = struct.Struct("<IHHiIII")
_RECORD = struct.Struct("<IIII")
_MAC_A = bytes.fromhex("020000000001")
_MAC_B = bytes.fromhex("020000000002")


def _checksum(data: bytes) -> int:
    if len(data) % 2:
        data += b"\x00"
    total: int = sum(struct.unpack(f"!{len(data) // 2}H", data))
    while total >> 16:
        total = (total & 0xFFFF) + (total >> 16)
    return ~total & 0xFFFF


def ipv4(src: str, dst: str, protocol: int, payload: bytes, ident: int = 0) -> bytes:
    header = struct.pack("!BBHHHBBH4s4s", 0x45, 0, 20 + len(payload), ident & 0xFFFF, 0x4000, 64, protocol, 0,
                         socket.inet_aton(src), socket.inet_aton(dst))
    return header[:10] + struct.pack("!H", _checksum(header)) + header[12:] + payload


def _pseudo(src: str, dst: str, protocol: int, length: int) -> bytes:
    return socket.inet_aton(src) + socket.inet_aton(dst) + struct.pack("!BBH", 0, protocol, length)


def udp(src: str, sport: int, dst: str, dport: int, payload: bytes) -> bytes:
    head = struct.pack("!HHHH", sport, dport, 8 + len(payload), 0)
    checksum = _checksum(_pseudo(src, dst, 17, len(head) + len(payload)) + head + payload) or 0xFFFF
    return ipv4(src, dst, 17, head[:6] + struct.pack("!H", checksum) + payload)


def tcp(src: str, sport: int, dst: str, dport: int, payload: bytes, seq: int, ack: int = 0,
        flags: int = 0x18) -> bytes:
    head = struct.pack("!HHIIBBHHH", sport, dport, seq & 0xFFFFFFFF, ack & 0xFFFFFFFF, 5 << 4, flags, 65535, 0, 0)
    checksum = _checksum(_pseudo(src, dst, 6, len(head) + len(payload)) + head + payload)
    return ipv4(src, dst, 6, head[:16] + struct.pack("!H", checksum) + head[18:] + payload)


def ethernet(ip_packet: bytes) -> bytes:
    return _MAC_B + _MAC_A + b"\x08\x00" + ip_packet


class PcapWriter:
    """Classic pcap (microsecond timestamps, little-endian)."""

    def __init__(self, stream: BinaryIO, linktype: int = LINKTYPE_ETHERNET) -> None:
        self.stream = stream
        stream.write(_PCAP_HEADER.pack(0xA1B2C3D4, 2, 4, 0, 0, 65535, linktype))

    def write(self, time: float, frame: bytes) -> None:
        seconds = int(time)
        micros = round((time - seconds) * 1e6)
        if micros >= 1_000_000:
            seconds, micros = seconds + 1, micros - 1_000_000
        self.stream.write(_RECORD.pack(seconds, micros, len(frame), len(frame)))
        self.stream.write(frame)


class TcpFlow:
    """Both directions of one TCP connection, with sequence numbers that follow the bytes sent."""

    def __init__(self, client: tuple[str, int], server: tuple[str, int]) -> None:
        self.client, self.server = client, server
        self.seq = {client: 1000, server: 5000}

    def handshake(self) -> list[bytes]:
        c, s = self.client, self.server
        frames = [tcp(*c, *s, b"", self.seq[c], 0, 0x02), tcp(*s, *c, b"", self.seq[s], self.seq[c] + 1, 0x12)]
        self.seq[c] += 1
        self.seq[s] += 1
        frames.append(tcp(*c, *s, b"", self.seq[c], self.seq[s], 0x10))
        return frames

    def send(self, from_client: bool, payload: bytes, seq_offset: int | None = None) -> bytes:
        src, dst = (self.client, self.server) if from_client else (self.server, self.client)
        seq = self.seq[src] if seq_offset is None else seq_offset
        frame = tcp(*src, *dst, payload, seq, self.seq[dst])
        if seq_offset is None:
            self.seq[src] += len(payload)
        return frame
