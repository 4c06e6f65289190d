"""Hold under attack: the attack cases of ``tests/attacks.py`` at a small, seeded scale (seconds),
plus the rules behind them pinned one by one, sans-I/O where a rule is a pure function of its input.

The adapter runs in-process on the precise event loop (the one the command line uses) in a
background thread, so the cases reach it through real loopback sockets exactly as a hostile
peer would; ``benchmarks/soak.py`` runs the same cases at length against a subprocess.
"""

from __future__ import annotations

import asyncio
import logging
import os
import random
import resource
import socket
import struct
import subprocess
import sys
import threading
from collections.abc import Callable, Coroutine, Iterator
from pathlib import Path
from typing import Any, TypeVar

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.eip.io_server import FD_SETSIZE, precise_event_loop
from cipstack.eip.target.core import DelayedReplies, EncapsulationTarget, TargetSettings
from cipstack.eip.target.limits import ConnectionLimiter, RateLimitedLog
from cipstack.eip.wire.cm_messages import ConnectionTriad
from tests import attacks
from tests.attacks import CASES, OPTIONS, AttackTarget, Client, served
from tests.ports import free_port

T = TypeVar("T")
ROOT = Path(__file__).resolve().parent.parent


class Records(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.lines: list[str] = []
        self.errors: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.levelno >= logging.INFO:
            self.lines.append(record.getMessage())
        if record.levelno >= logging.ERROR or record.exc_info:
            self.errors.append(f"{record.name}: {record.getMessage()}")


class InProcessAdapter:
    """The adapter with the attack options, on a precise event loop in a background thread."""

    def __init__(self, **overrides: Any) -> None:
        self.loop = precise_event_loop()
        self.thread = threading.Thread(target=self._serve, name="adapter-loop", daemon=True)
        self.thread.start()
        self.records = Records()
        logger = logging.getLogger("cipstack")
        self._level = logger.level
        logger.setLevel(logging.INFO)
        logger.addHandler(self.records)
        self.adapter: Adapter = self.run(self._start({**OPTIONS, **overrides}))

    def _serve(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.run_forever()

    async def _start(self, options: dict[str, Any]) -> Adapter:
        adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0, modbus_port=0, **options))
        await adapter.start()
        return adapter

    def run(self, coroutine: Coroutine[Any, Any, T], timeout: float = 30.0) -> T:
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop).result(timeout)

    def inspect(self, probe: Callable[[Adapter], T]) -> T:
        async def call() -> T:
            return probe(self.adapter)
        return self.run(call())

    def attack_target(self) -> AttackTarget:
        assert self.adapter.io_endpoint is not None
        assert self.adapter.modbus is not None
        return AttackTarget(self.adapter.port, self.adapter.io_endpoint.port,
                            fds=lambda: len(os.listdir("/proc/self/fd")), log_lines=lambda: list(self.records.lines),
                            extra={"modbus_port": self.adapter.modbus.port})

    def close(self) -> None:
        self.run(self.adapter.close())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()
        logger = logging.getLogger("cipstack")
        logger.removeHandler(self.records)
        logger.setLevel(self._level)


@pytest.fixture(scope="module")
def hardened() -> Iterator[InProcessAdapter]:
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < 4096 and (hard == resource.RLIM_INFINITY or hard >= 4096):
        resource.setrlimit(resource.RLIMIT_NOFILE, (4096, hard))  # as far as the hard limit allows
        soft = 4096
    if soft < 4096:
        pytest.skip(f"the open-file limit ({soft}) leaves no room for 1,024+ descriptors on each side")
    running = InProcessAdapter()
    yield running
    running.close()


@pytest.mark.parametrize("case", CASES, ids=[case.name for case in CASES])
def test_attack_case(hardened: InProcessAdapter, case: attacks.Case) -> None:
    """Each attack case at its suite scale, seeded; nothing logged at ERROR, no traceback."""
    errors_before = len(hardened.records.errors)
    figures = case.run(hardened.attack_target(), case.ci_scale, random.Random(f"hardening-{case.name}"))
    assert figures
    with Client(hardened.adapter.port) as good:
        served(hardened.attack_target(), good)
    assert hardened.records.errors[errors_before:] == []
    # Everything the attack opened is gone again (the well-behaved client's connection too).
    assert attacks.wait_for(lambda: hardened.inspect(lambda a: a.server.limiter.open) == 0)
    assert hardened.inspect(lambda a: len(a.target.sessions)) == 0


# -- 1. descriptors and TCP connections ---------------------------------------------------------------
def test_precise_loop_fires_timers_and_serves_sockets_when_made_after_1024_files() -> None:
    """The epoll descriptor itself above select()'s range: waits fall back and still work."""
    held = [socket.socket() for _ in range(FD_SETSIZE + 16)]
    try:
        loop = precise_event_loop()
        try:
            assert loop.selector.fileno() >= FD_SETSIZE   # the epoll descriptor

            async def exchange() -> tuple[bytes, bool]:
                fired = asyncio.get_running_loop().create_future()
                asyncio.get_running_loop().call_later(0.0015, fired.set_result, True)
                reader, writer = await asyncio.open_connection(*server_address)
                writer.write(b"ping")
                data = await reader.readexactly(4)
                writer.close()
                return data, await fired

            listener = socket.create_server(("127.0.0.1", 0))
            server_address = listener.getsockname()

            def echo() -> None:
                conn, _ = listener.accept()
                conn.sendall(conn.recv(4))
                conn.close()

            thread = threading.Thread(target=echo, daemon=True)
            thread.start()
            assert loop.run_until_complete(asyncio.wait_for(exchange(), 5)) == (b"ping", True)
            thread.join(5)
            listener.close()
        finally:
            loop.close()
    finally:
        for sock in held:
            sock.close()


def test_limiter_counts_in_total_and_per_host() -> None:
    limiter = ConnectionLimiter(4)
    assert limiter.per_host == 2
    assert [limiter.admit("10.0.0.1") for _ in range(3)] == [True, True, False]
    assert "per-host limit 2" in limiter.reason("10.0.0.1")
    assert [limiter.admit("10.0.0.2"), limiter.admit("10.0.0.2"), limiter.admit("10.0.0.3")] == [True, True, False]
    assert "4 connections open (limit 4)" in limiter.reason("10.0.0.3")
    limiter.release("10.0.0.1")
    limiter.release("10.0.0.9")  # never admitted: nothing to release
    assert limiter.open == 3 and limiter.admit("10.0.0.3") and limiter.refused == 2


def test_rate_limited_log_says_how_many_it_held_back(caplog: pytest.LogCaptureFixture) -> None:
    now = [0.0]
    line = RateLimitedLog(logging.getLogger("cipstack.test"), interval=10.0, clock=lambda: now[0])
    with caplog.at_level(logging.WARNING, logger="cipstack.test"):
        assert line("refused %s", "a")
        for _ in range(500):
            assert not line("refused %s", "b")
        now[0] = 10.0
        assert line("refused %s", "c")
    assert [r.getMessage() for r in caplog.records] == [
        "refused a", "refused c (500 more like it in the last 10 s)"]


def test_open_file_limit_lowers_the_tcp_limit_and_a_flood_is_one_line(tmp_path: Path) -> None:
    """The adapter's open-file limit (96) below its TCP limit (1,000): the limit is lowered to fit,
    with one line; 300 connections arrive, the excess is closed at once (no client hangs in the
    backlog), refusals are one line per 10 s, no traceback, and the connected client is served."""
    port = free_port()
    script = ("import resource, sys; resource.setrlimit(resource.RLIMIT_NOFILE, (96, 96)); "
              "from cipstack.cli import main; sys.exit(main(sys.argv[1:]))")
    stderr = tmp_path / "stderr"
    with open(stderr, "wb") as err:
        process = subprocess.Popen(
            [sys.executable, "-c", script, "adapter", "--port", str(port), "--io-port", "0", "--quiet",
             "--max-tcp-connections", "1000", "--state", str(tmp_path / "state.json"),
             "--control", str(tmp_path / "control")],
            stderr=err, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    held: list[socket.socket] = []
    closed = 0
    try:
        assert attacks.wait_for(lambda: _connectable(port), timeout=20), stderr.read_text()
        with Client(port) as good:
            for index in range(300):
                sock = socket.socket()
                sock.bind(("127.0.0.4", 0))
                sock.settimeout(5)
                try:
                    sock.connect(("127.0.0.1", port))
                except ConnectionResetError:  # closed before connect() even returned
                    closed += 1
                    sock.close()
                    continue
                held.append(sock)
                if index % 50 == 0:
                    served(AttackTarget(port, 0), good)
            for sock in held:
                sock.settimeout(0.01)
                try:
                    closed += sock.recv(1) == b""
                except ConnectionResetError:
                    closed += 1
                except TimeoutError:
                    pass
            served(AttackTarget(port, 0), good)
    except Exception as exc:
        raise AssertionError(f"{exc!r}; adapter log: {stderr.read_text()[-3000:]}") from exc
    finally:
        for sock in held:
            sock.close()
        process.terminate()
        process.wait(10)
    log = stderr.read_text()
    assert "Traceback" not in log, log[:3000]
    assert "--max-tcp-connections 1000 lowered to 32: the open-file limit is 96" in log
    assert closed == 300 - 31, (closed, log[-3000:])  # 32 admitted, one of them the well-behaved client
    assert 1 <= sum("refused" in line for line in log.splitlines()) <= 2, log[-3000:]


_SHEDDING_SERVER = """
import asyncio, logging, resource, sys
resource.setrlimit(resource.RLIMIT_NOFILE, (48, 48))
logging.basicConfig(level=logging.INFO, stream=sys.stderr)
from cipstack.eip.io_server import precise_event_loop
from cipstack.eip.target.limits import guarded_listener, quiet_accept_errors

class Hold(asyncio.Protocol):
    held = []
    def connection_made(self, transport):
        self.held.append(transport)

async def main():
    loop = asyncio.get_running_loop()
    quiet_accept_errors(loop)
    server = await loop.create_server(Hold, sock=guarded_listener("127.0.0.1", int(sys.argv[1])))
    print("ready", flush=True)
    await asyncio.sleep(float(sys.argv[2]))
    print(len(Hold.held), flush=True)
    sys.stdin.read()  # hold them until told (blocking: nothing more to serve)

loop = precise_event_loop()
loop.run_until_complete(main())
"""


def test_listener_sheds_connections_when_out_of_descriptors(tmp_path: Path) -> None:
    """accept() out of descriptors (EMFILE): each waiting connection is closed at once, one log
    line per 10 s, no traceback, no retry storm (asyncio alone logs a traceback per failure)."""
    port = free_port()
    process = subprocess.Popen([sys.executable, "-c", _SHEDDING_SERVER, str(port), "3"], stdin=subprocess.PIPE,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT,
                               env={**os.environ, "PYTHONPATH": str(ROOT)}, text=True)
    held: list[socket.socket] = []
    closed = 0
    try:
        assert process.stdout is not None and process.stdout.readline().strip() == "ready"
        for _ in range(200):
            sock = socket.socket()
            sock.settimeout(5)
            try:
                sock.connect(("127.0.0.1", port))
            except ConnectionResetError:  # shed before connect() even returned
                closed += 1
                sock.close()
                continue
            held.append(sock)
        held_by_server = int(process.stdout.readline())  # after 3 s, the server still holding its own
        for sock in held:
            sock.settimeout(0.01)
            try:
                closed += sock.recv(1) == b""
            except ConnectionResetError:
                closed += 1
            except TimeoutError:
                pass
        _, err = process.communicate("", timeout=20)
    finally:
        for sock in held:
            sock.close()
        if process.poll() is None:
            process.kill()
            process.wait()
    assert held_by_server + closed == 200, (held_by_server, closed, err[-2000:])
    assert held_by_server < 48 and closed > 150
    assert "Traceback" not in err and "out of system resource" not in err, err[-2000:]
    assert len([line for line in err.splitlines() if "accept()" in line]) == 1, err[-2000:]


def _connectable(port: int) -> bool:
    try:
        socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
        return True
    except OSError:
        return False


# -- 3. delayed ListIdentity replies -----------------------------------------------------------------
def test_delayed_replies_are_bounded_in_total_and_per_source() -> None:
    replies = DelayedReplies(total=6, per_host=2)
    pushed = [replies.push(b"r%d" % i, (f"10.0.0.{i % 5}", 44818), at=float(i)) for i in range(20)]
    assert pushed.count(True) == 6 and len(replies) == 6
    assert not replies.push(b"x", ("10.0.0.9", 1), 0.0)  # total reached, whoever asks
    assert replies.next_deadline() == 0.0
    assert replies.due(2.5) == [(b"r0", ("10.0.0.0", 44818)), (b"r1", ("10.0.0.1", 44818)),
                                (b"r2", ("10.0.0.2", 44818))]
    assert replies.push(b"y", ("10.0.0.0", 1), 9.0)  # its source has room again
    assert len(replies.due(100.0)) == 4 and len(replies) == 0 and replies.next_deadline() is None


def test_list_identity_flood_keeps_a_bounded_queue_and_counts_the_drops() -> None:
    from cipstack.devices.profiles import build_device

    device = build_device()
    target = EncapsulationTarget(device.router, device.identity_record, TargetSettings(rng=random.Random(3)))
    request = struct.pack("<HHII8sI", 0x63, 0, 0, 0, b"\xff\xff" + bytes(6), 0)
    from cipstack.eip.wire.cpf import SockAddr

    local = SockAddr("127.0.0.1", 44818)
    for index in range(20_000):
        assert target.datagram_from(request, (f"10.0.{index % 256}.{index % 7}", 2000), local, 0.0) is None
    assert len(target.delayed) == 64  # TargetSettings.max_delayed_replies
    assert target.stats.replies_dropped == 20_000 - 64
    sent = target.delayed.due(2.0)  # every reply within LIST_IDENTITY_MAX_DELAY
    assert len(sent) == 64 and len(target.delayed) == 0


# -- 2. wrong-size class 1 datagrams (sans-I/O, exact bytes) ------------------------------------------
def _io_rig() -> tuple[Any, int, Callable[[bytes, float], None]]:
    from cipstack.cip.router import RequestContext
    from cipstack.devices.profiles import build_device
    from cipstack.eip.target.io_target import IoTarget
    from cipstack.eip.wire.cm_messages import ForwardOpenRequest

    device = build_device()
    io = IoTarget(device.io_profile(), device)
    raw = attacks.class1_open(0x0E01)[6:]  # Forward_Open data after the request header
    context = RequestContext(device.router, 0.0, "127.0.0.1:5000", None)
    reply = io.forward_open(ForwardOpenRequest.decode(raw, large=False), context)
    return io, reply.ot_connection_id, lambda datagram, now: io.receive(datagram, ("127.0.0.1", 2222), now)


def test_wrong_size_datagrams_do_not_feed_the_watchdog() -> None:
    io, ot_id, receive = _io_rig()
    receive(attacks.io_datagram(ot_id, 1, b"\x01\x00\x00\x00" + bytes(4)), 0.0)  # accepted: 40 ms timeout
    for step in range(1, 100):
        receive(attacks.io_datagram(ot_id, 1 + step, b"\x01\x00\x00\x00" + bytes(5)), step * 0.01)
    assert io.dropped == 99
    assert [c.ot_connection_id for c in io.expire(0.041)] == [ot_id]


def test_wrong_size_datagram_does_not_move_the_sequence_window() -> None:
    io, ot_id, receive = _io_rig()
    connection = io.connections[ot_id]
    receive(attacks.io_datagram(ot_id, 1, b"\x01\x00\x00\x00" + bytes(4)), 0.0)
    receive(attacks.io_datagram(ot_id, 0x80000000, b"\x01\x00\x00\x00" + bytes(5)), 0.001)
    receive(attacks.io_datagram(ot_id, 2, b"\x01\x00\x00\x00" + bytes(4)), 0.002)
    assert connection.consumer.last_encap_sequence == 2 and connection.stats.stale == 0
    assert connection.consumer.deadline == pytest.approx(0.042)


def test_heartbeat_datagram_must_have_the_size_it_was_opened_with() -> None:
    from cipstack.cip.router import RequestContext
    from cipstack.devices.profiles import build_device
    from cipstack.eip.target.io_target import IoTarget
    from cipstack.eip.wire.cm_messages import ForwardOpenRequest

    device = build_device()
    io = IoTarget(device.io_profile(), device)
    raw = attacks.class1_open(0x0E02, path=attacks.ACG_INPUT_ONLY_PATH, ot_size=6)[6:]
    context = RequestContext(device.router, 0.0, "127.0.0.1:1", None)
    reply = io.forward_open(ForwardOpenRequest.decode(raw, large=False), context)
    connection = io.connections[reply.ot_connection_id]
    io.receive(attacks.io_datagram(reply.ot_connection_id, 1, b""), ("127.0.0.1", 2222), 0.0)
    assert connection.stats.received == 0 and io.dropped == 1
    io.receive(attacks.io_datagram(reply.ot_connection_id, 2, b"\x01\x00\x00\x00"), ("127.0.0.1", 2222), 0.0)
    assert connection.stats.received == 1 and connection.run is True


# -- 4. Forward_Close from another address (sans-I/O) -------------------------------------------------
def test_class3_connection_is_named_by_triad_and_originator_address() -> None:
    from cipstack.eip.target.connection_manager import ConnectionTable, ExplicitConnection

    table = ConnectionTable()
    triad = ConnectionTriad(1, 0x1234, 0xC0FFEE)
    table.connections[5] = ExplicitConnection(5, 6, triad, 1.0, None, 10.0, host="10.0.0.1")
    assert table.by_triad(triad, "10.0.0.1") is table.connections[5]
    assert table.by_triad(triad, "10.0.0.2") is None


# -- 5. limits per transport class ---------------------------------------------------------------------
def test_adapter_help_names_every_limit_and_its_default() -> None:
    from cipstack.cli import build_parser
    from cipstack.cli.parser import subcommands

    adapter = subcommands(build_parser())["adapter"]
    text = adapter.format_help()
    for option, words in (("--max-connections", "class 3"), ("--max-io-connections", "class 1"),
                          ("--max-tcp-connections", "default 256"), ("--max-sessions-per-host", "half"),
                          ("--max-tcp-connections-per-host", "half")):
        assert option in text and words in " ".join(text.split()), option


@pytest.mark.parametrize("argv", [["--max-tcp-connections", "0"], ["--max-sessions-per-host", "0"],
                                  ["--max-io-connections", "-1"]])
def test_adapter_refuses_a_limit_below_its_minimum(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    from cipstack.cli import main

    assert main(["adapter", "--port", "0", *argv]) == 2
    err = capsys.readouterr().err
    assert argv[0] in err and len(err.strip().splitlines()) == 1


# -- 10. rules pinned exactly ----------------------------------------------------------------------------
def _open_status(raw: bytes) -> tuple[int, tuple[int, ...]]:
    """(general, extended words) of a class 1 Forward_Open (request bytes) to a fresh ACG-ET2."""
    from cipstack.cip.router import RequestContext
    from cipstack.cip.status import CipError
    from cipstack.devices.profiles import build_device
    from cipstack.eip.target.io_target import IoTarget
    from cipstack.eip.wire.cm_messages import ForwardOpenRequest

    device = build_device()
    io = IoTarget(device.io_profile(), device)
    try:
        io.forward_open(ForwardOpenRequest.decode(raw[6:], large=False),
                        RequestContext(device.router, 0.0, "127.0.0.1:1", None))
    except CipError as exc:
        return exc.general, tuple(exc.extended)
    return 0, ()


# Output assembly 21 holds 4 bytes: a fixed O->T size is exactly 4 + 6 = 10, whichever side it misses.
@pytest.mark.parametrize(("ot_params", "expected"), [
    (0x4000 | 10, (0, ())),
    (0x4000 | 11, (0x01, (0x0127, 10))),  # larger than the assembly: refused, with the right size
    (0x4000 | 64, (0x01, (0x0127, 10))),
    (0x4000 | 9, (0x01, (0x0127, 10))),
    (0x4200 | 11, (0, ())),  # variable size: a larger maximum is fine
    (0x4200 | 9, (0x01, (0x0127, 10))),
])
def test_fixed_ot_size_must_equal_the_assembly(ot_params: int, expected: tuple[int, tuple[int, ...]]) -> None:
    raw = attacks.forward_open(1, transport=0x01, ot_params=ot_params, to_params=0x4000 | 6, rpi_us=10_000,
                               path=attacks.ACG_OWNER_PATH)
    assert _open_status(raw) == expected


@pytest.mark.parametrize(("to_params", "expected"), [
    (0x4000 | 6, (0, ())), (0x4000 | 7, (0x01, (0x0128, 6))), (0x4000 | 5, (0x01, (0x0128, 6)))])
def test_fixed_to_size_must_equal_the_assembly(to_params: int, expected: tuple[int, tuple[int, ...]]) -> None:
    raw = attacks.forward_open(1, transport=0x01, ot_params=0x4000 | 10, to_params=to_params, rpi_us=10_000,
                               path=attacks.ACG_OWNER_PATH)
    assert _open_status(raw) == expected


def _routed(message: bytes) -> bytes:
    """Unconnected_Send to the Connection Manager 6/1 with an empty route path (the device itself)."""
    pad = b"\x00" if len(message) % 2 else b""
    return bytes((0x52, 2, 0x20, 0x06, 0x24, 0x01)) + struct.pack("<BBH", 0x0A, 0x0E, len(message)) + message + pad + (
        b"\x00\x00")


def _packet(message: bytes) -> bytes:
    """Multiple_Service_Packet to the Message Router 2/1 holding one request."""
    return bytes((0x0A, 2, 0x20, 0x02, 0x24, 0x01)) + struct.pack("<HH", 1, 4) + message


def _serve(raw: bytes) -> bytes:
    from cipstack.cip.router import RequestContext
    from cipstack.devices.profiles import build_device

    device = build_device()
    return device.router.handle(raw, RequestContext(device.router, 0.0, "127.0.0.1:1", None))


@pytest.mark.parametrize("depth", [1, 4])
def test_requests_nested_four_deep_are_served(depth: int) -> None:
    routed, packed = attacks.GET_NAME, attacks.GET_NAME
    for _ in range(depth):
        routed, packed = _routed(routed), _packet(packed)
    assert _serve(routed) == bytes.fromhex("8e000000") + attacks.IDENTITY_NAME
    ok = bytes.fromhex("8a000000" "01000400")
    assert _serve(packed) == ok * depth + bytes.fromhex("8e000000") + attacks.IDENTITY_NAME


def test_a_fifth_level_is_resource_unavailable() -> None:
    """The request nested five deep is answered 0x02 (resource unavailable); the enclosing
    Unconnected_Sends pass its reply up, the enclosing packets report 0x1E (embedded service error)."""
    routed, packed = attacks.GET_NAME, attacks.GET_NAME
    for _ in range(5):
        routed, packed = _routed(routed), _packet(packed)
    assert _serve(routed) == bytes.fromhex("8e000200")
    assert _serve(packed) == bytes.fromhex("8a001e00" "01000400") * 5 + bytes.fromhex("8e000200")
