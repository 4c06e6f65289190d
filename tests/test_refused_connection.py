"""A refused connection is said in one way, whichever command, library call or relay meets it:
``cannot connect to HOST:PORT: Connection refused``, after the command's name on the command line.

A blocking ``connect`` and asyncio's ``create_connection`` word the same refusal differently
(``[Errno 111] Connection refused``, ``[Errno 111] Connect call failed ('127.0.0.1', PORT)``), and so
did the commands built on each (``get`` and ``conform`` on the first, ``io``, ``params`` and ``eds check
--against`` on the second): ``cipstack.errors.connect_failure`` words both the same."""

from __future__ import annotations

import asyncio
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from cipstack.errors import PeerUnreachable, connect_failure
from cipstack.scanner import Scanner, SyncScanner
from tests.cli_errors import one_line_error
from tests.ports import free_port, refused


def cipstack(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", *args], capture_output=True, text=True, timeout=60,
                          cwd=cwd, stdin=subprocess.DEVNULL)


@pytest.fixture
def refusing_port() -> int:
    """A port on 127.0.0.1 where nothing listens: a connection to it is refused."""
    port = free_port()
    assert refused(port)
    return port


#: Each command that connects to a target, by the name it reports under and its exit status for an
#: unreachable target (``conform``'s is 2, docs/conformance.md); ``{a}`` is the refusing address.
COMMANDS = [
    ("identity", ["identity", "{a}"], 1),
    ("get", ["get", "{a}", "1/1/1"], 1),
    ("get", ["get", "{a}", "1/1/1", "--connected"], 1),
    ("set", ["set", "{a}", "0x2A/1/102", "50"], 1),
    ("io", ["io", "{a}", "--output", "20", "--input", "70"], 1),
    ("params", ["params", "dump", "{a}"], 1),
    ("eds", ["eds", "fetch", "{a}", "-o", "fetched.eds"], 1),
    ("eds", ["eds", "check", "ACG-ET2_1.01.eds", "--against", "{a}"], 1),
    ("conform", ["conform", "{a}"], 2),
]


@pytest.mark.parametrize(("name", "argv", "status"), COMMANDS, ids=[" ".join(argv[:2]) for _, argv, _ in COMMANDS])
def test_every_command_says_a_refused_connection_in_one_line_of_the_same_words(
        name: str, argv: list[str], status: int, refusing_port: int, tmp_path: Path) -> None:
    if "check" in argv:
        assert cipstack("eds", "generate", "--profile", "acg", "-o", ".", cwd=tmp_path).returncode == 0
    address = f"127.0.0.1:{refusing_port}"
    result = cipstack(*(a.format(a=address) for a in argv), cwd=tmp_path)
    assert result.returncode == status, result.stderr
    assert one_line_error(result) == f"cipstack {name}: cannot connect to {address}: Connection refused"
    assert result.stdout == ""


async def test_the_library_says_it_in_the_same_words(refusing_port: int) -> None:
    expected = f"cannot connect to 127.0.0.1:{refusing_port}: Connection refused"
    with pytest.raises(PeerUnreachable) as asynchronous:
        await Scanner.connect(f"127.0.0.1:{refusing_port}", timeout=5)
    assert str(asynchronous.value) == expected
    with pytest.raises(PeerUnreachable) as blocking:
        await asyncio.to_thread(SyncScanner, f"127.0.0.1:{refusing_port}", timeout=5)
    assert str(blocking.value) == expected
    assert isinstance(blocking.value, ConnectionError)      # what callers caught before


async def test_a_fleet_that_refuses_the_plant_says_it_in_the_same_words(refusing_port: int) -> None:
    """The relay of a plant (and of a fleet's workers) over aiohttp, whose own words are asyncio's."""
    pytest.importorskip("aiohttp", reason="aiohttp is not installed (the http extra): pip install '.[http]'")
    from yarl import URL

    from cipstack.control.http_relay import Backend, RelayApi

    backend = Backend(f"fleet 127.0.0.1:{refusing_port}", None, url=URL(f"http://127.0.0.1:{refusing_port}"))
    backend.open()
    try:
        with pytest.raises(PeerUnreachable) as raised:
            await RelayApi.listing(backend)
    finally:
        await backend.close()
    assert str(raised.value) == (f"fleet 127.0.0.1:{refusing_port}: its HTTP API does not answer "
                                 f"(cannot connect to 127.0.0.1:{refusing_port}: Connection refused)")


@pytest.mark.parametrize(("failure", "said"), [
    (ConnectionRefusedError(111, "Connection refused"), "Connection refused"),                 # socket.connect
    (ConnectionRefusedError(111, "Connect call failed ('127.0.0.1', 1)"), "Connection refused"),  # asyncio
    (OSError("Multiple exceptions: [Errno 111] Connect call failed ('::1', 1, 0, 0), "
             "[Errno 111] Connect call failed ('127.0.0.1', 1)"), "Connection refused"),     # asyncio, a name
    (OSError("Multiple exceptions: [Errno 111] Connect call failed ('::1', 1, 0, 0), "
             "[Errno 101] Connect call failed ('10.0.0.1', 1)"),
     "Multiple exceptions: [Errno 111] Connect call failed ('::1', 1, 0, 0), "
     "[Errno 101] Connect call failed ('10.0.0.1', 1)"),                                      # two reasons: both
    (socket.gaierror(-2, "Name or service not known"), "Name or service not known"),
    (TimeoutError(), "timed out"),                                                           # asyncio.wait_for
    (TimeoutError("timed out"), "timed out"),                                               # a socket's timeout
])
def test_the_reason_is_the_operating_system_s_words_for_its_number(failure: BaseException, said: str) -> None:
    assert connect_failure(failure) == said
