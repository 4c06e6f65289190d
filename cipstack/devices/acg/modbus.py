"""Modbus TCP on the ACG-ET2 card (ACG-ET2 manual, "Modbus TCP Frame"), served from the same drive
model as EtherNet/IP.

* Frame: the 7-byte MBAP header (transaction id, protocol id 0, length, unit id) and the PDU.
  The unit id is echoed (the card uses 0xFF when Modbus TCP is used alone).
* Function codes 0x03 Read Holding Registers, 0x04 Read Input Registers, 0x06 Write Single
  Register, 0x10 Write Multiple Registers and 0x17 Read/Write Multiple Registers, 1-16 words per
  request ("1-16 (ACG drives)").
* Numbering: the manual's "Modbus TCP" column numbers a register 40001 + its communication
  address (``registers.modbus_tcp_number``; 0x0300 is 40769): holding register 40769 is sent as
  PDU address 0x0300, so the PDU address is the communication address.
* Exception codes (ACG-ET2 manual, "Exception Code"): 0x01 unsupported function, 0x02 unused address,
  0x03 value out of range (and malformed requests), 0x04 server error, 0x20 write-protected
  parameter (a read-only register, or one not writable while the drive runs). 0x06 (busy during
  a parameter initialization) cannot occur here: the drive model initializes in no time.
* Every request counts as Modbus activity: five seconds without one is a command loss (Pr.12
  after Pr.13, ACG-ET2 manual "Lost command conditions by protocol").

The protocol core (``ModbusTcpCore``, ``MbapBuffer``, this module) takes bytes and the time and
returns bytes; its PDUs are served by the Modbus layer it shares with the RS-485 port
(``modbus_core``); ``cipstack.modbus.tcp_server.ModbusTcpServer`` is its asyncio shell. pymodbus 3.16's server
is not used: its supported custom datastore (``SimDevice`` with an ``action``) can only return
members of its ``ExcCodes`` enum, which has no 0x20, and treats any other return value of a write
as success.
"""

from __future__ import annotations

import struct

from ...errors import ProtocolError
from .drive import AcgDrive
from .modbus_core import (
    MAX_WORDS,
    TCP_DIALECT,
    DriveSource,
    ExceptionCode,
    FunctionCode,
    ModbusCore,
    ModbusException,
    RegisterWritten,
)

MBAP = struct.Struct(">HHHB")
MBAP_SIZE = MBAP.size
#: The MBAP length counts the unit id and the PDU; a PDU is at most 253 bytes.
MAX_LENGTH = 254


class ModbusTcpCore(ModbusCore):
    """Serves MBAP frames from a drive, sans I/O: the shared Modbus layer (``modbus_core``) as the
    card's dialect has it, in the MBAP header."""

    def __init__(self, drive: AcgDrive | DriveSource, written: RegisterWritten | None = None) -> None:
        super().__init__(drive, TCP_DIALECT, written)

    def handle_adu(self, adu: bytes, now: float, source: object = None) -> bytes | None:
        """One MBAP frame in, its reply out (None: a frame of another protocol, discarded); ``source``
        as ``handle_pdu`` takes it (the peer's address)."""
        transaction, protocol, _length, unit = MBAP.unpack_from(adu)
        if protocol != 0:
            return None
        pdu = self.handle_pdu(adu[MBAP_SIZE:], now, source)
        return MBAP.pack(transaction, 0, len(pdu) + 1, unit) + pdu

    def framer(self) -> MbapBuffer:
        """A new splitter of one connection's stream into MBAP frames."""
        return MbapBuffer()

    def exception_adu(self, adu: bytes, code: ExceptionCode) -> bytes:
        """The exception reply to the request ``adu`` (e.g. 0x04 for a save the file did not take)."""
        transaction, _protocol, _length, unit = MBAP.unpack_from(adu)
        function = adu[MBAP_SIZE] if len(adu) > MBAP_SIZE else 0
        return MBAP.pack(transaction, 0, 3, unit) + self.exception_pdu(function, code)


class MbapLengthError(ProtocolError, ValueError):
    """A frame announced an impossible length: the stream cannot be framed past it. ``frames`` are the
    complete frames that came before it (in the same read), still to be served."""

    def __init__(self, length: int, frames: list[bytes]) -> None:
        super().__init__(f"MBAP length {length}")
        self.frames = frames


class MbapBuffer:
    """Splits a TCP byte stream into MBAP frames."""

    def __init__(self) -> None:
        self._buffer = bytearray()

    @property
    def pending(self) -> int:
        """Bytes of a frame begun and not complete yet."""
        return len(self._buffer)

    def feed(self, data: bytes) -> list[bytes]:
        """The complete frames ``data`` finishes; raises ``MbapLengthError`` (with the frames before
        it) on an impossible length."""
        self._buffer += data
        frames: list[bytes] = []
        while len(self._buffer) >= MBAP_SIZE:
            _, _, length, _ = MBAP.unpack_from(self._buffer)
            if not 2 <= length <= MAX_LENGTH:
                raise MbapLengthError(length, frames)
            end = MBAP_SIZE - 1 + length
            if len(self._buffer) < end:
                break
            frames.append(bytes(self._buffer[:end]))
            del self._buffer[:end]
        return frames


__all__ = ["MAX_WORDS", "DriveSource", "ExceptionCode", "FunctionCode", "MbapBuffer", "MbapLengthError",
           "ModbusException", "ModbusTcpCore"]
