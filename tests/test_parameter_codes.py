"""Read and write by parameter code (issue 43, item 6): a scanner author thinks in the drive's codes
(``ACC``, ``dEC``, ``CM.24``, ``A004``), not class/instance/attribute. ``parameter``/``set_parameter``
on both scanners, for the built-in profiles and a device with an EDS file (by ``ParamN`` or its
name), and ``cipstack get|set HOST CODE``, against real emulators over loopback."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest

from cipstack.catalog import Catalog
from cipstack.devices.profiles import build_device, catalog_for
from cipstack.eds.emulated_device import build_eds_device
from cipstack.eds.reader import read_eds
from cipstack.objects.tcpip import NetworkInterface
from cipstack.parameter_codes import ParameterValueError, UnknownParameterError, find_parameter
from cipstack.scanner import Scanner, SyncScanner
from tests.cli_errors import one_line_error
from tests.library_support import adapter_process, run_cli, threaded_adapter

ACG = catalog_for(259, 100)
DRIVE_EDS = Path(__file__).parent / "eds" / "files" / "vendor_drive_own_data.eds"


def test_a_code_is_found_as_a_person_types_it() -> None:
    assert find_parameter(ACG, "ACC").path == (0x2A, 1, 102)
    assert find_parameter(ACG, "acc") is find_parameter(ACG, "ACC")
    assert find_parameter(ACG, "cm-24") is find_parameter(ACG, "CM.24") is find_parameter(ACG, "CM 24")
    assert find_parameter(ACG, "Deceleration Time").code == "dEC"        # by its name too
    with pytest.raises(UnknownParameterError) as unknown:
        find_parameter(ACG, "ACX")
    assert "did you mean ACC?" in str(unknown.value) and "`cipstack params dump HOST` lists them" in str(unknown.value)
    with pytest.raises(KeyError, match="give an EDS file"):
        find_parameter(Catalog(), "ACC")


def test_both_scanners_read_and_write_the_acg_by_code() -> None:
    with threaded_adapter(build_device("acg")) as adapter, SyncScanner(f"127.0.0.1:{adapter.port}") as drive:
        accel = drive.parameter("ACC")
        assert (accel.raw, accel.value, accel.unit) == (50, 5.0, "s")
        written = drive.set_parameter("ACC", 2.5)                        # in its unit: 2.5 s
        assert written.raw == 25 and drive.read(0x2A, 1, 102) == 25
        assert drive.set_parameter("dEC", "7.5").raw == 75 and drive.read(0x2A, 1, 103) == 75
        with pytest.raises(ParameterValueError, match=r"2\.55 s is not a whole number of steps of 0\.1 s"):
            drive.set_parameter("ACC", 2.55)
        assert drive.parameter("ACC") == 25                              # nothing written by the refusal

        async def from_asyncio() -> None:
            async with await Scanner.connect(f"127.0.0.1:{adapter.port}") as scanner:
                assert await scanner.set_parameter("Pr.13", 1.5) == 15  # Lost Cmd Time, 0.1 s steps
                reading = await scanner.parameter("Pr.13")
                assert (reading.value, reading.unit) == (1.5, "s")

        asyncio.run(from_asyncio())


def test_an_mx2_by_its_function_code() -> None:
    with threaded_adapter(build_device("mx2")) as adapter, SyncScanner(f"127.0.0.1:{adapter.port}") as drive:
        before = drive.parameter("A004")                                 # Maximum frequency, Hz
        assert before.unit == "Hz" and before.value > 0
        drive.set_parameter("A004", 55)
        assert drive.parameter("A004").value == 55.0


def test_a_device_with_an_eds_file_by_its_paramn_or_name() -> None:
    device = build_eds_device(read_eds(DRIVE_EDS), NetworkInterface(ip_address="127.0.0.1"))
    with threaded_adapter(device) as adapter, \
            SyncScanner(f"127.0.0.1:{adapter.port}", eds=str(DRIVE_EDS)) as drive:
        assert drive.parameter("Param4") == 10000 and drive.parameter("Param4").unit == "ms"
        drive.set_parameter("Accel Time", 2500)                          # by its name, in ms
        assert drive.parameter("param4") == 2500 and drive.read(0x2A, 1, 0x12) == 2500


def test_get_and_set_by_code_on_the_command_line() -> None:
    with adapter_process("--factory") as (address, _):
        got = run_cli("get", address, "ACC")
        assert got.returncode == 0 and got.stdout == "ACC Acceleration Time = 5.0 s (50)\n", got.stderr
        done = run_cli("set", address, "ACC", "2.5")
        assert done.returncode == 0 and done.stdout == "set ACC Acceleration Time = 2.5 s (25)\n", done.stderr
        as_json = json.loads(run_cli("get", address, "acc", "--json").stdout)
        assert as_json == {"status": 0, "code": "ACC", "name": "Acceleration Time", "path": "0x2A/1/102",
                           "value": 25, "engineering": 2.5, "unit": "s"}
        between = run_cli("set", address, "ACC", "2.55")
        unknown = run_cli("get", address, "ACX")
        with_type = run_cli("get", address, "ACC", "--type", "UINT")
        assert run_cli("get", address, "0x2A/1/102").stdout == "Acceleration Time = 2.5 s (25)\n"
    assert between.returncode == 2 and one_line_error(between) == (
        "cipstack set: ACC (Acceleration Time): 2.55 s is not a whole number of steps of 0.1 s")
    assert unknown.returncode == 2 and "no parameter 'ACX' in profile acg" in one_line_error(unknown)
    assert "did you mean ACC?" in one_line_error(unknown)
    assert with_type.returncode == 2 and "whose type is its declaration" in one_line_error(with_type)


def test_get_by_eds_name_on_the_command_line() -> None:
    with adapter_process("--eds", str(DRIVE_EDS)) as (address, _):
        got = run_cli("get", address, "Param4", "--eds", str(DRIVE_EDS))
        done = run_cli("set", address, "Accel Time", "2500", "--eds", str(DRIVE_EDS))
    assert got.returncode == 0 and got.stdout == "Param4 Accel Time = 10000 ms\n", got.stderr
    assert done.returncode == 0 and done.stdout == "set Param4 Accel Time = 2500 ms\n", done.stderr
