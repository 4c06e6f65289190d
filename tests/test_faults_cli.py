"""`cipstack drive fault`, `drive fault clear` and `drive faults`, run as a user runs them against a real
adapter process: faults applied over the control socket are seen by a scanner in this process; bad
names and options get one line listing what is valid, exit 2; a connection that is not open, exit 1."""

from __future__ import annotations

import json
import re
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from cipstack.cip.status import CipError
from cipstack.control.service import SETTLE_S
from cipstack.scanner import SyncScanner
from tests.cli_errors import one_line_error
from tests.ports import free_port
from tests.test_cli import run, stop
from tests.test_control_sockets import start

HOST = "127.0.0.1"


@pytest.fixture(scope="module")
def emulator(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[int, subprocess.Popen[str]]]:
    port = free_port()
    state = tmp_path_factory.mktemp("faults-cli") / "acg.json"
    process = start(HOST, port, "--state", str(state))
    yield port, process
    stop(process)


def drive(port: int, *args: str) -> subprocess.CompletedProcess[str]:
    return run("drive", *args, "--host", HOST, "--port", str(port))


def test_unknown_fault_and_option_are_one_line_listing_the_valid_ones(
        emulator: tuple[int, subprocess.Popen[str]]) -> None:
    port, _ = emulator
    unknown = drive(port, "fault", "stop")
    assert unknown.returncode == 2
    line = one_line_error(unknown)
    assert "unknown fault 'stop'; valid: stop-producing, drop, duplicate" in line and "power-cycle" in line
    option = drive(port, "fault", "drop", "--shar", "0.1")
    assert option.returncode == 2
    assert one_line_error(option).endswith(
        "unknown option --shar for drop; valid: --connection, --originator, --share, --every, --for")
    value = drive(port, "fault", "drop", "--share", "2")
    assert value.returncode == 2 and "share '2' is not in (0, 1]" in one_line_error(value)
    missing = drive(port, "fault", "refuse-forward-open")
    assert missing.returncode == 2 and "needs its STATUS" in one_line_error(missing)


def test_a_fault_on_a_connection_that_is_not_open_is_a_clear_error(
        emulator: tuple[int, subprocess.Popen[str]]) -> None:
    port, _ = emulator
    result = drive(port, "fault", "stop-producing", "--connection", "0x12345678")
    assert result.returncode == 1
    assert re.search(r"no class 1 connection 0x12345678 \(open, O->T/T->O: none\)$", one_line_error(result))


def test_apply_list_and_clear_over_the_control_socket(emulator: tuple[int, subprocess.Popen[str]]) -> None:
    port, _ = emulator
    applied = drive(port, "fault", "error-status", "--status", "0x08", "--class", "1", "--attribute", "7",
                    "--for", "30s")
    assert applied.returncode == 0, applied.stderr
    assert re.fullmatch(r"fault \d+: error-status --status 0x08 --class 1 --attribute 7 --for 30s\n", applied.stdout)
    with SyncScanner(f"{HOST}:{port}") as scanner:
        with pytest.raises(CipError) as refused:
            scanner.get_attribute_single(0x01, 1, 7)
        assert refused.value.general == 0x08
        listed = drive(port, "faults", "--json")
        assert listed.returncode == 0, listed.stderr
        faults = json.loads(listed.stdout)
        assert [(f["name"], f["options"]["status"]) for f in faults] == [("error-status", "0x08")]
        assert 0 < faults[0]["remaining_s"] <= 30
        text = drive(port, "faults")
        assert re.match(r"\d+: error-status --status 0x08 --class 1 --attribute 7 --for 30s +since 20", text.stdout)
        cleared = drive(port, "fault", "clear")
        assert cleared.returncode == 0 and cleared.stdout == "cleared 1 fault(s)\n"
        assert scanner.get_attribute_single(0x01, 1, 7)                   # answered as before
    assert drive(port, "faults").stdout == "no fault active\n"
    # Nothing of that name is there: a failure (1) and HTTP's 404, as a connection that is not open,
    # from one table (cipstack.control.service.OUTCOMES); 2 is for a request that is malformed.
    again = drive(port, "fault", "clear", "error-status")
    assert again.returncode == 1 and "no active fault 'error-status' (active: none)" in one_line_error(again)


def test_refuse_forward_open_and_unplug_from_the_command_line(emulator: tuple[int, subprocess.Popen[str]]) -> None:
    port, _ = emulator
    assert drive(port, "fault", "refuse-forward-open", "0x0106", "--count", "1").returncode == 0
    with SyncScanner(f"{HOST}:{port}") as scanner:
        with pytest.raises(CipError) as refused:
            scanner.open_connection()
        assert (refused.value.general, refused.value.extended[:1]) == (0x01, (0x0106,))
    unplugged = drive(port, "fault", "unplug")
    assert unplugged.returncode == 0, unplugged.stderr
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection((HOST, port), timeout=1).close()
    assert drive(port, "fault", "unplug").returncode == 1                  # already unplugged: the state says no
    assert drive(port, "fault", "plug").returncode == 0
    socket.create_connection((HOST, port), timeout=1).close()


def test_help_names_every_fault(tmp_path: Path) -> None:
    result = run("drive", "fault", "--help")
    assert result.returncode == 0
    for name in ("stop-producing", "refuse-forward-open", "power-cycle", "clear"):
        assert name in result.stdout


#: The power-cycle's off period: longer than the command service's wait cap (``SETTLE_S``), beyond
#: which it answers while the power is off, and longer by the room a loaded machine needs for the
#: answer to reach this test (a process descheduled for seconds, beside the other workers).
LONG_OFF_S = SETTLE_S + 4.0


def test_a_long_power_cycle_answers_before_the_power_is_back(tmp_path: Path) -> None:
    """The command answers once the ports are closed, while the power is still off: within
    ``SETTLE_S`` of the fault's start however long the cycle, so the power comes back at least
    ``LONG_OFF_S - SETTLE_S`` after the answer, less the time the answer takes to arrive here."""
    port = free_port()
    process = start(HOST, port, "--state", str(tmp_path / "acg.json"))
    try:
        command = subprocess.Popen([sys.executable, "-m", "cipstack", "drive", "fault", "power-cycle", "--off",
                                    f"{LONG_OFF_S:g}s", "--host", HOST, "--port", str(port)],
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert command.stdout is not None
        # Timed from the line it prints on its answer, not from its start (a command's start-up takes
        # seconds on a loaded machine, and comes before the fault begins) nor from its exit.
        line = command.stdout.readline()
        answered = time.monotonic()
        _, errors = command.communicate(timeout=30)
        assert command.returncode == 0 and line.startswith("fault ") and "power-cycle" in line, line + errors
        with pytest.raises(ConnectionRefusedError):   # the ports are closed when it answers
            socket.create_connection((HOST, port), timeout=1).close()
        deadline = answered + LONG_OFF_S + 30
        while True:
            try:
                socket.create_connection((HOST, port), timeout=1).close()
                break
            except ConnectionRefusedError:
                assert time.monotonic() < deadline, "the power did not come back"
                time.sleep(0.1)
        back = time.monotonic()
        # Room for the answer's way here: the half of what the off period leaves after the cap.
        room = (LONG_OFF_S - SETTLE_S) / 2
        assert back - answered >= room, f"answered {back - answered:.1f} s before the power was back"
    finally:
        stop(process)
