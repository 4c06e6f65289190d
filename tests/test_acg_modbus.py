"""Modbus TCP of the ACG-ET2 (ACG-ET2 manual, "Modbus TCP Frame"): the wire bytes from a scripted peer, and
pymodbus's client, an independent peer (marked ``interop``), with the same drive served over CIP."""

from __future__ import annotations

import asyncio
import socket
import struct
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.catalog import Catalog
from cipstack.devices.acg.device import AcgDevice, build_acg_device
from cipstack.devices.acg.drive import MODBUS_SILENCE_TIME, AcgDrive, Trip
from cipstack.devices.acg.modbus import MbapBuffer, ModbusTcpCore
from cipstack.devices.acg.registers import ACG_REGISTERS, CLASS_64_INSTANCES, modbus_tcp_number
from cipstack.modbus.tcp_server import ModbusTcpServer
from cipstack.scanner import Scanner
from tests.optional import needs

if TYPE_CHECKING:
    from pymodbus.client import AsyncModbusTcpClient

UNIT = 0xFF  # "The address is fixed to 0xFF when Modbus TCP communication is used alone."


def addr(code: str) -> int:
    return ACG_REGISTERS.by_code(code).address


def pdu_address(tcp_number: int) -> int:
    """The PDU address of a register numbered as the manual's "Modbus TCP" column."""
    return tcp_number - 40001


@dataclass
class Bench:
    device: AcgDevice
    scanner: Scanner
    client: AsyncModbusTcpClient
    state_file: Path


@pytest.fixture
async def modbus_port() -> AsyncIterator[int]:
    """A Modbus TCP server of a fresh ACG drive, for a scripted peer."""
    device = build_acg_device()
    async with ModbusTcpServer(ModbusTcpCore(lambda: device.drive), "127.0.0.1", 0) as modbus:
        yield modbus.port


@pytest.fixture
async def bench(tmp_path: Path) -> AsyncIterator[Bench]:
    client_class = needs("pymodbus.client").AsyncModbusTcpClient
    state_file = tmp_path / "acg.json"
    device = build_acg_device(state_path=state_file)
    async with Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0), device=device) as adapter, \
            ModbusTcpServer(ModbusTcpCore(lambda: device.drive), "127.0.0.1", 0, saves=device.saves) as modbus:
        scanner = await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=Catalog(device.catalog_classes()))
        client = client_class("127.0.0.1", port=modbus.port, timeout=3)
        assert await client.connect()
        try:
            yield Bench(device, scanner, client, state_file)
        finally:
            client.close()
            await scanner.close()


async def read(client: AsyncModbusTcpClient, address: int, count: int = 1, function: int = 3) -> list[int]:
    call = client.read_holding_registers if function == 3 else client.read_input_registers
    reply = await call(address, count=count, device_id=UNIT)
    assert not reply.isError(), reply
    return list(reply.registers)


async def exception_code(request: object) -> int:
    reply = await request  # type: ignore[misc]
    assert reply.isError(), reply
    return int(reply.exception_code)


@pytest.mark.interop
async def test_numbering_of_the_modbus_tcp_column(bench: Bench) -> None:
    # 0x0300 "Drive model" is register 40769 in the Modbus TCP column (40768 in the RTU one): ACG = 0x0010.
    assert modbus_tcp_number(0x0300) == 40769
    assert await read(bench.client, pdu_address(40769)) == [0x0010]
    # CM.23 is 45912 (0x1717); ACC/dEC are 47938/47939 (0x1F01/0x1F02): 5.0 s and 10.0 s.
    assert await read(bench.client, pdu_address(45912)) == [1]
    assert await read(bench.client, pdu_address(47938), 2) == [50, 100]
    assert await read(bench.client, pdu_address(47938), 2, function=4) == [50, 100]


@pytest.mark.interop
async def test_same_values_as_over_cip(bench: Bench) -> None:
    client, scanner = bench.client, bench.scanner
    reply = await client.write_registers(addr("ACC"), [25, 35], device_id=UNIT)        # function 16
    assert not reply.isError()
    assert (await scanner.read(0x2A, 1, 102), await scanner.read(0x2A, 1, 103)) == (25, 35)
    await scanner.set_attribute_single(0x2A, 1, 103, 45)
    assert await read(client, addr("dEC")) == [45]
    await scanner.set_attribute_single(0x64, CLASS_64_INSTANCES["Pr"], 12, 4)
    assert await read(client, addr("Pr.12")) == [4]
    reply = await client.write_register(addr("bA.13"), 87, device_id=UNIT)             # function 6
    assert not reply.isError() and reply.registers == [87]
    assert await scanner.read(0x28, 1, 6) == 87
    # Function 23: the write is done before the read.
    reply = await client.readwrite_registers(read_address=addr("Pr.12"), read_count=3, write_address=addr("Pr.13"),
                                             values=[15, 500], device_id=UNIT)
    assert not reply.isError() and reply.registers == [4, 15, 500]
    assert await scanner.read(0x64, CLASS_64_INSTANCES["Pr"], 14) == 500


@pytest.mark.interop
async def test_run_ramp_trip_reset_save_over_modbus(bench: Bench) -> None:
    client, scanner = bench.client, bench.scanner
    await client.write_registers(addr("drv"), [4, 8], device_id=UNIT)                 # drv, Frq: Field Bus
    await client.write_register(addr("ACC"), 10, device_id=UNIT)                      # 1.0 s to 60 Hz
    await client.write_register(0x0380, 3000, device_id=UNIT)                         # 30.00 Hz
    await client.write_register(0x0382, 0x0003, device_id=UNIT)                       # forward run
    seen = []
    for _ in range(200):
        [frequency] = await read(client, 0x0311)
        seen.append(frequency)
        if frequency == 3000:
            break
        await asyncio.sleep(0.01)
    assert seen[-1] == 3000 and any(0 < f < 3000 for f in seen) and seen == sorted(seen)
    assert await scanner.read(0x29, 1, 7) == 1 and await scanner.read(0x2A, 1, 3) == 1
    assert await scanner.read(0x2A, 1, 7) == (await read(client, 0x0312))[0] == 900
    bench.device.inject_trip(Trip.OVER_VOLTAGE)
    assert await read(client, 0x0330) == [1 << 11]                                   # Overvoltage Trip bit
    assert await scanner.read(0x29, 1, 13) == 0x3210
    await client.write_register(0x0382, 0x0004, device_id=UNIT)                       # B2 0 -> 1 trip reset, B0 stop
    assert await scanner.read(0x29, 1, 10) == 0 and await scanner.read(0x29, 1, 6) == 3
    for value in (0, 1):                                                               # 0x03E0 0 -> 1: save
        assert not (await client.write_register(0x03E0, value, device_id=UNIT)).isError()
    assert not (await client.write_register(addr("ACC"), 99, device_id=UNIT)).isError()  # not saved
    restarted = build_acg_device(state_path=bench.state_file)
    assert restarted.drive.read(addr("ACC")) == 10 and restarted.drive.read(addr("drv")) == 4


@pytest.mark.interop
async def test_exception_codes(bench: Bench) -> None:
    client = bench.client
    assert await exception_code(client.read_coils(0, count=1, device_id=UNIT)) == 0x01       # unsupported function
    assert await exception_code(client.mask_write_register(address=addr("ACC"), device_id=UNIT)) == 0x01
    assert await exception_code(client.read_holding_registers(0x0400, device_id=UNIT)) == 0x02  # unused address
    assert await exception_code(client.read_holding_registers(0x001B, count=2, device_id=UNIT)) == 0x02
    assert await exception_code(client.write_register(0x1A00, 1, device_id=UNIT)) == 0x02
    assert await exception_code(client.read_holding_registers(0x0300, count=17, device_id=UNIT)) == 0x03  # 1-16
    assert await exception_code(client.write_register(addr("Pr.12"), 6, device_id=UNIT)) == 0x03  # 0-5
    assert await exception_code(client.write_register(0x0300, 1, device_id=UNIT)) == 0x20        # read only
    assert await exception_code(client.write_register(addr("CM.6"), 0x0102, device_id=UNIT)) == 0x20
    # A multiple write is checked whole before any word is written.
    assert await exception_code(client.write_registers(addr("ACC"), [30, 0xFFFF], device_id=UNIT)) == 0x03
    assert await read(client, addr("ACC")) == [50]
    # CM.23 "cannot be written while the drive is operating": write-protected while running.
    await client.write_registers(addr("drv"), [4, 8], device_id=UNIT)
    await client.write_register(0x0382, 0x0003, device_id=UNIT)
    assert await exception_code(client.write_register(addr("CM.23"), 0, device_id=UNIT)) == 0x20


async def test_cm94_has_no_modbus_address(modbus_port: int) -> None:
    # The ACG RS-485 manual's address table prints "CM.94 - - -" (001:1384), as "bA.20 - - -" (001:1245): no Modbus
    # RTU or TCP address. 0x175E (the CM group's base + 94) and 0x1214 (bA.20) are refused alike, 0x02,
    # alone or inside a range; class 0x64 instance 7 attribute 94 serves CM.94 (ACG-ET2 manual, test_acg_objects).
    reader, writer = await asyncio.open_connection("127.0.0.1", modbus_port)
    try:
        for transaction, pdu in enumerate(("03 175e 0001", "04 175e 0001", "06 175e 0001", "10 175e 0001 02 0001",
                                           "03 175d 0002", "03 1214 0001", "06 1214 0001"), start=1):
            body = bytes.fromhex("ff " + pdu)
            writer.write(struct.pack(">HHH", transaction, 0, len(body)) + body)
            function = body[1]
            assert await reader.readexactly(9) == struct.pack(">HHHBBB", transaction, 0, 3, 0xFF, function | 0x80, 2)
        writer.write(bytes.fromhex("0010 0000 0006 ff 03 175d 0001"))          # CM.93, the code before: served
        assert (await reader.readexactly(11))[:9] == bytes.fromhex("0010 0000 0005 ff 03 02")
    finally:
        writer.close()


async def test_frames_on_the_wire(modbus_port: int) -> None:
    port = modbus_port
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        # Two requests in one segment, the second split: replies echo transaction and unit id.
        one = struct.pack(">HHHBBHH", 0x1234, 0, 6, 0xFF, 0x03, 0x0300, 1)
        two = struct.pack(">HHHBBHH", 0x1235, 0, 6, 0x07, 0x04, 0x1F01, 2)
        writer.write(one + two[:5])
        await writer.drain()
        await asyncio.sleep(0.05)
        writer.write(two[5:])
        assert await reader.readexactly(11) == bytes.fromhex("1234 0000 0005 ff 03 02 0010")
        assert await reader.readexactly(13) == bytes.fromhex("1235 0000 0007 07 04 04 0032 0064")
        # Exception frame: 0x80 + function, then the code (0x20 write permission).
        writer.write(struct.pack(">HHHBBHH", 1, 0, 6, 0xFF, 0x06, 0x0300, 1))
        assert await reader.readexactly(9) == bytes.fromhex("0001 0000 0003 ff 86 20")
        # Another protocol id is not Modbus: no reply. An impossible length closes the connection.
        writer.write(struct.pack(">HHHBBHH", 2, 1, 6, 0xFF, 0x03, 0x0300, 1))
        writer.write(struct.pack(">HHHB", 3, 0, 400, 0xFF))
        assert await reader.read() == b""
    finally:
        writer.close()


async def test_requests_before_an_impossible_length_are_answered_then_closed(modbus_port: int) -> None:
    """Two valid requests and a frame announcing 400 bytes (over the 254 an MBAP frame can hold) in
    one segment: both requests are executed and answered in order, then the connection closes."""
    write_acc = bytes.fromhex("0011 0000 0006 01 06 1f01 0064")       # ACC (0x1F01) = 100: 10.0 s
    read_acc = bytes.fromhex("0012 0000 0006 01 03 1f01 0001")
    impossible = bytes.fromhex("0013 0000 0190 01 03")

    def exchange() -> bytes:   # a plain socket (in a thread: the server runs on this loop)
        with socket.create_connection(("127.0.0.1", modbus_port), timeout=5) as sock:
            sock.sendall(write_acc + read_acc + impossible)
            received = b""
            while chunk := sock.recv(4096):
                received += chunk
            return received

    assert await asyncio.to_thread(exchange) == write_acc + bytes.fromhex("0012 0000 0005 01 03 02 0064")


async def test_bytes_beyond_the_pdu_refuse_the_request(modbus_port: int) -> None:
    # Write Single Register 0x1F01 (ACC) = 100 with two bytes more than function 6 has: refused with
    # 0x03 (the implied length is wrong), nothing written, and the stream goes on with the next frame.
    reader, writer = await asyncio.open_connection("127.0.0.1", modbus_port)
    try:
        writer.write(bytes.fromhex("0001 0000 0008 01 06 1f01 0064 abcd"))
        assert await reader.readexactly(9) == bytes.fromhex("0001 0000 0003 01 86 03")
        writer.write(bytes.fromhex("0002 0000 0006 01 03 1f01 0001"))
        assert await reader.readexactly(11) == bytes.fromhex("0002 0000 0005 01 03 02 0032")  # ACC still 5.0 s
        # The same for a read, and for a request one byte short.
        writer.write(bytes.fromhex("0003 0000 0007 01 03 1f01 0001 00"))
        assert await reader.readexactly(9) == bytes.fromhex("0003 0000 0003 01 83 03")
        writer.write(bytes.fromhex("0004 0000 0005 01 06 1f01 00"))
        assert await reader.readexactly(9) == bytes.fromhex("0004 0000 0003 01 86 03")
    finally:
        writer.close()


async def test_connections_past_the_limit_are_closed_and_the_rest_served(caplog: pytest.LogCaptureFixture) -> None:
    """The Modbus TCP port has the EtherNet/IP port's connection limits (issue: one peer holding every
    connection): past 2 from one address a connection is closed at accept; with all 4 taken, a new
    address gets the idlest connection of the address holding the most, and when nobody holds more
    than it would, it is closed at accept. One log line per refused address; the others are served."""
    device = build_acg_device()
    read_acc = bytes.fromhex("0001 0000 0006 01 03 1f01 0001")
    async with ModbusTcpServer(ModbusTcpCore(lambda: device.drive), "127.0.0.1", 0, max_connections=4,
                               max_connections_per_host=2) as modbus:
        async def connect(source: str) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
            return await asyncio.open_connection("127.0.0.1", modbus.port, local_addr=(source, 0))

        async def served(stream: tuple[asyncio.StreamReader, asyncio.StreamWriter]) -> bool:
            reader, writer = stream
            writer.write(read_acc)
            try:
                return await asyncio.wait_for(reader.readexactly(11), 2.0) == bytes.fromhex(
                    "0001 0000 0005 01 03 02 0032")
            except (asyncio.IncompleteReadError, ConnectionError):
                return False

        first, second = await connect("127.0.0.2"), await connect("127.0.0.2")
        assert await served(first) and await served(second)
        assert not await served(await connect("127.0.0.2"))      # a third from one address
        third, fourth = await connect("127.0.0.3"), await connect("127.0.0.4")
        assert await served(third) and await served(fourth)
        fifth = await connect("127.0.0.5")                       # all 4 taken: 127.0.0.2 holds 2
        assert await served(fifth)
        assert not await served(first) and await served(second)  # its idlest made the room
        assert not await served(await connect("127.0.0.6"))      # everyone holds 1: refused
        assert (modbus.limiter.refused, modbus.limiter.evicted) == (2, 1)
        second[1].close()
        await second[1].wait_closed()
        await asyncio.sleep(0.05)
        assert await served(await connect("127.0.0.6"))          # its slot is free again
    refused = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
    assert len(refused) == 2 and "127.0.0.2" in refused[0] and "127.0.0.6" in refused[1], refused


def test_pdu_length_is_exact() -> None:
    core = ModbusTcpCore(AcgDrive(now=0.0))
    assert core.handle_pdu(bytes.fromhex("06 1f01 0064"), 0.0) == bytes.fromhex("06 1f01 0064")
    assert core.handle_pdu(bytes.fromhex("06 1f01 0064 abcd"), 0.0) == bytes.fromhex("86 03")
    assert core.handle_pdu(bytes.fromhex("04 1f01 0001 ff"), 0.0) == bytes.fromhex("84 03")
    # 0x10 and 0x17: the byte count must match the bytes that follow.
    assert core.handle_pdu(bytes.fromhex("10 1f01 0001 02 0032 00"), 0.0) == bytes.fromhex("90 03")
    assert core.handle_pdu(bytes.fromhex("17 1f01 0001 1f02 0001 02 0032 00"), 0.0) == bytes.fromhex("97 03")
    assert core.handle_pdu(bytes.fromhex("17 1f01 0001 1f02 0001 02 0032"), 0.0) == bytes.fromhex("17 02 0064")


def test_modbus_silence_is_a_lost_command() -> None:
    # "If the Modbus TCP receives no data from the client for five seconds, ... the drive will operate
    # according to the settings at Pr.12 after the time set with Pr.13 has elapsed."
    drive = AcgDrive(now=0.0)
    core = ModbusTcpCore(drive)
    for code, value in (("drv", 4), ("Frq", 8), ("Pr.12", 1), ("Pr.13", 5)):
        assert core.handle_pdu(struct.pack(">BHH", 6, addr(code), value), 0.0)[0] == 6
    core.handle_pdu(struct.pack(">BHH", 6, 0x0380, 3000), 0.0)
    core.handle_pdu(struct.pack(">BHH", 6, 0x0382, 3), 1.0)
    drive.advance(1.0 + MODBUS_SILENCE_TIME + 0.49)
    assert not drive.faulted
    drive.advance(1.0 + MODBUS_SILENCE_TIME + 0.51)
    assert drive.trip is Trip.LOST_COMMAND and drive.output_frequency == 0


def test_mbap_buffer() -> None:
    buffer = MbapBuffer()
    frame = struct.pack(">HHHBBHH", 7, 0, 6, 0xFF, 3, 0, 1)
    assert buffer.feed(frame[:3]) == [] and buffer.feed(frame[3:] + frame) == [frame, frame]
    with pytest.raises(ValueError):
        buffer.feed(struct.pack(">HHHB", 0, 0, 255, 0))
