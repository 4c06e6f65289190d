"""An emulated MX2 and RX over real loopback sockets: our scanner runs, stops, trips, resets and
parameterises them through the Control Supervisor (0x29), the AC/DC Drive (0x2A), the Modbus Register
(0x64) and Function Code (0x65) objects, directly and routed through the CompoNet gateway; a class 1
connection exchanges assemblies 21/71."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable, Sequence
from typing import Any

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.catalog import Catalog
from cipstack.cip.epath import PortSegment
from cipstack.cip.status import CipError
from cipstack.cip.types import UDINT, UINT
from cipstack.componet.gateway import COMPONET_PORT
from cipstack.devices.base import Device
from cipstack.devices.omron.device import OmronDevice, build_componet_gateway, build_omron_device
from cipstack.devices.omron.registers import function_code_path
from cipstack.scanner import Scanner

MX2 = "MX2-A2015-E"
RX = "RX-A4055-E"
NODE = 3


async def started(device: Device) -> Adapter:
    adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0), device=device)
    await adapter.start()
    return adapter


async def until(check: Callable[[], Any], timeout: float = 5.0) -> Any:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    while True:
        value = await check()
        if value:
            return value
        if loop.time() > deadline:
            raise AssertionError("condition not reached in time")
        await asyncio.sleep(0.02)


async def drive_scenario(scanner: Scanner, name: str, inverter: Any) -> None:
    """Section 4-1 to 4-5 and appendix E through explicit messages only."""
    rx = name.startswith("RX")
    assert await scanner.read(1, 1, 1) == 47
    assert await scanner.read(1, 1, 3) == (2073 if rx else 1806)
    # Parameterise: A001/A002 by function code, ramp time through 0x2A (0.5 s), F001 through 0x64.
    source = 5 if rx else 4
    await scanner.set_attribute_single(0x65, *function_code_path("A001"), source, UINT)
    await scanner.set_attribute_single(0x65, *function_code_path("A002"), source, UINT)
    assert await scanner.read(0x65, *function_code_path("A002"), UINT) == source
    await scanner.set_attribute_single(0x2A, 1, 0x12, 500)
    await scanner.set_attribute_single(0x2A, 1, 0x13, 500)
    assert await scanner.read(0x65, *function_code_path("F002"), UDINT) == 50
    await scanner.set_attribute_single(0x64, 0x00, 0x01, 1234, UDINT)       # F001 at 0001h/0002h
    assert await scanner.read(0x64, 0x00, 0x01, UDINT) == 1234
    # Run: Speed Ref 10.00 Hz, Run1.
    await scanner.set_attribute_single(0x2A, 1, 8, 1000)
    await scanner.set_attribute_single(0x29, 1, 3, 0)
    await scanner.set_attribute_single(0x29, 1, 3, 1)
    assert await scanner.read(0x29, 1, 7) == 1
    await until(lambda: scanner.read(0x2A, 1, 3))                             # At Reference
    assert await scanner.read(0x2A, 1, 7) == 1000
    assert await scanner.read(0x29, 1, 6) == 4                                # Enabled
    assert await scanner.read(0x65, *function_code_path("d001"), UDINT) == 1000
    assert await scanner.read(0x64, 0x1E, 0x01, UINT) == 0x1A                 # coil data 1: Rdy, RUN, FA1
    # Stop.
    await scanner.set_attribute_single(0x29, 1, 3, 0)
    await until(lambda: _equals(scanner.read(0x29, 1, 6), 3))
    assert await scanner.read(0x2A, 1, 0x7A) == 1                             # At Zero Speed
    # Trip by Force Fault (appendix E Examples 2 and 3) and reset.
    await scanner.set_attribute_single(0x29, 1, 0x11, 1)
    assert await scanner.read(0x29, 1, 0x0A) == 1
    assert await scanner.read(0x29, 1, 0x65) == (72 if rx else 62)
    assert await scanner.read(0x29, 1, 0x0D) == 0x7510
    await scanner.set_attribute_single(0x29, 1, 0x11, 0)
    await scanner.set_attribute_single(0x29, 1, 0x0C, 1)
    assert await scanner.read(0x29, 1, 0x0A) == 0
    # Errors of Table E-5 on the wire.
    with pytest.raises(CipError) as error:
        await scanner.set_attribute_single(0x65, *function_code_path("F001"), 1, UDINT)
    assert error.value.general == 0x0E
    with pytest.raises(CipError) as error:
        await scanner.read(0x64, 0x77, 0x01, UINT)
    assert error.value.general == 0x16
    # Save (ENTER at 0900h): Identity attribute 9 counts it.
    await scanner.set_attribute_single(0x64, 0x09, 0x00, 1, UINT)
    assert await scanner.read(1, 1, 9) == 1
    assert inverter.consistency_value == 1


async def _equals(value: Any, expected: Any) -> bool:
    return await value == expected


@pytest.fixture(params=[MX2, RX])
def model_name(request: pytest.FixtureRequest) -> str:
    return request.param


@pytest.fixture
async def direct(model_name: str) -> AsyncIterator[Adapter]:
    adapter = await started(build_omron_device(model_name))
    yield adapter
    await adapter.close()


@pytest.fixture
async def gateway(model_name: str) -> AsyncIterator[Adapter]:
    profile = "rx" if model_name.startswith("RX") else "mx2"
    adapter = await started(build_componet_gateway([(profile, model_name, NODE)]))
    yield adapter
    await adapter.close()


def catalog(device: OmronDevice) -> Catalog:
    return Catalog(device.catalog_classes(), device.schemas().values())


async def test_direct(direct: Adapter, model_name: str) -> None:
    device = direct.device
    assert isinstance(device, OmronDevice)
    async with await Scanner.connect(f"127.0.0.1:{direct.port}", catalog=catalog(device)) as scanner:
        await drive_scenario(scanner, model_name, device.inverter)


async def test_through_the_componet_gateway(gateway: Adapter, model_name: str) -> None:
    device = gateway.device
    slave = device.slave(NODE)  # type: ignore[attr-defined]
    route: Sequence[PortSegment] = [PortSegment(COMPONET_PORT, bytes([NODE]))]
    async with await Scanner.connect(f"127.0.0.1:{gateway.port}", catalog=catalog(slave), route=route) as scanner:
        await drive_scenario(scanner, model_name, slave.inverter)
    assert device.gateway.routed > 20  # type: ignore[attr-defined]
    async with await Scanner.connect(f"127.0.0.1:{gateway.port}") as plain:
        assert await plain.read(1, 1, 1) == 47                                # the gateway itself
        # Node 3's input word in the master's IN area: RDY again once the next cycle has refreshed it.
        await until(lambda: _ready_in_area(plain))


async def _ready_in_area(scanner: Scanner) -> bool:
    area = (await scanner.read(4, 101, 3)).raw
    return bool(area[2 * NODE] & 0x10) and not area[2 * NODE] & 0x01


async def test_class1_extended_speed(direct: Adapter, model_name: str) -> None:
    device = direct.device
    assert isinstance(device, OmronDevice) and direct.io_endpoint is not None
    source = 5 if model_name.startswith("RX") else 4
    async with await Scanner.connect(f"127.0.0.1:{direct.port}", catalog=catalog(device)) as scanner:
        await scanner.set_attribute_single(0x65, *function_code_path("A001"), source, UINT)
        await scanner.set_attribute_single(0x65, *function_code_path("A002"), source, UINT)
        await scanner.set_attribute_single(0x2A, 1, 0x12, 200)
        async with scanner.io_connection(output=21, input=71, rpi=0.01, timeout_multiplier=5,
                                         target_io_port=direct.io_endpoint.port) as io:
            io.output.speed_reference = 1500
            await io.wait_input(lambda i: i.ready and i.ctrl_from_net, timeout=5)
            io.output.run_forward = True
            image = await io.wait_input(lambda i: i.at_reference and i.speed_actual == 1500, timeout=5)
            assert image.running_forward and image.drive_state == 4
            io.output.run_forward = False
            await io.wait_input(lambda i: i.drive_state == 3 and i.speed_actual == 0, timeout=5)
            io.output.fault_reset = False
            device.inject_trip(5)
            image = await io.wait_input(lambda i: i.faulted, timeout=5)
            assert image.drive_state == 7
            io.output.fault_reset = True
            await io.wait_input(lambda i: not i.faulted, timeout=5)
        with pytest.raises(CipError) as refused:   # a pair Table 10 does not offer
            async with scanner.io_connection(output=21, input=153, rpi=0.01, target_io_port=direct.io_endpoint.port):
                pass
        assert (refused.value.general, refused.value.extended[:1]) == (0x01, (0x012F,))


async def test_class1_idle_and_timeout_actions() -> None:
    """Table 12: network idle while running -> P048 (default 0: trip E63); connection timed out -> P045."""
    adapter = await started(build_omron_device(MX2))
    device = adapter.device
    assert isinstance(device, OmronDevice) and adapter.io_endpoint is not None
    try:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=catalog(device)) as scanner:
            await scanner.set_attribute_single(0x2A, 1, 0x12, 200)
            await scanner.set_attribute_single(0x65, *function_code_path("P045"), 3, UINT)   # free-run stop
            async with scanner.io_connection(output=21, input=71, rpi=0.01, timeout_multiplier=0,
                                             target_io_port=adapter.io_endpoint.port) as io:
                io.output.update(net_ctrl=True, net_ref=True, speed_reference=1000)
                await io.wait_input(lambda i: i.ctrl_from_net, timeout=5)
                io.output.run_forward = True
                await io.wait_input(lambda i: i.at_reference, timeout=5)
                io.set_run(False)                                                  # the scanner goes idle
                image = await io.wait_input(lambda i: i.faulted, timeout=5)
                assert device.inverter.trip == 63 and image.drive_state == 7       # P048 = 0: trip E63
                io.output.update(run_forward=False, fault_reset=True)
                io.set_run(True)
                await io.wait_input(lambda i: not i.faulted, timeout=5)
                io.output.run_forward = True
                await io.wait_input(lambda i: i.at_reference, timeout=5)
                io.stop_producing()                                                # the scanner stops sending
                await until(lambda: _true(not adapter.io or not adapter.io.connections))
            status = device.inverter.status()                                      # P045 = 3: free run, no trip
            assert device.inverter.trip == 0 and status.output_frequency == 0 and not status.running
            assert device.identity.status == 0x0001                                # Table C-2: no bits 4-7
    finally:
        await adapter.close()


async def _true(value: bool) -> bool:
    return value
