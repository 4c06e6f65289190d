"""The asyncio shell of Modbus-RTU: one RS-485 line, a pseudo-terminal or a serial device, with one drive
or several (a multi-drop line, as many as the drives' family declares: ``RtuPort.max_drives``). Each
drive's sans-I/O slave is its family's (``RtuPort.slave``): the shell knows no register map.

The line's file descriptor is watched by the event loop (``add_reader``): a read takes what the
driver holds, without blocking, and every drive on the line hears it, as every station on a bus
does; each frames it with its own line settings and answers only its own station ID. Frame ends,
response delays and the drives' own timers (lost command) are loop timers. A reply is written in
one piece, without blocking; what the driver cannot take at once waits for the descriptor to
become writable (``add_writer``), and a line whose output stays blocked drops replies past a bound
rather than keep them. A request that saves parameters is answered once the state file took the
save (off the loop, ``StateWriter``); a save it did not take is answered with exception 06.
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import logging
import os
import tty
from typing import Any, Protocol

from ..devices.state import StateFileError, StateWriter
from ..errors import BadRequest, CipstackError

log = logging.getLogger(__name__)

#: Bytes taken per read: more than any frame, so a burst of them is read in a few calls.
READ_SIZE = 4096
#: Bytes of replies the line holds while its output is blocked (a reader that stopped reading).
MAX_PENDING_OUTPUT = 16 * 1024
#: Replies waiting for their moment (the response delay): a master waits for each, so a few at most.
MAX_QUEUED_REPLIES = 64


#: Modbus exception code 06, Slave Device Busy (Modbus Application Protocol, section 7): a save the
#: state file did not take.
SLAVE_DEVICE_BUSY = 0x06


class LineSettings(Protocol):
    """A drive's line settings, as its family's slave reads them from the drive's registers."""

    station: int
    baud: int
    data_bits: int
    parity: str
    stop_bits: int

    def describe(self) -> str: ...


class Reply(Protocol):
    """A reply and when to write it; ``request``: the frame it answers."""

    frame: bytes
    due: float
    request: bytes


class Slave(Protocol):
    """One drive on the line, sans I/O: its family's Modbus-RTU slave (``RtuPort.slave``)."""

    @property
    def settings(self) -> Any: ...

    @property
    def drive(self) -> Any: ...

    @property
    def counters(self) -> Any:
        """What the slave counted (frames, CRC errors, replies), for the metrics and the runtime."""

    def feed(self, data: bytes, now: float) -> list[Any]: ...

    def poll(self, now: float) -> list[Any]: ...

    def deadline(self) -> float | None: ...

    def forget_input(self) -> None: ...

    def exception_reply(self, request: bytes, code: Any) -> bytes: ...


class RtuPortError(CipstackError):
    """A serial device that cannot be opened (one line naming it), or pyserial missing for one."""


class LinePort(Protocol):
    name: str
    #: The line moves bytes at once (a pty): the drives time them at their CM.3 rate themselves.
    paced: bool

    def fileno(self) -> int: ...

    def configure(self, settings: LineSettings) -> None: ...

    def close(self) -> None: ...


class PtyPort:
    """A pseudo-terminal pair: the emulator holds the master side, a client opens ``name``, the
    slave side (what pyserial, a test or ``socat`` opens as if it were a serial port). A pty has
    no baud rate: the slaves pace themselves by their CM.3 setting."""

    paced = True

    def __init__(self) -> None:
        self._master, self._slave = os.openpty()
        # Raw, no echo: the bytes pass as they are, and a reply is not echoed back as a request.
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.name = os.ttyname(self._slave)

    def fileno(self) -> int:
        return self._master

    def configure(self, settings: LineSettings) -> None:
        pass    # nothing to set on a pty: the slaves time the line themselves

    def close(self) -> None:
        # The slave side stays open while the line is served: with no slave open, a read of the
        # master fails (EIO) for as long as no client holds the path.
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)


class SerialDevicePort:
    """A serial device (``/dev/ttyUSB0``) through pyserial, set to the line settings."""

    paced = False

    def __init__(self, path: str, settings: LineSettings) -> None:
        try:
            import serial
        except ImportError:
            raise RtuPortError(f"--rtu {path} needs pyserial: pip install 'cipstack[rtu]' "
                               "(--rtu pty needs nothing)") from None
        self._serial_module = serial
        try:
            self.serial = serial.Serial(path, **self._options(settings), timeout=0, write_timeout=0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise RtuPortError(f"cannot open serial device {path}: {_reason(exc)}") from None
        self.name = path
        os.set_blocking(self.serial.fileno(), False)

    def _options(self, settings: LineSettings) -> dict[str, Any]:
        serial = self._serial_module
        parity = {"N": serial.PARITY_NONE, "E": serial.PARITY_EVEN, "O": serial.PARITY_ODD}[settings.parity]
        return {"baudrate": settings.baud, "bytesize": settings.data_bits, "parity": parity,
                "stopbits": settings.stop_bits}

    def fileno(self) -> int:
        return int(self.serial.fileno())

    def configure(self, settings: LineSettings) -> None:
        self.serial.apply_settings(self._options(settings))

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.serial.close()


def _reason(exc: BaseException) -> str:
    """The reason alone: pyserial's exception repeats the path around the errno's text."""
    number = getattr(exc, "errno", None)
    if isinstance(number, int) and number > 0:
        return os.strerror(number)
    return " ".join(str(getattr(exc, "strerror", None) or exc).split())


def open_port(device: str, settings: LineSettings) -> LinePort:
    """``pty``: a new pseudo-terminal; else the serial device at that path (``RtuPortError`` if not)."""
    return PtyPort() if device == "pty" else SerialDevicePort(device, settings)


class _Station:
    """One drive on the line: its sans-I/O slave, its state writer and its own timer."""

    def __init__(self, slave: Slave, saves: StateWriter | None) -> None:
        self.slave = slave
        self.saves = saves
        self.drive_timer: asyncio.TimerHandle | None = None


class RtuLine:
    """An RS-485 line served by the drives added to it (``add``), up to ``max_drives`` (``source`` says
    where that bound comes from, for the message that refuses one more)."""

    def __init__(self, port: LinePort, max_drives: int = 1, source: str = "") -> None:
        self.port = port
        self.max_drives = max_drives
        self.source = source
        self.stations: list[_Station] = []
        self.loop: asyncio.AbstractEventLoop | None = None
        self._frame_timer: asyncio.TimerHandle | None = None
        self._output = bytearray()
        self._writing = False
        self._tasks: set[asyncio.Task[None]] = set()
        self._settings: LineSettings | None = None
        #: Replies dropped because the line's output stayed blocked.
        self.dropped_replies = 0
        self._queue: list[tuple[float, int, bytes]] = []
        self._sequence = 0
        self._send_timer: asyncio.TimerHandle | None = None
        self._closed = False
        #: The drives on the line have power: they hear and answer. Without it the tty stays open (the
        #: client's side of a pty never sees the line vanish) and whatever comes is read and dropped.
        self.powered = True

    @property
    def name(self) -> str:
        return self.port.name

    def add(self, slave: Slave, saves: StateWriter | None = None) -> Slave:
        """Put a drive's slave on the line (made with this line's ``port.paced``); ``saves``: its state
        writer, whose saves the replies wait for."""
        if len(self.stations) >= self.max_drives:
            raise BadRequest(f"an RS-485 line takes at most {self.max_drives} drives"
                             + (f" ({self.source})" if self.source else ""))
        self.stations.append(_Station(slave, saves))
        return slave

    @property
    def slaves(self) -> list[Slave]:
        return [s.slave for s in self.stations]

    async def start(self) -> None:
        self.loop = asyncio.get_running_loop()
        self._configure()
        self.loop.add_reader(self.port.fileno(), self._on_readable)
        for station in self.stations:
            log.info("Modbus-RTU on %s: %s", self.name, station.slave.settings.describe())

    def _configure(self) -> None:
        """Set the device to the first drive's settings when they changed (CM.3/CM.4)."""
        if not self.stations:
            return
        settings = self.stations[0].slave.settings
        if settings != self._settings:
            self._settings = settings
            try:
                self.port.configure(settings)
            except Exception as exc:  # a setting the device refuses: keep serving at the old one
                log.warning("Modbus-RTU on %s: cannot apply %s: %s", self.name, settings.describe(), exc)

    # -- input -------------------------------------------------------------------------------------
    def _on_readable(self) -> None:
        assert self.loop is not None
        try:
            data = os.read(self.port.fileno(), READ_SIZE)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            log.debug("Modbus-RTU on %s: read: %s", self.name, exc)
            return
        if not data or not self.powered:
            return
        now = self.loop.time()
        for station in self.stations:
            submitted = station.saves.submitted if station.saves is not None else 0
            self._answer(station, station.slave.feed(data, now), submitted)
        self._rearm_frames()

    def _rearm_frames(self) -> None:
        """A timer at the earliest frame end (the silence after the last byte heard)."""
        assert self.loop is not None
        if self._frame_timer is not None:
            self._frame_timer.cancel()
            self._frame_timer = None
        deadlines = [d for d in (s.slave.deadline() for s in self.stations) if d is not None]
        if deadlines:
            self._frame_timer = self.loop.call_at(min(deadlines), self._on_frame_timer)

    def _on_frame_timer(self) -> None:
        assert self.loop is not None
        self._frame_timer = None
        now = self.loop.time()
        for station in self.stations:
            submitted = station.saves.submitted if station.saves is not None else 0
            self._answer(station, station.slave.poll(now), submitted)
        self._rearm_frames()

    # -- replies -----------------------------------------------------------------------------------
    def _answer(self, station: _Station, replies: list[Reply], submitted: int) -> None:
        """Send ``replies``; if the frames they answer saved (the writer took a save since
        ``submitted``), once the state file has it."""
        saves = station.saves
        saved = saves is not None and saves.submitted != submitted and saves.last is not None
        for reply in replies:
            if saved:
                assert saves is not None
                task = asyncio.ensure_future(self._after_save(station, reply, saves.last))
                self._tasks.add(task)
                task.add_done_callback(self._tasks.discard)
            else:
                self._send_at(reply.due, reply.frame)
        self._rearm_drive(station)
        self._configure()

    async def _after_save(self, station: _Station, reply: Reply, save: Any) -> None:
        frame = reply.frame
        try:
            await asyncio.wrap_future(save)
        except StateFileError as exc:
            log.debug("Modbus-RTU: %s", exc)
            frame = station.slave.exception_reply(reply.request, SLAVE_DEVICE_BUSY)
        self._send_at(reply.due, frame)

    def _send_at(self, due: float, frame: bytes) -> None:
        """Write ``frame`` at ``due`` (a bounded queue: a flood of requests cannot grow it)."""
        assert self.loop is not None
        if self._closed or not self.powered:
            return
        if len(self._queue) >= MAX_QUEUED_REPLIES:
            self.dropped_replies += 1
            return
        self._sequence += 1
        heapq.heappush(self._queue, (due, self._sequence, frame))
        if self._send_timer is None or due < self._send_timer.when():
            if self._send_timer is not None:
                self._send_timer.cancel()
            self._send_timer = self.loop.call_at(due, self._on_send_timer)

    def _on_send_timer(self) -> None:
        assert self.loop is not None
        self._send_timer = None
        now = self.loop.time()
        while self._queue and self._queue[0][0] <= now:
            self._write(heapq.heappop(self._queue)[2])
        if self._queue:
            self._send_timer = self.loop.call_at(self._queue[0][0], self._on_send_timer)

    def _write(self, frame: bytes) -> None:
        if len(self._output) + len(frame) > MAX_PENDING_OUTPUT:
            self.dropped_replies += 1
            return
        self._output += frame
        self._flush()

    def _flush(self) -> None:
        assert self.loop is not None
        fd = self.port.fileno()
        try:
            written = os.write(fd, self._output)
        except (BlockingIOError, InterruptedError):
            written = 0
        except OSError as exc:
            log.debug("Modbus-RTU on %s: write: %s", self.name, exc)
            self._output.clear()
            written = 0
        del self._output[:written]
        if self._output and not self._writing:
            self._writing = True
            self.loop.add_writer(fd, self._on_writable)
        elif not self._output and self._writing:
            self._writing = False
            self.loop.remove_writer(fd)

    def _on_writable(self) -> None:
        self._flush()

    # -- the drives' own timers --------------------------------------------------------------------
    def _rearm_drive(self, station: _Station) -> None:
        """A timer at the drive's next deadline (the RS-485 lost-command timer, a ramp's end)."""
        assert self.loop is not None
        if station.drive_timer is not None:
            station.drive_timer.cancel()
            station.drive_timer = None
        deadline = station.slave.drive.next_deadline()
        if deadline is not None:
            station.drive_timer = self.loop.call_at(deadline, self._on_drive_timer, station)

    def _on_drive_timer(self, station: _Station) -> None:
        assert self.loop is not None
        station.drive_timer = None
        drive = station.slave.drive
        drive.advance(max(self.loop.time(), drive.time))
        self._rearm_drive(station)

    def power_off(self) -> None:
        """The drives lose power: nothing is answered, nothing half heard or queued is kept, until
        ``power_on``."""
        self.powered = False
        self._queue.clear()
        self._output.clear()
        for timer in (self._frame_timer, self._send_timer):
            if timer is not None:
                timer.cancel()
        self._frame_timer = self._send_timer = None
        for station in self.stations:
            station.slave.forget_input()

    def power_on(self) -> None:
        self.powered = True

    async def close(self) -> None:
        self._closed = True
        self._queue.clear()
        if self.loop is not None:
            with contextlib.suppress(Exception):
                self.loop.remove_reader(self.port.fileno())
            if self._writing:
                with contextlib.suppress(Exception):
                    self.loop.remove_writer(self.port.fileno())
        for timer in (self._frame_timer, self._send_timer, *(s.drive_timer for s in self.stations)):
            if timer is not None:
                timer.cancel()
        for task in list(self._tasks):
            task.cancel()
        self.port.close()

    async def __aenter__(self) -> RtuLine:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()


__all__ = ["LinePort", "PtyPort", "RtuLine", "RtuPortError", "SerialDevicePort", "open_port"]
