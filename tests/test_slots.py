"""TCP connection slots cannot be locked (issue 30, item 15).

Two attacker addresses holding their per-host share (half of the slots each) took every slot and
locked every other host out; and any byte reset the inactivity timer, so a peer trickling one byte
a second held a slot forever. Now a new host is let in by closing the idlest connection of the
host that holds the most (only while it holds more than the newcomer would), and a frame, once
begun, has ``--frame-timeout`` to arrive whole. Real sockets from several loopback addresses, on
both server paths: the precise loop's lane (the command line's) and plain asyncio."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import threading
import time
from collections.abc import Callable, Coroutine, Iterator
from typing import Any, TypeVar

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.eip.io_server import precise_event_loop
from cipstack.eip.target.limits import ConnectionLimiter
from tests.attacks import NOP, REGISTER, AttackTarget, Client, frame, served

T = TypeVar("T")

LOOPS: dict[str, Callable[[], asyncio.AbstractEventLoop]] = {
    "lane": precise_event_loop, "asyncio": asyncio.new_event_loop}


class Running:
    """An adapter on a loop of the given kind, in a background thread."""

    def __init__(self, loop: asyncio.AbstractEventLoop, **settings: Any) -> None:
        self.loop = loop
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()
        self.adapter: Adapter = self.run(self._start(settings))

    def _serve(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.run_forever()

    async def _start(self, settings: dict[str, Any]) -> Adapter:
        adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0, **settings))
        await adapter.start()
        return adapter

    def run(self, coroutine: Coroutine[Any, Any, T]) -> T:
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop).result(30)

    def open_connections(self) -> dict[str, int]:
        async def look() -> dict[str, int]:
            return dict(self.adapter.server.limiter.by_host)
        return self.run(look())

    def close(self) -> None:
        self.run(self.adapter.close())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)
        self.loop.close()


@pytest.fixture(params=sorted(LOOPS))
def adapter(request: pytest.FixtureRequest) -> Iterator[Running]:
    running = Running(LOOPS[request.param](), max_tcp_connections=8, frame_timeout=1.0, modbus_port=0)
    yield running
    running.close()


def closed_by_peer(sock: socket.socket, within: float) -> bool:
    """Whether the adapter closes ``sock`` within ``within`` seconds (reading what it sends)."""
    sock.settimeout(within)
    try:
        while sock.recv(4096):
            pass
    except TimeoutError:
        return False
    except OSError:
        return True
    return True


def test_two_addresses_holding_their_share_do_not_lock_a_third_out(adapter: Running) -> None:
    port = adapter.adapter.port
    target = AttackTarget(port, 0)
    held = [Client(port, source) for source in ("127.0.0.2", "127.0.0.3") for _ in range(4)]
    try:
        assert adapter.open_connections() == {"127.0.0.2": 4, "127.0.0.3": 4}      # every slot taken
        time.sleep(0.05)
        served(target, held[7])            # 127.0.0.3's last one is the least idle of its host
        with Client(port, "127.0.0.4") as newcomer:                                  # was refused
            served(target, newcomer)
            assert adapter.open_connections() == {"127.0.0.2": 3, "127.0.0.3": 4, "127.0.0.4": 1}
            assert closed_by_peer(held[0].sock, 2.0)                # 127.0.0.2's idlest made the room
            # The attackers coming back take from each other, never from the host that holds one.
            for attempt in range(10):
                source = "127.0.0.2" if attempt % 2 else "127.0.0.3"
                with contextlib.suppress(OSError, AssertionError):
                    held.append(Client(port, source))
            served(target, newcomer)
            assert adapter.open_connections()["127.0.0.4"] == 1
            with Client(port, "127.0.0.5") as another:               # and one more new host gets in
                served(target, another)
            served(target, newcomer)
    finally:
        for client in held:
            client.close()


def assert_trickle_closed(port: int, request: bytes) -> None:
    """All but the last byte of ``request``, one every 0.2 s: the server closes the connection about
    1 s (the adapter's ``frame_timeout``) after the first byte."""
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        started = time.monotonic()
        closed = False
        for byte in request[:-1]:
            try:
                sock.sendall(bytes([byte]))
            except OSError:
                closed = True
                break
            if closed_by_peer(sock, 0.2):
                closed = True
                break
        took = time.monotonic() - started
    assert closed and 0.9 <= took < 3.0, (closed, took)


def test_a_frame_trickled_a_byte_at_a_time_is_closed_at_the_frame_timeout(adapter: Running) -> None:
    """One byte every 0.2 s of a 28-byte RegisterSession: closed 1 s (``frame_timeout``) after its
    first byte although bytes keep coming (the inactivity timeout, 120 s, was reset by each)."""
    port = adapter.adapter.port
    request = frame(REGISTER, b"\x01\x00\x00\x00")
    assert_trickle_closed(port, request)


def test_complete_frames_keep_a_slow_peer_connected(adapter: Running) -> None:
    """A peer that sends whole frames slowly (a NOP every 0.4 s, then a request) is no trickle: it
    stays connected past the frame timeout and is served."""
    port = adapter.adapter.port
    with Client(port, "127.0.0.6") as client:
        for _ in range(4):
            client.sock.sendall(frame(NOP))
            time.sleep(0.4)            # the subject: slow whole frames, 1.6 s in all, past the 1 s frame timeout
        served(AttackTarget(port, 0), client)


#: Modbus TCP Read Holding Registers of ACC (0x1F01), and its answer (5.0 s).
READ_ACC = bytes.fromhex("0001 0000 0006 01 03 1f01 0001")
ACC = bytes.fromhex("0001 0000 0005 01 03 02 0032")


def modbus_client(port: int, source: str) -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", port), timeout=3, source_address=(source, 0))
    assert modbus_served(sock)
    return sock


def modbus_served(sock: socket.socket) -> bool:
    try:
        sock.sendall(READ_ACC)
        answer = b""
        while len(answer) < len(ACC):
            chunk = sock.recv(len(ACC) - len(answer))
            if not chunk:
                return False
            answer += chunk
    except OSError:
        return False
    return answer == ACC


def test_modbus_slots_are_not_locked_either(adapter: Running) -> None:
    """The Modbus TCP port has the same rules: a third address gets in past two holding every slot,
    and a frame trickled a byte at a time is closed at the frame timeout."""
    assert adapter.adapter.modbus is not None
    port = adapter.adapter.modbus.port
    held = [modbus_client(port, source) for source in ("127.0.0.2", "127.0.0.3") for _ in range(4)]
    try:
        newcomer = modbus_client(port, "127.0.0.4")                  # was closed at accept
        assert modbus_served(newcomer) and sum(modbus_served(sock) for sock in held) == 7
        newcomer.close()
    finally:
        for sock in held:
            sock.close()
    assert_trickle_closed(port, READ_ACC)


def test_the_limiter_names_the_host_to_make_room() -> None:
    limiter = ConnectionLimiter(4)
    for host in ("a", "a", "b", "b"):
        assert limiter.admit(host)
    assert limiter.victim("c") in ("a", "b")       # a newcomer: the biggest holder gives one up
    assert limiter.victim("a") is None             # at its per-host share: refused as before
    limiter.release("a")
    assert limiter.victim("c") is None             # a free slot: nothing to close
    assert limiter.admit("c")                      # a 1, b 2, c 1: full again
    assert limiter.victim("d") == "b"              # a newcomer takes from the one holding 2
    assert limiter.victim("a") is None             # b holding 2 against a's 1 + 1 gains nothing
