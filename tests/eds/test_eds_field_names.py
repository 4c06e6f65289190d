"""One device, one set of field names: the EDS files the project generates name the members of their
I/O assemblies so that the field-name rule gives exactly the names of the device's profile, and a
script that sets fields by name works the same with ``--eds`` as with the profile.

* ACG: every connection of the file `cipstack eds generate --profile acg` writes, through
  `cipstack io --eds FILE --connection N --list-fields`, lists what `cipstack io --list-fields` lists
  from the profile of a live `cipstack adapter` (the assemblies the profile declares whatever the
  CM settings), or the device's own schemas at the factory settings the file describes (the smart
  scaling 121-128 / 141-148, whose words follow CM.31-CM.58).
* MX2 and RX: their files are CompoNet files and declare no ``[Connection Manager]``; every
  assembly they declare reads back with the device's fields, for two models of each family and for
  a device whose flexible mapping (P160-P177) makes 139/159.
"""

from __future__ import annotations

import contextlib
import io
import json
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from cipstack.assemblies.schema import AssemblySchema
from cipstack.cli import main
from cipstack.devices.acg.device import build_acg_device
from cipstack.devices.omron.device import OmronDevice, build_omron_device
from cipstack.devices.omron.eds_file import omron_description
from cipstack.devices.profiles import PROFILES
from cipstack.eds.generator import eds_text
from cipstack.eds.interpret import read_view
from cipstack.eds.reader import read_eds
from tests.ports import free_port


def run(*args: str, timeout: float = 30) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", *args], capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


def layout(schema: AssemblySchema | None) -> list[tuple[Any, ...]]:
    """Name, byte offset, bit position and width of every field (whole-byte fields: their size)."""
    assert schema is not None
    return [(f.name, f.offset, f.bit if f.bits else None, f.size_bits) for f in schema.fields]


@pytest.fixture(scope="module")
def acg_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`cipstack eds generate --profile acg`, in this process (the Omron tests below run the command)."""
    directory = tmp_path_factory.mktemp("acg")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["eds", "generate", "--profile", "acg", "-o", str(directory)]) == 0
    return Path(printed.getvalue().strip())


@pytest.fixture(scope="module")
def acg_adapter() -> Iterator[tuple[str, int]]:
    """An ACG taking run command and frequency from the network (drv = 4, Frq = 8)."""
    port, io_port = free_port(), free_port()
    process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--host", "127.0.0.1", "--port",
                                str(port), "--io-port", str(io_port), "--param", "drv=4", "--param", "Frq=8",
                                "--quiet"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 20
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                break
            except OSError:
                assert process.poll() is None, process.stderr.read() if process.stderr else ""
                assert time.monotonic() < deadline, "the adapter did not start"
                time.sleep(0.05)
        yield f"127.0.0.1:{port}", io_port
    finally:
        process.terminate()
        process.wait(10)


def list_fields(capsys: pytest.CaptureFixture[str], *args: str) -> str:
    assert main(["io", *args, "--list-fields"]) == 0
    return capsys.readouterr().out


#: The connections of the ACG's file: 12 exclusive owners, 12 input only, 12 listen only.
ACG_CONNECTIONS = 36


@pytest.fixture(scope="module")
def acg_view(acg_file: Path) -> Any:
    return read_view(read_eds(acg_file))


@pytest.fixture(scope="module")
def acg_declared() -> dict[int, AssemblySchema]:
    """The assemblies the profile declares whatever the CM settings."""
    return PROFILES["acg"].catalog().assemblies  # type: ignore[misc]  # catalog is optional in Profile; the ACG's has one


def by_profile(connection: Any, declared: dict[int, AssemblySchema]) -> bool:
    """Whether ``cipstack io`` lists this connection's fields from the profile's declarations alone."""
    return bool((connection.heartbeat or connection.o_t_point in declared) and connection.t_o_point in declared)


def test_the_acg_file_offers_each_connection_kind(acg_view: Any, acg_declared: dict[int, AssemblySchema]) -> None:
    """The 4 pairs and their 4 inputs that need no CM setting, by the profile; the others by the schemas
    of the device at the factory settings the file describes."""
    by_command = sum(by_profile(c, acg_declared) for c in acg_view.connections)
    assert (len(acg_view.connections), by_command) == (ACG_CONNECTIONS, 12)


@pytest.mark.parametrize("number", range(1, ACG_CONNECTIONS + 1))
def test_each_acg_connection_lists_the_profile_fields(number: int, acg_file: Path, acg_adapter: tuple[str, int],
                                                      acg_view: Any, acg_declared: dict[int, AssemblySchema],
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    address, _ = acg_adapter
    connection = next(c for c in acg_view.connections if c.number == number)
    from_file = list_fields(capsys, address, "--eds", str(acg_file), "--connection", str(connection.number))
    output = ["--heartbeat" if connection.heartbeat else "--output", str(connection.o_t_point)]
    if by_profile(connection, acg_declared):
        from_profile = list_fields(capsys, address, *output, "--input", str(connection.t_o_point))
        assert from_file == from_profile, connection.name
    else:
        device = build_acg_device()
        points = [connection.t_o_point] if connection.heartbeat else [connection.o_t_point, connection.t_o_point]
        for point in points:
            assert layout(acg_view.schema(point)) == layout(device.assembly_schema(point)), connection.name
            assert f"assembly {point} " in from_file


def test_the_issue_names(acg_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The names the issue saw differ (drive_fault, drive_ready, speedactual, control_from_net) are the
    profile's now, and the explicit attributes keep the names of the manual's object table."""
    text = list_fields(capsys, "127.0.0.1:1", "--eds", str(acg_file), "--connection", "1")
    names = [line.split()[0] for line in text.splitlines() if line.startswith("  ")]
    assert names == ["run_forward", "run_reverse", "fault_reset", "net_ctrl", "net_ref", "speed_reference",
                     "faulted", "warning", "running_forward", "running_reverse", "ready", "ctrl_from_net",
                     "ref_from_net", "at_reference", "drive_state", "speed_actual"]
    view = read_view(read_eds(acg_file))
    by_link: dict[tuple[int, int, int], list[str]] = {}
    for param in view.params.values():
        if param.link is not None:
            by_link.setdefault(param.link, []).append(param.name)
    # ACG-ET2 manual: "Drive Fault" in the Control Supervisor table, "Faulted" in the input instance table.
    assert by_link[(0x29, 1, 10)] == ["Drive Fault", "Faulted"]
    assert by_link[(0x29, 1, 9)] == ["Drive Ready", "Ready"]
    assert by_link[(0x29, 1, 14)] == ["Control From Net.", "Ctrl From Net"]
    # A declared name the rule maps to the field's is the member's parameter itself: no second one.
    assert by_link[(0x2A, 1, 7)] == ["SpeedActual"]
    assert by_link[(0x29, 1, 7)] == ["Running Forward"]
    # Attributes the card does not serve (ACG-ET2 manual: Net Control 0x29/5 and Net Reference 0x2A/4 "N/A",
    # Warning 0x29/11 "Not supported") are named by no link path: the members' parameters have none.
    assert {(0x29, 1, 5), (0x2A, 1, 4), (0x29, 1, 11)}.isdisjoint(by_link)
    schema = view.schema(21)
    assert schema is not None and schema.field("net_ctrl").link is None


OMRON_MODELS = ["MX2-A2015-E", "MX2-AB001-E", "RX-A4055-E", "RX-A2004-E"]


def _omron_file(tmp_path: Path, description: Any) -> Path:
    path = tmp_path / "omron.eds"
    path.write_bytes(eds_text(description).encode("ascii"))
    return path


def _same_fields(path: Path, device: OmronDevice) -> None:
    view = read_view(read_eds(path))
    schemas = device.schemas()
    assert {info.instance for info in view.assemblies.values()} == set(schemas)
    for instance, schema in schemas.items():
        assert layout(view.schema(instance)) == layout(schema), instance
        assert view.schema(instance).name == schema.name  # type: ignore[union-attr]


@pytest.mark.parametrize("model", OMRON_MODELS)
def test_omron_assemblies_read_back_with_the_profile_fields(model: str, tmp_path: Path) -> None:
    family = "mx2" if model.startswith("MX2") else "rx"
    written = run("eds", "generate", "--profile", family, "--model", model, "-o", str(tmp_path))
    assert written.returncode == 0, written.stderr
    _same_fields(Path(written.stdout.strip()), build_omron_device(model))


@pytest.mark.parametrize("model", ["MX2-A2015-E", "RX-A4055-E"])
def test_omron_flexible_and_special_assemblies(model: str, tmp_path: Path) -> None:
    """139/159 as appendix F's typical configuration makes them (3 output words, 4 input words), and the
    special I/O 100/150 (Tables B-13, B-15) beside them."""
    device = build_omron_device(model)
    device.advance(0.0)
    for code, value in dict(P046=6, P160=0x1F01, P161=0x0001, P162=0x0002, P170=0x0005, P171=0x1E01,
                            P172=0x1001, P173=0x1002).items():
        device.inverter.write_code(code, value, 0.0)
    device.reset(0)
    schemas = device.schemas()
    assert {139, 159, 100, 150} <= set(schemas)
    outputs = [schema for instance, schema in schemas.items() if device.assembly.points[instance].consumed]
    inputs = [schema for instance, schema in schemas.items() if not device.assembly.points[instance].consumed]
    path = _omron_file(tmp_path, omron_description(model, outputs=outputs, inputs=inputs))
    _same_fields(path, device)
    view = read_view(read_eds(path))
    assert [f.name for f in view.schema(159).fields] == ["word_0", "word_1", "word_2", "word_3"]  # type: ignore[union-attr]
    assert [f.name for f in view.schema(150).fields] == [  # type: ignore[union-attr]
        "function_code", "register_number", "data_word_0", "data_word_1"]


def test_one_script_runs_both_ways(acg_file: Path, acg_adapter: tuple[str, int]) -> None:
    """`--set run_forward=... --set speed_reference=...` by the profile, then the same fields by the EDS:
    both are accepted, both reach the drive (its SpeedRef and Forward Run Cmd. attributes), and both
    print the input under the same names."""
    address, io_port = acg_adapter
    # Half a second: about 50 RPIs of 10 ms, and the ramp begun (speed_actual > 0).
    common = ["--duration", "0.5s", "--print", "summary", "--json", "--io-port", "0", "--target-io-port", str(io_port)]
    inputs = {}
    for way, run_forward, speed in ((["--output", "21", "--input", "71"], 1, 900),
                                    (["--eds", str(acg_file), "--connection", "1"], 0, 450)):
        result = run("io", address, *way, "--set", f"run_forward={run_forward}", "--set", f"speed_reference={speed}",
                     *common)
        assert result.returncode == 0, result.stderr
        records = [json.loads(line) for line in result.stdout.splitlines()]
        inputs[way[0]] = next(record["input"] for record in records if "input" in record)
        assert records[-1]["summary"]["received"] > 5
        reference = json.loads(run("get", address, "0x2A/1/8", "--json").stdout)
        command = json.loads(run("get", address, "0x29/1/3", "--json").stdout)
        assert (reference["value"], command["value"]) == (speed, run_forward)
    assert set(inputs["--output"]) == set(inputs["--eds"])
    assert inputs["--output"]["running_forward"] is True and inputs["--output"]["speed_actual"] > 0
