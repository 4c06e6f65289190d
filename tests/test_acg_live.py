"""The emulated ACG drive in an in-process adapter, driven by our scanner over loopback sockets:
explicit messaging (0x29/0x2A/0x64, assemblies) and a class 1 connection 21/71."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.catalog import Catalog
from cipstack.cip.types import UINT
from cipstack.devices.acg.device import AcgDevice, build_acg_device
from cipstack.devices.acg.registers import ACG_REGISTERS, CLASS_64_INSTANCES
from cipstack.eip.originator.asyncio_client import EncapsulationClient
from cipstack.eip.originator.io_context import shared_io_endpoint
from cipstack.scanner import Scanner

CM, PR = CLASS_64_INSTANCES["CM"], CLASS_64_INSTANCES["Pr"]
SAVE_PARAMETERS = 0x03E0
DRV, FRQ = ACG_REGISTERS.by_code("drv").address, ACG_REGISTERS.by_code("Frq").address


@pytest.fixture
def state_file(tmp_path: Path) -> Path:
    return tmp_path / "acg-state.json"


@pytest.fixture
async def adapter(state_file: Path) -> AsyncIterator[Adapter]:
    device = build_acg_device(state_path=state_file)
    async with Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0), device=device) as running:
        yield running


@pytest.fixture
async def scanner(adapter: Adapter) -> AsyncIterator[Scanner]:
    assert isinstance(adapter.device, AcgDevice)
    scanner = await Scanner.connect(f"127.0.0.1:{adapter.port}", timeout=3,
                                    catalog=Catalog(adapter.device.catalog_classes()))
    yield scanner
    await scanner.close()


async def write_registers(scanner: Scanner, values: dict[int, int]) -> None:
    """Write drive registers over CIP alone: name them in CM.51.. (Para Control-n, class 0x64 instance 7)
    and set the smart-scaling output assembly 12n (ACG-ET2 manual, CM.50-CM.58, output instances 121-128)."""
    for index, address in enumerate(values):
        await scanner.set_attribute_single(0x64, CM, 51 + index, address)
    data = b"".join(UINT.encode(v) for v in values.values())
    await scanner.set_attribute_single(0x04, 120 + len(values), 3, data)


async def bring_under_network_control(scanner: Scanner, accel_tenths: int = 10) -> None:
    # drv = 4 and Frq = 8 "Field Bus" (ACG-ET2 manual, Keypad Parameters Related to ACG-ET2).
    await write_registers(scanner, {DRV: 4, FRQ: 8})
    assert await scanner.read(0x29, 1, 14) == 1 and await scanner.read(0x2A, 1, 29) == 1
    await scanner.set_attribute_single(0x2A, 1, 102, accel_tenths)   # ACC: 0 to 60 Hz in 1.0 s


async def test_scanner_runs_trips_resets_and_saves(scanner: Scanner, adapter: Adapter, state_file: Path) -> None:
    device = adapter.device
    assert isinstance(device, AcgDevice)
    assert await scanner.read(0x29, 1, 6) == 3                           # Ready
    await bring_under_network_control(scanner)
    await scanner.set_attribute_single(0x2A, 1, 8, 900)                  # SpeedRef 900 rpm = 30 Hz
    await scanner.set_attribute_single(0x29, 1, 3, 1)                    # Forward Run Cmd 0 -> 1
    seen: list[int] = []
    deadline = time.monotonic() + 3
    while time.monotonic() < deadline:
        seen.append((await scanner.read(0x2A, 1, 7)).raw)
        if await scanner.read(0x2A, 1, 3) == 1:
            break
        await asyncio.sleep(0.02)
    assert await scanner.read(0x2A, 1, 3) == 1 and await scanner.read(0x2A, 1, 7) == 900
    assert any(0 < s < 900 for s in seen), seen                          # it ramped
    assert seen == sorted(seen)
    assert (await scanner.read(0x29, 1, 6), await scanner.read(0x29, 1, 7)) == (4, 1)  # Enabled, forward
    assert await scanner.read(0x2A, 1, 100) == 3000

    device.inject_trip(0x4200)                                           # OverHeat
    assert (await scanner.read(0x29, 1, 10), await scanner.read(0x29, 1, 13)) == (1, 0x4200)
    assert await scanner.read(0x29, 1, 6) == 6 and await scanner.read(0x2A, 1, 7) == 0
    assert (await scanner.read(1, 1, 5)).raw & 0x0800
    await scanner.set_attribute_single(0x29, 1, 12, 1)                   # Drive Fault Reset 0 -> 1
    assert (await scanner.read(0x29, 1, 10), await scanner.read(0x29, 1, 6)) == (0, 3)

    await scanner.set_attribute_single(0x2A, 1, 103, 55)                 # dEC 5.5 s
    await scanner.set_attribute_single(0x64, PR, 12, 2)                  # Pr.12 Dec
    await write_registers(scanner, {SAVE_PARAMETERS: 0})
    await write_registers(scanner, {SAVE_PARAMETERS: 1})                 # 0x03E0: 0 -> 1 saves
    await scanner.set_attribute_single(0x2A, 1, 103, 77)                 # changed, not saved
    assert await scanner.read(0x2A, 1, 103) == 77
    assert adapter.device.flush_saves(5)                                 # written off the event loop
    assert state_file.exists()

    restarted = build_acg_device(state_path=state_file)                  # a power cycle on the same file
    assert restarted.drive.read(ACG_REGISTERS.by_code("dEC").address) == 55
    assert restarted.drive.read(ACG_REGISTERS.by_code("Pr.12").address) == 2
    assert restarted.drive.read(DRV) == 4 and restarted.drive.read(ACG_REGISTERS.by_code("ACC").address) == 10


async def test_class1_21_71_ramps_and_lost_command(scanner: Scanner, adapter: Adapter) -> None:
    device = adapter.device
    assert isinstance(device, AcgDevice) and adapter.io_endpoint is not None
    await bring_under_network_control(scanner)
    await scanner.set_attribute_single(0x64, PR, 12, 1)                  # Pr.12 Free-Run: Lost Command trip
    await scanner.set_attribute_single(0x64, PR, 13, 2)                  # Pr.13 0.2 s
    client = await EncapsulationClient.connect("127.0.0.1", adapter.port)
    try:
        async with client.io_connection(
                21, 71, 0.01, output_size=4, input_size=4, target_io_port=adapter.io_endpoint.port,
                output_schema=device.assembly_schema(21), input_schema=device.assembly_schema(71)) as io:
            io.output.speed_reference = 900
            io.output.run_forward = True
            seen: list[int] = []
            async for image in io.updates():
                seen.append(image.speed_actual)
                if image.at_reference:
                    break
            assert seen[-1] == 900 and any(0 < s < 900 for s in seen) and seen == sorted(seen)
            image = io.input
            assert (image.running_forward, image.ready, image.ctrl_from_net, image.drive_state) == (True, True,
                                                                                                    True, 4)
            assert await scanner.read(1, 1, 5) == 0x0061                 # owned, I/O connection made (6)
            # Break the connection: the originator's class 1 endpoint goes away (no Forward_Close).
            _, endpoint = await shared_io_endpoint(client.local_host())
            await endpoint.close()
            broken = time.monotonic()
            while not device.drive.faulted and time.monotonic() < broken + 5:
                await asyncio.sleep(0.02)
            elapsed = time.monotonic() - broken
            assert await scanner.read(0x29, 1, 13) == 0x1000             # LostCommand
            # Not before the connection timeout (40 ms) + the one-second break + Pr.13 (0.2 s); how much
            # later depends on the machine, so only the loop above bounds it.
            assert elapsed >= 1.2, elapsed
            assert await scanner.read(0x2A, 1, 7) == 0                   # free-run stop
            assert (await scanner.read(1, 1, 5)).raw & 0x00F0 == 0x0050        # major fault
    finally:
        await client.close()
