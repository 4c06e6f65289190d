"""The unit of an assembly word, as the manuals give it, wherever the word is named: ``io
--list-fields``, the generated EDS, the decoded value and the drive itself.

ACG-ET2 manual calls the speed words of the ACG's 100/101/110/111 "Hz unit"; the AC/DC Drive object
gives the same values (Reference Hz/Actual Hz, 0x2A attributes 101/100) as "0-400.00 Hz" and the
ACG RS-485 manual gives the frequency command 0x0380 in 0.01 Hz: one count is 0.01 Hz, and 3000 runs the drive at
30.00 Hz. The words of 20/21/70/71 are in rpm (0x2A attributes 7/8, "[rpm]")."""

from __future__ import annotations

import socket
import subprocess
import sys
from pathlib import Path

import pytest

from cipstack.capture.decoding import decode_value
from cipstack.cip.units import count_unit, decimal_places, scaled_text
from cipstack.devices.acg.device import build_acg_device
from cipstack.devices.acg.objects import OUTPUT_FREQUENCY
from cipstack.devices.acg.registers import ACG_REGISTERS
from cipstack.devices.omron.assemblies import CENTIHERTZ, DECIHERTZ, RPM, omron_schemas
from cipstack.eds.interpret import read_view
from cipstack.eds.reader import read_eds
from tests.ports import free_port
from tests.waiting import wait_for

#: The unit of one count of each ACG speed word (ACG-ET2 manual instance tables, 0x2A attributes 7/8/100/101).
ACG_SPEED_UNITS = {20: "rpm", 21: "rpm", 70: "rpm", 71: "rpm",
                   100: "0.01 Hz", 101: "0.01 Hz", 110: "0.01 Hz", 111: "0.01 Hz"}


def accepts(host: str, port: int) -> bool:
    try:
        socket.create_connection((host, port), timeout=0.2).close()
    except OSError:
        return False
    return True


def cipstack(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", *args], capture_output=True, text=True, timeout=60,
                          stdin=subprocess.DEVNULL)


@pytest.fixture(scope="module")
def acg_eds(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("eds")
    result = cipstack("eds", "generate", "--profile", "acg", "-o", str(out))
    assert result.returncode == 0, result.stderr
    return next(out.glob("*.eds"))


def test_count_unit_and_scaled_text() -> None:
    assert count_unit("Hz", 0.01) == "0.01 Hz"
    assert count_unit("rpm", 1.0) == "rpm"
    assert count_unit("A", 0.1) == "0.1 A"
    assert count_unit("", 1.0) == ""
    assert scaled_text(3000, "Hz", 0.01) == "30.00 Hz"
    assert scaled_text(-25, "%", 1.0) == "-25 %"
    assert scaled_text(33, "s", 0.1) == "3.3 s"
    assert (decimal_places(0.01), decimal_places(1.0), decimal_places(10.0)) == (2, 0, 0)


def test_decimal_places_are_those_decimal_reads() -> None:
    """``decimal_places`` reads the float's repr without importing decimal; Decimal's normal form of it
    is the definition."""
    from decimal import Decimal

    def by_decimal(scale: float) -> int:
        exponent = Decimal(repr(float(scale))).normalize().as_tuple().exponent
        return max(0, -exponent) if isinstance(exponent, int) else 0

    scales = [0.1, 0.01, 1, 5, 10, 100, 1e-5, 1.5e-5, 0.005, 0.25, -0.1, 1e16, 1e22, 123.456, 0.0, 2.5e-10,
              1e-320, float("inf"), float("nan")]
    scales += [m * 10.0 ** e for m in (1, 2, 2.5, 5, 7.25) for e in range(-9, 10)]
    assert [decimal_places(s) for s in scales] == [by_decimal(s) for s in scales]


def test_every_acg_speed_word_is_in_the_manual_s_unit() -> None:
    device = build_acg_device(now=0.0)
    for instance, unit in ACG_SPEED_UNITS.items():
        schema = device.assembly_schema(instance)
        name = "speed_reference" if instance < 70 or instance in (100, 101) else "speed_actual"
        assert schema.field(name).count_unit == unit, instance


def test_every_omron_word_is_in_the_manual_s_unit() -> None:
    """CompoNet manual, appendix B: Rotational Speed in RPM, 0.1 Hz or 0.01 Hz (P049, d060; default 0.01 Hz),
    torque in 1 %, output current in 0.1 A, acceleration and deceleration times in 0.1 s; flags,
    states, codes and registers carry no unit."""
    fixed = {"torque_reference": "%", "torque_actual": "%", "torque_bias": "%", "output_current": "0.1 A",
             "accel_time": "0.1 s", "decel_time": "0.1 s"}
    for unit, speed in ((CENTIHERTZ, "0.01 Hz"), (DECIHERTZ, "0.1 Hz"), (RPM, "rpm")):
        for schema in omron_schemas(unit).values():
            for item in schema.fields:
                expected = speed if item.name.startswith("speed_") else fixed.get(item.name, "")
                assert item.count_unit == expected, (schema.instance, item.name)


def test_list_fields_names_the_unit_of_a_count(acg_eds: Path) -> None:
    """``--list-fields`` from the generated EDS (the README's way): [0.01 Hz] for 101/111, [rpm] for 21/71."""
    seen: dict[str, list[str]] = {}
    for connection in ("1", "4"):
        result = cipstack("io", "127.0.0.1", "--eds", str(acg_eds), "--connection", connection, "--list-fields")
        assert result.returncode == 0, result.stderr
        seen[connection] = [line.split("[")[1].rstrip("]") for line in result.stdout.splitlines()
                            if line.split()[0] in ("speed_reference", "speed_actual")]
        assert "assembly 21 " in result.stdout if connection == "1" else "assembly 101 " in result.stdout
    assert seen == {"1": ["rpm", "rpm"], "4": ["0.01 Hz", "0.01 Hz"]}


def test_the_generated_eds_gives_the_speed_words_of_101_and_111_in_0_01_hz(acg_eds: Path) -> None:
    """The ``ParamN`` of the member: Units "Hz" scaled by multiplier x base / divider = 0.01
    (fields 8, 13-15), which a configuration tool shows as 30.00 Hz for 3000."""
    doc = read_eds(acg_eds)
    view = read_view(doc)
    for instance, keyword in ((101, "speed_reference"), (111, "speed_actual"), (21, "speed_reference")):
        entry = doc.entry("Assembly", f"Assem{instance}")
        assert entry is not None
        members = entry.fields[6:]
        param_keyword = members[-1].value  # the speed word is the last member of each
        param = doc.entry("Params", param_keyword)
        assert param is not None
        units = param.field(8).value
        scale = 1.0
        if param.field(4).value & 0x04:
            scale = param.field(13).value * param.field(15).value / param.field(14).value
        assert count_unit(units, scale) == ACG_SPEED_UNITS[instance], instance
        schema = view.schema(instance)
        assert schema is not None
        assert schema.field(keyword).count_unit == ACG_SPEED_UNITS[instance]


def test_3000_on_output_101_runs_the_drive_at_30_hz() -> None:
    """The value to set comes from the declared unit: 30 Hz in 0.01 Hz counts is 3000; the drive
    runs at 30.00 Hz and input 111 reports it in the same unit."""
    device = build_acg_device(now=0.0)
    device.drive.write(ACG_REGISTERS.by_code("drv").address, 4, 0.0)   # run from the network
    device.drive.write(ACG_REGISTERS.by_code("Frq").address, 8, 0.0)   # reference from the network
    output = device.assembly_schema(101)
    reference = output.field("speed_reference")
    counts = round(30 / reference.scale)
    assert counts == 3000
    device.assembly.deliver(101, output.encode(run_forward=1, speed_reference=counts), 0.0)
    device.advance(10.0)
    assert scaled_text(device.drive.output_frequency, OUTPUT_FREQUENCY.unit, OUTPUT_FREQUENCY.scale) == "30.00 Hz"
    actual = device.assembly_schema(111)
    field = actual.field("speed_actual")
    word = actual.decode(device.assembly.data(111))["speed_actual"]
    assert scaled_text(word, field.unit, field.scale) == "30.00 Hz"

def test_a_decoded_eds_parameter_is_shown_scaled(acg_eds: Path) -> None:
    """Capture decoding by an EDS: Reference Hz (0x2A/1/101) of 3000 is 30.00 Hz, not 3000 Hz."""
    view = read_view(read_eds(acg_eds))
    param = next(p for p in view.params.values() if p.link == (0x2A, 1, 101))
    assert decode_value(param, (3000).to_bytes(2, "little"))["text"] == "30.00 Hz"


def test_3000_on_output_101_over_class_1_runs_the_emulator_at_30_hz(tmp_path: Path) -> None:
    """The same over a real class 1 connection: an adapter process taking 101/111 (CM.24 = CM.23 = 3,
    applied by CM.94), `cipstack io` setting the word in the unit --list-fields names."""
    port, io_port = free_port(), free_port()
    control = ("--control", str(tmp_path / "control"))
    adapter = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), *control,
                                "--io-port", str(io_port),
                                "--state", str(tmp_path / "state.json"), "--quiet", "--log-level", "WARNING",
                                # ACC 0.5 s: the ramp to 30 Hz is over well within the run (5.0 s would take 2.5 s).
                                *(f"--param={p}" for p in ("drv=4", "Frq=8", "CM.24=3", "CM.23=3", "CM.94=1",
                                                           "ACC=0.5"))],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        wait_for(lambda: accepts("127.0.0.1", port), 15, "the adapter")
        target = ("io", f"127.0.0.1:{port}", "--output", "101", "--input", "111", "--target-io-port", str(io_port))
        listed = cipstack(*target, "--list-fields")
        assert "speed_reference              byte 2 UINT [0.01 Hz]" in listed.stdout, listed.stderr
        # RPI x 64 (multiplier 4): a stall of the loaded machine is not a timeout here.
        ran = cipstack(*target, "--set", "run_forward=1", "--set", "speed_reference=3000", "--duration", "1.5s",
                       "--timeout-multiplier", "4", "--print", "summary", "--json")
        assert ran.returncode == 0, ran.stderr
        status = cipstack("drive", "status", *control, "--json")
        assert status.returncode == 0, status.stderr
        assert '"output_frequency_hz": 30.0' in status.stdout and '"reference_hz": 30.0' in status.stdout
        assert '"speed_actual": 3000' in ran.stdout
    finally:
        adapter.terminate()
        adapter.wait(10)
