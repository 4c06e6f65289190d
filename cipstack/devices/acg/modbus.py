"""Modbus TCP on the ACG-ET2 card (seed 000, "Modbus TCP Frame"), served from the same drive
model as EtherNet/IP.

* Frame: the 7-byte MBAP header (transaction id, protocol id 0, length, unit id) and the PDU.
  The unit id is echoed (the card uses 0xFF when Modbus TCP is used alone).
* Function codes 0x03 Read Holding Registers, 0x04 Read Input Registers, 0x06 Write Single
  Register, 0x10 Write Multiple Registers and 0x17 Read/Write Multiple Registers, 1-16 words per
  request ("1-16 (ACG drives)").
* Numbering: the seed's "Modbus TCP" column numbers a register 40001 + its communication
  address (``registers.modbus_tcp_number``; 0x0300 is 40769): holding register 40769 is sent as
  PDU address 0x0300, so the PDU address is the communication address.
* Exception codes (seed 000, "Exception Code"): 0x01 unsupported function, 0x02 unused address,
  0x03 value out of range (and malformed requests), 0x04 server error, 0x20 write-protected
  parameter (a read-only register, or one not writable while the drive runs). 0x06 (busy during
  a parameter initialization) cannot occur here: the drive model initializes in no time.
* Every request counts as Modbus activity: five seconds without one is a command loss (Pr.12
  after Pr.13, seed 000 "Lost command conditions by protocol").

The protocol core (``ModbusTcpCore``, ``MbapBuffer``, this module) takes bytes and the time and
returns bytes; ``modbus_server.ModbusTcpServer`` is its asyncio shell. pymodbus 3.16's server is not used: its supported
custom datastore (``SimDevice`` with an ``action``) can only return members of its ``ExcCodes``
enum, which has no 0x20, and treats any other return value of a write as success.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from enum import IntEnum

from ..registers import RegisterAccess, RegisterError, RegisterRefusal
from .drive import AcgDrive

log = logging.getLogger(__name__)

MBAP = struct.Struct(">HHHB")
MBAP_SIZE = MBAP.size
#: The MBAP length counts the unit id and the PDU; a PDU is at most 253 bytes.
MAX_LENGTH = 254
#: "Number of data requests 1-16 (ACG drives)".
MAX_WORDS = 16


class FunctionCode(IntEnum):
    READ_HOLDING_REGISTERS = 0x03
    READ_INPUT_REGISTERS = 0x04
    WRITE_SINGLE_REGISTER = 0x06
    WRITE_MULTIPLE_REGISTERS = 0x10
    READ_WRITE_MULTIPLE_REGISTERS = 0x17


class ExceptionCode(IntEnum):
    """Seed 000, "Exception Code"."""

    ILLEGAL_FUNCTION = 0x01
    ILLEGAL_DATA_ADDRESS = 0x02
    ILLEGAL_DATA_VALUE = 0x03
    SLAVE_DEVICE_FAILURE = 0x04
    SLAVE_DEVICE_BUSY = 0x06
    WRITE_PERMISSION_ERROR = 0x20


_REFUSAL_CODES = {
    RegisterRefusal.NO_SUCH_REGISTER: ExceptionCode.ILLEGAL_DATA_ADDRESS,
    RegisterRefusal.OUT_OF_RANGE: ExceptionCode.ILLEGAL_DATA_VALUE,
    RegisterRefusal.READ_ONLY: ExceptionCode.WRITE_PERMISSION_ERROR,
    RegisterRefusal.NOT_WHILE_RUNNING: ExceptionCode.WRITE_PERMISSION_ERROR,
    RegisterRefusal.SAVE_FAILED: ExceptionCode.SLAVE_DEVICE_FAILURE,   # the state file took no write
}


class ModbusException(Exception):
    def __init__(self, code: ExceptionCode, detail: str = "") -> None:
        self.code = code
        super().__init__(f"{code.name} ({detail})" if detail else code.name)


DriveSource = Callable[[], AcgDrive]


class ModbusTcpCore:
    """Serves Modbus PDUs from a drive, sans I/O."""

    def __init__(self, drive: AcgDrive | DriveSource) -> None:
        self._drive: DriveSource = drive if callable(drive) else (lambda: drive)
        self.requests = 0
        self.exceptions = 0

    @property
    def drive(self) -> AcgDrive:
        return self._drive()

    def handle_adu(self, adu: bytes, now: float) -> bytes | None:
        """One MBAP frame in, its reply out (None: a frame of another protocol, discarded)."""
        transaction, protocol, _length, unit = MBAP.unpack_from(adu)
        if protocol != 0:
            return None
        pdu = self.handle_pdu(adu[MBAP_SIZE:], now)
        return MBAP.pack(transaction, 0, len(pdu) + 1, unit) + pdu

    def exception_adu(self, adu: bytes, code: ExceptionCode) -> bytes:
        """The exception reply to the request ``adu`` (e.g. 0x04 for a save the file did not take)."""
        transaction, _protocol, _length, unit = MBAP.unpack_from(adu)
        function = adu[MBAP_SIZE] if len(adu) > MBAP_SIZE else 0
        self.exceptions += 1
        return MBAP.pack(transaction, 0, 3, unit) + bytes((function | 0x80, code))

    def handle_pdu(self, pdu: bytes, now: float) -> bytes:
        drive = self.drive
        now = max(now, drive.time)
        drive.on_modbus_activity(now)
        self.requests += 1
        function = pdu[0] if pdu else 0
        try:
            return bytes((function,)) + self._serve(function, pdu[1:], drive, now)
        except ModbusException as exc:
            self.exceptions += 1
            log.debug("Modbus function 0x%02X: %s", function, exc)
            return bytes((function | 0x80, exc.code))
        except Exception:  # a drive bug must not take the server down
            self.exceptions += 1
            log.exception("Modbus function 0x%02X failed", function)
            return bytes((function | 0x80, ExceptionCode.SLAVE_DEVICE_FAILURE))

    def _serve(self, function: int, data: bytes, drive: AcgDrive, now: float) -> bytes:
        # A PDU is exactly as long as its function says: bytes beyond it (a wrong MBAP length, or
        # data the request does not have) refuse the request with 0x03, which the Modbus
        # Application Protocol gives for "the implied length is incorrect".
        if function in (FunctionCode.READ_HOLDING_REGISTERS, FunctionCode.READ_INPUT_REGISTERS):
            address, count = _unpack(">HH", data)
            return self._read(drive, address, count)
        if function == FunctionCode.WRITE_SINGLE_REGISTER:
            address, value = _unpack(">HH", data)
            self._write(drive, address, [value], now)
            return data
        if function == FunctionCode.WRITE_MULTIPLE_REGISTERS:
            address, count, byte_count = _unpack(">HHB", data[:5])  # the values' length: _values
            values = _values(data[5:], count, byte_count)
            self._write(drive, address, values, now)
            return struct.pack(">HH", address, count)
        if function == FunctionCode.READ_WRITE_MULTIPLE_REGISTERS:
            read_address, read_count, write_address, write_count, byte_count = _unpack(">HHHHB", data[:9])
            values = _values(data[9:], write_count, byte_count)
            _check_count(read_count)
            self._check_addresses(drive, read_address, read_count)
            self._write(drive, write_address, values, now)  # the write is done before the read
            return self._read(drive, read_address, read_count)
        raise ModbusException(ExceptionCode.ILLEGAL_FUNCTION, f"function 0x{function:02X} is not supported")

    @staticmethod
    def _check_addresses(drive: AcgDrive, address: int, count: int) -> None:
        for word in range(address, address + count):
            found = drive.registers.word(word) if word <= 0xFFFF else None
            # A parameter its address table gives no address (CM.94) is not at one (0x02, as bA.20).
            if found is None or not found[0].addressed:
                raise ModbusException(ExceptionCode.ILLEGAL_DATA_ADDRESS, f"no register 0x{word:04X}")

    def _read(self, drive: AcgDrive, address: int, count: int) -> bytes:
        _check_count(count)
        self._check_addresses(drive, address, count)
        words = [drive.read(a) & 0xFFFF for a in range(address, address + count)]
        return bytes((2 * count,)) + struct.pack(f">{count}H", *words)

    def _write(self, drive: AcgDrive, address: int, values: list[int], now: float) -> None:
        _check_count(len(values))
        self._check_addresses(drive, address, len(values))
        # Every word is checked against its declaration before any is written.
        raws = []
        for offset, value in enumerate(values):
            register = drive.registers[address + offset]
            if register.access is RegisterAccess.READ:
                raise ModbusException(ExceptionCode.WRITE_PERMISSION_ERROR, f"0x{register.address:04X} is read only")
            raw = register.from_words([value])
            try:
                register.check(raw)
            except RegisterError as exc:
                raise ModbusException(_REFUSAL_CODES[exc.refusal], str(exc)) from None
            raws.append(raw)
        for offset, raw in enumerate(raws):
            try:
                drive.write(address + offset, raw, now)
            except RegisterError as exc:
                raise ModbusException(_REFUSAL_CODES[exc.refusal], str(exc)) from None


def _unpack(fmt: str, data: bytes) -> tuple[int, ...]:
    """The fields of a fixed-size request, which must be exactly ``fmt`` long."""
    size = struct.calcsize(fmt)
    if len(data) != size:
        raise ModbusException(ExceptionCode.ILLEGAL_DATA_VALUE,
                              f"request data of {len(data)} bytes, the function takes {size}")
    return struct.unpack(fmt, data)


def _check_count(count: int) -> None:
    if not 1 <= count <= MAX_WORDS:
        raise ModbusException(ExceptionCode.ILLEGAL_DATA_VALUE, f"{count} words (1-{MAX_WORDS} per request)")


def _values(data: bytes, count: int, byte_count: int) -> list[int]:
    _check_count(count)
    if byte_count != 2 * count or len(data) != byte_count:
        raise ModbusException(ExceptionCode.ILLEGAL_DATA_VALUE, "byte count does not match the quantity")
    return list(struct.unpack(f">{count}H", data))


class MbapLengthError(ValueError):
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
        frames = []
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
           "ModbusTcpCore"]
