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
from cipstack.eip.wire.cpf import SockAddr
from cipstack.eip.wire.identity_items import IdentityRecord, encode_identity_item
from cipstack.errors import BadRequest
from cipstack.objects.tcpip import NetworkInterface
from cipstack.parameter_codes import ParameterValueError, UnknownParameterError, find_parameter
from cipstack.scanner import Scanner, SyncScanner
from tests.cli_errors import one_line_error
from tests.fakes import ScriptedTarget
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


# -- a value out of the parameter's range, by code or by path: refused before anything is sent ----------------
def _scripted_acg() -> ScriptedTarget:
    """A target that says it is an ACG (ListIdentity) and records every request; a Set is answered 0x08."""
    record = IdentityRecord(259, 2, 100, (1, 1), 0, 1, "CENT")
    return ScriptedTarget(identity=encode_identity_item(record, SockAddr(host="127.0.0.1", port=44818)))


@pytest.mark.parametrize("value", ["7000", "6500"])
def test_out_of_range_by_code_is_refused_in_its_unit_and_nothing_is_sent(value: str) -> None:
    """Issue 52, item 4: 7000 s (raw 70000, beyond UINT) and 6500 s (a UINT, beyond the declared
    0..60000) are both outside ACC's range: one line in the parameter's unit, exit 2, no Set sent."""
    with _scripted_acg() as target:
        done = run_cli("set", target.address, "ACC", value)
        with SyncScanner(target.address) as drive, pytest.raises(BadRequest) as refused:
            drive.set_parameter("ACC", float(value))
        sets = target.services(0x10)
    assert done.returncode == 2 and one_line_error(done) == "cipstack set: ACC (Acceleration Time) takes 0.0..6000.0 s"
    assert isinstance(refused.value, ParameterValueError)
    assert str(refused.value) == "ACC (Acceleration Time) takes 0.0..6000.0 s"
    assert sets == []


def test_out_of_range_by_path_is_refused_from_the_compact_declarations() -> None:
    """``cipstack set HOST 0x2A/1/102 65000`` (the one-shot path, compact declarations): the range the
    declaration gives, in its unit and raw, before sending; ``--type`` sets the declaration aside."""
    with _scripted_acg() as target:
        raw = run_cli("set", target.address, "0x2A/1/102", "65000")
        scaled = run_cli("set", target.address, "0x2A/1/102", "6500", "--scaled")
        assert target.services(0x10) == []
        forced = run_cli("set", target.address, "0x2A/1/102", "65000", "--type", "UINT")
        sent = target.services(0x10)
    assert raw.returncode == 2 and one_line_error(raw) == (
        "cipstack set: 0x2A/1/102 (Acceleration Time) takes 0.0..6000.0 s (raw 0..60000); "
        "--type UINT sends 65000 anyway")
    assert scaled.returncode == 2 and one_line_error(scaled) == (
        "cipstack set: 0x2A/1/102 (Acceleration Time) takes 0.0..6000.0 s; --type UINT sends 6500 anyway")
    assert [r.data for r in sent] == [(65000).to_bytes(2, "little")]   # sent as asked; the target says 0x08
    assert forced.returncode == 1


def test_the_range_is_worded_alike_by_code_and_on_the_keypad() -> None:
    """One wording: ``cipstack set HOST dr.20`` (the catalog's declaration) and the keypad's
    ``cipstack drive set-parameter dr.20`` (the HTTP API's and ``--param``'s check) say the same; an
    enumeration lists its choices."""
    with adapter_process("--factory") as (address, _):
        port = address.rsplit(":", 1)[1]
        by_code = run_cli("set", address, "dr.20", "500")
        keypad = run_cli("drive", "set-parameter", "dr.20", "500", "--port", port)
        choice = run_cli("set", address, "CM.23", "12")
        assert run_cli("get", address, "dr.20").stdout == "dr.20 Max Freq = 60.00 Hz (6000)\n"
    assert by_code.returncode == 2
    assert one_line_error(by_code) == "cipstack set: dr.20 (Max Freq) takes 40.00..400.00 Hz"
    assert keypad.returncode == 2 and one_line_error(keypad).endswith("dr.20 (Max Freq) takes 40.00..400.00 Hz")
    assert choice.returncode == 2 and one_line_error(choice).startswith(
        "cipstack set: CM.23 (Opt Parameter 14) takes 0..11 (0 instance 70, 1 instance 71, ")
