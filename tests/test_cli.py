"""The cipstack command, run as a user runs it: a real adapter process and real clients."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from cipstack.cli import parse_duration, parse_object_path
from tests.cli_errors import one_line_error
from tests.optional import needs
from tests.ports import free_port
from tests.waiting import wait_for


def run(*args: str, timeout: float = 20) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", *args], capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def adapter_process() -> Iterator[tuple[str, subprocess.Popen[str]]]:
    port = free_port()
    process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--host", "127.0.0.1", "--port",
                                str(port), "--io-port", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            break
        except OSError:
            time.sleep(0.05)
    else:
        process.kill()
        pytest.fail("adapter did not start")
    yield f"127.0.0.1:{port}", process
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
        process.wait(10)


def test_get_single_json(adapter_process: tuple[str, subprocess.Popen[str]]) -> None:
    address, _ = adapter_process
    result = run("get", address, "1/1/7", "--json")
    assert result.returncode == 0, result.stderr
    record = json.loads(result.stdout)
    assert record == {"status": 0, "data": "0443454e54", "value": "CENT", "type": "SHORT_STRING",
                      "name": "Product Name", "path": "1/1/7"}


def test_get_forms(adapter_process: tuple[str, subprocess.Popen[str]]) -> None:
    address, _ = adapter_process
    assert run("get", address, "0x01/0x01/0x03").stdout.strip() == "Product Code = 100"
    assert run("get", address, "1/1/1", "--connected").stdout.strip() == "Vendor ID = 259"
    everything = run("get", address, "1/1", "--json")
    assert json.loads(everything.stdout)["value"]["product_name"] == "CENT"
    typed = run("get", address, "0xF5/1/13", "--type", "INT", "--json")
    assert json.loads(typed.stdout)["type"] == "INT"


def test_set_then_get(adapter_process: tuple[str, subprocess.Popen[str]]) -> None:
    address, _ = adapter_process
    result = run("set", address, "0xF5/1/13", "0x3c", "--type", "UINT", "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == {"status": 0, "path": "0xF5/1/13", "data": "3c00", "value": 60, "unit": "s"}
    assert run("get", address, "0xF5/1/13").stdout.strip() == "Encapsulation Inactivity Timeout = 60 s"
    run("set", address, "0xF5/1/13", "120", "--type", "UINT")


@pytest.mark.parametrize(("args", "code", "fragment"), [
    (("get", "{a}", "1/1/99"), 1, "0x14 (attribute not supported)"),
    (("get", "{a}", "0x99/1/1"), 1, "0x05 (path destination unknown)"),
    (("set", "{a}", "0xF5/1/13", "9999", "--type", "UINT"), 1, "0x09 (invalid attribute value)"),
    (("set", "{a}", "0xF5/1/13", "70000", "--type", "UINT"), 2, "not a valid UINT"),
    (("set", "{a}", "0xF5/1/13", "x", "--type", "UINT"), 2, "not a valid UINT"),
    (("set", "{a}", "0xF5/1/13", "1", "--type", "FLOATY"), 2, "unknown CIP type"),
    (("set", "{a}", "0x99/1/1", "1"), 2, "is not declared in profile acg"),   # nothing to take the type from
    (("get", "{a}", "1/1/zz"), 2, "not a number"),
    (("get", "{a}", "1"), 2, "CLASS/INSTANCE"),
    (("get", "127.0.0.1:notaport", "1/1/1"), 2, "bad port"),
    (("get", "127.0.0.1:1", "1/1/1", "--timeout", "1"), 1, "cannot connect"),
    (("frobnicate",), 2, "invalid choice"),
    (("adapter", "--profile", "nope"), 2, "unknown profile"),
])
def test_errors_are_one_line(adapter_process: tuple[str, subprocess.Popen[str]], args: tuple[str, ...], code: int,
                             fragment: str) -> None:
    address, _ = adapter_process
    result = run(*(a.format(a=address) for a in args))
    assert result.returncode == code
    assert fragment in one_line_error(result)


def test_an_engineering_value_without_scaled_says_scaled(adapter_process: tuple[str, subprocess.Popen[str]]) -> None:
    """`cipstack set HOST 0x2A/1/102 2.5`: Accel Time counts 0.1 s steps, so 2.5 is the engineering
    value, and the message says `--scaled` (as the library says scaled=True); nothing is written."""
    address, _ = adapter_process
    before = run("get", address, "0x2A/1/102", "--json")
    result = run("set", address, "0x2A/1/102", "2.5")
    assert result.returncode == 2
    assert one_line_error(result) == ("cipstack set: 0x2A/1/102 Acceleration Time takes a raw integer (0.1 s per "
                                      "step): give 2.5 with --scaled, or the raw value 25")
    between = run("set", address, "0x2A/1/102", "2.55")
    assert between.returncode == 2 and "2.55 s is not a whole number of steps of 0.1 s" in one_line_error(between)
    assert run("get", address, "0x2A/1/102", "--json").stdout == before.stdout
    raw = run("set", address, "0x2A/1/102", str(json.loads(before.stdout)["value"]))
    assert raw.returncode == 0 and raw.stdout.startswith("set 0x2A/1/102 Acceleration Time = ")


def test_error_status_json(adapter_process: tuple[str, subprocess.Popen[str]]) -> None:
    address, _ = adapter_process
    result = run("get", address, "1/1/99", "--json")
    assert result.returncode == 1
    assert json.loads(result.stdout) == {"status": 0x14, "extended_status": [], "path": "1/1/99",
                                         "error": "0x14 (attribute not supported)"}


def test_identity_and_discover(adapter_process: tuple[str, subprocess.Popen[str]]) -> None:
    address, _ = adapter_process
    identity = json.loads(run("identity", address, "--json").stdout)
    assert identity["product_name"] == "CENT" and identity["vendor_id"] == 259
    # One Identity shape: ListIdentity's and the Identity object's Get_Attributes_All.
    everything = json.loads(run("get", address, "1/1", "--json").stdout)["value"]
    assert everything == {k: v for k, v in identity.items() if k not in ("state", "address")}
    host, port = address.split(":")
    found = run("discover", "--broadcast", host, "--port", port, "--timeout", "1", "--json")
    assert found.returncode == 0
    [record] = [json.loads(line) for line in found.stdout.splitlines()]
    assert record["product_code"] == 100 and record["address"] == address


def test_adapter_logs_and_stops_on_sigterm() -> None:
    port = free_port()
    command = [sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port", "0",
               "--log-level", "info"]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for _ in range(200):
            if run("get", f"127.0.0.1:{port}", "1/1/1", "--timeout", "1").returncode == 0:
                break
            time.sleep(0.05)
        process.send_signal(signal.SIGTERM)
        _, stderr = process.communicate(timeout=10)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0
    assert "listening on 127.0.0.1" in stderr
    assert "session" in stderr and "registered" in stderr
    assert "stopping" in stderr and "Traceback" not in stderr


def test_adapter_port_in_use() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        result = run("adapter", "--port", str(port), "--io-port", "0", timeout=10)
    assert result.returncode == 2
    assert one_line_error(result) == (f"cipstack adapter: cannot listen on TCP 127.0.0.1:{port} (EtherNet/IP, --port): "
                                      "Address already in use")


def test_python_dash_m_and_version() -> None:
    result = run("--version")
    assert result.returncode == 0 and result.stdout.startswith("cipstack ")
    assert os.path.exists(os.path.join(os.path.dirname(__import__("cipstack").__file__), "py.typed"))


def test_argument_parsers() -> None:
    assert parse_object_path("0x2A/1/8") == (0x2A, 1, 8)
    assert parse_object_path("@1/1") == (1, 1, None)
    assert parse_duration("500ms") == 0.5
    assert parse_duration("2s") == 2.0


def test_eds_check_against_a_live_device(adapter_process: tuple[str, subprocess.Popen[str]], tmp_path: Path) -> None:
    """The ACG's own EDS against the ACG emulator: no error; the sample file, written by hand for
    the ACG, differs from the device in three parameters, and a ProdCode edited in it in one more."""
    from tests.eds.samples import ADAPTER_EDS

    address, _ = adapter_process
    assert run("eds", "generate", "--profile", "acg", "-o", str(tmp_path)).returncode == 0
    result = run("eds", "check", str(tmp_path / "ACG-ET2_1.01.eds"), "--against", address, "--no-connections")
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.splitlines()[-1] == "1 file: 0 errors, 0 warnings"
    # With its class 1 connections too: a report, and not a log line of the originator's own socket.
    result = run("eds", "check", str(tmp_path / "ACG-ET2_1.01.eds"), "--against", address)
    assert result.returncode == 0 and result.stderr == "", result.stderr
    good = tmp_path / "acg.eds"
    good.write_text(ADAPTER_EDS)
    wrong = tmp_path / "other.eds"
    wrong.write_text(ADAPTER_EDS.replace("ProdCode = 100;", "ProdCode = 101;"))
    result = run("eds", "check", str(good), str(wrong), "--against", address, "--json", "--no-connections")
    assert result.returncode == 1
    records = [json.loads(line) for line in result.stdout.splitlines()]
    assert records[0]["against"].startswith(f"against {address}: identity by Get_Attributes_All, 4 parameters")
    rules = {record["file"]: [f["rule"] for f in record["findings"] if f["severity"] == "error"]
             for record in records if "file" in record}
    assert rules == {str(good): ["live-parameter"] * 3, str(wrong): ["device-identity"] + ["live-parameter"] * 3}
    shown = run("eds", "show", str(good))
    assert shown.returncode == 0 and "CENT" in shown.stdout
    missing = run("eds", "check", str(tmp_path / "nope.eds"))
    assert missing.returncode == 2 and "nope.eds" in one_line_error(missing)


def start_adapter(*args: str) -> tuple[str, subprocess.Popen[str]]:
    port = free_port()
    process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port", "0",
                                *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for _ in range(300):
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return f"127.0.0.1:{port}", process
        except OSError:
            if process.poll() is not None:
                pytest.fail(f"adapter exited: {process.stderr.read() if process.stderr else ''}")
            time.sleep(0.05)
    process.kill()
    pytest.fail("adapter did not start")


def stop(process: subprocess.Popen[str]) -> str:
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=10)
    assert process.returncode == 0, stderr
    return stderr


def test_saved_parameters_survive_a_restart_of_the_process(tmp_path: Path) -> None:
    """ACG RS-485 manual memory control: writing 0x03E0 from 0 to 1 saves every parameter; what is written
    afterwards and not saved is gone after a restart."""
    ModbusTcpClient = needs("pymodbus.client").ModbusTcpClient
    from cipstack.devices.acg.registers import ACG_REGISTERS

    state = tmp_path / "acg.json"
    pr12, pr13 = ACG_REGISTERS.by_code("Pr.12"), ACG_REGISTERS.by_code("Pr.13")
    modbus_port = free_port()
    address, process = start_adapter("--state", str(state), "--modbus-port", str(modbus_port))
    try:
        client = ModbusTcpClient("127.0.0.1", port=modbus_port, timeout=3)
        assert client.connect()
        assert not client.write_register(pr12.address, 2, device_id=1).isError()   # Pr.12 = Dec
        assert not client.write_register(0x03E0, 1, device_id=1).isError()         # save all
        assert not client.write_register(pr13.address, 55, device_id=1).isError()  # Pr.13: not saved
        # The same value over CIP (class 0x64, instance = group Pr (11), attribute = code number).
        assert json.loads(run("get", address, "0x64/11/12", "--json").stdout)["value"] == 2
        assert json.loads(run("get", address, "0x64/11/13", "--json").stdout)["value"] == 55
        client.close()
    finally:
        stop(process)
    assert state.exists()
    address, process = start_adapter("--state", str(state))
    try:
        assert json.loads(run("get", address, "0x64/11/12", "--json").stdout)["value"] == 2
        assert json.loads(run("get", address, "0x64/11/13", "--json").stdout)["value"] == pr13.default
    finally:
        stop(process)
    state.write_text("{not json")
    result = run("adapter", "--port", str(free_port()), "--io-port", "0", "--state", str(state))
    assert result.returncode == 2 and str(state) in one_line_error(result)


def test_drive_trip_and_status_over_the_control_socket(tmp_path: Path) -> None:
    control = tmp_path / "control.sock"
    address, process = start_adapter("--control", str(control), "--state", str(tmp_path / "s.json"))
    try:
        tripped = run("drive", "trip", "0x4200", "--control", str(control), "--json")
        assert tripped.returncode == 0, tripped.stderr
        assert "OverHeat" in json.loads(tripped.stdout)["result"]
        # The trip shows over CIP: Control Supervisor Faulted (0x29/10) and the fault code (0x29/13).
        assert json.loads(run("get", address, "0x29/1/10", "--json").stdout)["value"] == 1
        assert json.loads(run("get", address, "0x29/1/13", "--json").stdout)["value"] == 0x4200
        status = run("drive", "status", "--control", str(control))
        assert status.returncode == 0 and "OverHeat" in status.stdout
        unknown = run("drive", "trip", "0x9999", "--control", str(control))
        # A code the drive's table lacks is a bad argument (2); the line lists the valid codes.
        assert unknown.returncode == 2 and "0x9999" in one_line_error(unknown)
        assert "valid codes: 0x1000, 0x2200" in one_line_error(unknown)
    finally:
        stderr = stop(process)
    assert "Traceback" not in stderr
    assert not control.exists()


def test_mx2_rx_profiles_models_and_componet_gateway() -> None:
    models = [json.loads(line) for line in run("models", "--json").stdout.splitlines()]
    # The ACG family's one model, then the 61 of Tables 2/3; every one brought by cipstack itself.
    assert len(models) == 62 and [m["profile"] for m in models[:2]] == ["acg", "mx2"]
    assert {m["profile"] for m in models[1:]} == {"mx2", "rx"} and {m["distribution"] for m in models} == {"cipstack"}
    for profile, model in (("mx2", "MX2-A2015-E"), ("rx", "RX-A4055-E")):
        entry = next(m for m in models if m["model"] == model)
        address, process = start_adapter("--profile", profile, "--model", model, "--quiet")
        try:
            identity = json.loads(run("identity", address, "--json").stdout)
            assert (identity["vendor_id"], identity["product_code"]) == (47, entry["product_code"])
            assert identity["product_name"] == entry["product_name"]
        finally:
            stop(process)
    port = free_port()
    gateway = subprocess.Popen([sys.executable, "-m", "cipstack", "componet", "--nodes",
                                "mx2:MX2-A2015-E@3,rx:RX-A4055-E@5", "--port", str(port), "--io-port", "0",
                                "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for _ in range(300):
            with contextlib.suppress(OSError):
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                break
            time.sleep(0.05)
        for node, model in ((3, "MX2-A2015-E"), (5, "RX-A4055-E")):
            entry = next(m for m in models if m["model"] == model)
            name = run("get", f"127.0.0.1:{port}", "1/1/7", "--route", f"2/{node}", "--type", "SHORT_STRING",
                       "--json")
            assert name.returncode == 0, name.stderr
            assert json.loads(name.stdout)["value"] == entry["product_name"]
        absent = run("get", f"127.0.0.1:{port}", "1/1/7", "--route", "2/9")
        assert absent.returncode == 1 and "0x01" in one_line_error(absent)
    finally:
        stop(gateway)


def test_eds_generate_then_check(tmp_path: Path) -> None:
    written = run("eds", "generate", "--profile", "rx", "--all", "-o", str(tmp_path))
    assert written.returncode == 0, written.stderr
    files = sorted(Path(line).name for line in written.stdout.splitlines())
    rx = [json.loads(line)["eds_file"] for line in run("models", "--profile", "rx", "--json").stdout.splitlines()]
    assert files == sorted(set(rx))
    checked = run("eds", "check", *(str(tmp_path / name) for name in files))
    assert checked.returncode == 0, checked.stdout
    bad = run("eds", "generate", "--profile", "rx", "--model", "MX2-A2015-E", "-o", str(tmp_path))
    assert bad.returncode == 2 and "MX2-A2015-E" in one_line_error(bad)


def test_io_list_fields_of_a_profile(adapter_process: tuple[str, subprocess.Popen[str]]) -> None:
    """The ACG's fields by the names `--set` and the printed input use, from its identity's profile."""
    address, _ = adapter_process
    result = run("io", address, "--output", "21", "--input", "71", "--list-fields")
    assert result.returncode == 0, result.stderr
    names = [line.split()[0] for line in result.stdout.splitlines() if line.startswith("  ")]
    assert names == ["run_forward", "run_reverse", "fault_reset", "net_ctrl", "net_ref", "speed_reference",
                     "faulted", "warning", "running_forward", "running_reverse", "ready", "ctrl_from_net",
                     "ref_from_net", "at_reference", "drive_state", "speed_actual"]


@pytest.mark.parametrize(("argv", "word"), [
    (["get", "h", "1/1/7"], "get"),
    (["--log-level", "DEBUG", "eds", "show", "f"], "eds"),
    (["--log-level=DEBUG", "capture", "analyze", "f"], "capture"),
    (["--version"], None),
    ([], None),
])
def test_the_command_word_is_found_past_the_global_options(argv: list[str], word: str | None) -> None:
    from cipstack.cli.parser import command_word

    assert command_word(argv) == word


def test_a_one_shot_get_loads_neither_the_eds_tool_nor_a_device_profile() -> None:
    """The eds and capture commands' arguments are built only for them; a standard attribute
    decodes without the device's profile, and data types without ``construct`` (assembly schemas
    import it when they build their parser); names come from the Connection Manager's declaration
    without its Forward_Open codecs: `cipstack get` stays a short process."""
    port = free_port()
    adapter = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port",
                                str(free_port()), "--log-level", "WARNING", "--quiet"], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    try:
        probe = (f"import runpy, sys; sys.argv = ['cipstack', 'get', '127.0.0.1:{port}', '1/1/7'];\n"
                 "try:\n    runpy.run_module('cipstack', run_name='__main__')\nexcept SystemExit as e:\n"
                 "    print(sorted(m for m in sys.modules if m.startswith(('cipstack.eds', 'cipstack.capture',"
                 " 'cipstack.devices', 'construct', 'cipstack.eip.wire.cm_messages',"
                 " 'cipstack.eip.target.connection_manager'))), e.code)")
        def accepting() -> bool:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            except OSError:
                return False
            return True

        # The adapter listening, before a probe (a process start each) is tried.
        wait_for(accepting, 15, "the adapter to listen")
        deadline = time.monotonic() + 10
        while True:
            out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=30)
            if "CENT" in out.stdout or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        assert "Product Name = 'CENT'" in out.stdout
        assert out.stdout.strip().splitlines()[-1] == "[] 0"
        # The eds command still has its whole parser when it is the command.
        shown = subprocess.run([sys.executable, "-m", "cipstack", "--log-level", "WARNING", "eds", "show",
                                str(Path(__file__).parent / "eds" / "files" / "ez_style_io_block.eds")],
                               capture_output=True, text=True, timeout=30)
        assert shown.returncode == 0 and "IOB-8" in shown.stdout
    finally:
        adapter.terminate()
        adapter.wait(10)
