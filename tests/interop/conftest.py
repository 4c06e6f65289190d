"""Peers in their own processes: our adapter (for blocking clients) and cpppo's server.

pycomm3 and cpppo's tools block, so the adapter they talk to cannot share the test's event
loop: it runs as ``python -m cipstack adapter`` on a free loopback port. Every process a
fixture starts is stopped by its PID.
"""

from __future__ import annotations

import ast
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from tests.ports import free_port

HOST = "127.0.0.1"
START_TIMEOUT = 15.0
STOP_TIMEOUT = 5.0

#: What the adapter's default profile (ACG-ET2) reports as its identity.
IDENTITY = {
    "vendor_id": 259,
    "device_type": 2,
    "product_code": 100,
    "revision": (1, 1),
    "serial_number": 0x10000064,
    "product_name": "CENT",
}




def python_module(module: str, *args: str) -> list[str]:
    """The command that runs ``module`` in this Python; the test is skipped when the module (a peer
    such as cpppo) is not installed, as ``pytest.importorskip`` skips one imported in the test."""
    pytest.importorskip(module.split(".")[0], reason=f"{module.split('.')[0]}, a peer of this test, is not "
                                                      "installed: pip install '.[test]'")
    return [sys.executable, "-m", module, *args]


#: One result line of cpppo's get_attribute, e.g. ``...:   0: Single G_A_S      @0x002A/1/7 == [132, 3]``.
CPPPO_RESULT_LINE = re.compile(r":\s+(\d+): (?:Single|Multi\.) (G_A_S|S_A_S|G_A_A)\s+(@\S+) == (.*)$")
CPPPO_TIMEOUT = 30.0


def cpppo_get_attribute(address: str, *arguments: str) -> tuple[int, list[tuple[str, str, Any]], str]:
    """Run cpppo's get_attribute against ``address`` with options and tags; returns its exit status,
    the (operation, path, value) of each result line, and its whole output."""
    result = subprocess.run(python_module("cpppo.server.enip.get_attribute", "-a", address, *arguments),
                            capture_output=True, text=True, timeout=CPPPO_TIMEOUT, check=False)
    rows = []
    for line in result.stdout.splitlines():
        match = CPPPO_RESULT_LINE.search(line)
        if match:
            rows.append((match.group(2), match.group(3), ast.literal_eval(match.group(4))))
    return result.returncode, rows, result.stdout + result.stderr


@dataclass
class PeerProcess:
    """A server in a child process, listening on host:port."""

    name: str
    host: str
    port: int
    process: subprocess.Popen[bytes]
    log: Path

    @property
    def address(self) -> str:
        return f"{self.host}:{self.port}"

    @property
    def pid(self) -> int:
        return self.process.pid

    def log_text(self) -> str:
        try:
            return self.log.read_text(errors="replace")
        except OSError:
            return ""

    def alive(self) -> bool:
        return self.process.poll() is None

    def stop(self, sig: int = signal.SIGTERM) -> int:
        """Signal the process by its PID and wait; SIGKILL (by PID) if it does not go."""
        if self.process.poll() is None:
            os.kill(self.process.pid, sig)
            try:
                self.process.wait(STOP_TIMEOUT)
            except subprocess.TimeoutExpired:
                os.kill(self.process.pid, signal.SIGKILL)
                self.process.wait(STOP_TIMEOUT)
        return self.process.returncode


def wait_listening(peer: PeerProcess, timeout: float = START_TIMEOUT) -> None:
    """Poll until the peer accepts TCP connections; fail with its log if it exits or hangs."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if not peer.alive():
            raise RuntimeError(f"{peer.name} exited with {peer.process.returncode} before listening:\n"
                               f"{peer.log_text()}")
        try:
            with socket.create_connection((peer.host, peer.port), timeout=0.5):
                return
        except OSError:
            time.sleep(0.05)
    peer.stop(signal.SIGKILL)
    raise RuntimeError(f"{peer.name} not listening on {peer.address} after {timeout} s:\n{peer.log_text()}")


def start_peer(name: str, command: Sequence[str], host: str, port: int, log: Path) -> PeerProcess:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    with log.open("wb") as out:
        process = subprocess.Popen(list(command), stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                   env=env)
    peer = PeerProcess(name, host, port, process, log)
    wait_listening(peer)
    return peer


def adapter_command(host: str, port: int) -> list[str]:
    # --io-port 0: class 1 I/O on a free port, so adapters of several tests never compete for 2222.
    return python_module("cipstack", "adapter", "--host", host, "--port", str(port), "--io-port", "0")


CPPPO_TAG = "Speed@0x2A/1/7=INT"


def cpppo_server_command(host: str, port: int) -> list[str]:
    return python_module("cpppo.server.enip", "--address", f"{host}:{port}", CPPPO_TAG)


@pytest.fixture(scope="module")
def adapter(tmp_path_factory: pytest.TempPathFactory) -> Iterator[PeerProcess]:
    """``cipstack adapter`` on a free loopback port; it must stop cleanly on SIGTERM."""
    port = free_port()
    log = tmp_path_factory.mktemp("adapter") / "adapter.log"
    peer = start_peer("cipstack adapter", adapter_command(HOST, port), HOST, port, log)
    try:
        yield peer
    finally:
        was_alive = peer.alive()
        code = peer.stop(signal.SIGTERM)
    text = peer.log_text()
    assert was_alive, f"the adapter died during the tests (exit {code}):\n{text}"
    assert code == 0, f"the adapter exited with {code} on SIGTERM:\n{text}"
    assert "Traceback" not in text, f"the adapter logged an exception:\n{text}"


@pytest.fixture(scope="module")
def cpppo_server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[PeerProcess]:
    """cpppo's EtherNet/IP server with one INT tag at 0x2A/1/7, on a free loopback port."""
    port = free_port()
    log = tmp_path_factory.mktemp("cpppo") / "cpppo-server.log"
    peer = start_peer("cpppo server", cpppo_server_command(HOST, port), HOST, port, log)
    try:
        yield peer
    finally:
        peer.stop(signal.SIGTERM)
