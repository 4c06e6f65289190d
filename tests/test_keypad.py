"""Keypad parameters of every drive family (``cipstack.devices.keypad``) and the ``parameter write``
events of every route.

The MX2/RX Digital Operator's function codes are set over the HTTP API, at start with ``--param`` and
with the pytest plugin's marker, in the operator's unit (A004 in 0.1 Hz, F001 in 0.01 Hz, P044 in
0.1 s: CompoNet manual and the register tables); a write the inverter refuses (a monitor, a parameter not
run-mode editable while running) is a 409 with its reason. Each write the device accepts, over CIP,
Modbus TCP (pymodbus), Modbus-RTU (a pty) or HTTP, is exactly one ``parameter write`` event naming
its origin and what was written. Real sockets and processes throughout."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import subprocess
import sys
import textwrap
import tty
from collections.abc import AsyncIterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.cip.status import CipError
from cipstack.devices.acg.modbus_rtu import with_crc
from cipstack.devices.acg.registers import ACG_REGISTERS
from cipstack.devices.profiles import catalog_for
from cipstack.scanner import Scanner
from tests.http_client import call
from tests.inner_pytest import environment
from tests.optional import needs
from tests.test_cli import one_line_error, run, start_adapter, stop
from tests.waiting import wait_for

if TYPE_CHECKING:
    import aiohttp

ROOT = Path(__file__).resolve().parents[1]
#: Class 0x65 (Function Code, Table E-3): instance/attribute = the function code number's bytes.
FUNCTION_CODE = 0x65
A004 = (0x00, 0x04)         # 4
P044 = (0x3A, 0xC4)         # 15044
F001 = (0x13, 0x89)         # 5001


async def _serving(tmp_path: Path, **settings: Any) -> Adapter:
    adapter = Adapter(AdapterSettings(port=0, io_port=0, state_path=tmp_path / "state.json",
                                      control_path=tmp_path / "control.sock", http="127.0.0.1:0", **settings))
    await adapter.start_serving()
    return adapter


@contextlib.asynccontextmanager
async def serving(tmp_path: Path, **settings: Any) -> AsyncIterator[tuple[Adapter, tuple[aiohttp.ClientSession, str]]]:
    aiohttp = needs("aiohttp")
    adapter = await _serving(tmp_path, **settings)
    try:
        async with aiohttp.ClientSession() as session:
            yield adapter, (session, f"http://127.0.0.1:{adapter.http_api.port}")
    finally:
        await adapter.stop_serving()


def writes(adapter: Adapter, after: int = 0) -> list[dict[str, Any]]:
    return [e.fields for e in adapter.events.since(after) if e.kind == "parameter write"]


def last(adapter: Adapter) -> int:
    events = adapter.events.events
    return events[-1].number if events else 0


# -- the Digital Operator over HTTP ----------------------------------------------------------------------------
async def test_mx2_function_codes_over_http_in_the_operators_unit(tmp_path: Path) -> None:
    async with serving(tmp_path, profile="mx2") as (adapter, http), \
            await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=_catalog(adapter)) as scanner:
        status, a004 = await call(http, "GET", "/parameters/A004")
        assert (status, a004) == (200, {"code": "A004", "name": "Maximum frequency", "value": "50.0", "raw": 500,
                                        "unit": "Hz", "address": "0x1204"})
        status, a004 = await call(http, "PUT", "/parameters/a004", json={"value": 60})      # 60.0 Hz, 0.1 Hz steps
        assert status == 200 and (a004["value"], a004["raw"]) == ("60.0", 600)  # type: ignore[index]
        assert (await scanner.read(FUNCTION_CODE, *A004, cip_type=_uint())).raw == 600
        status, p044 = await call(http, "PUT", "/parameters/P044", json={"value": "1.5"})  # 0.1 s steps
        assert status == 200 and (p044["raw"], p044["unit"]) == (15, "s")  # type: ignore[index]
        status, p046 = await call(http, "PUT", "/parameters/P046", json={"value": "Extended Control IO"})
        assert status == 200 and (p046["raw"], p046["meaning"]) == (4, "Extended Control IO")  # type: ignore[index]
        # F001: the operator sets it (A001 = 2, "digital operator (F001)"); the Function Code object may not
        # (section E-2-2), and still refuses it.
        status, f001 = await call(http, "PUT", "/parameters/F001", json={"value": "12.5"})
        assert status == 200 and (f001["value"], f001["raw"]) == ("12.50", 1250)  # type: ignore[index]
        with pytest.raises(CipError) as refused:
            await scanner.set_attribute_single(FUNCTION_CODE, *F001, 100, _udint())
        assert refused.value.general == 0x0E
        # What the operator does not take: 400 for a value, 404 for a code, 409 when the inverter refuses.
        status, body = await call(http, "PUT", "/parameters/A004", json={"value": "60.05"})
        assert status == 400 and body["error"] == "A004=60.05: finer than the keypad's step 0.1"  # type: ignore[index]
        status, body = await call(http, "PUT", "/parameters/A004", json={"value": 4000})
        assert status == 400 and "A004 (Maximum frequency) takes 30.0..400.0 Hz" in body["error"]  # type: ignore[index]
        status, body = await call(http, "GET", "/parameters/X999")
        assert status == 404 and body["error"] == ("'X999' is not a code of the MX2 Digital Operator "  # type: ignore[index]
                                                   "(e.g. F001, A001, A004, b049, P044, P046)")
        status, body = await call(http, "PUT", "/parameters/d001", json={"value": 5})
        assert status == 409 and "read-only" in body["error"] and "d001" in body["error"]  # type: ignore[index]
        status, body = await call(http, "PUT", "/parameters/A004", json={"value": 60, "unit": "Hz"})
        assert status == 400
        assert (await call(http, "GET", "/parameters/A004"))[1]["raw"] == 600  # type: ignore[index]


async def test_rx_refuses_what_is_not_run_mode_editable_while_running(tmp_path: Path) -> None:
    async with serving(tmp_path, profile="rx") as (adapter, http):
        status, a004 = await call(http, "GET", "/parameters/A004")
        assert status == 200 and a004["address"] is None   # type: ignore[index]  # RX: by function code only
        # The FW terminal (A002 = 1, control terminal): the test rig's wiring runs the inverter.
        adapter.device.inverter.set_local_run(asyncio.get_running_loop().time(), 1)  # type: ignore[attr-defined]
        mark = last(adapter)
        status, body = await call(http, "PUT", "/parameters/A004", json={"value": 60})
        assert status == 409 and body["error"].endswith("(A004 is not run-mode editable)")  # type: ignore[index]
        status, f001 = await call(http, "PUT", "/parameters/F001", json={"value": 30})   # run-mode editable
        assert status == 200 and f001["raw"] == 3000  # type: ignore[index]
        assert [w["code"] for w in writes(adapter, mark)] == ["F001"]                   # the refused one is none
        status, body = await call(http, "PUT", "/parameters/b180", json={"value": 1})
        assert status == 409 and "stores every parameter to EEPROM: write it over the network" in body["error"]  # type: ignore[index]


async def test_a_device_without_a_keypad_says_so(tmp_path: Path) -> None:
    aiohttp = needs("aiohttp")
    from cipstack.devices.base import DeviceLimits
    from cipstack.eds.emulated_device import build_eds_device
    from cipstack.eds.reader import read_eds
    from cipstack.objects.tcpip import NetworkInterface

    device = build_eds_device(read_eds(str(ROOT / "tests" / "eds" / "files" / "ez_style_io_block.eds")),
                              NetworkInterface(), DeviceLimits())
    adapter = Adapter(AdapterSettings(port=0, io_port=0, control_path=tmp_path / "control.sock",
                                      http="127.0.0.1:0"), device=device)
    await adapter.start_serving()
    try:
        async with aiohttp.ClientSession() as session:
            http = (session, f"http://127.0.0.1:{adapter.http_api.port}")
            status, body = await call(http, "GET", "/parameters/ACC")
            assert status == 404 and "this device has no keypad" in body["error"]  # type: ignore[index]
            status, body = await call(http, "PUT", "/parameters/ACC", json={"value": 1})
            assert status == 404 and "this device has no keypad" in body["error"]  # type: ignore[index]
    finally:
        await adapter.stop_serving()


# -- at start: the command line and the pytest plugin -------------------------------------------------------------
def test_param_sets_an_mx2_function_code_from_the_command_line(tmp_path: Path) -> None:
    address, process = start_adapter("--quiet", "--profile", "mx2", "--control", str(tmp_path / "mx2.sock"),
                                     "--state", str(tmp_path / "mx2.json"), "--param", "A004=60",
                                     "--param", "P044=1.5")
    try:
        got = run("get", address, f"0x65/{A004[0]}/{A004[1]}", "--json")
        assert got.returncode == 0, got.stderr
        assert json.loads(got.stdout)["value"] == 600 and json.loads(got.stdout)["engineering"] == 60.0
    finally:
        stderr = stop(process)
    assert "keypad parameter A004 Maximum frequency = 60.0 Hz" in stderr
    assert "keypad parameter P044 Network error timer = 1.5 s" in stderr


def _power_cycle(address: str, control: Path, probe: str) -> None:
    """``cipstack drive power cycle`` and wait for the power to come back (a CIP read of ``probe`` answers)."""
    cycled = run("drive", "power", "cycle", "--off", "1s", "--control", str(control))
    assert cycled.returncode == 0, cycled.stderr
    wait_for(lambda: run("get", address, probe).returncode == 0, 30, "the power to come back")


def _cip(address: str, path: str) -> int:
    got = run("get", address, path, "--json")
    assert got.returncode == 0, got.stderr
    return int(json.loads(got.stdout)["value"])


def _keypad(control: Path, code: str) -> int:
    got = run("drive", "parameter", code, "--control", str(control), "--json")
    assert got.returncode == 0, got.stderr
    return int(json.loads(got.stdout)["raw"])


@pytest.mark.parametrize("unsaved", [False, True])
def test_acg_param_values_are_keypad_entries_a_power_cycle_keeps(unsaved: bool, tmp_path: Path) -> None:
    """ACG RS-485 manual, "Saving Parameters Defined by Communication": what is written over communication
    and not saved is lost at a power-cycle, a keypad entry is not. ``--param`` is the keypad: drv = 4 and
    Frq = 8 survive the power-cycle, so a PLC drives the drive again after it; ACC written over CIP and not
    saved goes back to the keypad's 2.5 s. ``--param-unsaved`` makes them communication writes: factory
    values after the power-cycle."""
    control, state = tmp_path / "acg.sock", tmp_path / "acg.json"
    address, process = start_adapter("--quiet", "--control", str(control), "--state", str(state), "--param", "drv=4",
                                      "--param", "Frq=8", "--param", "ACC=2.5", *(["--param-unsaved"] * unsaved))
    try:
        assert _cip(address, "0x29/1/14") == 1                                # Control From Net: drv = 4
        assert run("set", address, "0x2A/1/102", "75").returncode == 0        # ACC 7.5 s over CIP, not saved
        _power_cycle(address, control, "0x29/1/14")
        after = (_keypad(control, "drv"), _keypad(control, "Frq"), _cip(address, "0x29/1/14"),
                 _cip(address, "0x2A/1/29"), _cip(address, "0x2A/1/102"))
    finally:
        stop(process)
    # drv, Frq, Control From Net (drv = 4), Ref.From Network (0x2A/1/29: Frq = 8), ACC (0.1 s)
    assert after == ((1, 0, 0, 0, 50) if unsaved else (4, 8, 1, 1, 25))
    assert not state.exists()   # kept as the keypad keeps them, in the drive's memory: no save was asked


@pytest.mark.parametrize("unsaved", [False, True])
def test_mx2_operator_entries_a_power_cycle_keeps(unsaved: bool, tmp_path: Path) -> None:
    """CompoNet manual section 3-3 Step 3: a setting on the Digital Operator, then power OFF and ON, and it
    takes effect; network writes are temporary until the ENTER command (section E-2-2 note). Identity
    attribute 9 counts saves through the option board only (Table C-2): an operator entry is none."""
    control = tmp_path / "mx2.sock"
    address, process = start_adapter("--quiet", "--profile", "mx2", "--control", str(control), "--factory",
                                     "--param", "A004=60", *(["--param-unsaved"] * unsaved))
    a004 = f"0x65/{A004[0]}/{A004[1]}"
    try:
        assert _cip(address, a004) == 600
        _power_cycle(address, control, a004)
        after = (_cip(address, a004), _cip(address, "1/1/9"))
    finally:
        stop(process)
    assert after == ((500, 0) if unsaved else (600, 0))   # A004 in 0.1 Hz (default 50.0 Hz); attribute 9


def test_param_unsaved_needs_param(tmp_path: Path) -> None:
    result = run("adapter", "--port", "0", "--state", str(tmp_path / "state.json"), "--param-unsaved")
    assert result.returncode == 2 and one_line_error(result) == \
        "cipstack adapter: --param-unsaved goes with --param CODE=VALUE", result.stderr


@pytest.mark.parametrize(("args", "message"), [
    (["--profile", "mx2", "--param", "A004=600"],
     "cipstack adapter: --param 'A004=600': A004 (Maximum frequency) takes 30.0..400.0 Hz"),
    (["--profile", "rx", "--param", "d001=5"], "cipstack adapter: --param 'd001=5': register 0x1001"),
    (["--profile", "mx2", "--param", "drv=4"],
     "cipstack adapter: --param 'drv=4': 'drv' is not a code of the MX2 Digital Operator (e.g. F001, A001, "
     "A004, b049, P044, P046)"),
])
def test_a_bad_mx2_param_is_one_line_and_exit_2(args: list[str], message: str, tmp_path: Path) -> None:
    result = run("adapter", "--port", "0", "--state", str(tmp_path / "state.json"), *args)
    assert result.returncode == 2 and one_line_error(result).startswith(message), result.stderr


def test_a_fleet_spec_gives_an_rx_its_function_codes(tmp_path: Path) -> None:
    from cipstack.fleet.serve import build_adapter
    from cipstack.fleet.spec import assign, read_spec_file

    spec = tmp_path / "plant.toml"
    spec.write_text('[[device]]\nprofile = "rx"\nfirst = "127.0.0.71"\nparams = { P044 = "1.5", A004 = 60 }\n')
    _, groups = read_spec_file(spec)
    (device,) = assign(groups, None, tmp_path)
    adapter = build_adapter(device, 0, 0)
    try:
        assert (adapter.keypad_parameter("P044")["raw"], adapter.keypad_parameter("A004")["raw"]) == (15, 600)
    finally:
        adapter.device.close()


SUITE = '''
import pytest


@pytest.mark.cip_adapter(profile="mx2", params=["A004=60", "P046=5"])
def test_the_marker_sets_the_operators_parameters(cip_adapter, cip_scanner):
    assert cip_adapter.parameter("A004")["value"] == "60.0"
    assert cip_scanner.read(0x65, 0, 4, cip_type=UINT).raw == 600
    # The option board starts with the connection path set on the operator (section 1-1-1).
    assert cip_adapter.adapter.device.inverter.connection_path == 5
    assert [e for e in cip_adapter.events() if e.kind == "parameter write"] == []   # start-up: no event
    assert cip_adapter.set_parameter("F001", "12.5")["raw"] == 1250
    written = [e.fields for e in cip_adapter.events() if e.kind == "parameter write"]
    assert written == [{"origin": "python", "code": "F001", "address": "0x0001", "raw": 1250, "value": "12.50"}]


def test_the_factory_takes_an_rx_parameter(cip_adapter_factory):
    rx = cip_adapter_factory(profile="rx", params=["P044=1.5"])
    assert rx.parameter("P044")["raw"] == 15
'''


def test_the_pytest_plugin_takes_mx2_parameters(tmp_path: Path) -> None:
    (tmp_path / "test_mx2.py").write_text("from cipstack.cip.types import UINT\n" + textwrap.dedent(SUITE))
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "cipstack.testing",
                             "test_mx2.py"], capture_output=True, text=True, cwd=tmp_path, timeout=180, check=False,
                            env=environment())
    assert "2 passed" in result.stdout, result.stdout + result.stderr


# -- events: one per accepted write, from every route --------------------------------------------------------------
async def test_each_route_writes_one_event_with_what_it_wrote(tmp_path: Path) -> None:
    AsyncModbusTcpClient = needs("pymodbus.client").AsyncModbusTcpClient

    async with serving(tmp_path, modbus_port=0, rtu="pty") as (adapter, http):
        assert adapter.modbus is not None and adapter.rtu is not None
        events = adapter.events
        # CIP: class 0x64 (dr.20 Max Freq, instance 1 attribute 20) and AC/DC Drive 102 (ACC): one event each.
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=catalog_for(259, 100)) as scanner:
            await scanner.set_attribute_single(0x64, 1, 20, 5000)
            await scanner.set_attribute_single(0x2A, 1, 102, 25)
            with pytest.raises(CipError):
                await scanner.set_attribute_single(0x64, 7, 6, 1)          # CM.6 is read only: no event
        cip = writes(adapter)
        assert [{k: w[k] for k in ("origin", "code", "address", "raw", "value", "service", "path", "data")}
                for w in cip] == [
            {"origin": "cip", "code": "dr.20", "address": "0x1114", "raw": 5000, "value": "50.00", "service": "0x10",
             "path": "20642401" + "3014", "data": "8813"},
            {"origin": "cip", "code": "ACC", "address": "0x1F01", "raw": 25, "value": "2.5", "service": "0x10",
             "path": "202a24013066", "data": "1900"}]
        assert all(w["peer"].startswith("127.0.0.1:") for w in cip)
        # Modbus TCP (pymodbus): one event per register written; a refused write is none.
        mark = last(adapter)
        client = AsyncModbusTcpClient("127.0.0.1", port=adapter.modbus.port)
        await client.connect()
        try:
            assert not (await client.write_register(ACG_REGISTERS.by_code("dEC").address, 35)).isError()
            assert (await client.write_register(ACG_REGISTERS.by_code("CM.6").address, 1)).isError()
            local = client.ctx.transport.get_extra_info("sockname")   # type: ignore[union-attr]
        finally:
            client.close()
        assert writes(adapter, mark) == [{"origin": "modbus-tcp", "peer": f"{local[0]}:{local[1]}", "code": "dEC",
                                          "address": "0x1F02", "raw": 35, "value": "3.5"}]
        # Modbus-RTU on the pty: station 1 (CM.1), PDU address = communication address - 1.
        mark = last(adapter)
        fd = os.open(adapter.rtu.name, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(fd)
        try:
            acc = ACG_REGISTERS.by_code("ACC").address - 1
            os.write(fd, with_crc(bytes.fromhex("01 06") + acc.to_bytes(2, "big") + (99).to_bytes(2, "big")))
            event = await events.wait_for(lambda e: e.kind == "parameter write" and e.number > mark, 5)
        finally:
            os.close(fd)
        assert event.fields == {"origin": "modbus-rtu", "station": 1, "code": "ACC", "address": "0x1F01", "raw": 99,
                                "value": "9.9"}
        # HTTP: the keypad's write is the event; nothing else sees it again.
        mark = last(adapter)
        status, _ = await call(http, "PUT", "/parameters/drv", json={"value": "Field Bus"})
        assert status == 200
        (http_write,) = writes(adapter, mark)
        assert {k: v for k, v in http_write.items() if k != "peer"} == {
            "origin": "http", "code": "drv", "address": "0x1F03", "raw": 4, "value": "4"}
        assert http_write["peer"].startswith("127.0.0.1:")
        status, body = await call(http, "GET", f"/events?since={mark}")
        assert [e["kind"] for e in body] == ["parameter write"] and body[0]["origin"] == "http"  # type: ignore[index]


async def test_an_mx2_function_code_written_over_cip_is_one_event(tmp_path: Path) -> None:
    async with serving(tmp_path, profile="mx2") as (adapter, _), \
            await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=_catalog(adapter)) as scanner:
        adapter.events  # noqa: B018 (watching from now on)
        await scanner.set_attribute_single(FUNCTION_CODE, *P044, 20, _uint())           # P044 2.0 s
        await scanner.set_attribute_single(0x64, 0x12, 0x04, 650, _uint())                # A004 by Modbus address
    (p044, a004) = writes(adapter)
    assert {k: p044[k] for k in ("origin", "code", "address", "raw", "value")} == {
        "origin": "cip", "code": "P044", "address": "0x162E", "raw": 20, "value": "2.0"}
    assert {k: a004[k] for k in ("code", "raw", "value")} == {"code": "A004", "raw": 650, "value": "65.0"}


async def test_a_modbus_port_nobody_watches_has_no_tap(tmp_path: Path) -> None:
    adapter = Adapter(AdapterSettings(port=0, io_port=0, modbus_port=0, state_path=tmp_path / "acg.json"))
    await adapter.start()
    try:
        assert adapter.modbus is not None and adapter.observers == []
        stream = adapter.events
        assert adapter.observers == [stream]
        stream.stop()
        assert adapter.observers == []
        before = len(stream.events)
        reader, writer = await asyncio.open_connection("127.0.0.1", adapter.modbus.port)
        dec = ACG_REGISTERS.by_code("dEC").address.to_bytes(2, "big")
        writer.write(bytes.fromhex("0001 0000 0006 01 06") + dec + (35).to_bytes(2, "big"))   # write single register
        reply = await asyncio.wait_for(reader.readexactly(8), 5)
        assert reply[7] == 0x06                                            # answered, not an exception
        writer.close()
        assert adapter.keypad_parameter("dEC")["raw"] == 35                # written
        assert len(stream.events) == before                                # and no event: nobody watches
    finally:
        await adapter.close()


def _catalog(adapter: Adapter) -> Any:
    info = adapter.device.identity_info
    return catalog_for(info.vendor_id, info.product_code)


def _uint() -> Any:
    from cipstack.cip.types import UINT

    return UINT


def _udint() -> Any:
    from cipstack.cip.types import UDINT

    return UDINT

