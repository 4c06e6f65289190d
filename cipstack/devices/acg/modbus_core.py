"""The ACG drive's Modbus application layer, shared by Modbus TCP (the ACG-ET2 card, ACG-ET2 manual) and
Modbus-RTU (the built-in RS-485 port, ACG RS-485 manual), sans I/O: a PDU and the time in, a PDU out.

Both ports serve one register map (ACG RS-485 manual, "Total Memory Map for Communication") with the same
write rules, the same save rule (0x03E0 from 0 to 1, ACG RS-485 manual "Saving Parameters Defined by
Communication") and the same drive. What differs between them is a ``ModbusDialect``:

* the function codes: 0x03, 0x04, 0x06, 0x10 on both (ACG RS-485 manual, "Modbus-RTU Protocol"; ACG-ET2 manual,
  "Modbus TCP Frame"), and 0x17 Read/Write Multiple Registers on the card only (ACG-ET2 manual);
* the exception codes: the card's table (ACG-ET2 manual, "Exception Code": 0x01-0x04, 0x06 and the
  ACG's own 0x20 Write Permission Error) or the serial chapter's (ACG RS-485 manual, "Exception Code":
  01 Illegal Function, 02 Illegal Data Address, 03 Illegal Data Value, 06 Slave Device Busy);
* the addresses: the card's PDU address is the communication address (its "Modbus TCP" column
  numbers a register 40001 + address, ACG RS-485 manual and ACG-ET2 manual); on the RS-485 port the "Modbus RTU"
  column numbers it 40000 + address, so its PDU address is the communication address minus one.
  The chapter's worked example sends "Starting Address -1 (0x1246-1)", 0x1245, to write 0x1246,
  and "Hex Address 0000 is unavailable with Modbus RTU" (no PDU address reaches it);
* the command source a run command written through the port belongs to (drv 4 Field Bus for the
  card, drv 3 Int485 for the RS-485 port) and the lost-command watch a request feeds (ACG-ET2 manual,
  "Lost command conditions by protocol": five seconds of Modbus TCP silence; ACG RS-485 manual, Command
  Loss Protective Operation: Pr.13 of RS-485 silence).
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import IntEnum

from ...errors import ProtocolError
from ..registers import RegisterAccess, RegisterError, RegisterRefusal
from .drive import AcgDrive
from .run_command import CommandPort

log = logging.getLogger(__name__)

#: "Number of data requests 1-16 (ACG drives)" (ACG-ET2 manual). The serial chapter gives no number of
#: its own; the drive behind both ports is the same, so the RS-485 port takes the same 1-16.
MAX_WORDS = 16


class FunctionCode(IntEnum):
    READ_HOLDING_REGISTERS = 0x03
    READ_INPUT_REGISTERS = 0x04
    WRITE_SINGLE_REGISTER = 0x06
    WRITE_MULTIPLE_REGISTERS = 0x10
    READ_WRITE_MULTIPLE_REGISTERS = 0x17


class ExceptionCode(IntEnum):
    """ACG-ET2 manual, "Exception Code" (the card); ACG RS-485 manual lists 0x01, 0x02, 0x03 and 0x06 of them."""

    ILLEGAL_FUNCTION = 0x01
    ILLEGAL_DATA_ADDRESS = 0x02
    ILLEGAL_DATA_VALUE = 0x03
    SLAVE_DEVICE_FAILURE = 0x04
    SLAVE_DEVICE_BUSY = 0x06
    WRITE_PERMISSION_ERROR = 0x20


class ModbusException(ProtocolError):
    def __init__(self, code: ExceptionCode, detail: str = "") -> None:
        self.code = code
        super().__init__(f"{code.name} ({detail})" if detail else code.name)


@dataclass(frozen=True)
class ModbusDialect:
    """What one port of the drive makes of the shared Modbus layer (module docstring)."""

    name: str
    functions: frozenset[int]
    #: The exception code of each reason the drive refuses a write.
    refusal_codes: Mapping[RegisterRefusal, ExceptionCode]
    #: The exception code of a failure inside the drive (a bug must not take the port down).
    failure_code: ExceptionCode
    #: The command source run commands written through this port belong to.
    port: CommandPort
    #: The communication address of PDU address 0.
    address_offset: int = 0

    def refusal(self, refusal: RegisterRefusal) -> ExceptionCode:
        return self.refusal_codes[refusal]


#: The ACG-ET2 card (ACG-ET2 manual, "Exception Code"): 0x20 for a write-protected parameter, 0x04 for a
#: server error (the state file took no write). 0x06 (busy during a parameter initialization)
#: cannot occur here: the drive model initializes in no time.
TCP_DIALECT = ModbusDialect(
    "Modbus TCP",
    frozenset(FunctionCode),
    {
        RegisterRefusal.NO_SUCH_REGISTER: ExceptionCode.ILLEGAL_DATA_ADDRESS,
        RegisterRefusal.OUT_OF_RANGE: ExceptionCode.ILLEGAL_DATA_VALUE,
        RegisterRefusal.READ_ONLY: ExceptionCode.WRITE_PERMISSION_ERROR,
        RegisterRefusal.NOT_WHILE_RUNNING: ExceptionCode.WRITE_PERMISSION_ERROR,
        RegisterRefusal.SAVE_FAILED: ExceptionCode.SLAVE_DEVICE_FAILURE,
    },
    ExceptionCode.SLAVE_DEVICE_FAILURE,
    CommandPort.FIELDBUS,
)

#: The RS-485 port (ACG RS-485 manual, "Exception Code": 01, 02, 03, 06 and no other). A write the drive
#: does not take at that address (read only, locked, or not while running) is 02, the code the
#: card's table gives to "modification ... requested for the data at an unused address": the
#: chapter has no write-protect code. A save the state file did not take is 06 Slave Device Busy
#: (the chapter: "it may take longer to set the parameter values in the drive memory control area
#: because all data is saved"), and so is a failure inside the drive, for want of 04 in the table.
RTU_DIALECT = ModbusDialect(
    "Modbus-RTU",
    frozenset({FunctionCode.READ_HOLDING_REGISTERS, FunctionCode.READ_INPUT_REGISTERS,
               FunctionCode.WRITE_SINGLE_REGISTER, FunctionCode.WRITE_MULTIPLE_REGISTERS}),
    {
        RegisterRefusal.NO_SUCH_REGISTER: ExceptionCode.ILLEGAL_DATA_ADDRESS,
        RegisterRefusal.OUT_OF_RANGE: ExceptionCode.ILLEGAL_DATA_VALUE,
        RegisterRefusal.READ_ONLY: ExceptionCode.ILLEGAL_DATA_ADDRESS,
        RegisterRefusal.NOT_WHILE_RUNNING: ExceptionCode.ILLEGAL_DATA_ADDRESS,
        RegisterRefusal.SAVE_FAILED: ExceptionCode.SLAVE_DEVICE_BUSY,
    },
    ExceptionCode.SLAVE_DEVICE_BUSY,
    CommandPort.INT485,
    address_offset=1,
)

DriveSource = Callable[[], AcgDrive]


#: Told of one register a Modbus request wrote: the drive, the address, the raw value, the time, and the
#: request's source (a TCP peer's ``host:port``, the RTU station addressed).
RegisterWritten = Callable[["AcgDrive", int, int, float, object], None]


class ModbusCore:
    """Serves Modbus PDUs from a drive, sans I/O, as ``dialect``'s port does."""

    def __init__(self, drive: AcgDrive | DriveSource, dialect: ModbusDialect = TCP_DIALECT,
                 written: RegisterWritten | None = None) -> None:
        """``written``: told of each register a request wrote (an observer: the event stream)."""
        self._drive: DriveSource = drive if callable(drive) else (lambda: drive)
        self.dialect = dialect
        self.written = written
        self.requests = 0
        self.exceptions = 0

    @property
    def drive(self) -> AcgDrive:
        return self._drive()

    def exception_pdu(self, function: int, code: ExceptionCode) -> bytes:
        self.exceptions += 1
        return bytes((function | 0x80, code))

    def handle_pdu(self, pdu: bytes, now: float, source: object = None) -> bytes:
        """One request PDU in, its reply out. ``source``: who sent it (a TCP peer's address, the RTU
        station addressed), handed to ``store`` with each register written, for an observer."""
        drive = self.drive
        now = max(now, drive.time)
        drive.on_modbus_activity(now, self.dialect.port)
        self.requests += 1
        function = pdu[0] if pdu else 0
        # The writes of this request come in through the dialect's port (``AcgDrive.commands_from``,
        # inline: it is on every request).
        previous, drive.command_port = drive.command_port, self.dialect.port
        try:
            return bytes((function,)) + self._serve(function, pdu[1:], drive, now, source)
        except ModbusException as exc:
            log.debug("%s function 0x%02X: %s", self.dialect.name, function, exc)
            return self.exception_pdu(function, exc.code)
        except Exception:  # a drive bug must not take the server down
            log.exception("%s function 0x%02X failed", self.dialect.name, function)
            return self.exception_pdu(function, self.dialect.failure_code)
        finally:
            drive.command_port = previous

    def _serve(self, function: int, data: bytes, drive: AcgDrive, now: float, source: object) -> bytes:
        # A PDU is exactly as long as its function says: bytes beyond it (a wrong MBAP length, or
        # data the request does not have) refuse the request with 0x03, which the Modbus
        # Application Protocol gives for "the implied length is incorrect".
        if function not in self.dialect.functions:
            raise ModbusException(ExceptionCode.ILLEGAL_FUNCTION, f"function 0x{function:02X} is not supported")
        # The reply echoes the PDU addresses as they came; the drive is addressed by communication
        # address (``ModbusDialect.address_offset``).
        offset = self.dialect.address_offset
        if function in (FunctionCode.READ_HOLDING_REGISTERS, FunctionCode.READ_INPUT_REGISTERS):
            address, count = _unpack(">HH", data)
            return self._read(drive, address + offset, count)
        if function == FunctionCode.WRITE_SINGLE_REGISTER:
            address, value = _unpack(">HH", data)
            self._write(drive, address + offset, [value], now, source)
            return data
        if function == FunctionCode.WRITE_MULTIPLE_REGISTERS:
            address, count, byte_count = _unpack(">HHB", data[:5])  # the values' length: _values
            values = _values(data[5:], count, byte_count)
            self._write(drive, address + offset, values, now, source)
            return struct.pack(">HH", address, count)
        # FunctionCode.READ_WRITE_MULTIPLE_REGISTERS
        read_address, read_count, write_address, write_count, byte_count = _unpack(">HHHHB", data[:9])
        values = _values(data[9:], write_count, byte_count)
        _check_count(read_count)
        self._check_addresses(drive, read_address + offset, read_count)
        self._write(drive, write_address + offset, values, now, source)  # the write is done before the read
        return self._read(drive, read_address + offset, read_count)

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

    def _write(self, drive: AcgDrive, address: int, values: list[int], now: float, source: object) -> None:
        _check_count(len(values))
        self._check_addresses(drive, address, len(values))
        # Every word is checked against its declaration before any is written.
        raws = []
        for offset, value in enumerate(values):
            register = drive.registers[address + offset]
            if register.access is RegisterAccess.READ:
                raise ModbusException(self.dialect.refusal(RegisterRefusal.READ_ONLY),
                                      f"0x{register.address:04X} is read only")
            raw = register.from_words([value])
            try:
                register.check(raw)
            except RegisterError as exc:
                raise ModbusException(self.dialect.refusal(exc.refusal), str(exc)) from None
            raws.append(raw)
        for offset, raw in enumerate(raws):
            try:
                self.store(drive, address + offset, raw, now, source)
            except RegisterError as exc:
                raise ModbusException(self.dialect.refusal(exc.refusal), str(exc)) from None

    def store(self, drive: AcgDrive, address: int, raw: int, now: float, source: object) -> None:
        """Write one register of a request, checked: the one place a Modbus request changes the drive,
        and so where its observer (``written``) hears of it."""
        drive.write(address, raw, now)
        if self.written is not None:
            self.written(drive, address, raw, now, source)


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


__all__ = ["MAX_WORDS", "RTU_DIALECT", "TCP_DIALECT", "DriveSource", "ExceptionCode", "FunctionCode",
           "ModbusCore", "ModbusDialect", "ModbusException"]
