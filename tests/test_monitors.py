"""Monitor values while running (issue 52, item 7): the output voltage and the DC link voltage follow
the running state as the manuals define the drives (a V/f line up to the rated voltage, the rectified
input), and what the emulator has no model for (output current, power, torque) is declared "not
simulated" and says so. Sans-I/O rules first, then over the wire against a running emulator: CIP and
Modbus TCP for the ACG, CIP for the MX2."""

from __future__ import annotations

import json
import math
import socket
import struct

import pytest

from cipstack.devices.acg.drive import AcgDrive
from cipstack.devices.acg.registers import ACG_REGISTERS
from tests.library_support import adapter_process, run_cli
from tests.ports import free_port
from tests.waiting import wait_for

#: The emulated ACG is the 230 V class (0x0002 = 0 "230V level"): its DC link is the rectified input.
DC_LINK = round(math.sqrt(2) * 230)       # 325 V


def code(name: str) -> int:
    return ACG_REGISTERS.by_code(name).address


def running_drive(hz: float, *, rated_voltage: int = 0, reverse: bool = False) -> AcgDrive:
    drive = AcgDrive()
    for name, value in (("drv", 4), ("Frq", 8), ("ACC", 1), ("dEC", 1), ("bA.15", rated_voltage)):
        drive.write(code(name), value, 0.0)
    drive.set_speed_reference(round(hz * 100), 0.0)
    (drive.set_run_reverse if reverse else drive.set_run_forward)(True, 0.0)
    drive.advance(5.0)
    assert drive.output_frequency == round(hz * 100)
    return drive


def voltages(drive: AcgDrive) -> tuple[int, ...]:
    """Output voltage and DC link at each address that shows them (common area, monitoring area, keypad)."""
    return tuple(drive.read(a) for a in (0x000B, 0x0314, code("vOL"), 0x000C, 0x0315, code("dCL")))


@pytest.mark.parametrize(("hz", "rated", "reverse", "volts"), [
    (50.0, 0, False, 192),     # bA.15 = 0 (factory): the 230 V input, 230 x 50 / 60 (dr.20 Max Freq)
    (60.0, 0, False, 230),     # at dr.20 the whole rated voltage
    (30.0, 200, False, 100),   # bA.15 = 200 V: 200 x 30 / 60
    (30.0, 200, True, 100),    # the magnitude, whichever the direction
])
def test_acg_output_voltage_is_v_f_and_the_dc_link_the_rectified_input(hz: float, rated: int, reverse: bool,
                                                                        volts: int) -> None:
    drive = running_drive(hz, rated_voltage=rated, reverse=reverse)
    assert voltages(drive) == (volts,) * 3 + (DC_LINK,) * 3
    drive.set_run_reverse(False, 5.0) if reverse else drive.set_run_forward(False, 5.0)
    drive.advance(20.0)
    assert drive.output_frequency == 0 and not drive.running
    assert voltages(drive) == (0,) * 3 + (DC_LINK,) * 3     # stopped: no output, the bus still charged


def test_acg_current_power_and_torque_are_declared_not_simulated() -> None:
    drive = running_drive(50.0)
    for address in (0x0009, 0x000D, 0x0310, 0x0316, 0x0317, code("Cur")):
        assert not ACG_REGISTERS[address].simulated and drive.read(address) == 0
    assert all(ACG_REGISTERS[a].simulated for a in (0x000B, 0x000C, 0x0314, 0x0315, code("vOL"), code("dCL")))


def modbus_read(port: int, address: int, count: int) -> list[int]:
    """Read holding registers (function 3) over Modbus TCP, unit 0xFF (ACG-ET2 manual)."""
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        sock.sendall(struct.pack(">HHHBBHH", 1, 0, 6, 0xFF, 0x03, address, count))
        reply = b""
        while len(reply) < 9 + 2 * count:
            chunk = sock.recv(256)
            assert chunk, reply
            reply += chunk
    assert reply[7] == 0x03, reply.hex()
    return list(struct.unpack(f">{count}H", reply[9:9 + 2 * count]))


def test_a_running_acg_reports_its_voltages_over_cip_and_modbus() -> None:
    modbus = free_port()
    with adapter_process("--factory", "--param", "drv=4", "--param", "Frq=8", "--param", "ACC=0.5",
                         "--param", "dEC=0.5", "--modbus-port", str(modbus)) as (address, _):
        port = address.rsplit(":", 1)[1]

        def cip(path: str) -> int:
            got = run_cli("get", address, path, "--json")
            assert got.returncode == 0, got.stderr
            return int(json.loads(got.stdout)["value"])

        assert run_cli("set", address, "0x2A/1/101", "5000").returncode == 0        # Reference Hz 50.00
        assert run_cli("set", address, "0x29/1/3", "1").returncode == 0            # Forward Run Cmd.
        wait_for(lambda: cip("0x2A/1/100") == 5000, 30, "50 Hz")
        # 0x0009 current, 0x000A frequency, 0x000B output voltage, 0x000C DC link (common area)
        common = modbus_read(modbus, 0x0009, 4)
        # 0x0310 current, 0x0311 frequency, 0x0312 rpm, 0x0313 feedback, 0x0314 voltage, 0x0315 DC link
        monitoring = modbus_read(modbus, 0x0310, 6)
        def keypad_record(name: str) -> dict[str, object]:
            got = run_cli("drive", "parameter", name, "--port", port, "--json")
            assert got.returncode == 0, got.stderr
            return dict(json.loads(got.stdout))

        def keypad_raw(name: str) -> object:
            return keypad_record(name)["raw"]

        keypad = [keypad_record(c) for c in ("vOL", "Cur")]
        status = json.loads(run_cli("drive", "status", "--port", port, "--json").stdout)
        current = cip("0x2A/1/9")                                                  # AC/DC Drive Actual Current
        assert run_cli("set", address, "0x29/1/3", "0").returncode == 0
        # The keypad's monitor alone (no CIP request moves the drive on): read as of now.
        wait_for(lambda: keypad_raw("vOL") == 0, 30, "vOL 0 V once stopped, read on the keypad")
        assert cip("0x29/1/6") == 3                                                # Ready: stopped
        stopped = modbus_read(modbus, 0x000B, 2) + modbus_read(modbus, 0x0314, 2)
    assert common == [0, 5000, 192, DC_LINK]
    assert monitoring == [0, 5000, 1500, 1500, 192, DC_LINK]
    assert keypad[0]["raw"] == 192 and "simulated" not in keypad[0]
    assert keypad[1]["raw"] == 0 and keypad[1]["simulated"] is False
    assert status["not_simulated"] == ["output_current_a"] and current == 0
    assert stopped == [0, DC_LINK, 0, DC_LINK]


def test_a_running_mx2_reports_its_output_voltage_over_cip() -> None:
    """CompoNet manual Table D-7 Output Voltage (11h), V/f on the Motor Data object's Rated Voltage
    (Table D-2 attribute 7: 200 V for the MX2-A2015-E) and Rated Frequency (attribute 9, 50 Hz)."""
    with adapter_process("--factory", "--profile", "mx2") as (address, _):
        def cip(path: str) -> int:
            got = run_cli("get", address, path, "--json")
            assert got.returncode == 0, got.stderr
            return int(json.loads(got.stdout)["value"])

        for path, value in (("0x29/1/5", "1"), ("0x2A/1/4", "1"),                  # Net Ctrl, Net Ref
                            ("0x2A/1/0x12", "100"), ("0x2A/1/0x13", "100"),          # Accel, Decel Time 100 ms
                            ("0x2A/1/8", "2500"), ("0x29/1/3", "1")):                # 25.00 Hz, Run1
            assert run_cli("set", address, path, value).returncode == 0, path
        wait_for(lambda: cip("0x2A/1/7") == 2500, 30, "25 Hz")
        rated = (cip("0x28/1/7"), cip("0x28/1/9"))
        running = (cip("0x2A/1/0x11"), cip("0x2A/1/9"), cip("0x2A/1/0x0F"))
        assert run_cli("set", address, "0x29/1/3", "0").returncode == 0
        wait_for(lambda: cip("0x2A/1/7") == 0, 30, "0 Hz")
        wait_for(lambda: cip("0x2A/1/0x11") == 0, 30, "no output voltage once stopped")
    assert rated == (200, 50)
    assert running == (100, 0, 0)     # 200 V x 25 / 50 Hz; current and power: not simulated


def test_a_monitor_read_on_the_keypad_is_as_of_now() -> None:
    """``cipstack drive parameter vOL`` after a stop, with no other request to move the drive on: the
    output voltage of the stopped drive (0 V), not the last value a CIP request left (192 V at 50 Hz)."""
    with adapter_process("--factory", "--param", "drv=4", "--param", "Frq=8", "--param", "ACC=0.5",
                         "--param", "dEC=0.5") as (address, _):
        port = address.rsplit(":", 1)[1]
        assert run_cli("set", address, "0x2A/1/101", "5000").returncode == 0
        assert run_cli("set", address, "0x29/1/3", "1").returncode == 0
        wait_for(lambda: json.loads(run_cli("get", address, "0x2A/1/100", "--json").stdout)["value"] == 5000, 30,
                 "50 Hz")
        assert run_cli("set", address, "0x29/1/3", "0").returncode == 0        # 0.42 s down to 0 Hz

        def volts() -> int:
            got = run_cli("drive", "parameter", "vOL", "--port", port, "--json")
            assert got.returncode == 0, got.stderr
            return int(json.loads(got.stdout)["raw"])

        wait_for(lambda: volts() == 0, 15, "vOL 0 V once stopped")
