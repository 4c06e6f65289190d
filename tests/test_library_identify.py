"""The scanner identifies the device and decodes by its profile's declarations by default (issue 26,
items 1, 3 and 9): values carry their unit and scale, the CLI prints what the library reads, and a
name nothing declares says where it was looked for.

Units and scales are those of the manuals' tables: ACG-ET2 manual (ACG-ET2, AC/DC Drive object 0x2A:
100 Actual Hz "0-400.00 Hz", 102 Acceleration Time "0-6000.0 sec", 9 Actual Current "0-111.0 A")
and CompoNet manual (Omron option board, Table D-7 AC/DC Drive Object: 0x09 Current Actual "Unit:
[0.1 A]", 0x12 Accel Time "Unit: [ms]").
"""

from __future__ import annotations

import json
import struct
from collections.abc import AsyncIterator

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.catalog import Catalog
from cipstack.cip.epath import PortSegment
from cipstack.cip.values import Scaling, Value
from cipstack.componet.gateway import COMPONET_PORT
from cipstack.devices.acg.device import build_acg_device
from cipstack.devices.omron.device import build_componet_gateway, build_omron_device
from cipstack.scanner import Scanner, SyncScanner, UnknownAttributeError
from tests.fakes import GET_ATTRIBUTE_SINGLE, MrRequest, ScriptedTarget, mr_reply, rr_body
from tests.library_support import run_cli, threaded_adapter


@pytest.fixture
async def acg() -> AsyncIterator[Adapter]:
    settings = AdapterSettings(host="127.0.0.1", port=0, io_port=0)
    async with Adapter(settings, device=build_acg_device()) as running:
        yield running


# -- item 1: identify by default -------------------------------------------------------------------------
async def test_connect_identifies_and_decodes_by_the_profile(acg: Adapter) -> None:
    async with await Scanner.connect(f"127.0.0.1:{acg.port}") as scanner:
        identity = scanner.identity
        assert identity is not None and (identity.vendor_id, identity.product_code) == (259, 100)
        assert scanner.catalog.source.startswith("profile acg ")
        accel = await scanner.read(0x2A, 1, 102)
    # ACG-ET2 manual, AC/DC Drive attribute 102 "Acceleration Time, 0-6000.0 sec": 0.1 s per step; ACC's
    # factory value is 5.0 s (ACG RS-485 manual, dr ACC).
    assert (accel.raw, accel.value, accel.unit, str(accel)) == (50, 5.0, "s", "5.0 s")
    assert accel.name == "Acceleration Time" and accel.scaled


async def test_catalog_wins_and_identify_false_opts_out(acg: Adapter) -> None:
    async with await Scanner.connect(f"127.0.0.1:{acg.port}", catalog=Catalog()) as given:
        assert given.identity is None
        assert (await given.read(0x2A, 1, 102)).raw == b"\x32\x00"      # nothing declares it: the bytes
    async with await Scanner.connect(f"127.0.0.1:{acg.port}", identify=False) as plain:
        assert plain.identity is None and plain.catalog.source == "the standard objects only"
        assert (await plain.read(0x2A, 1, 102)).raw == b"\x32\x00"


def test_sync_scanner_identifies() -> None:
    with threaded_adapter(build_acg_device()) as adapter, SyncScanner(f"127.0.0.1:{adapter.port}") as scanner:
        assert scanner.identity is not None and scanner.identity.product_name == "CENT"
        assert str(scanner.read(0x2A, 1, 102)) == "5.0 s"
        assert str(scanner.read(0x2A, 1, 100)) == "0.00 Hz"                 # ACG-ET2 manual: 0-400.00 Hz


def _identity_only_by_attributes(request: MrRequest) -> bytes | None:
    """A device that answers ListIdentity with no item, and Identity attributes 1-4 and 7 of the ACG
    (vendor 259, device type 2, product code 100, revision 1.1, 'CENT'); 0x2A/1/102 is 50."""
    if request.service != GET_ATTRIBUTE_SINGLE:
        return None
    values = {bytes.fromhex("200124013001"): struct.pack("<H", 259),
              bytes.fromhex("200124013002"): struct.pack("<H", 2),
              bytes.fromhex("200124013003"): struct.pack("<H", 100),
              bytes.fromhex("200124013004"): bytes((1, 1)),
              bytes.fromhex("200124013007"): b"\x04CENT",
              bytes.fromhex("202A24013066"): struct.pack("<H", 50)}
    data = values.get(request.path)
    return rr_body(mr_reply(request.service, data=data)) if data is not None else None


async def test_identity_attributes_where_list_identity_gives_nothing() -> None:
    with ScriptedTarget(_identity_only_by_attributes) as target:
        async with await Scanner.connect(target.address, timeout=2) as scanner:
            assert scanner.identity is not None and scanner.identity.product_code == 100
            assert scanner.identity.revision == (1, 1) and scanner.identity.product_name == "CENT"
            assert str(await scanner.read(0x2A, 1, 102)) == "5.0 s"
        asked = [r.path[-1] for r in target.services(GET_ATTRIBUTE_SINGLE)]
        assert asked[:5] == [1, 3, 2, 4, 7]


def test_cli_identifies_the_same_way() -> None:
    """One code path: the CLI decodes the scripted device's attribute by the identity the attributes gave."""
    with ScriptedTarget(_identity_only_by_attributes) as target:
        result = run_cli("get", target.address, "0x2A/1/102", "--timeout", "2")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "Acceleration Time = 5.0 s (50)"


async def test_a_device_that_does_not_identify_keeps_the_standard_objects_and_says_why() -> None:
    with ScriptedTarget() as target:                    # no ListIdentity item, 0x08 to every request
        async with await Scanner.connect(target.address, timeout=2) as scanner:
            assert scanner.identity is None
            assert "did not identify itself" in scanner.catalog.source
            with pytest.raises(UnknownAttributeError, match=r"did not identify itself.*give eds= or catalog="):
                await scanner.write(0x2A, 1, 102, 5.0, scaled=True)


async def test_routed_identification_asks_the_componet_node() -> None:
    """Through the CompoNet gateway (CompoNet manual), ListIdentity would describe the gateway: the routed
    node's own Identity attributes give its profile."""
    device = build_componet_gateway([("mx2", "MX2-A2015-E", 3)])
    route = [PortSegment(COMPONET_PORT, bytes([3]))]
    async with Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0), device=device) as gateway, \
            await Scanner.connect(f"127.0.0.1:{gateway.port}", route=route) as scanner:
        assert scanner.catalog.source.startswith("profile mx2 ")
        accel = await scanner.read(0x2A, 1, 0x12)
    # Table D-7: 0x12 Accel Time, UINT, "Unit: [ms]", default 10000.
    assert (accel.raw, str(accel)) == (10000, "10000 ms")


# -- item 3: values with their unit ------------------------------------------------------------------------
async def test_omron_values_carry_the_units_of_table_d7() -> None:
    settings = AdapterSettings(host="127.0.0.1", port=0, io_port=0)
    async with Adapter(settings, device=build_omron_device("MX2-A2015-E")) as adapter, \
            await Scanner.connect(f"127.0.0.1:{adapter.port}") as scanner:
        current = await scanner.read(0x2A, 1, 0x09)
        assert (current.unit, current.scaling.scale) == ("A", 0.1)      # Table D-7: "Unit: [0.1 A]"
        assert str(current) == f"{current.raw / 10:.1f} A"
        await scanner.write(0x2A, 1, 0x12, 2500)                          # raw: ms
        assert str(await scanner.read(0x2A, 1, 0x12)) == "2500 ms"


async def test_write_takes_raw_or_scaled_by_one_rule(acg: Adapter) -> None:
    async with await Scanner.connect(f"127.0.0.1:{acg.port}") as scanner:
        await scanner.write(0x2A, 1, 102, 7.5, scaled=True)
        assert (await scanner.read(0x2A, 1, 102)).raw == 75
        await scanner.write(0x2A, 1, 102, 60)                                 # raw: 6.0 s
        assert str(await scanner.read(0x2A, 1, 102)) == "6.0 s"
        await scanner.write(0x2A, 1, 102, await scanner.read(0x2A, 1, 103))   # a Value writes its raw value
        assert (await scanner.read(0x2A, 1, 102)).raw == 100
        with pytest.raises(ValueError, match=r"scaled=True"):
            await scanner.write(0x2A, 1, 102, 5.0)                            # a float is not raw steps
        with pytest.raises(ValueError, match=r"not a whole number of steps of 0\.1 s"):
            await scanner.write(0x2A, 1, 102, 5.05, scaled=True)
        assert (await scanner.read(0x2A, 1, 102)).raw == 100                  # nothing was written


def test_value_object() -> None:
    hz = Value(3000, "Actual Hz", None, Scaling("Hz", 0.01))
    assert (str(hz), hz.value, hz.raw, hz == 3000, hz == Value(3000, "x", None, Scaling("Hz", 0.01))) == \
        ("30.00 Hz", 30.0, 3000, True, True)
    assert hz.json() == {"value": 3000, "engineering": 30.0, "unit": "Hz"}
    state = Value(3, "Drive State", None, Scaling(enum={3: "Ready"}))
    assert (str(state), state.meaning, state.json()) == ("3 (Ready)", "Ready", {"value": 3, "meaning": "Ready"})
    offset = Scaling("degC", 0.5, offset=-40, decimals=1)                     # EDS fields 13-16 and 21
    assert offset.text(100) == "30.0 degC" and offset.to_raw(30.0) == 100
    assert str(Value(b"\x32\x00")) == "32 00"


def test_cli_get_and_set_by_the_declaration() -> None:
    with threaded_adapter(build_acg_device()) as adapter:
        address = f"127.0.0.1:{adapter.port}"
        assert run_cli("get", address, "0x2A/1/102").stdout.strip() == "Acceleration Time = 5.0 s (50)"
        record = json.loads(run_cli("get", address, "0x2A/1/102", "--json").stdout)
        assert (record["value"], record["engineering"], record["unit"]) == (50, 5.0, "s")
        done = run_cli("set", address, "0x2A/1/102", "7.5", "--scaled")        # no --type: declared
        assert done.returncode == 0, done.stderr
        assert done.stdout.strip() == "set 0x2A/1/102 Acceleration Time = 7.5 s (75)"
        assert run_cli("set", address, "0x2A/1/102", "80").returncode == 0   # raw
        assert run_cli("get", address, "0x2A/1/102").stdout.strip() == "Acceleration Time = 8.0 s (80)"
        # A BOOL takes true/false/on/off/1/0: Forward Run Cmd. (0x29/1/3) on, then off.
        assert run_cli("set", address, "0x29/1/3", "on").returncode == 0
        assert run_cli("get", address, "0x29/1/3").stdout.strip() == "Forward Run Cmd. = 1"
        assert run_cli("set", address, "0x29/1/3", "false").returncode == 0
        assert run_cli("get", address, "0x29/1/3").stdout.strip() == "Forward Run Cmd. = 0"
        refused = run_cli("set", address, "0x2A/1/102", "5.05", "--scaled")
        assert refused.returncode == 2 and "not a whole number of steps of 0.1 s" in refused.stderr
        assert "Traceback" not in refused.stderr and refused.stderr.count("\n") == 1


# -- item 9: errors explain themselves ---------------------------------------------------------------------
async def test_unknown_attribute_names_the_catalog(acg: Adapter) -> None:
    async with await Scanner.connect(f"127.0.0.1:{acg.port}") as scanner:
        with pytest.raises(UnknownAttributeError, match=r"0x99/1/1 is not declared in profile acg .*give cip_type"):
            await scanner.set_attribute_single(0x99, 1, 1, 5)


def test_unknown_field_names_the_schema_and_its_fields() -> None:
    with threaded_adapter(build_acg_device()) as adapter, \
            SyncScanner(f"127.0.0.1:{adapter.port}") as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.02, target_io_port=adapter.io_endpoint.port) as io:
        with pytest.raises(AttributeError) as known:
            io.output.run_forwrd = 1
        message = str(known.value)
        assert "no field 'run_forwrd' in assembly 21 'Extended Speed Control Output' of profile acg" in message
        assert "run_forward" in message and "speed_reference" in message
    with threaded_adapter(build_acg_device()) as adapter, \
            SyncScanner(f"127.0.0.1:{adapter.port}", identify=False) as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.02, target_io_port=adapter.io_endpoint.port) as io, \
            pytest.raises(AttributeError, match=r"no field 'run_forward': no schema of assembly 21 in the standard "
                                                r"objects only \(use \.raw\)"):
        io.output.run_forward = 1


def test_cli_io_flags_take_on_and_off() -> None:
    """``cipstack io --set run_forward=on``: a flag field takes what a BOOL attribute takes."""
    with threaded_adapter(build_acg_device(), params=("drv=4", "Frq=8")) as adapter:
        address = f"127.0.0.1:{adapter.port}"
        io_port = str(adapter.io_endpoint.port)
        ran = run_cli("io", address, "--output", "21", "--input", "71", "--set", "run_forward=on", "--set",
                      "speed_reference=300", "--duration", "0.5s", "--target-io-port", io_port, "--io-port", "0",
                      "--print", "summary")
        assert ran.returncode == 0, ran.stderr
        assert run_cli("get", address, "0x29/1/7").stdout.strip() == "Running Forward = 1"
        bad = run_cli("io", address, "--output", "21", "--input", "71", "--set", "run_forward=maybe",
                      "--duration", "0.2s", "--target-io-port", io_port, "--io-port", "0")
        assert bad.returncode == 2 and "--set run_forward=maybe" in bad.stderr
