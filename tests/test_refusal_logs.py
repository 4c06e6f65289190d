"""One rule for every refusal log line (issue 30, item 13): each kind of refusal is logged at most
once per 10 s per source, and the next line of that source says how many were held back. A flood of
10,000 refusals writes a bounded number of lines, whatever its kind: Forward_Opens over the class 1
connection limit, RegisterSessions over the per-host limit, another user knocking on the control
socket. The sans-I/O cores are driven from their wire bytes with the time they are given."""

from __future__ import annotations

import dataclasses
import logging
import os
import re
import struct
import subprocess
import sys

import pytest

from cipstack.control import default_control_path
from cipstack.eip.target.core import EncapsulationTarget, TargetSettings
from cipstack.eip.target.limits import MAX_LOGGED_SOURCES, OTHER_SOURCES, RateLimitedLog
from tests import attacks
from tests.ports import free_port

HELD_BACK = re.compile(r"\((\d+) more like it in the last (\d+) s\)$")


def _held_back(lines: list[str]) -> int:
    return sum(int(match.group(1)) for line in lines if (match := HELD_BACK.search(line)))


def test_class1_forward_opens_over_the_limit_are_a_line_per_10_s_with_the_count(
        caplog: pytest.LogCaptureFixture) -> None:
    """2 class 1 connections allowed; 10,000 more Forward_Opens over 30 s from one originator are
    refused with 0x01/0x0113 and write 3 lines (at 0, 10 and 20 s), the later ones counting the rest."""
    from cipstack.cip.router import RequestContext
    from cipstack.cip.status import CipError
    from cipstack.devices.profiles import build_device
    from cipstack.eip.target.io_target import IoTarget
    from cipstack.eip.wire.cm_messages import ForwardOpenRequest

    device = build_device()
    io = IoTarget(dataclasses.replace(device.io_profile(), max_connections=2), device)
    context = RequestContext(device.router, 0.0, "127.0.0.9:5000", None)
    for serial in (1, 2):
        raw = attacks.class1_open(serial, path=attacks.ACG_INPUT_ONLY_PATH, ot_size=6)[6:]
        io.forward_open(ForwardOpenRequest.decode(raw, large=False), context)
    refusals = 10_000
    with caplog.at_level(logging.INFO, logger="cipstack.eip.target.io_target"):
        for index in range(refusals):
            context.now = index * 0.003
            raw = attacks.class1_open(3 + index)[6:]
            with pytest.raises(CipError) as refused:
                io.forward_open(ForwardOpenRequest.decode(raw, large=False), context)
            assert (refused.value.general, refused.value.extended[:1]) == (0x01, (0x0113,))
    lines = [r.getMessage() for r in caplog.records if "Forward_Open from" in r.getMessage()]
    assert len(lines) == 3, lines
    assert "refused" in lines[0] and not HELD_BACK.search(lines[0])
    assert all(HELD_BACK.search(line) for line in lines[1:])
    # Every refusal is a line or counted in a later one, but those after the last line (under 10 s).
    assert refusals - 3334 <= len(lines) + _held_back(lines) <= refusals


def _frame(command: int, body: bytes = b"", session: int = 0) -> bytes:
    return struct.pack("<HHII8sI", command, len(body), session, 0, bytes(8), 0) + body


def test_sessions_over_the_per_host_limit_are_a_line_per_10_s_with_the_count(
        caplog: pytest.LogCaptureFixture) -> None:
    from cipstack.devices.profiles import build_device
    from cipstack.eip.wire.cpf import SockAddr

    device = build_device()
    target = EncapsulationTarget(device.router, device.identity_record, TargetSettings(max_sessions=4))
    local = SockAddr("127.0.0.1", 44818)
    register = _frame(0x65, struct.pack("<HH", 1, 0))
    for port in (1, 2):   # the host's share: 2 of 4
        held = target.connection(f"127.0.0.9:{port}", local, 0.0)
        held.receive(register, 0.0)
        assert struct.unpack_from("<I", held.data_to_send(), 8)[0] == 0
    with caplog.at_level(logging.INFO, logger="cipstack.eip.target.core"):
        for index in range(10_000):
            now = index * 0.002
            connection = target.connection(f"127.0.0.9:{10_000 + index}", local, now)
            connection.receive(register, now)
            assert struct.unpack_from("<I", connection.data_to_send(), 8)[0] == 0x0002   # insufficient memory
            connection.connection_lost()
    lines = [r.getMessage() for r in caplog.records if "RegisterSession refused" in r.getMessage()]
    assert len(lines) == 2, lines        # at 0 s and 10 s; those after 10 s wait for the next line
    assert HELD_BACK.search(lines[1]) and _held_back(lines) == 4999


def test_each_source_has_its_own_line_and_the_table_of_sources_is_bounded(
        caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    line = RateLimitedLog(logging.getLogger("cipstack.test"), clock=lambda: now[0])
    with caplog.at_level(logging.WARNING, logger="cipstack.test"):
        assert line("refused %s", "a", source="10.0.0.1")
        assert line("refused %s", "b", source="10.0.0.2")          # another source: its own line
        assert not line("refused %s", "a", source="10.0.0.1")
        for index in range(3 * MAX_LOGGED_SOURCES):               # a flood from ever new sources
            line("refused %s", index, source=f"10.1.{index // 256}.{index % 256}")
        assert len(line.sources) <= MAX_LOGGED_SOURCES + 1
        now[0] = 10.0
        assert line("refused %s", "c", source="10.0.0.1")
    messages = [r.getMessage() for r in caplog.records]
    # Two named sources and the 254 others that fit, then one line for every source past the table.
    assert len(messages) == MAX_LOGGED_SOURCES + 1 + 1
    assert messages[-1] == "refused c (1 more like it in the last 10 s)"
    assert OTHER_SOURCES in line.sources


@pytest.mark.skipif(not sys.platform.startswith("linux") or os.geteuid() != 0
                    or not os.path.exists("/usr/bin/python3"), reason="needs root to act as another user")
def test_another_user_knocking_on_the_control_socket_is_one_line() -> None:
    from tests.test_cli import stop
    from tests.test_control_sockets import start

    port = free_port()
    process = start("127.0.0.1", port)
    address = default_control_path(port, "127.0.0.1")
    assert isinstance(address, str)
    knocks = ("import socket,sys\n"
              "for _ in range(2000):\n"
              "    s=socket.socket(socket.AF_UNIX); s.settimeout(5); s.connect('\\0' + sys.argv[1])\n"
              "    try: s.recv(1)\n"
              "    except OSError: pass\n"
              "    s.close()\n")
    try:
        other = subprocess.run(["/usr/bin/python3", "-c", knocks, address[1:]], capture_output=True, text=True,
                               timeout=60, user=65534, env={"PATH": "/usr/bin:/bin"})
        assert other.returncode == 0, other.stderr
    finally:
        stderr = stop(process)
    assert stderr.count("a process of user 65534 refused") == 1, stderr
