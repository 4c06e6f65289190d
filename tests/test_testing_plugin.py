"""The pytest plugin (``cipstack.testing``) as a user's suite meets it: pytest run in another process
on test files that use its fixtures, sync and async, with markers and the factory; and the example
suite of a scanner program's comm-loss handling (examples/comm_loss)."""

from __future__ import annotations

import inspect
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.inner_pytest import environment

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]

SUITE = '''
import asyncio

import pytest

from cipstack.scanner import Scanner


@pytest.mark.cip_adapter(profile="mx2")
def test_marker_chooses_the_device(cip_adapter, cip_scanner):
    assert cip_scanner.read(0x01, 1, 7) == cip_adapter.adapter.device.identity_info.product_name
    assert cip_adapter.options.state_path.name == "adapter.json"


def test_factory_and_fleet(cip_adapter_factory, cip_fleet):
    rx = cip_adapter_factory(profile="rx")
    assert len(cip_fleet) == 2 and len({d.port for d in [rx, *cip_fleet]}) == 3
    assert "RX" in rx.adapter.device.identity_info.product_name


@pytest.mark.cip_fleet(count=3)
def test_fleet_count(cip_fleet):
    assert len(cip_fleet) == 3


@pytest.mark.asyncio
async def test_async_faults_and_events(cip_adapter):
    scanner = await Scanner.connect(cip_adapter.address)
    async with scanner, scanner.io_connection(output=21, input=71, rpi=0.01, timeout_multiplier=1,
                                              target_io_port=cip_adapter.io_port):
        await cip_adapter.event("connection opened")
        fault = cip_adapter.fault("unplug")
        assert [f["name"] for f in cip_adapter.faults()] == ["unplug"] and fault["id"] == 1
        event = await cip_adapter.event("connection timed out")
        assert event.fields["originator"] == "127.0.0.1"


def test_a_power_cycle_ends_the_session_and_a_new_scanner_waits_for_the_power(cip_adapter, cip_scanner):
    cip_scanner.write(0x2A, 1, 102, 75)                     # ACC 7.5 s, not saved
    cip_adapter.fault("power-cycle", off="3s")              # answers while the power is off
    with pytest.raises(ConnectionError):                    # cip_scanner's session went with the power
        cip_scanner.read(0x2A, 1, 102)
    scanner = cip_adapter.scanner()                         # connects once the power is back
    assert scanner.read(0x2A, 1, 102) == 50                 # what was not saved is lost


def test_sync_wait_for_a_trip(cip_adapter):
    cip_adapter.trip(0x4200)
    assert cip_adapter.wait_for("trip", 5).fields["trip"] == "OverHeat"


def test_every_operation_s_method(cip_adapter):
    """The methods made from the operations' declarations, each called as a user's test calls it."""
    assert cip_adapter.status()["faults"] == 0
    assert {"code": "OverHeat", "label": "OverHeat", "fault_code": 0x4200} in cip_adapter.trips()
    assert cip_adapter.trip("OverHeat")["trip"] == "OverHeat"
    assert cip_adapter.reset()["cleared"] == "OverHeat"
    assert cip_adapter.set_parameter("ACC", 2.5)["value"] == cip_adapter.parameter(code="ACC")["value"]
    assert cip_adapter.parameters()["keypad"] == "the ACG keypad"
    assert any(row["name"] == "stop-producing" for row in cip_adapter.fault_table())
    assert cip_adapter.fault("delay-replies", by="10ms", for_=5)["options"]["for"] == 5.0
    assert [f["name"] for f in cip_adapter.faults()] == ["delay-replies"]
    assert [f["name"] for f in cip_adapter.clear_faults("delay-replies")] == ["delay-replies"]
    assert cip_adapter.link("unplug")["name"] == "unplug" and cip_adapter.link(state="plug")["name"] == "plug"
    assert cip_adapter.power("cycle", off="0.1s")["name"] == "power-cycle"
    assert cip_adapter.connections()["sessions"] == []
    with pytest.raises(TypeError, match="code"):
        cip_adapter.trip()


EDS = {eds!r}


@pytest.mark.cip_adapter(eds=EDS)
def test_an_eds_device(cip_adapter, cip_scanner):
    assert cip_adapter.options.state_path is None
    assert cip_scanner.read(0x01, 1, 1) == cip_adapter.adapter.device.identity_info.vendor_id


@pytest.mark.cip_adapter(colour="red")
def test_a_bad_marker_option(cip_adapter):
    pass
'''


def pytest_in_subprocess(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "cipstack.testing",
                           *args], capture_output=True, text=True, cwd=cwd, timeout=180, check=False,
                          env=environment())


def test_the_fixtures_in_a_users_suite(tmp_path: Path) -> None:
    eds = str(ROOT / "tests" / "eds" / "files" / "ez_style_io_block.eds")
    (tmp_path / "test_users.py").write_text(textwrap.dedent(SUITE).replace("{eds!r}", repr(eds)))
    result = pytest_in_subprocess("-rA", "test_users.py", cwd=tmp_path)
    out = result.stdout
    assert "8 passed, 1 error" in out, out + result.stderr
    assert "ERROR test_users.py::test_a_bad_marker_option" in out
    assert ("cip_adapter: unknown option colour; valid: profile, model, eds, params, params_unsaved, host, "
            "settings") in out


def test_the_device_s_methods_are_made_from_the_operations() -> None:
    """Each operation the declarations give a Python name is a method of the plugin's device whose
    parameters are its argument record's keys (a fault's options as keywords), with its summary as help;
    none is written by hand, and the event stream's own methods stay."""
    from cipstack.control.operations import OPERATIONS
    from cipstack.testing.device import EmulatedDevice

    named = [op for op in OPERATIONS if op.python_name is not None]
    assert {op.python_name for op in named} >= {"fault", "clear_faults", "faults", "status", "trip", "parameter",
                                                 "set_parameter", "reset", "power", "link"}
    for operation in named:
        method = getattr(EmulatedDevice, str(operation.python_name))
        assert method.__module__ == "cipstack.testing.device" and method.__name__ == operation.python_name
        parameters = inspect.signature(method).parameters
        assert [name for name in parameters if name != "self"] == [a.key for a in operation.arguments]
        assert operation.summary[1:] in (method.__doc__ or "")
    assert inspect.signature(EmulatedDevice.fault).parameters["options"].kind is inspect.Parameter.VAR_KEYWORD
    assert {"events", "wait_for", "event", "call"} <= set(vars(EmulatedDevice))


def test_an_async_test_without_pytest_asyncio_is_told_what_it_needs(tmp_path: Path) -> None:
    """The docs say async tests need pytest-asyncio: without it, pytest fails such a test and names it."""
    (tmp_path / "test_async.py").write_text("async def test_async(cip_adapter):\n    assert cip_adapter.port\n")
    result = pytest_in_subprocess("-p", "no:asyncio", "test_async.py", cwd=tmp_path)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "async def functions are not natively supported" in result.stdout and "pytest-asyncio" in result.stdout


def test_io_connection_names_its_keyword_arguments() -> None:
    """``io_connection``'s options are in its signature (IDEs and the API reference show them), and a
    misspelt one is refused by name before anything is sent."""
    from cipstack.scanner import Scanner, SyncScanner

    for method in (Scanner.io_connection, SyncScanner.io_connection):
        parameters = inspect.signature(method).parameters
        assert not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values())
        assert {"target_io_port", "timeout_multiplier", "multicast", "ot_format", "config_data", "heartbeat",
                "local_io_port", "run"} <= set(parameters)
    scanner = SyncScanner.__new__(SyncScanner)
    with pytest.raises(TypeError, match="timeout_multipler"):
        scanner.io_connection(output=21, input=71, timeout_multipler=3)  # type: ignore[call-arg]


def test_the_example_suite_passes() -> None:
    result = pytest_in_subprocess("examples/comm_loss", cwd=ROOT)
    assert result.returncode == 0 and "4 passed" in result.stdout, result.stdout + result.stderr


def test_the_plugin_is_registered_under_its_module_name() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert project["project"]["entry-points"]["pytest11"] == {"cipstack.testing": "cipstack.testing"}
