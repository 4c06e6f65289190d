"""Modbus-RTU live: pymodbus's RTU client (an independent peer) over a pseudo-terminal, the line
served by the event loop in this process or by a ``cipstack adapter`` / ``cipstack fleet`` process."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
import tty
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import pytest

pytest.importorskip("pymodbus", reason="pymodbus, the peer these tests talk to, is not installed: "
                                      "pip install '.[test]'")

from pymodbus import FramerType
from pymodbus.client import AsyncModbusSerialClient, ModbusSerialClient
from pymodbus.exceptions import ModbusIOException

from cipstack.devices.acg.drive import AcgDrive
from cipstack.devices.acg.modbus_rtu import RtuSlave, with_crc
from cipstack.devices.acg.registers import ACG_REGISTERS
from cipstack.modbus.rtu_line import PtyPort, RtuLine
from tests.ports import free_port

pytestmark = pytest.mark.interop

LINE = re.compile(r"^Modbus-RTU on (\S+) \(")


def addr(code: str) -> int:
    return ACG_REGISTERS.by_code(code).address


def pdu(code_or_address: str | int) -> int:
    """The PDU address pymodbus sends for a register: its communication address - 1 (the chapter's
    "Modbus RTU" column numbers it 40000 + address)."""
    address = addr(code_or_address) if isinstance(code_or_address, str) else code_or_address
    return address - 1


@contextlib.asynccontextmanager
async def line_with(drive: AcgDrive) -> AsyncIterator[tuple[RtuLine, RtuSlave]]:
    line = RtuLine(PtyPort())
    slave = RtuSlave(drive, line.port.paced)
    line.add(slave)
    async with line:
        yield line, slave


@contextlib.asynccontextmanager
async def client_of(line: RtuLine, baud: int = 9600) -> AsyncIterator[AsyncModbusSerialClient]:
    client = AsyncModbusSerialClient(port=line.name, framer=FramerType.RTU, baudrate=baud, bytesize=8, parity="N",
                                     stopbits=1, timeout=1, retries=0)
    assert await client.connect()
    try:
        yield client
    finally:
        client.close()


async def test_pymodbus_reads_and_writes_the_register_map_and_gets_the_chapters_exception_codes() -> None:
    drive = AcgDrive(now=0.0)
    async with line_with(drive) as (line, slave), client_of(line) as client:
        reply = await client.read_holding_registers(pdu(0x0300), count=4, device_id=1)
        assert reply.registers == [0x0010, 0x3200, 0x0230, 0x0100]          # monitoring area 0x0300-0x0303
        reply = await client.read_input_registers(pdu(0x0000) + 1, count=1, device_id=1)   # 0x0001
        assert reply.registers == [0]
        assert not (await client.write_register(pdu("ACC"), 25, device_id=1)).isError()
        assert not (await client.write_registers(pdu("bA.70"), [50, 100], device_id=1)).isError()
        assert (await client.read_holding_registers(pdu("ACC"), count=1, device_id=1)).registers == [25]
        assert drive.read(addr("bA.70")) == 50 and drive.read(addr("bA.71")) == 100
        codes = [
            (await client.read_holding_registers(0xFFFF, count=1, device_id=1)).exception_code,   # 0x0000's place
            (await client.write_register(pdu(0x0300), 1, device_id=1)).exception_code,          # read only
            (await client.write_register(pdu("CM.1"), 251, device_id=1)).exception_code,        # 1-250
            (await client.readwrite_registers(read_address=pdu("ACC"), read_count=1, write_address=pdu("dEC"),
                                              values=[5], device_id=1)).exception_code,
        ]
        assert codes == [2, 2, 3, 1]
        assert slave.counters.replies == 9 and slave.counters.crc_errors == 0


async def test_the_virtual_inputs_run_the_drive_over_the_line() -> None:
    """The chapter's example over pymodbus: CM.70 = FX, then 0h0001 at 0h0322 runs forward."""
    drive = AcgDrive(now=0.0)
    async with line_with(drive) as (line, _), client_of(line) as client:
        assert not (await client.write_register(pdu("drv"), 1, device_id=1)).isError()      # Fx/Rx-1
        assert not (await client.write_register(pdu("CM.70"), 1, device_id=1)).isError()    # FX
        assert not (await client.write_register(pdu(0x0322), 0x0001, device_id=1)).isError()
        status = (await client.read_holding_registers(pdu(0x000E), count=1, device_id=1)).registers[0]
        assert status & 0b11 == 0b10                                                          # forward, not stopped
        assert (await client.read_holding_registers(pdu("CM.86"), count=1, device_id=1)).registers == [1]
        assert drive.running_forward


def _raw_slave(path: str) -> int:
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(fd)
    return fd


async def _read_reply(fd: int, within: float) -> bytes:
    end = time.monotonic() + within
    data = b""
    while time.monotonic() < end:
        with contextlib.suppress(BlockingIOError):
            data += os.read(fd, 256)
        await asyncio.sleep(0.005)
    return data


async def test_a_frame_split_across_writes_to_the_pty_is_one_frame_or_two_by_the_gap() -> None:
    """At 1,200 bps (CM.3 = 0) a character is 8.3 ms and a frame ends after 29 ms of silence: a frame
    written in two pieces 2 ms apart is answered; 100 ms apart it is two frames, neither answered."""
    drive = AcgDrive(now=0.0)
    drive.write(addr("CM.3"), 0, 0.0)
    drive.write(addr("CM.5"), 0, 0.0)
    request = with_crc(bytes.fromhex("01 03") + pdu("ACC").to_bytes(2, "big") + bytes.fromhex("0001"))
    async with line_with(drive) as (line, slave):
        fd = _raw_slave(line.name)
        try:
            for _attempt in range(5):        # a gap that the machine's load stretched is tried again
                os.write(fd, request[:3])
                sent = time.monotonic()
                await asyncio.sleep(0.002)
                os.write(fd, request[3:])
                if time.monotonic() - sent < 0.012:
                    break
                await _read_reply(fd, 0.3)
            assert await _read_reply(fd, 0.4) == with_crc(bytes.fromhex("01 03 02 0032"))
            frames = slave.counters.frames
            os.write(fd, request[:3])
            await asyncio.sleep(0.1)
            os.write(fd, request[3:])
            assert await _read_reply(fd, 0.4) == b""
            assert slave.counters.frames == frames + 2
            assert slave.counters.truncated + slave.counters.crc_errors >= 2
        finally:
            os.close(fd)


# -- the command ------------------------------------------------------------------------------------
def _wait_for_line(process: subprocess.Popen[str], timeout: float = 20) -> str:
    """The pty path the process prints (``Modbus-RTU on PATH (...)``), read by a thread so that the
    wait has a timeout."""
    lines: queue.Queue[str] = queue.Queue()

    def pump() -> None:
        assert process.stdout is not None
        for text in process.stdout:
            lines.put(text)

    threading.Thread(target=pump, daemon=True).start()
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            match = LINE.match(lines.get(timeout=0.2))
        except queue.Empty:
            if process.poll() is not None:
                pytest.fail(f"exited: {process.stderr.read() if process.stderr else ''}")
            continue
        if match:
            return match.group(1)
    process.kill()
    pytest.fail("no Modbus-RTU line printed")


@contextlib.contextmanager
def cipstack(*args: str) -> Iterator[str]:
    process = subprocess.Popen([sys.executable, "-m", "cipstack", *args], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    try:
        yield _wait_for_line(process)
    finally:
        process.send_signal(signal.SIGTERM)
        assert process.wait(15) == 0, process.stderr.read() if process.stderr else ""


def adapter(tmp_path: Path, *args: str) -> contextlib.AbstractContextManager[str]:
    return cipstack("adapter", "--port", str(free_port()), "--io-port", "0", "--quiet", "--rtu", "pty",
                    "--state", str(tmp_path / "acg.json"), "--control", str(tmp_path / "control.sock"), *args)


def serial_client(path: str) -> ModbusSerialClient:
    client = ModbusSerialClient(port=path, framer=FramerType.RTU, baudrate=9600, bytesize=8, parity="N", stopbits=1,
                                timeout=1, retries=0)
    assert client.connect()
    return client


def test_a_saved_parameter_survives_a_restart_and_an_unsaved_one_does_not(tmp_path: Path) -> None:
    """ACG RS-485 manual, Saving Parameters Defined by Communication: 0x03E0 from 0 to 1 saves; a value
    written afterwards and not saved reverts at the next power-up. CM.1 from --param: station 5."""
    with adapter(tmp_path, "--param", "CM.1=5") as path:
        client = serial_client(path)
        try:
            assert not client.write_register(pdu("Pr.12"), 2, device_id=5).isError()
            assert not client.write_register(pdu(0x03E0), 1, device_id=5).isError()          # 0 -> 1: save
            assert not client.write_register(pdu("Pr.13"), 55, device_id=5).isError()        # not saved
            assert client.read_holding_registers(pdu("Pr.13"), count=1, device_id=5).registers == [55]
        finally:
            client.close()
    with adapter(tmp_path) as path:
        client = serial_client(path)
        try:
            # CM.1 = 5 was saved with the others: the drive answers at 5 after the restart, and not at 1.
            with pytest.raises(ModbusIOException):                 # no reply at station 1
                client.read_holding_registers(pdu("Pr.12"), count=1, device_id=1)
            assert client.read_holding_registers(pdu("Pr.12"), count=1, device_id=5).registers == [2]
            assert client.read_holding_registers(pdu("Pr.13"), count=1, device_id=5).registers == [
                ACG_REGISTERS.by_code("Pr.13").default]
        finally:
            client.close()
        # The port's counters, over the control socket: the frame for station 1 was heard, not answered.
        status = subprocess.run([sys.executable, "-m", "cipstack", "drive", "status", "--control",
                                 str(tmp_path / "control.sock"), "--json"], capture_output=True, text=True, timeout=30)
        rtu = json.loads(status.stdout)["rtu"]
        assert rtu["device"] == path
        assert (rtu["frames"], rtu["replies"], rtu["other_station"], rtu["crc_errors"]) == (3, 2, 1, 0)


def test_a_multi_drop_line_of_drives_answers_by_station_id(tmp_path: Path) -> None:
    """ACG RS-485 manual, Multi-drop Link System: three drives on one line, each answers its own ID."""
    with cipstack("fleet", "--device", "acg*3", "--addresses", "127.0.0.61-127.0.0.63", "--port", str(free_port()),
                  "--io-port", "0", "--state-dir", str(tmp_path), "--rtu", "pty") as path:
        client = serial_client(path)
        try:
            for station in (1, 2, 3):
                assert not client.write_register(pdu("ACC"), 10 * station, device_id=station).isError()
            for station in (1, 2, 3):
                reply = client.read_holding_registers(pdu("CM.1"), count=1, device_id=station)
                assert reply.registers == [station]
                assert client.read_holding_registers(pdu("ACC"), count=1, device_id=station).registers == [
                    10 * station]
            with pytest.raises(ModbusIOException):                 # no drive at station 4
                client.read_holding_registers(pdu("ACC"), count=1, device_id=4)
            # A broadcast (station 0) write: every drive executes it, none answers.
            fd = _raw_slave(path)
            try:
                os.write(fd, with_crc(bytes.fromhex("00 06") + pdu("ACC").to_bytes(2, "big") + b"\x00\x63"))
                time.sleep(0.3)                # the subject: no answer comes in this window
                with contextlib.suppress(BlockingIOError):
                    assert os.read(fd, 256) == b""
            finally:
                os.close(fd)
            for station in (1, 2, 3):
                assert client.read_holding_registers(pdu("ACC"), count=1, device_id=station).registers == [99]
        finally:
            client.close()


def test_more_drives_than_a_line_takes_is_one_line_and_exit_2(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "cipstack", "fleet", "--device", "acg*17", "--addresses",
                             "127.0.0.100-127.0.0.116", "--state-dir", str(tmp_path), "--rtu", "pty"],
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "cipstack fleet: --rtu: 17 ACG drives, but an RS-485 line takes at most 16 (ACG RS-485 manual, Communication "
        "Standards)"]


def test_a_device_that_cannot_be_opened_is_one_line_naming_it(tmp_path: Path) -> None:
    missing = tmp_path / "ttyUSB9"
    result = subprocess.run([sys.executable, "-m", "cipstack", "adapter", "--port", str(free_port()), "--io-port", "0",
                             "--quiet", "--rtu", str(missing), "--state", str(tmp_path / "acg.json")],
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        f"cipstack adapter: cannot open serial device {missing}: No such file or directory"]


def test_a_serial_device_without_pyserial_names_the_extra(tmp_path: Path) -> None:
    """pyserial is an extra: without it, --rtu DEVICE says which to install (--rtu pty needs none)."""
    script = ("import sys; sys.modules['serial'] = None\n"
              "from cipstack.cli import main\n"
              f"sys.exit(main(['adapter', '--port', '{free_port()}', '--io-port', '0', '--quiet', '--rtu', "
              f"'/dev/ttyUSB0', '--state', {str(tmp_path / 'acg.json')!r}]))")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=30)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "cipstack adapter: --rtu /dev/ttyUSB0 needs pyserial: pip install 'cipstack[rtu]' (--rtu pty needs nothing)"]


async def test_a_serial_device_is_served_through_pyserial() -> None:
    """``--rtu DEVICE``: pyserial opens the device at the CM.3/CM.4 settings (here the slave side of a
    pty this test holds the master of, which takes a serial port's settings); its UART would time
    the bytes, so the reply is written CM.5 after the frame ended, unpaced."""
    from cipstack.devices.acg.modbus_rtu import LineSettings
    from cipstack.modbus.rtu_line import SerialDevicePort

    master, slave_fd = os.openpty()
    try:
        os.set_blocking(master, False)
        drive = AcgDrive(now=0.0)
        drive.write(addr("CM.1"), 9, 0.0)
        drive.write(addr("CM.4"), 2, 0.0)                    # D8/PE/S1
        port = SerialDevicePort(os.ttyname(slave_fd), LineSettings.from_drive(drive))
        assert not port.paced and port.serial.parity == "E" and port.serial.baudrate == 9600
        line = RtuLine(port)
        slave = RtuSlave(drive, port.paced)
        line.add(slave)
        async with line:
            request = with_crc(bytes.fromhex("09 03") + pdu("ACC").to_bytes(2, "big") + bytes.fromhex("0001"))
            os.write(master, request)
            assert await _read_reply(master, 0.5) == with_crc(bytes.fromhex("09 03 02 0032"))
            assert slave.counters.replies == 1
            os.write(master, with_crc(bytes.fromhex("09 06") + pdu("CM.3").to_bytes(2, "big") + b"\x00\x07"))
            await _read_reply(master, 0.3)
            assert port.serial.baudrate == 115200                 # CM.3 = 7 applied to the device
    finally:
        os.close(master)
        os.close(slave_fd)


async def test_a_flood_on_the_pty_is_dropped_and_the_line_answers_a_frame_after_it() -> None:
    """Noise at the pty as fast as it takes it, for a while: dropped at line rate (counted as overrun),
    never queued, so a request soon after the noise stops is answered (it was deaf for days before)."""
    drive = AcgDrive(now=0.0)
    request = with_crc(bytes.fromhex("01 03") + pdu("ACC").to_bytes(2, "big") + bytes.fromhex("0001"))
    async with line_with(drive) as (line, slave):
        fd = _raw_slave(line.name)
        try:
            noise = os.urandom(4096)
            until = time.monotonic() + 0.5
            sent = 0
            while time.monotonic() < until and sent < 4_000_000:      # bounded in time and in bytes
                with contextlib.suppress(BlockingIOError):
                    sent += os.write(fd, noise)
                await asyncio.sleep(0)
            assert sent > 100_000
            await asyncio.sleep(0.5)                                   # > one largest frame at 9,600 bps
            await _read_reply(fd, 0.1)                                 # whatever the noise made it answer
            os.write(fd, request)
            assert await _read_reply(fd, 1.0) == with_crc(bytes.fromhex("01 03 02 0032"))
            assert slave.counters.overrun > 90_000
        finally:
            os.close(fd)
