"""The HTTP control API against a hostile web page and careless clients, through a real HTTP client on
loopback, on one adapter and through a fleet's relay.

A page of another origin cannot change the emulator: a cross-origin ``Origin`` (``null`` too), a
``Sec-Fetch-Site`` of another site, a body that is not ``application/json`` (what a form or a
``no-cors`` fetch sends) are refused; a ``Host`` that is not the API's (DNS rebinding) is refused for
every request. Bodies that would have raised inside the server (deep nesting, a 400-digit number,
``NaN``) and a token header that is not UTF-8 get a 4xx with a JSON error, and the API and
EtherNet/IP go on serving."""

from __future__ import annotations

import asyncio
import http.client
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

pytest.importorskip("aiohttp", reason="aiohttp is not installed (the http extra): pip install '.[http]'")

import aiohttp

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.cli.emulators import TOKEN_VARIABLE
from tests.cli_errors import one_line_error
from tests.http_client import status as http_status
from tests.ports import free_port
from tests.test_cli import run, stop
from tests.waiting import wait_for

FAULT = b'{"name": "error-status", "options": {"status": "0x08", "class": 1}}'


@pytest.fixture
async def api(tmp_path: Path) -> AsyncIterator[tuple[Adapter, str]]:
    adapter = Adapter(AdapterSettings(port=0, io_port=0, state_path=tmp_path / "acg.json",
                                      control_path=tmp_path / "control.sock", http="127.0.0.1:0",
                                      http_hosts=("rig.example",)))
    await adapter.start_serving()
    try:
        yield adapter, f"http://127.0.0.1:{adapter.http_api.port}"
    finally:
        await adapter.stop_serving()


async def send(url: str, method: str = "POST", body: bytes | None = FAULT, **headers: str) -> tuple[int, dict]:
    """One request with exactly these headers (plus what aiohttp always sends: Host, unless given)."""
    async with aiohttp.ClientSession() as session, \
            session.request(method, url, data=body, headers=headers,
                            skip_auto_headers=["Content-Type"] if "Content-Type" not in headers else []) as reply:
        assert reply.content_type == "application/json"
        return reply.status, await reply.json()


def json_type() -> dict[str, str]:
    return {"Content-Type": "application/json"}


async def test_a_page_of_another_origin_cannot_change_the_emulator(api: tuple[Adapter, str]) -> None:
    adapter, base = api
    for headers, status in (
            ({**json_type(), "Origin": "http://127.0.0.2:8000"}, 403),              # another origin
            ({**json_type(), "Origin": "null"}, 403),                               # a sandboxed or file:// page
            ({**json_type(), "Sec-Fetch-Site": "cross-site"}, 403),                 # a browser, no Origin
            ({**json_type(), "Sec-Fetch-Site": "same-site"}, 403),                  # another port of the site
            ({"Content-Type": "text/plain"}, 415),                                  # a no-cors fetch
            ({"Content-Type": "application/x-www-form-urlencoded"}, 415),           # a plain HTML form
            ({}, 415)):                                                             # no content type
        code, body = await send(base + "/faults", **headers)
        assert code == status and "error" in body, (headers, body)
    assert adapter.faults.faults() == []                                          # nothing was applied
    code, _ = await send(base + "/trip", body=b'{"code": "OverHeat"}', Origin="http://evil.example")
    assert code == 403 and adapter.service.status()["drive"]["trip"] is None
    # The API's own origin, and a script (curl: no Origin, no Sec-Fetch-Site) are served.
    code, fault = await send(base + "/faults", **json_type(), Origin=base)
    assert code == 201 and fault["name"] == "error-status"
    code, _ = await send(base + "/faults", method="DELETE", body=None, **{"Sec-Fetch-Site": "same-origin"})
    assert code == 200 and adapter.faults.faults() == []
    code, _ = await send(base + "/faults", **json_type())
    assert code == 201


async def test_a_foreign_host_name_is_refused_for_every_request(api: tuple[Adapter, str]) -> None:
    """DNS rebinding: a page on evil.example whose name now points at 127.0.0.1 reads and writes as
    'evil.example'; the API answers to its address, localhost and the names given to it only."""
    _, base = api
    port = base.rsplit(":", 1)[1]
    for host in ("evil.example", f"evil.example:{port}", "127.0.0.1.evil.example"):
        code, body = await send(base + "/status", method="GET", body=None, Host=host)
        assert code == 403 and "Host" in body["error"]
        code, _ = await send(base + "/faults", **json_type(), Host=host)
        assert code == 403
    for host in (f"127.0.0.1:{port}", f"localhost:{port}", "rig.example", f"[::1]:{port}"):
        code, _ = await send(base + "/status", method="GET", body=None, Host=host)
        assert code == 200, host


async def test_bodies_that_would_break_the_server_are_a_clear_400(api: tuple[Adapter, str]) -> None:
    adapter, base = api
    deep = b'{"name": "drop", "options": ' + b"[" * 5000 + b"]" * 5000 + b"}"
    nested = b'{"name": "drop", "options": {"share": ' + b'{"a": ' * 12 + b"1" + b"}" * 12 + b"}}"
    for body, said in ((deep, "nests deeper"), (nested, "nests deeper"),
                       (b'{"name": "delay", "options": {"by": ' + b"9" * 400 + b"}}", "more than 20 digits"),
                       (b'{"name": "delay", "options": {"by": NaN}}', "NaN is not a JSON number"),
                       (b'{"name": "delay", "options": {"by": 1e400}}', "not a finite time"),
                       (b'{"name": "drop", "options": {"share": "\xff"}}', "not UTF-8")):
        code, reply = await send(base + "/faults", body=body, **json_type())
        assert code == 400 and said in reply["error"], (body[:60], reply)
    assert adapter.faults.faults() == []
    socket.create_connection(("127.0.0.1", adapter.port), timeout=2).close()      # EtherNet/IP serves on


async def test_a_token_header_that_is_not_utf8_is_refused_not_a_crash(tmp_path: Path) -> None:
    adapter = Adapter(AdapterSettings(port=0, io_port=0, state_path=tmp_path / "acg.json",
                                      control_path=tmp_path / "control.sock", http="127.0.0.1:0",
                                      http_token="s3cret"))
    await adapter.start_serving()
    try:
        port = adapter.http_api.port
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(b"GET /status HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer \xff\xfe\xc3\r\n"
                     b"Connection: close\r\n\r\n")
        reply = await asyncio.wait_for(reader.read(), 5)
        writer.close()
        assert reply.startswith(b"HTTP/1.1 401") and b'"error"' in reply
        code, _ = await send(f"http://127.0.0.1:{port}/status", method="GET", body=None,
                             Authorization="Bearer s3cret")
        assert code == 200
    finally:
        await adapter.stop_serving()


def _serve(tmp_path: Path, *args: str, env: dict[str, str] | None = None) -> tuple[subprocess.Popen[str], int]:
    """``cipstack adapter --http`` in a process of its own; it and the HTTP API's port once it answers."""
    port, http = free_port(), free_port()
    process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port", "0",
                                "--state", str(tmp_path / "acg.json"), "--control", str(tmp_path / "control.sock"),
                                "--http", f"127.0.0.1:{http}", *args],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env={**os.environ, **(env or {})})

    def answering() -> bool:
        if process.poll() is not None:
            pytest.fail(f"the adapter exited: {process.communicate()[1]}")
        try:
            socket.create_connection(("127.0.0.1", http), timeout=0.2).close()
        except OSError:
            return False
        return True

    wait_for(answering, 20, "the HTTP API")
    return process, http


def _status(http: int, token: str | None) -> int:
    return http_status(f"http://127.0.0.1:{http}/status", token)


@pytest.mark.parametrize("where", ["file", "environment"])
def test_the_token_comes_from_a_file_or_the_environment_never_the_process_list(tmp_path: Path, where: str) -> None:
    token = "t0ken-" + where
    secret = tmp_path / "token"
    secret.write_text(token + "\n", encoding="utf-8")
    secret.chmod(0o600)
    args, env = (("--http-token-file", str(secret)), None) if where == "file" else ((), {TOKEN_VARIABLE: token})
    process, http = _serve(tmp_path, *args, env=env)
    try:
        assert _status(http, None) == 401 and _status(http, "wrong") == 401 and _status(http, token) == 200
        assert token.encode() not in Path(f"/proc/{process.pid}/cmdline").read_bytes()   # what ps shows
    finally:
        stop(process)


def test_an_empty_or_missing_token_file_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "empty").write_text("\n", encoding="utf-8")
    for file, said in ((tmp_path / "empty", "the token is empty"), (tmp_path / "nowhere", "No such file")):
        result = run("adapter", "--port", str(free_port()), "--http", "127.0.0.1:0", "--http-token-file", str(file))
        assert result.returncode == 2 and said in one_line_error(result)
    both = run("adapter", "--http", "127.0.0.1:0", "--http-token", "x", "--http-token-file", str(tmp_path / "empty"))
    assert both.returncode == 2 and "not both" in one_line_error(both)


def test_sigint_stops_the_adapter_within_2s_during_a_long_power_cycle(tmp_path: Path) -> None:
    process, http = _serve(tmp_path)
    try:
        request = urllib.request.Request(f"http://127.0.0.1:{http}/power", method="POST",
                                         data=b'{"action": "cycle", "off": "3000s"}',
                                         headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(request, timeout=10) as reply:
            assert reply.status == 200
        process.send_signal(signal.SIGINT)
        started = time.monotonic()
        _, stderr = process.communicate(timeout=30)
        assert process.returncode == 0 and "Traceback" not in stderr, stderr
        assert time.monotonic() - started < 2.0
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()


@pytest.mark.parametrize(("step", "said"), [
    ('on = "conection opened"\nclear = true', 'on = \'conection opened\' is no event kind; valid: connection opened'),
    ('on = "frequency"\nhz = nan\nclear = true', "hz = a number 0..1000"),
    ('at = 1e9\nclear = true', "longer than 86400s"),
    ('at = 1\nfault = "delay"\noptions = { by = ' + "9" * 400 + " }", "a number of about 400 digits"),
    ('at = 1\nfault = "power-cycle"\noptions = { off = "2h" }', "not a duration"),
    ("at = 1\nclear = true\nx = " + "[" * 2000 + "]" * 2000, "not TOML"),
    ('at = 1\ntrip = "bogus"', "step 1: trip 'bogus': unknown trip 'bogus'"),
    ("at = 1\ntrip = 0x1234", "valid codes: 0x"),
], ids=["event-kind", "hz-nan", "huge-at", "400-digits", "duration-unit", "nested-toml", "trip-name", "trip-code"])
def test_a_scenario_is_checked_whole_when_it_is_read(tmp_path: Path, step: str, said: str) -> None:
    """Refused at load, with one line naming the step, exit 2, before anything listens."""
    path = tmp_path / "bad.toml"
    path.write_text(f"[[step]]\n{step}\n", encoding="utf-8")
    port = free_port()
    result = run("adapter", "--port", str(port), "--io-port", "0", "--scenario", str(path))
    assert result.returncode == 2 and said in one_line_error(result), result.stderr
    assert "Traceback" not in result.stderr


def test_idle_http_connections_neither_exhaust_the_process_nor_stay(tmp_path: Path) -> None:
    """Under a low open-file limit (256), 300 connections to the HTTP API that never send a request
    head: at most ``MAX_CONNECTIONS`` are kept, each of the others is answered 503 (a refusal is an
    answer), EtherNet/IP and a new HTTP client (once there is room) are served meanwhile, and each idle
    one is closed ``HEADER_TIMEOUT`` after it came."""
    import resource

    from cipstack.control.http_connections import HEADER_TIMEOUT, MAX_CONNECTIONS

    def low_limit() -> None:
        resource.setrlimit(resource.RLIMIT_NOFILE, (256, 256))

    port, http = free_port(), free_port()
    process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port", "0",
                                "--state", str(tmp_path / "acg.json"), "--control", str(tmp_path / "control.sock"),
                                "--http", f"127.0.0.1:{http}"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=low_limit)
    idle: list[socket.socket] = []
    try:
        wait_for(lambda: _status(http, None) == 200 if _accepting(http) else False, 20, "the HTTP API")
        came = time.monotonic()
        for _ in range(300):
            idle.append(socket.create_connection(("127.0.0.1", http), timeout=5))
        # The API closes each one past its limit as soon as it accepts it: wait until it has.
        # A reset is reported once, to the first read that meets it: a peek that meets one remembers it.
        reset: set[socket.socket] = set()
        wait_for(lambda: sum(_still_open(s, reset) for s in idle) <= MAX_CONNECTIONS, 10,
                 "the connections past the limit closed")
        open_ones = [s for s in idle if _still_open(s, reset)]
        assert 0 < len(open_ones) <= MAX_CONNECTIONS
        refused = [s for s in idle if s not in open_ones]
        # Each is answered 503; under this low limit one accepted when no descriptor is left is shed (reset
        # at once, the listener's rule for running out), never closed without a word.
        answers = [None if s in reset else _answer_or_reset(s) for s in refused]
        assert all(a is None or a.startswith(b"HTTP/1.1 503 ") for a in answers), answers
        assert any(a is not None for a in answers)
        # EtherNet/IP accepts and answers a RegisterSession meanwhile.
        with socket.create_connection(("127.0.0.1", port), timeout=5) as eip:
            eip.sendall(bytes.fromhex("6500 0400 00000000 00000000 0000000000000000 00000000 0100 0000"))
            assert eip.recv(28)[:2] == b"\x65\x00"
        for sock in open_ones[:5]:                                         # room again: a client is served
            sock.close()
        wait_for(lambda: _served(http), 10, "a client served once there is room")
        # The subject: each idle one is closed HEADER_TIMEOUT after it came, not before.
        wait_for(lambda: not any(_still_open(s) for s in open_ones[5:]), HEADER_TIMEOUT + 1,
                 "the idle ones closed by the API")
        assert time.monotonic() - came >= HEADER_TIMEOUT
        assert _status(http, None) == 200
    finally:
        for sock in idle:
            sock.close()
        stop(process)


def _served(port: int) -> bool:
    """A request of a new client is answered 200 (a connection past the limit is closed unanswered)."""
    try:
        return _status(port, None) == 200
    except (OSError, http.client.HTTPException):
        return False


def _accepting(port: int) -> bool:
    try:
        socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
    except OSError:
        return False
    return True


def _still_open(sock: socket.socket, reset: set[socket.socket] | None = None) -> bool:
    """The peer has neither answered nor closed ``sock`` (nothing was sent on it: a read would block).
    A reset met here is added to ``reset``: the socket reports it to this one read, and a later read
    sees only the end (as if closed without a word)."""
    sock.setblocking(False)
    try:
        sock.recv(1, socket.MSG_PEEK)       # an answer (kept for a read) or the end
        return False
    except BlockingIOError:
        return True
    except ConnectionResetError:
        if reset is not None:
            reset.add(sock)
        return False
    except OSError:
        return False
    finally:
        sock.setblocking(True)


def _answer_or_reset(sock: socket.socket) -> bytes | None:
    """What the peer sent on ``sock`` until it closed it; None if it reset the connection."""
    sock.settimeout(10)
    received = b""
    try:
        while chunk := sock.recv(4096):
            received += chunk
    except ConnectionResetError:
        return None
    return received
