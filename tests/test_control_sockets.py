"""The emulator's control socket is keyed by its address and port, and (on Linux, as an abstract
socket) by its network namespace: two emulators on two addresses with one port, or in two namespaces
with one address and port, never clash; a killed emulator leaves nothing that stops the next one; and
`cipstack drive --host H --port P` reaches the one emulator listening there."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from cipstack.control import default_control_path, describe, is_abstract
from tests.ports import free_port
from tests.test_cli import one_line_error, run, stop

LINUX = sys.platform.startswith("linux")


def start(host: str, port: int, *args: str, prefix: tuple[str, ...] = ()) -> subprocess.Popen[str]:
    """An ACG emulator on ``host:port`` (no state file, class 1 on a free port), once it accepts."""
    process = subprocess.Popen([*prefix, sys.executable, "-m", "cipstack", "adapter", "--host", host, "--port",
                                str(port), "--io-port", "0", "--quiet", *args],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if prefix:  # in another network namespace: this one cannot connect to it; wait for its log line
        return _logged_emulating(process)
    for _ in range(300):
        try:
            socket.create_connection((host, port), timeout=0.2).close()
            return process
        except OSError:
            if process.poll() is not None:
                pytest.fail(f"adapter exited: {process.stderr.read() if process.stderr else ''}")
            time.sleep(0.05)
    process.kill()
    pytest.fail("adapter did not start")


def _logged_emulating(process: subprocess.Popen[str], timeout: float = 30.0) -> subprocess.Popen[str]:
    """``process`` once it logs "emulating ...": it serves, and SIGTERM (handled from before that line)
    stops it cleanly. A loaded machine may take seconds to get there; no fixed sleep guesses how many."""
    assert process.stderr is not None
    watchdog = threading.Timer(timeout, process.kill)  # a blocking readline() ends with the process
    watchdog.start()
    seen: list[str] = []
    try:
        for line in iter(process.stderr.readline, ""):
            seen.append(line)
            if "emulating" in line:
                return process
    finally:
        watchdog.cancel()
    process.wait(10)
    pytest.fail(f"adapter did not start (exit {process.returncode}): {''.join(seen)}")


def status(host: str, port: int) -> dict[str, object]:
    result = run("drive", "status", "--host", host, "--port", str(port), "--json")
    assert result.returncode == 0, result.stderr
    return dict(json.loads(result.stdout))


def test_default_address_names_host_and_port() -> None:
    one, two = default_control_path(44818, "127.0.0.2"), default_control_path(44818, "127.0.0.3")
    assert one != two and "127.0.0.2" in describe(one) and "44818" in describe(one)
    assert is_abstract(one) == LINUX


def test_two_emulators_on_two_addresses_with_one_port() -> None:
    port = free_port("127.0.0.2", "127.0.0.3")
    first, second = start("127.0.0.2", port), start("127.0.0.3", port)
    try:
        tripped = run("drive", "trip", "0x4200", "--host", "127.0.0.2", "--port", str(port))
        assert tripped.returncode == 0, tripped.stderr
        assert status("127.0.0.2", port)["trip"] == "OverHeat"
        assert status("127.0.0.3", port)["trip"] is None            # the other drive is untouched
        absent = run("drive", "status", "--host", "127.0.0.4", "--port", str(port))
        assert absent.returncode == 1 and "no emulator listens" in one_line_error(absent)
    finally:
        stop(first)
        stop(second)


@pytest.mark.skipif(not LINUX, reason="abstract control sockets are Linux's")
def test_a_killed_emulator_leaves_nothing_behind() -> None:
    port = free_port()
    first = start("127.0.0.1", port)
    first.send_signal(signal.SIGKILL)
    first.wait(timeout=10)
    second = start("127.0.0.1", port)                                # no stale socket refuses it
    try:
        assert status("127.0.0.1", port)["trip"] is None
    finally:
        stop(second)


@pytest.mark.skipif(not LINUX or os.geteuid() != 0 or shutil.which("unshare") is None,
                    reason="needs root and unshare for a second network namespace")
def test_two_namespaces_with_one_address_and_port() -> None:
    port = free_port()
    here = start("127.0.0.1", port)
    there = start("127.0.0.1", port, prefix=("unshare", "-n", "--", "sh", "-c", 'ip link set lo up && exec "$@"',
                                             "sh"))
    try:
        assert there.poll() is None                                  # it started: no clash
        assert status("127.0.0.1", port)["trip"] is None             # this namespace's emulator answers
    finally:
        there.send_signal(signal.SIGTERM)
        _, err = there.communicate(timeout=10)
        assert there.returncode == 0, err
        stop(here)


@pytest.mark.skipif(not LINUX or os.geteuid() != 0 or not os.path.exists("/usr/bin/python3"),
                    reason="needs root to act as another user")
def test_another_user_is_not_served() -> None:
    port = free_port()
    process = start("127.0.0.1", port)
    address = default_control_path(port, "127.0.0.1")
    assert isinstance(address, str)
    probe = ("import socket,sys\n"
             "s=socket.socket(socket.AF_UNIX); s.settimeout(5); s.connect('\\0' + sys.argv[1])\n"
             "try:\n"
             "    s.sendall(b'{\"command\": \"status\"}\\n')\n"
             "    print('reply' if s.recv(4096) else 'closed')\n"
             "except (BrokenPipeError, ConnectionResetError): print('closed')\n")  # refused before or after it wrote
    try:
        # The system interpreter as user nobody (the project's may sit in a directory nobody can read).
        other = subprocess.run(["/usr/bin/python3", "-c", probe, address[1:]], capture_output=True, text=True,
                               timeout=20, user=65534, env={"PATH": "/usr/bin:/bin"})
        assert other.returncode == 0, other.stderr
        assert other.stdout.strip() == "closed"                      # closed without a reply
        assert status("127.0.0.1", port)["trip"] is None             # its own user is served
    finally:
        stderr = stop(process)
    assert "a process of user 65534 refused" in stderr


#: A process of another user that takes an abstract name first and answers anything with a status.
SQUATTER = ("import socket,sys\n"
            "s=socket.socket(socket.AF_UNIX); s.bind('\\0' + sys.argv[1]); s.listen(8)\n"
            "print('ready', flush=True)\n"
            "while True:\n"
            "    c,_=s.accept()\n"
            "    try:\n"
            "        c.recv(4096)\n"
            "        c.sendall(b'{\"ok\": true, \"status\": \"RUN 60.00 Hz\", \"drive\": {\"trip\": null}, '\n"
            "                  b'\"sessions\": 0, \"class3_connections\": 0, \"class1_connections\": 0}\\n')\n"
            "    except OSError: pass\n"
            "    c.close()\n")


@pytest.mark.skipif(not LINUX or os.geteuid() != 0 or not os.path.exists("/usr/bin/python3"),
                    reason="needs root to act as another user")
def test_a_control_socket_of_another_user_is_not_believed_and_says_what_to_do() -> None:
    """User nobody (65534) takes this user's default control name first: `cipstack drive status`
    refuses it in one line naming that user, exit 1 (it printed the squatter's answer with exit 0);
    an adapter on that host and port cannot start and says so in one line that names the holder and
    what to do, without mentioning the --control it was not given."""
    import pwd

    port = free_port()
    address = default_control_path(port, "127.0.0.1")
    assert isinstance(address, str)
    squatter = subprocess.Popen(["/usr/bin/python3", "-c", SQUATTER, address[1:]], stdout=subprocess.PIPE,
                                text=True, user=65534, env={"PATH": "/usr/bin:/bin"})
    try:
        assert squatter.stdout is not None and squatter.stdout.readline().strip() == "ready"
        name = pwd.getpwuid(65534).pw_name
        result = run("drive", "status", "--host", "127.0.0.1", "--port", str(port))
        assert result.returncode == 1 and result.stdout == ""
        line = one_line_error(result)
        assert f"user 65534 ({name})" in line and "refused" in line, line
        adapter = run("adapter", "--host", "127.0.0.1", "--port", str(port), "--io-port", "0", "--quiet")
        assert adapter.returncode == 2
        line = one_line_error(adapter)
        assert f"user 65534 ({name})" in line and "--control" not in line, line
        assert "another --host or --port" in line and f"process {squatter.pid}" in line, line
    finally:
        squatter.kill()
        squatter.wait(10)


def test_a_taken_control_path_names_the_option_it_was_given(tmp_path: Path) -> None:
    """With --control, the message names that option and asks for another path."""
    path = tmp_path / "control.sock"
    held = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    held.bind(str(path))
    held.listen(1)
    try:
        port = free_port()
        adapter = run("adapter", "--host", "127.0.0.1", "--port", str(port), "--io-port", "0", "--quiet",
                      "--control", str(path))
        assert adapter.returncode == 2
        line = one_line_error(adapter)
        assert "--control" in line and "another --control path" in line, line
    finally:
        held.close()
