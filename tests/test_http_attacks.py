"""The HTTP control API, a fleet's relay and ``cipstack plant`` attacked from outside, as a noisy client,
a careless rig script and a hostile neighbour would: real processes, real sockets on loopback, the
exact bytes written by hand where the bytes are the point.

- Connection floods: 200 connections trickling their heads from 50 addresses leave a well-behaved
  client served (the listeners' one per-address policy); connections already closed take no slot;
  at the limit a client is answered 503 with a JSON body and ``Retry-After``, never a bare close.
- Streams: 32 front-panel streams through a fleet's relay take the streams' own slots, never the
  requests': ``/devices``, ``/metrics`` and every device route go on answering.
- Parsing: a query number that is not ASCII digits, an absolute-form or otherwise foreign request
  target, a request aiohttp cannot parse: a 400 with a JSON body, before any other answer begins.
- Logs: one line per source per 10 s for malformed requests, never a traceback, never the token
  (the log is searched for it after every attack).
- Every answer says ``X-Content-Type-Options: nosniff``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

pytest.importorskip("aiohttp", reason="aiohttp is not installed (the http extra): pip install '.[http]'")

import aiohttp

from cipstack.control.http import MAX_IN_FLIGHT
from cipstack.control.http_connections import HEADER_TIMEOUT, MAX_CONNECTIONS
from cipstack.control.panel_app import MAX_STREAMS
from tests.cli_errors import one_line_error
from tests.ports import free_port
from tests.test_cli import run, stop
from tests.test_fleet import Fleet
from tests.waiting import wait_for

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="any 127.x on loopback")

#: The token every API here is started with; no log line may ever carry it.
TOKEN = "h49-tok-5f0c7e21a9b84d36b1e0f4c2d8a6e913"
AUTH = f"Authorization: Bearer {TOKEN}\r\n".encode()
#: Where this module's fleet emulates its devices (127.49.x: nobody else's block).
FLEET_HOSTS = [f"127.49.1.{10 + n}" for n in range(4)]


# -- talking HTTP byte by byte ------------------------------------------------------------------------------
@dataclass
class Answer:
    status: int
    headers: dict[str, str]
    body: bytes
    raw: bytes

    def json(self) -> object:
        assert self.headers.get("content-type", "").startswith("application/json"), self.raw[:300]
        return json.loads(self.body)


def parse(raw: bytes) -> Answer:
    head, _, body = raw.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    assert lines[0].startswith("HTTP/1."), raw[:300]
    headers = {}
    for line in lines[1:]:
        name, _, value = line.partition(":")
        headers[name.strip().lower()] = value.strip()
    return Answer(int(lines[0].split()[1]), headers, body, raw)


def connect(port: int, source: str = "127.0.0.1") -> socket.socket:
    sock = socket.socket()
    sock.bind((source, 0))
    sock.settimeout(15)
    sock.connect(("127.0.0.1", port))
    return sock


def read_all(sock: socket.socket) -> bytes:
    received = b""
    while chunk := sock.recv(65536):
        received += chunk
    return received


def exchange(port: int, request: bytes, source: str = "127.0.0.1") -> Answer:
    """``request`` (whole, with ``Connection: close``) on a new connection from ``source``; the answer."""
    with connect(port, source) as sock:
        sock.sendall(request)
        return parse(read_all(sock))


def _served_now(port: int, source: str) -> bool:
    """Whether a GET /status from ``source`` is answered 200 now: a 503, or the reset of a refusal made
    while more than the lingering ones were out, is a no."""
    try:
        return exchange(port, get("/status"), source=source).status == 200
    except ConnectionResetError:
        return False


def get(path: str, *, auth: bool = True, extra: bytes = b"") -> bytes:
    return (f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n".encode() + (AUTH if auth else b"") + extra
            + b"Connection: close\r\n\r\n")


def assert_clean(log: Path) -> None:
    """Searched after every attack: no traceback, and the token nowhere."""
    text = log.read_text(errors="replace")
    assert TOKEN not in text and TOKEN[8:24] not in text, "the token was logged"
    assert "Traceback" not in text, text[-3000:]


# -- the processes ------------------------------------------------------------------------------------------
@dataclass
class Served:
    process: subprocess.Popen[bytes]
    port: int
    log: Path


def token_file(folder: Path) -> Path:
    path = folder / "token"
    path.write_text(TOKEN + "\n", encoding="utf-8")
    path.chmod(0o600)
    return path


def answering(port: int, process: subprocess.Popen[bytes], log: Path) -> bool:
    if process.poll() is not None:
        pytest.fail(f"it exited: {log.read_text()}")
    try:
        return exchange(port, get("/openapi.json")).status == 200
    except OSError:
        return False


@contextlib.contextmanager
def adapter(tmp_path: Path) -> Iterator[Served]:
    """``cipstack adapter --http`` with a token, its log in a file."""
    port, http = free_port(), free_port()
    log = tmp_path / "adapter.log"
    with log.open("wb") as err:
        process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--port", str(port), "--io-port", "0",
                                    "--state", str(tmp_path / "acg.json"), "--control", str(tmp_path / "control.sock"),
                                    "--http", f"127.0.0.1:{http}", "--http-token-file", str(token_file(tmp_path))],
                                   stdout=subprocess.DEVNULL, stderr=err, stdin=subprocess.DEVNULL)
    try:
        wait_for(lambda: answering(http, process, log), 30, "the HTTP API")
        yield Served(process, http, log)
        assert_clean(log)
    finally:
        stop(process)


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Served]:
    """``cipstack fleet --workers 4 --http`` (4 ACG drives, one per worker), with a token."""
    folder = tmp_path_factory.mktemp("fleet")
    port, http = free_port(*FLEET_HOSTS), free_port()
    started = Fleet(folder, "--addresses", f"{FLEET_HOSTS[0]}-{FLEET_HOSTS[-1]}", "--device", "acg*4",
                    "--port", str(port), "--io-port", "0", "--workers", "4", "--state-dir", str(folder / "state"),
                    "--http", f"127.0.0.1:{http}", "--http-token-file", str(token_file(folder)))
    try:
        started.wait_ready(90)
        yield Served(started.process, http, started.err)
        assert_clean(started.err)
    finally:
        started.kill()


# -- 1. connection floods ------------------------------------------------------------------------------------
#: The flood: connections that trickle a head that never ends, from 50 addresses (none the client's).
FLOOD_CONNECTIONS = 200
FLOOD_SOURCES = [f"127.0.0.{2 + n}" for n in range(50)]
#: How long the flood runs: past one ``HEADER_TIMEOUT``, so that slots held from the start turn over
#: while the attacker reconnects at once; and how many connections it may open in all.
FLOOD_SECONDS = HEADER_TIMEOUT + 3
FLOOD_ATTEMPTS = 4000


async def trickle(port: int, source: str, until: float, tally: dict[str, int]) -> None:
    """One attacker slot: connect, send a head a byte a second, reconnect as soon as it is closed."""
    loop = asyncio.get_running_loop()
    while loop.time() < until and tally["attempts"] < FLOOD_ATTEMPTS:
        tally["attempts"] += 1
        try:
            reader, writer = await asyncio.wait_for(
                asyncio.open_connection("127.0.0.1", port, local_addr=(source, 0)), 5)
        except asyncio.TimeoutError:         # a full backlog drops a SYN: the kernel's, not a refusal
            tally["connect timeouts"] += 1
            continue
        except OSError:
            tally["connect errors"] += 1
            await asyncio.sleep(0.1)
            continue
        try:
            writer.write(b"GET /status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ")
            while loop.time() < until:
                try:
                    answer = await asyncio.wait_for(reader.read(4096), 1.0)
                except asyncio.TimeoutError:
                    writer.write(b"a")          # one more byte of a header that never ends
                    continue
                tally["answered 503" if answer.startswith(b"HTTP/1.1 503 ") else "closed"] += 1
                break
        except OSError:
            tally["closed"] += 1
        finally:
            writer.close()


async def well_behaved(port: int, until: float) -> list[tuple[float, int | str]]:
    """A request every 0.5 s from 127.0.0.1, each on a new connection: when, and what it got."""
    loop = asyncio.get_running_loop()
    results: list[tuple[float, int | str]] = []
    connector = aiohttp.TCPConnector(force_close=True)
    async with aiohttp.ClientSession(connector=connector, headers={"Authorization": f"Bearer {TOKEN}"},
                                     timeout=aiohttp.ClientTimeout(total=10)) as session:
        while loop.time() < until:
            started = loop.time()
            try:
                async with session.get(f"http://127.0.0.1:{port}/status") as reply:
                    await reply.read()
                    results.append((loop.time() - started, reply.status))
            except (aiohttp.ClientError, asyncio.TimeoutError) as exc:
                results.append((loop.time() - started, type(exc).__name__))
            await asyncio.sleep(0.5)
    return results


async def test_a_well_behaved_client_is_served_through_a_trickling_flood(tmp_path: Path) -> None:
    """200 connections from 50 addresses trickle request heads that never end, and reconnect at once
    when closed: the 64 slots stay full, and yet every request of a client at another address is
    answered 200, because a newcomer takes the place of the idlest connection of the address holding
    the most; the attacker's extra connections are answered 503."""
    with adapter(tmp_path) as api:
        loop = asyncio.get_running_loop()
        until = loop.time() + FLOOD_SECONDS
        tally = dict.fromkeys(("attempts", "connect errors", "connect timeouts", "answered 503", "closed"), 0)
        attackers = [asyncio.ensure_future(trickle(api.port, FLOOD_SOURCES[n % len(FLOOD_SOURCES)], until, tally))
                     for n in range(FLOOD_CONNECTIONS)]
        await asyncio.sleep(1.0)                 # the slots are full before the client comes
        results = await well_behaved(api.port, until)
        await asyncio.gather(*attackers)
        assert len(results) >= 10, results
        assert all(status == 200 for _, status in results), (results, tally)
        assert max(took for took, _ in results) < 5.0, results
        assert tally["answered 503"] > 0 and tally["connect errors"] == 0, tally
        lines = api.log.read_text().splitlines()
        # One line per source per 10 s for the refusals and for the connections closed to make room.
        assert len([line for line in lines if "HTTP connection from" in line]) <= 4 * len(FLOOD_SOURCES) + 4


def keep_alive_request(sock: socket.socket, path: str) -> Answer:
    """``GET path`` on ``sock``, which stays open: the whole answer (read by its Content-Length)."""
    sock.sendall(f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n".encode() + AUTH + b"\r\n")
    received = b""
    while b"\r\n\r\n" not in received:
        chunk = sock.recv(65536)
        assert chunk, f"closed without an answer: {received!r}"
        received += chunk
    answer = parse(received)
    while len(answer.body) < int(answer.headers.get("content-length", "0")):
        chunk = sock.recv(65536)
        assert chunk, "closed in the middle of an answer"
        answer.body += chunk
    return answer


def test_connections_already_closed_take_no_slot(tmp_path: Path) -> None:
    """1,200 connections open and close at once (what a reconnecting script does under load); then 60
    clients are each served on a connection they keep open, and none of them is closed to make room
    for another: 60 live connections are below the limit, whatever closed before."""
    with adapter(tmp_path) as api:
        for _ in range(1200):
            connect(api.port, "127.0.0.2").close()
        # The closes are seen (a refusal meanwhile is of connections of the address not yet seen closed:
        # it cannot take a place from itself) within a bound far below the HEADER_TIMEOUT for which a
        # connection that had closed used to be counted.
        wait_for(lambda: _served_now(api.port, "127.0.0.2"), 3, "the closed connections to be counted out")
        live = [connect(api.port, "127.0.0.2") for _ in range(MAX_CONNECTIONS - 8)]
        live += [connect(api.port, "127.0.0.3") for _ in range(4)]
        try:
            for sock in live:
                answer = keep_alive_request(sock, "/status")
                assert answer.status == 200, answer.raw[:300]
            for sock in live:                          # nobody was closed to make room: there was room
                sock.setblocking(False)
                with pytest.raises(BlockingIOError):
                    sock.recv(1, socket.MSG_PEEK)
        finally:
            for sock in live:
                sock.close()


# -- 2. a refusal is an answer -------------------------------------------------------------------------------
def test_at_the_limit_a_client_is_answered_503_with_json_and_retry_after(tmp_path: Path) -> None:
    with adapter(tmp_path) as api:
        held = [connect(api.port) for _ in range(MAX_CONNECTIONS)]
        try:
            refused = exchange(api.port, get("/status"))        # the same address: no room to make for it
            assert refused.status == 503 and refused.headers["retry-after"] == "1", refused.raw
            assert refused.headers["x-content-type-options"] == "nosniff"
            assert refused.json() == {"error": f"{MAX_CONNECTIONS} HTTP connections are open; try again"}
            # Another address takes the place of one of the 64, and is served.
            assert exchange(api.port, get("/status"), source="127.0.0.2").status == 200
        finally:
            for sock in held:
                sock.close()
        wait_for(lambda: "HTTP connection from 127.0.0.1 refused (503)" in api.log.read_text(), 10, "the line")
        assert exchange(api.port, get("/status")).status == 200
        assert_clean(api.log)


# -- 3. streams do not starve the API ------------------------------------------------------------------------
async def test_32_streams_at_the_relay_leave_requests_their_room(fleet: Served) -> None:
    """32 panels open at once through the fleet's relay (4 workers: 8 streams each would fit): the relay
    serves ``MAX_STREAMS`` of them and answers the rest 503 with when to try again; ``/devices``,
    ``/metrics`` and every device's routes answer 200 meanwhile, many at once."""
    base = f"http://127.0.0.1:{fleet.port}"
    headers = {"Authorization": f"Bearer {TOKEN}"}
    connector = aiohttp.TCPConnector(limit=0)
    async with aiohttp.ClientSession(connector=connector, headers=headers,
                                     timeout=aiohttp.ClientTimeout(total=30)) as session:
        streams = await asyncio.gather(*(session.get(f"{base}/devices/{FLEET_HOSTS[n % 4]}/stream")
                                         for n in range(32)))
        try:
            served = [reply for reply in streams if reply.status == 200]
            refused = [reply for reply in streams if reply.status != 200]
            assert len(served) == MAX_STREAMS, [reply.status for reply in streams]
            for reply in refused:
                assert reply.status == 503 and reply.headers["Retry-After"] == "1"
                assert "panels are open" in (await reply.json())["error"]
            for reply in served:                             # each stream is live: its first event came
                assert (await asyncio.wait_for(reply.content.readline(), 10)).startswith(b"event: ")

            async def status(path: str) -> int:
                async with session.get(base + path) as reply:
                    await reply.read()
                    assert reply.headers["X-Content-Type-Options"] == "nosniff"
                    return reply.status

            paths = ["/devices", "/metrics", *(f"/devices/{host}/status" for host in FLEET_HOSTS),
                     *(f"/devices/{host}/faults" for host in FLEET_HOSTS)]
            asked = paths * 3                 # at once, within the requests' own bound
            assert len(asked) <= MAX_IN_FLIGHT
            answers = await asyncio.gather(*(status(path) for path in asked))
            assert answers == [200] * len(asked), list(zip(asked, answers, strict=True))
        finally:
            for reply in streams:
                reply.close()
    # The slots come back when the panels close: a stream opens again.
    async with aiohttp.ClientSession(headers=headers) as session:
        async def one_stream() -> bool:
            async with session.get(f"{base}/devices/{FLEET_HOSTS[0]}/stream") as reply:
                return reply.status == 200

        deadline = asyncio.get_running_loop().time() + 10
        while not await one_stream():
            assert asyncio.get_running_loop().time() < deadline, "the stream slots did not come back"
            await asyncio.sleep(0.2)
    assert_clean(fleet.log)


# -- 4. parsing that cannot 500 ------------------------------------------------------------------------------
#: Query values ``int()`` or ``str.isdigit()`` would take, and none of them a number of ASCII digits.
NOT_DIGITS = ["%C2%B2", "%D9%A1", "%2B1", "1_0", "%201", "-1", "0x1", "", "9" * 19]


def test_a_query_number_is_ascii_digits_or_a_400_before_any_answer(tmp_path: Path, fleet: Served) -> None:
    """``?since=`` of the stream and of the events: a superscript two (which ``str.isdigit()`` takes and
    ``int()`` refuses), an Arabic-Indic one, a sign, an underscore, a space: a 400 with a JSON body, as
    the first and only answer, from one process and through a fleet's relay."""
    with adapter(tmp_path) as api:
        for port, prefix in ((api.port, ""), (fleet.port, f"/devices/{FLEET_HOSTS[1]}")):
            for route in ("/stream", "/events"):
                for value in NOT_DIGITS:
                    answer = exchange(port, get(f"{prefix}{route}?since={value}"))
                    assert answer.status == 400, (route, value, answer.raw[:300])
                    error = answer.json()
                    assert isinstance(error, dict) and "since is a whole number" in error["error"], error
                    assert b"HTTP/1.1 200" not in answer.raw and answer.raw.count(b"HTTP/1.1 ") == 1
            assert exchange(port, get(f"{prefix}/events?since=0")).status == 200
            with connect(port) as sock:                  # a number of digits opens the stream
                sock.sendall(get(f"{prefix}/stream?since=7"))
                assert sock.recv(65536).startswith(b"HTTP/1.1 200 ")
        assert_clean(api.log)
    assert_clean(fleet.log)


def test_a_fault_id_in_a_path_is_ascii_digits(tmp_path: Path) -> None:
    """``DELETE /faults/ID``: an Arabic-Indic one (which ``int()`` reads as 1) is no fault's id and clears
    nothing, a superscript two (which ``str.isdigit()`` takes and ``int()`` refuses) is a 404 naming it,
    never a 500."""
    json_type = b"Content-Type: application/json\r\n"
    with adapter(tmp_path) as api:
        body = b'{"name": "error-status", "options": {"status": "0x08", "class": 1}}'
        applied = exchange(api.port, b"POST /faults HTTP/1.1\r\nHost: 127.0.0.1\r\n" + AUTH + json_type
                           + f"Content-Length: {len(body)}\r\nConnection: close\r\n\r\n".encode() + body)
        assert applied.status == 201 and applied.json() == {**applied.json(), "id": 1}, applied.raw[:300]
        for value in ("%D9%A1", "%C2%B2", "%2B1", "1_0", "%201"):
            answer = exchange(api.port, get(f"/faults/{value}").replace(b"GET", b"DELETE", 1))
            assert answer.status == 404, (value, answer.raw[:300])
            error = answer.json()
            assert isinstance(error, dict) and error["error"].startswith("no active fault '"), error
        active = exchange(api.port, get("/faults")).json()
        assert isinstance(active, list) and [fault["id"] for fault in active] == [1]
        assert exchange(api.port, get("/faults/1").replace(b"GET", b"DELETE", 1)).status == 200


def test_a_fleet_port_of_other_digits_is_one_line() -> None:
    result = run("plant", "--fleet", "cipstack-fleet:\u00b2", "--http", "127.0.0.1:0")
    assert result.returncode == 2 and "is not NAME:PORT" in one_line_error(result)


def test_a_request_target_that_is_not_a_path_is_a_400(tmp_path: Path, fleet: Served) -> None:
    """An absolute-form target (for proxies), a network-path one and ``*``: a 400 with a JSON body from
    one process, a fleet's relay and ``cipstack plant`` (whose relay would have forwarded it to a URL it
    cannot build), never a 500 or a traceback; the plant goes on serving."""
    plant_port = free_port()
    plant_log = fleet.log.parent / "plant.log"
    with plant_log.open("wb") as err:
        plant = subprocess.Popen([sys.executable, "-m", "cipstack", "plant", "--fleet", f"127.0.0.1:{fleet.port}",
                                  "--http", f"127.0.0.1:{plant_port}",
                                  "--http-token-file", str(fleet.log.parent / "token")],
                                 stdout=subprocess.DEVNULL, stderr=err, stdin=subprocess.DEVNULL)
    try:
        wait_for(lambda: answering(plant_port, plant, plant_log)
                 and exchange(plant_port, get("/devices")).json() != [], 30, "the plant to list the fleet's devices")
        with adapter(tmp_path) as api:
            for port, device in ((plant_port, f"/devices/{FLEET_HOSTS[2]}"), (fleet.port, f"/devices/{FLEET_HOSTS[2]}"),
                                 (api.port, "")):
                for target in (f"http://x{device}/status", f"http://127.0.0.1:{port}{device}/status",
                               f"//x{device}/status", "*"):
                    answer = exchange(port, get(target))
                    assert answer.status == 400, (port, target, answer.raw[:300])
                    error = answer.json()
                    assert isinstance(error, dict) and "error" in error
                    assert answer.headers["x-content-type-options"] == "nosniff"
                assert exchange(port, get(f"{device}/status")).status == 200      # and it goes on serving
            assert_clean(api.log)
            for log in (api.log, plant_log):            # 4 of them from one address in 10 s: one line
                lines = [line for line in log.read_text().splitlines() if "refused (400)" in line]
                assert len(lines) == 1 and "is not a path" in lines[0], lines
        assert_clean(plant_log)
        assert_clean(fleet.log)
    finally:
        stop(plant)


# -- 5. logs: one line per source, never a traceback, never a secret -----------------------------------------
def malformed(n: int) -> bytes:
    """A request aiohttp cannot parse, of one of six kinds (two carry the token in a broken header)."""
    kinds = [b"BLAH\r\n\r\n",
             b"GET /status HTTP/9.9\r\nHost: 127.0.0.1\r\n\r\n",
             b"GET /status HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer " + TOKEN.encode() + b"\x01\r\n\r\n",
             b"GET /status HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization Bearer " + TOKEN.encode() + b"\r\n\r\n",
             b"GET /sta tus HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
             b"GET /status HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Bad\x7f: 1\r\n\r\n"]
    return kinds[n % len(kinds)]


def test_malformed_requests_are_one_line_per_source_and_never_the_token(tmp_path: Path) -> None:
    """120 requests aiohttp cannot parse, from 3 addresses: each is answered 400 with a JSON body that
    says why (the token not echoed), and the log has one line per address with the reason and how many
    more came, no traceback, no token."""
    sources = ["127.0.0.2", "127.0.0.3", "127.0.0.4"]
    with adapter(tmp_path) as api:
        before = len(api.log.read_text().splitlines())
        for n in range(120):
            answer = exchange(api.port, malformed(n), source=sources[n % 3])
            assert answer.status == 400, answer.raw[:300]
            error = answer.json()
            assert isinstance(error, dict) and error["error"].startswith("malformed request: "), error
            assert TOKEN.encode() not in answer.raw
            assert answer.headers["x-content-type-options"] == "nosniff"
        assert_clean(api.log)
        lines = api.log.read_text().splitlines()[before:]
        assert len(lines) == 3, lines
        assert sorted(line.split("HTTP request from ")[1].split()[0] for line in lines) == sources
        assert all("refused (400): malformed request: " in line for line in lines), lines
        assert exchange(api.port, get("/status")).status == 200
        # A line later, from an address that went on: how many were held back.
        stop_at = time.monotonic() + 11
        while time.monotonic() < stop_at:
            exchange(api.port, malformed(2), source=sources[0])
            time.sleep(0.5)
        assert_clean(api.log)
        later = api.log.read_text().splitlines()[before + 3:]
        assert len(later) == 1 and "more like it in the last" in later[0], later


def test_credentials_are_redacted_whatever_the_token() -> None:
    """What a client sends as a credential is redacted even when it is no token of this process."""
    from cipstack.control.http import REDACTED, redact

    for text, secret in ((r"b'Authorization: Bearer s3cr3t-unknown\x01'", "s3cr3t-unknown"),
                         ("Proxy-Authorization: Basic dXNlcjpwYXNz", "dXNlcjpwYXNz"),
                         ("b'authorization bearer xyz987'", "xyz987"),
                         ("GET /status?token=abc123&since=1 HTTP/1.1", "abc123"),
                         ("Cookie: session=qwe-rty", "qwe-rty")):
        shown = redact(text)
        assert secret not in shown and REDACTED in shown, shown
    assert redact("HTTP GET /status refused (403): Host 'evil.example'") == \
        "HTTP GET /status refused (403): Host 'evil.example'"


# -- 6. nosniff on every answer ------------------------------------------------------------------------------
def test_every_answer_says_nosniff(tmp_path: Path) -> None:
    json_type = b"Content-Type: application/json\r\n"
    with adapter(tmp_path) as api:
        requests = {
            "status": get("/status"), "openapi": get("/openapi.json"), "metrics": get("/metrics"),
            "panel": get("/"), "not found": get("/nowhere"), "no token": get("/status", auth=False),
            "foreign host": b"GET /status HTTP/1.1\r\nHost: evil.example\r\n" + AUTH + b"Connection: close\r\n\r\n",
            "not json": b"POST /trip HTTP/1.1\r\nHost: 127.0.0.1\r\n" + AUTH + b"Content-Type: text/plain\r\n"
                        b"Content-Length: 2\r\nConnection: close\r\n\r\n{}",
            "bad body": b"POST /trip HTTP/1.1\r\nHost: 127.0.0.1\r\n" + AUTH + json_type
                        + b"Content-Length: 5\r\nConnection: close\r\n\r\n{nope",
            "too big": b"POST /trip HTTP/1.1\r\nHost: 127.0.0.1\r\n" + AUTH + json_type
                       + b"Content-Length: 20000\r\nConnection: close\r\n\r\n" + b" " * 20000,
            "malformed": malformed(0), "absolute": get("http://x/status")}
        statuses = {}
        for name, request in requests.items():
            answer = exchange(api.port, request)
            statuses[name] = answer.status
            assert answer.headers.get("x-content-type-options") == "nosniff", (name, answer.raw[:400])
        assert statuses == {"status": 200, "openapi": 200, "metrics": 200, "panel": 200, "not found": 404,
                            "no token": 401, "foreign host": 403, "not json": 415, "bad body": 400, "too big": 413,
                            "malformed": 400, "absolute": 400}
        with connect(api.port) as sock:                   # a stream's head
            sock.sendall(get("/stream"))
            head = parse(sock.recv(65536))
            assert head.status == 200 and head.headers["x-content-type-options"] == "nosniff"
        assert_clean(api.log)


def test_the_relay_answers_nosniff_too(fleet: Served) -> None:
    for path in ("/devices", "/metrics", f"/devices/{FLEET_HOSTS[3]}/status", "/devices/127.49.1.99/status",
                 "/status"):
        answer = exchange(fleet.port, get(path))
        assert answer.status in (200, 404) and answer.headers["x-content-type-options"] == "nosniff", answer.raw[:300]
    assert_clean(fleet.log)

