"""Modbus-RTU on the drive's built-in RS-485 port (ACG RS-485 manual, "Modbus-RTU Protocol"), sans I/O:
bytes and the time they arrived in, frames and replies with the time they leave out.

* Line settings: CM.1 station ID (1-250), CM.3 baud rate, CM.4 data/parity/stop bits, CM.5
  response delay (ACG RS-485 manual, Setting Communication Parameters). A character is a start bit, 8 data
  bits, the parity bit if any and the stop bits: 10 or 11 bits at the CM.3 rate.
* Framing: a frame ends at a silence of 3.5 character times, fixed at 1.75 ms above 19,200 bps
  (Modbus over serial line, V1.02, 2.5.1.1). The silence is measured from the end of the last byte
  heard to the next read: on a serial device a read's bytes have arrived when it is made; on a pty,
  which moves bytes at once, the slave models them on a line at its CM.3 rate (``RtuFramer``). On a
  pty the 1.5-character rule applies too (2.5.1.1: a silence of more than t1.5 inside a frame makes
  it incomplete, discarded; 0.75 ms above 19,200 bps), measured between the modelled end of the
  bytes heard and the next read; on a serial device it is the UART's, since a read holds many
  characters whose own spacing is not known. A frame longer than 256 bytes (the largest RTU frame)
  is dropped whole, up to the next silence.
* Bounded input: a line carries one character per character time. Bytes that come through a pty
  faster than that, beyond one largest frame ahead of the present, could not have come off a line
  (a UART would overrun): they are dropped and counted (``overrun``), never queued, so the line is
  free again within one frame time after a flood stops.
* Checks, in the order a slave makes them: a frame shorter than its function needs is truncated;
  a frame whose CRC-16 (polynomial 0xA001 reflected, initial 0xFFFF, low byte first) does not
  match is a CRC error; a frame for another station ID is not ours. None of them is answered;
  each is counted (``RtuCounters``). Station 0 is a broadcast: a write is executed, nothing answers.
* Addresses: a request's PDU address is the communication address minus one (the "Modbus RTU"
  column, 40000 + address; the chapter's example writes 0x1246 at "0x1246-1"), ``modbus_core``.
* Reply: station ID, the PDU of the Modbus layer (``modbus_core``, the RS-485 dialect) and the CRC,
  released CM.5 after the request's frame ended; on a pty, written when its last character would have
  left a real UART at the CM.3 rate (a pty moves bytes at once: the slave paces itself).
* A change of CM.1-CM.5 takes effect from the next frame: the reply to the write that changes them
  goes out as the request came in (ACG RS-485 manual gives no other rule; CM.94 gates CM.7 and CM.10-CM.24
  only, ACG-ET2 manual).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, field, fields

from .drive import AcgDrive
from .modbus_core import RTU_DIALECT, ExceptionCode, FunctionCode, ModbusCore, RegisterWritten
from .registers import ACG_REGISTERS

#: CM.3 settings (ACG RS-485 manual, Communication Parameters Setting Details; "56 Kbps" and "115 Kbps" are
#: the 57,600 and 115,200 bps of the Communication Standards table).
BAUD_RATES = {0: 1200, 1: 2400, 2: 4800, 3: 9600, 4: 19200, 5: 38400, 6: 57600, 7: 115200}
#: CM.4 settings: (data bits, parity, stop bits).
FRAMINGS = {0: (8, "N", 1), 1: (8, "N", 2), 2: (8, "E", 1), 3: (8, "O", 1)}
#: Above this rate the frame-end silence is fixed (Modbus over serial line V1.02, 2.5.1.1).
FIXED_SILENCE_ABOVE = 19200
FIXED_SILENCE = 0.00175
#: t1.5 above 19,200 bps (Modbus over serial line V1.02, 2.5.1.1).
FIXED_INTERCHARACTER = 0.00075
#: The largest RTU frame: address, 253-byte PDU, CRC (Modbus over serial line V1.02, 2.5.1).
MAX_FRAME = 256
#: "Number of connected drives: Maximum of 16 drives" (ACG RS-485 manual, Communication Standards).
MAX_DRIVES_PER_LINE = 16
BROADCAST = 0
#: Rounding room when a silence is compared with t3.5 (times are float seconds).
_EPSILON = 1e-9

_CM = {n: ACG_REGISTERS.by_code(f"CM.{n}").address for n in (1, 3, 4, 5)}


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes) -> int:
    """CRC-16/MODBUS: reflected polynomial 0xA001, initial value 0xFFFF, no final XOR."""
    crc = 0xFFFF
    for byte in data:
        crc = (crc >> 8) ^ _CRC_TABLE[(crc ^ byte) & 0xFF]
    return crc


def with_crc(frame: bytes) -> bytes:
    """``frame`` followed by its CRC, low byte first."""
    return frame + struct.pack("<H", crc16(frame))


@dataclass(frozen=True)
class LineSettings:
    """What CM.1, CM.3, CM.4 and CM.5 set."""

    station: int = 1
    baud: int = 9600
    data_bits: int = 8
    parity: str = "N"
    stop_bits: int = 1
    #: CM.5 Resp Delay, seconds.
    response_delay: float = 0.005

    @classmethod
    def from_drive(cls, drive: AcgDrive) -> LineSettings:
        values = {n: drive.read(address) for n, address in _CM.items()}
        data_bits, parity, stop_bits = FRAMINGS[values[4]]
        return cls(values[1], BAUD_RATES[values[3]], data_bits, parity, stop_bits, values[5] / 1000)

    @property
    def bits_per_character(self) -> int:
        return 1 + self.data_bits + (self.parity != "N") + self.stop_bits

    @property
    def character_time(self) -> float:
        return self.bits_per_character / self.baud

    @property
    def frame_silence(self) -> float:
        """t3.5: the silence that ends a frame."""
        return FIXED_SILENCE if self.baud > FIXED_SILENCE_ABOVE else 3.5 * self.character_time

    @property
    def intercharacter_silence(self) -> float:
        """t1.5: the longest silence a frame may hold between two of its characters."""
        return FIXED_INTERCHARACTER if self.baud > FIXED_SILENCE_ABOVE else 1.5 * self.character_time

    def transmission_time(self, size: int) -> float:
        """How long ``size`` bytes take on the line."""
        return size * self.character_time

    @property
    def mode(self) -> str:
        """CM.4 as the keypad shows it: D8/PN/S1."""
        return f"D{self.data_bits}/P{self.parity}/S{self.stop_bits}"

    def describe(self) -> str:
        return (f"station {self.station}, {self.baud:,} bps, {self.mode}, response delay "
                f"{round(self.response_delay * 1000)} ms")


@dataclass
class RtuCounters:
    """What a slave made of the frames on its line (a refused frame moves nothing else)."""

    frames: int = 0          # every frame the silence ended
    replies: int = 0
    broadcasts: int = 0      # station 0 frames executed (writes) or ignored (reads), unanswered
    other_station: int = 0
    crc_errors: int = 0
    truncated: int = 0
    oversize: int = 0
    #: Frames with a silence of more than t1.5 inside them (pty only), discarded.
    interrupted: int = 0
    #: Bytes that came faster than the line carries them (a pty flood), dropped.
    overrun: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class RtuFramer:
    """Splits the bytes of a line into frames by the silences between them (sans I/O).

    ``character_time`` given to ``feed`` is how long a byte takes on the line as the framer models
    it: 0 where the bytes come from a UART, which delivers each once it has been on the line (a read
    at ``now`` ends at ``now``); the line's character time where they come through a pty, which moves
    them at once: the bytes of a read are then on a modelled line from the read on (or from the end
    of the bytes before them, if those are still going out), and the silence is counted from the
    moment the last of them would have arrived."""

    def __init__(self, counters: RtuCounters | None = None) -> None:
        self.counters = counters if counters is not None else RtuCounters()
        self._buffer = bytearray()
        self._last: float | None = None     # when the last byte of the frame being heard ends
        self._oversize = False
        self._interrupted = False

    def feed(self, data: bytes, now: float, silence: float, character_time: float = 0.0,
             intercharacter: float | None = None) -> list[tuple[bytes, float]]:
        """Bytes read at ``now``; returns the frames (with the time they ended) that a silence of
        at least ``silence`` before them ended. With ``character_time`` (a pty) the bytes are modelled
        on the line, at most one largest frame ahead of ``now`` (the rest is an overrun, dropped), and
        a silence of more than ``intercharacter`` (t1.5) inside a frame makes it incomplete."""
        frames = self.poll(now, silence) if self._last is not None and now - self._last >= silence - _EPSILON else []
        if not data:
            return frames
        if character_time > 0:
            if self._last is not None and intercharacter is not None and now - self._last > intercharacter + _EPSILON:
                self._interrupted = True
            start = now if self._last is None else max(now, self._last)
            fits = max(0, int((now + MAX_FRAME * character_time - start) / character_time + _EPSILON))
            if len(data) > fits:
                self.counters.overrun += len(data) - fits
                self._interrupted = True     # characters were lost: the frame is not whole
                data = data[:fits]
                if not data:
                    return frames
            self._last = start + len(data) * character_time
        else:
            self._last = now
        if self._oversize or len(self._buffer) + len(data) > MAX_FRAME:
            self._oversize = True           # dropped whole, up to the next silence
            self._buffer.clear()
        else:
            self._buffer += data
        return frames

    def deadline(self, silence: float) -> float | None:
        """When the frame being heard ends if nothing more comes (None: none is)."""
        return None if self._last is None else self._last + silence

    def poll(self, now: float, silence: float) -> list[tuple[bytes, float]]:
        """The frame that a silence up to ``now`` ended, with its end (last byte + ``silence``)."""
        if self._last is None or now - self._last < silence - _EPSILON:
            return []
        end = self._last + silence
        frame, oversize, interrupted = bytes(self._buffer), self._oversize, self._interrupted
        self._buffer.clear()
        self._last = None
        self._oversize = self._interrupted = False
        self.counters.frames += 1
        if oversize:
            self.counters.oversize += 1
            return []
        if interrupted:
            self.counters.interrupted += 1
            return []
        return [(frame, end)]


def expected_length(frame: bytes) -> int | None:
    """The length a request of the frame's function has (None: not known from its first bytes)."""
    if len(frame) < 2:
        return 4
    function = frame[1]
    if function in (FunctionCode.READ_HOLDING_REGISTERS, FunctionCode.READ_INPUT_REGISTERS,
                     FunctionCode.WRITE_SINGLE_REGISTER):
        return 8
    if function == FunctionCode.WRITE_MULTIPLE_REGISTERS:
        return 9 + frame[6] if len(frame) > 6 else 9
    return None


_WRITES = frozenset({FunctionCode.WRITE_SINGLE_REGISTER, FunctionCode.WRITE_MULTIPLE_REGISTERS})


@dataclass
class Reply:
    """A reply and when to write it: the request's frame end + CM.5 + the reply's own time on the line."""

    frame: bytes
    due: float
    #: The request it answers (an exception reply is made of it if the drive's save fails).
    request: bytes = field(repr=False, default=b"")


class RtuSlave:
    """One drive on an RS-485 line, sans I/O: frames the bytes it hears with its own line settings
    and answers the frames for its station ID.

    ``paced``: the line moves bytes at once (a pty), so the slave times them at its CM.3 rate itself:
    a request is heard as it would come off the line (``RtuFramer``), and a reply is due when its
    last character would have left the UART. Unpaced (a serial device, whose UART does both), a
    reply is due when it is to start."""

    def __init__(self, drive: AcgDrive | Callable[[], AcgDrive], paced: bool = False,
                 written: RegisterWritten | None = None) -> None:
        self.paced = paced
        self.core = ModbusCore(drive, RTU_DIALECT, written)
        self.counters = RtuCounters()
        self.framer = RtuFramer(self.counters)

    @property
    def drive(self) -> AcgDrive:
        return self.core.drive

    def forget_input(self) -> None:
        """Drop a frame half heard: the slave lost power, and what it had heard with it."""
        self.framer = RtuFramer(self.counters)

    @property
    def settings(self) -> LineSettings:
        return LineSettings.from_drive(self.core.drive)

    def feed(self, data: bytes, now: float) -> list[Reply]:
        """Bytes heard on the line at ``now``; the replies of the frames they ended."""
        settings = self.settings
        if self.paced:
            frames = self.framer.feed(data, now, settings.frame_silence, settings.character_time,
                                      settings.intercharacter_silence)
        else:
            frames = self.framer.feed(data, now, settings.frame_silence)
        return self._serve(frames, settings)

    def deadline(self) -> float | None:
        """When the frame being heard ends if the line stays silent."""
        return self.framer.deadline(self.settings.frame_silence)

    def poll(self, now: float) -> list[Reply]:
        settings = self.settings
        return self._serve(self.framer.poll(now, settings.frame_silence), settings)

    def _serve(self, frames: list[tuple[bytes, float]], settings: LineSettings) -> list[Reply]:
        replies = []
        for frame, end in frames:
            answer = self.handle_frame(frame, end, settings)
            if answer is not None:
                on_line = settings.transmission_time(len(answer)) if self.paced else 0.0
                replies.append(Reply(answer, end + settings.response_delay + on_line, frame))
        return replies

    def handle_frame(self, frame: bytes, now: float, settings: LineSettings | None = None) -> bytes | None:
        """One whole frame heard at ``now``; its reply (None: none is sent)."""
        settings = settings or self.settings
        counters = self.counters
        expected = expected_length(frame)
        if len(frame) < 4 or (expected is not None and len(frame) < expected):
            counters.truncated += 1
            return None
        if crc16(frame[:-2]) != int.from_bytes(frame[-2:], "little"):
            counters.crc_errors += 1
            return None
        station = frame[0]
        if station == BROADCAST:
            counters.broadcasts += 1
            if frame[1] in _WRITES:          # "write functions only; every slave executes"
                self.core.handle_pdu(frame[1:-2], now, station)
            return None
        if station != settings.station:
            counters.other_station += 1
            return None
        counters.replies += 1
        return with_crc(frame[:1] + self.core.handle_pdu(frame[1:-2], now, station))

    def exception_reply(self, request: bytes, code: ExceptionCode) -> bytes:
        """The exception reply to ``request`` (e.g. 06 for a save the state file did not take)."""
        function = request[1] if len(request) > 1 else 0
        return with_crc(request[:1] + self.core.exception_pdu(function, code))


__all__ = ["BAUD_RATES", "BROADCAST", "FRAMINGS", "MAX_DRIVES_PER_LINE", "MAX_FRAME", "LineSettings", "Reply",
           "RtuCounters", "RtuFramer", "RtuSlave", "crc16", "expected_length", "with_crc"]
