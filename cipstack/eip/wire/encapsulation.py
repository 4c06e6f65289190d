"""EtherNet/IP encapsulation: the 24-byte header, its commands and status codes.

Header: command UINT, length UINT (bytes after the header), session handle UDINT, status
UDINT, sender context 8 bytes (echoed unchanged), options UDINT (must be 0). Little-endian.
"""

from __future__ import annotations

import struct
from enum import IntEnum
from typing import NamedTuple

from ...errors import ProtocolError

HEADER = struct.Struct("<HHII8sI")
HEADER_SIZE = HEADER.size  # 24


class Command(IntEnum):
    NOP = 0x0000
    LIST_SERVICES = 0x0004
    LIST_IDENTITY = 0x0063
    LIST_INTERFACES = 0x0064
    REGISTER_SESSION = 0x0065
    UNREGISTER_SESSION = 0x0066
    SEND_RR_DATA = 0x006F
    SEND_UNIT_DATA = 0x0070


#: Commands a target also answers over UDP 44818.
UDP_COMMANDS = frozenset({Command.LIST_SERVICES, Command.LIST_IDENTITY, Command.LIST_INTERFACES})


class EncapsulationStatus(IntEnum):
    SUCCESS = 0x0000
    INVALID_COMMAND = 0x0001
    INSUFFICIENT_MEMORY = 0x0002
    INCORRECT_DATA = 0x0003
    INVALID_SESSION = 0x0064
    INVALID_LENGTH = 0x0065
    UNSUPPORTED_PROTOCOL = 0x0069


class EncapsulationError(ProtocolError):
    """An encapsulation-level failure, answered with ``status`` in the reply header."""

    def __init__(self, status: EncapsulationStatus, message: str = "", offset: int | None = None) -> None:
        self.status = status
        #: Where in the decoded buffer the problem is, when the decoder knows (capture analysis reports it).
        self.offset = offset
        super().__init__(message or status.name.lower().replace("_", " "))


class EncapsulationHeader(NamedTuple):
    """The 24-byte encapsulation header: command, data length, session handle, status, sender
    context and options."""

    command: int
    length: int
    session: int
    status: int
    context: bytes
    options: int

    @classmethod
    def decode(cls, raw: bytes | bytearray | memoryview, offset: int = 0) -> EncapsulationHeader:
        return cls(*HEADER.unpack_from(raw, offset))

    def encode(self) -> bytes:
        return HEADER.pack(self.command, self.length, self.session, self.status, self.context, self.options)


def encode_frame(command: int, data: bytes = b"", session: int = 0, status: int = 0,
                 context: bytes = b"\x00" * 8, options: int = 0) -> bytes:
    """One whole encapsulation frame: the header (its length from ``data``) and the data."""
    return HEADER.pack(command, len(data), session, status, context, options) + data


PROTOCOL_VERSION = 1
#: The registered EtherNet/IP port: TCP and UDP 44818 (explicit messages, ListIdentity).
DEFAULT_PORT = 44818
#: EtherNet/IP over TLS (TCP) and DTLS (UDP), CIP Security: 2221 (Wireshark's packet-enip.c,
#: ``ENIP_SECURE_PORT``).
SECURE_PORT = 2221
#: The registered port of class 1 I/O: UDP 2222.
DEFAULT_IO_PORT = 2222
#: Seconds a TCP frame, once begun, has to arrive whole by default (``TargetSettings.frame_timeout``).
DEFAULT_FRAME_TIMEOUT = 5.0
REGISTER_SESSION_DATA = struct.Struct("<HH")

#: Interface handle UDINT (0 for CIP) and timeout UINT that open SendRRData/SendUnitData.
RR_PREFIX = struct.Struct("<IH")
