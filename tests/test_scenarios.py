"""Scenarios (``cipstack adapter --scenario FILE.toml``): the three examples of docs/scenarios.md run
against a real adapter process with our scanner doing its part; the run prints what happened when,
and its exit status says whether every step fired. A scenario file that cannot run is one line, exit 2."""

from __future__ import annotations

import asyncio
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from cipstack.cip.status import CipError
from cipstack.cip.types import UINT
from cipstack.devices.acg.registers import CLASS_64_INSTANCES
from cipstack.devices.profiles import catalog_for
from cipstack.eip.originator.io_originator import IoTimeoutError
from cipstack.scanner import Scanner
from tests.cli_errors import one_line_error
from tests.ports import free_port
from tests.test_cli import run
from tests.waiting import wait_for

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "scenarios"
CATALOG = catalog_for(259, 100)
CM = CLASS_64_INSTANCES["CM"]


def start(tmp_path: Path, scenario: str, *args: str) -> tuple[subprocess.Popen[str], int, int]:
    port, io_port = free_port(), free_port()
    process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port",
                                str(io_port), "--quiet", "--state", str(tmp_path / "acg.json"), "--control",
                                str(tmp_path / "control.sock"), "--scenario", str(EXAMPLES / scenario), *args],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    import socket

    def accepting() -> bool:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return True
        except OSError:
            return False
    wait_for(accepting, 20, "the adapter")
    return process, port, io_port


def finish(process: subprocess.Popen[str]) -> tuple[int, list[str]]:
    out, err = process.communicate(timeout=60)
    assert "Traceback" not in err, err
    return process.returncode, out.splitlines()


async def test_comm_loss_during_a_ramp(tmp_path: Path) -> None:
    process, port, io_port = start(tmp_path, "comm_loss_during_ramp.toml", "--param", "drv=4", "--param", "Frq=8",
                                   "--param", "ACC=2")
    try:
        async with await Scanner.connect(f"127.0.0.1:{port}", catalog=CATALOG) as scanner:
            with pytest.raises(IoTimeoutError):
                # RPI x 64 (multiplier 4): 0.64 s, past the stalls of a loaded machine (which timed the
                # connection out at x 8 before the fault came) and well within the fault's 2 s.
                async with scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=4,
                                                 target_io_port=io_port) as io:
                    io.output.speed_reference = 1800
                    io.output.run_forward = True
                    async for _ in io.updates():
                        pass
        code, lines = await asyncio.get_running_loop().run_in_executor(None, finish, process)
    finally:
        if process.poll() is None:
            process.kill()
    assert code == 0, lines
    assert re.fullmatch(r" +\d+\.\d{3}s  ramping fired: fault stop-producing --for 2s \(on frequency 10 Hz\)",
                        lines[1]), lines
    assert "the scanner gave up fired" in lines[2] and lines[-1].endswith("complete: every step fired; no fault "
                                                                          "left active")


async def test_forward_open_refused_twice_then_accepted(tmp_path: Path) -> None:
    process, port, io_port = start(tmp_path, "forward_open_refused_twice.toml")
    try:
        def progress() -> object:
            status = run("drive", "status", "--json", "--control", str(tmp_path / "control.sock"))
            return json.loads(status.stdout).get("scenario")

        # How far it is, for status and the front panel: the first step fired, the second awaited.
        wait_for(lambda: progress() == {"file": "forward_open_refused_twice.toml", "state": "running", "steps": 2,
                                        "fired": 1, "next": "accepted"}, 10, "the scenario's first step")
        refused = []
        async with await Scanner.connect(f"127.0.0.1:{port}", catalog=CATALOG) as scanner:
            for _ in range(3):
                try:
                    async with scanner.io_connection(output=21, input=71, rpi=0.010, target_io_port=io_port) as io:
                        await io.wait_input(lambda image: True, 5)
                except CipError as exc:
                    refused.append(exc.extended[0])
        code, lines = await asyncio.get_running_loop().run_in_executor(None, finish, process)
    finally:
        if process.poll() is None:
            process.kill()
    assert refused == [0x0113, 0x0113]
    assert code == 0 and [line.split("s  ", 1)[1] for line in lines[1:]] == [
        "refuse two fired: fault refuse-forward-open --status 0x0113 --count 2 (at 0s)",
        "accepted fired: clear (on connection opened)",
        "scenario complete: every step fired; no fault left active"], lines


async def test_power_cycle_with_an_unsaved_parameter(tmp_path: Path) -> None:
    process, port, _ = start(tmp_path, "power_cycle_unsaved.toml")
    try:
        async with await Scanner.connect(f"127.0.0.1:{port}", catalog=CATALOG) as scanner:
            await scanner.set_attribute_single(0x2A, 1, 102, 55)                  # ACC 5.5 s
            await scanner.set_attribute_single(0x64, CM, 51, 0x03E0, UINT)        # CM.51 names 0x03E0
            await scanner.set_attribute_single(0x04, 121, 3, UINT.encode(0))
            await scanner.set_attribute_single(0x04, 121, 3, UINT.encode(1))      # 0 -> 1: saved
            await scanner.set_attribute_single(0x2A, 1, 103, 77)                  # dEC 7.7 s, not saved
        code, lines = await asyncio.get_running_loop().run_in_executor(None, finish, process)
    finally:
        if process.poll() is None:
            process.kill()
    assert code == 0, lines
    assert [line.split("s  ", 1)[1] for line in lines[1:]][-2:] == [
        "power cycle fired: fault power-cycle --off 0.3s (on parameter write + 0.2s)",
        "scenario complete: every step fired; no fault left active"]
    # What the drive came back with is in its state file: the saved ACC, and dEC is not there.
    import json
    saved = json.loads((tmp_path / "acg.json").read_text())["parameters"]
    assert saved["0x1F01"] == 55 and saved.get("0x1F02") != 77


def test_a_step_that_does_not_fire_is_exit_1(tmp_path: Path) -> None:
    scenario = tmp_path / "never.toml"
    scenario.write_text('[[step]]\non = "trip"\nwithin = "0.3s"\nclear = true\n')
    port = free_port()
    result = subprocess.run([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port", "0",
                             "--quiet", "--state", str(tmp_path / "s.json"), "--control", str(tmp_path / "c.sock"),
                             "--scenario", str(scenario)], capture_output=True, text=True, timeout=30)
    assert result.returncode == 1
    assert "step 1 did not fire: no clear (on trip) within 0.3s" in result.stdout


#: Every kind of step: each operation a step can take (from their declarations, ``STEP_KINDS``) and a
#: wait-for step, a fault by name with options and a device fault by the fault's name too, both clears,
#: each step after the first waiting for what the one before did where an event shows it.
EVERY_KIND = """
[[step]]
at = "0.1s"
fault = "delay-replies"
options = { by = "10ms" }

[[step]]
name = "named clear"
at = "0.2s"
clear = "delay-replies"

[[step]]
on = "fault cleared"
within = "2s"
trip = "0x4200"

[[step]]
name = "wait for the trip"
on = "trip"
within = "2s"

[[step]]
at = "0.4s"
reset = true

[[step]]
on = "trip reset"
within = "2s"
link = "unplug"

[[step]]
at = "0.6s"
link = "plug"

[[step]]
at = "0.7s"
fault = "unplug"

[[step]]
at = "0.8s"
fault = "plug"

[[step]]
at = "0.9s"
power = "cycle"
off = "0.2s"

[[step]]
at = "1.5s"
fault = "refuse-forward-open"
options = { status = "0x0113" }

[[step]]
name = "clear all"
on = "fault applied"
within = "2s"
clear = true
"""


def test_every_step_kind_runs_from_a_file(tmp_path: Path) -> None:
    """A fault by name with options, a clear by name (the step after it waits for its event), a trip, a
    step that waits for the trip, a reset, the link unplugged and plugged (as a step of its own and as a
    fault), the power cycled, a Forward_Open refusal, and clear all: every step kind the operations
    declare is in the file."""
    from cipstack.control.scenario import STEP_KINDS

    assert {line.split(" = ")[0] for line in EVERY_KIND.splitlines()} >= set(STEP_KINDS)
    scenario = tmp_path / "every.toml"
    scenario.write_text(EVERY_KIND)
    port = free_port()
    result = subprocess.run([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port", "0",
                             "--quiet", "--state", str(tmp_path / "s.json"), "--control", str(tmp_path / "c.sock"),
                             "--scenario", str(scenario)], capture_output=True, text=True, timeout=60)
    assert "Traceback" not in result.stderr, result.stderr
    fired = [line.split("s  ", 1)[1] for line in result.stdout.splitlines() if " fired: " in line]
    assert fired == ["step 1 fired: fault delay-replies --by 0.01s (at 0.1s)",
                     "named clear fired: clear delay-replies (at 0.2s)",
                     "step 3 fired: trip 0x4200 (on fault cleared)",
                     "wait for the trip fired: wait (on trip)",
                     "step 5 fired: reset (at 0.4s)",
                     "step 6 fired: link unplug (on trip reset)",
                     "step 7 fired: link plug (at 0.6s)",
                     "step 8 fired: fault unplug (at 0.7s)",
                     "step 9 fired: fault plug (at 0.8s)",
                     "step 10 fired: power cycle --off 0.2s (at 0.9s)",
                     "step 11 fired: fault refuse-forward-open --status 0x0113 (at 1.5s)",
                     "clear all fired: clear (on fault applied)"], result.stdout
    assert result.returncode == 0, result.stdout
    assert result.stdout.splitlines()[-1].endswith("complete: every step fired; no fault left active")


@pytest.mark.parametrize(("text", "message"), [
    ("[[step]]\nat = \"1s\"\nfault = \"stop\"\n", "step 1: unknown fault 'stop'; valid: stop-producing"),
    ("[[step]]\nfault = \"unplug\"\n", "step 1: one trigger, at = TIME or on = EVENT"),
    ("[[step]]\nat = \"1s\"\n", "step 1: one action (trip = CODE, reset = true, fault = NAME, "),
    ("[[step]]\nat = \"1s\"\ntrip = 5\nreset = true\n", "step 1: one action, not trip and reset"),
    ("[[step]]\nat = \"1s\"\ntrip = 5\noff = \"1s\"\n", "step 1: off goes with power = ..."),
    ("[[step]]\nat = \"1s\"\nlink = \"pull\"\n", "step 1: link: 'pull' is not one of unplug, plug"),
    ("[[step]]\nat = \"1s\"\npower = \"cycle\"\noff = \"2h\"\n", "not a duration"),
    ("[[step]]\nat = \"1s\"\nreset = false\n", "step 1: reset is written reset = true"),
    ("[[step]]\nat = \"1s\"\nclear = 3\n", "step 1: clear = 3: clear is true or a fault's name"),
    ("[[step]]\nat = \"1s\"\ntrip = 1.5\n", "step 1: trip: \"code\" is a string or integer, not 1.5"),
    ("[[step]]\nat = \"1s\"\nclear = true\ncolour = 1\n", "step 1: unknown key 'colour'"),
    ("[[step\n", "not TOML"),
    ("[[step]]\nat = \"1s\"\nclear = \"bogus\"\n", "step 1: unknown fault 'bogus'; valid: stop-producing"),
])
def test_a_scenario_that_cannot_run_is_one_line(tmp_path: Path, text: str, message: str) -> None:
    scenario = tmp_path / "bad.toml"
    scenario.write_text(text)
    result = run("adapter", "--port", "0", "--scenario", str(scenario))
    assert result.returncode == 2 and message in one_line_error(result)


def test_the_documentation_shows_the_example_files() -> None:
    page = (ROOT / "docs" / "scenarios.md").read_text()
    for example in sorted(EXAMPLES.glob("*.toml")):
        assert example.read_text() in page, example.name
