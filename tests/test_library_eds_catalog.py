"""An EDS file as a catalog, for any device (issue 26, item 2): ``Scanner.connect(host, eds=FILE)`` and
``cipstack get/set --eds FILE`` decode, scale and name by the file's ``ParamN`` (link path, type, range,
enumeration, unit; scaling fields 13-16 and 21 of the EDS specification (CIP Vol. 1, chapter 7)) and its assemblies'
members; a device the profiles know reads the same by its EDS as by its profile."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.devices.acg.device import build_acg_device
from cipstack.devices.acg.eds_file import acg_et2_description
from cipstack.eds.catalog import catalog_from_eds
from cipstack.eds.emulated_device import build_eds_device
from cipstack.eds.generator import eds_text
from cipstack.eds.reader import parse_eds
from cipstack.objects.tcpip import NetworkInterface
from cipstack.scanner import Scanner
from tests.eds.samples import GENERIC_EDS
from tests.library_support import run_cli, threaded_adapter

#: The hand-written flow controller with scaling (descriptor bit 2): Flow Setpoint in 0.1 l/min
#: (multiplier 1, divider 10, base 1, offset 0, one decimal place) and a temperature of
#: (raw - 40) x 0.5 degC (multiplier 1, divider 2, base 1, offset -40, one place), a parameter the
#: plain sample does not have.
SCALED_EDS = GENERIC_EDS.replace(
    '''Param1 = 0, 6, "20 70 24 01 30 01", 0x0000,''',
    '''Param1 = 0, 6, "20 70 24 01 30 01", 0x0004,''').replace(
    '''"Flow to hold",
        0, 500, 120, , , , , , , , , 0;''',
    '''"Flow to hold",
        0, 5000, 120, 1, 10, 1, 0, , , , , 1;''').replace(
    '''    Param7 =''',
    '''    Param8 = 0, 6, "20 70 24 01 30 05", 0x0004, 0xC3, 2, "Coolant Temperature", "degC", "",
        0, 400, 100, 1, 2, 1, -40, , , , , 1;
    Param7 =''')


@pytest.fixture
async def flow_controller() -> AsyncIterator[Adapter]:
    device = build_eds_device(parse_eds(SCALED_EDS), NetworkInterface(ip_address="127.0.0.1"))
    async with Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0), device=device) as running:
        yield running


@pytest.fixture
def eds_file(tmp_path: Path) -> Path:
    path = tmp_path / "fc10.eds"
    path.write_text(SCALED_EDS)
    return path


def test_params_declare_their_attributes(eds_file: Path) -> None:
    catalog = catalog_from_eds(eds_file)
    assert catalog.source == "EDS file fc10.eds (Acme FC-10)"
    setpoint = catalog.attribute(0x70, 1, 1)
    assert setpoint is not None and (setpoint.name, setpoint.type.name, setpoint.unit) == ("Flow Setpoint", "UINT",
                                                                                             "l/min")
    assert (setpoint.scale, setpoint.minimum, setpoint.maximum, setpoint.default) == (0.1, 0, 5000, 120)
    valve = catalog.attribute(0x70, 1, 3)
    assert valve is not None and valve.enum == {0: "Closed", 1: "Open"}
    assert catalog.attribute(0x70, 2, 1).name == "Mode"                          # instance 2, not instance 1's
    assert catalog.attribute(0x01, 1, 1).name == "Vendor ID"                      # the standard objects remain
    assert catalog.attribute(0x70, 1, 99) is None
    status = catalog.assemblies[101]
    assert [f.name for f in status.fields] == ["flow_actual", "flow_setpoint", "valve_open"]
    assert status.field("flow_setpoint").scale == 0.1


async def test_scanner_decodes_and_scales_by_the_eds(flow_controller: Adapter, eds_file: Path) -> None:
    async with await Scanner.connect(f"127.0.0.1:{flow_controller.port}", eds=eds_file) as scanner:
        setpoint = await scanner.read(0x70, 1, 1)
        assert (setpoint.raw, setpoint.value, str(setpoint)) == (120, 12.0, "12.0 l/min")
        temperature = await scanner.read(0x70, 1, 5)
        assert (temperature.raw, str(temperature)) == (100, "30.0 degC")          # (100 - 40) x 0.5
        await scanner.write(0x70, 1, 1, 15.5, scaled=True)
        assert (await scanner.read(0x70, 1, 1)).raw == 155
        assert str(await scanner.read(0x70, 1, 3)) == "0 (Closed)"
        async with scanner.io_connection(output=100, input=101, rpi=0.02,
                                         target_io_port=flow_controller.io_endpoint.port) as io:
            io.output.update(flow_setpoint=200, valve_open=1, mode=2)
            image = await io.wait_input(lambda i: i.flow_setpoint == 200, timeout=5)
            assert image.valve_open == 1


async def test_without_the_eds_the_message_says_to_give_it(flow_controller: Adapter) -> None:
    async with await Scanner.connect(f"127.0.0.1:{flow_controller.port}") as scanner:
        assert "no profile for vendor 1234 product code 77 (give eds= or catalog=)" in scanner.catalog.source
        assert (await scanner.read(0x70, 1, 1)).raw == b"\x78\x00"
        async with scanner.io_connection(output=100, input=101, rpi=0.02,
                                         target_io_port=flow_controller.io_endpoint.port,
                                         output_size=4, input_size=6) as io:
            with pytest.raises(AttributeError, match=r"no field 'flow_setpoint': no schema of assembly 100 in the "
                                                     r"standard objects only: no profile for vendor 1234"):
                io.output.flow_setpoint = 1


async def test_a_profile_device_reads_the_same_by_its_eds(tmp_path: Path) -> None:
    path = tmp_path / "acg.eds"
    path.write_text(eds_text(acg_et2_description()), encoding="latin-1")
    async with Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0), device=build_acg_device()) as adapter, \
            await Scanner.connect(f"127.0.0.1:{adapter.port}") as by_profile, \
            await Scanner.connect(f"127.0.0.1:{adapter.port}", eds=path) as by_eds:
        assert by_eds.catalog.source.startswith("EDS file acg.eds")
        for path_ in [(0x2A, 1, 102), (0x2A, 1, 100), (0x2A, 1, 7), (0x29, 1, 6), (0x28, 1, 6)]:
            profile_value, eds_value = await by_profile.read(*path_), await by_eds.read(*path_)
            assert (eds_value.raw, str(eds_value)) == (profile_value.raw, str(profile_value)), path_
        assert str(await by_eds.read(0x2A, 1, 102)) == "5.0 s"                   # ACG-ET2 manual: 0-6000.0 sec


def test_cli_get_and_set_with_eds(eds_file: Path) -> None:
    device = build_eds_device(parse_eds(SCALED_EDS), NetworkInterface(ip_address="127.0.0.1"))
    with threaded_adapter(device) as adapter:
        address = f"127.0.0.1:{adapter.port}"
        got = run_cli("get", address, "0x70/1/1", "--eds", str(eds_file))
        assert got.stdout.strip() == "Flow Setpoint = 12.0 l/min (120)", got.stderr
        done = run_cli("set", address, "0x70/1/5", "35", "--scaled", "--eds", str(eds_file))
        assert done.stdout.strip() == "set 0x70/1/5 Coolant Temperature = 35.0 degC (110)", done.stderr
        unknown = run_cli("set", address, "0x70/1/5", "35")
        assert unknown.returncode == 2 and "no profile for vendor 1234 product code 77" in unknown.stderr
