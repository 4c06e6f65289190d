"""Encapsulation TCP served on the precise loop's lane (``cipstack.eip.target.tcp_lane``): the same rules as
asyncio's transport path (admission, back-pressure, closing), checked on real loopback sockets.

The tests run on the precise loop (the one the command line runs); the clients are plain
non-blocking sockets driven with the loop's ``sock_*`` calls, so the test controls exactly when
they read."""

from __future__ import annotations

import asyncio
import itertools
import socket
import struct
import threading
import time
from collections.abc import AsyncIterator

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.devices.profiles import identity_only_device
from cipstack.eip.io_server import PreciseEventLoop
from cipstack.eip.target.tcp_lane import LaneTcpConnection

HEADER = struct.Struct("<HHII8sI")
REGISTER_SESSION, SEND_RR_DATA, LIST_SERVICES = 0x0065, 0x006F, 0x0004
#: Get_Attribute_Single 1/1/7 in the common two-item SendRRData.
GET_NAME = bytes((0x0E, 0x03, 0x20, 0x01, 0x24, 0x01, 0x30, 0x07))
RR_BODY = struct.pack("<IHHHHHH", 0, 0, 2, 0, 0, 0xB2, len(GET_NAME)) + GET_NAME


def frame(command: int, data: bytes = b"", session: int = 0, context: bytes = b"\0" * 8) -> bytes:
    return HEADER.pack(command, len(data), session, 0, context, 0) + data


async def connect(port: int) -> socket.socket:
    loop = asyncio.get_running_loop()
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setblocking(False)
    await loop.sock_connect(sock, ("127.0.0.1", port))
    return sock


async def read_frame(sock: socket.socket, buffer: bytearray) -> tuple[int, int, int, bytes, bytes]:
    """(command, session, status, sender context, data) of the next frame."""
    loop = asyncio.get_running_loop()
    while True:
        if len(buffer) >= HEADER.size:
            command, length, session, status, context, _options = HEADER.unpack_from(buffer)
            if len(buffer) >= HEADER.size + length:
                data = bytes(buffer[HEADER.size:HEADER.size + length])
                del buffer[:HEADER.size + length]
                return command, session, status, context, data
        chunk = await asyncio.wait_for(loop.sock_recv(sock, 65536), 5)
        if not chunk:
            raise ConnectionError("closed by the adapter")
        buffer += chunk


async def register(sock: socket.socket, buffer: bytearray) -> int:
    await asyncio.get_running_loop().sock_sendall(sock, frame(REGISTER_SESSION, b"\x01\x00\x00\x00"))
    _command, session, status, _context, _data = await read_frame(sock, buffer)
    assert status == 0 and session
    return session


async def until(condition: object, timeout: float = 5.0) -> None:
    deadline = asyncio.get_running_loop().time() + timeout
    while not condition():  # type: ignore[operator]
        assert asyncio.get_running_loop().time() < deadline, "condition not met in time"
        await asyncio.sleep(0.01)


@pytest.fixture
async def adapter() -> AsyncIterator[Adapter]:
    assert isinstance(asyncio.get_running_loop(), PreciseEventLoop)
    async with Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0, max_tcp_connections=4,
                                       max_tcp_connections_per_host=4),
                       device=identity_only_device()) as running:
        yield running


async def test_connections_are_served_on_the_lane_and_leave_it_when_closed(adapter: Adapter) -> None:
    loop = asyncio.get_running_loop()
    lane = loop.selector.lane  # type: ignore[attr-defined]
    sock = await connect(adapter.port)
    buffer = bytearray()
    session = await register(sock, buffer)
    [served] = adapter.server.connections
    assert isinstance(served, LaneTcpConnection)
    assert served.sock.fileno() in lane.readers
    await loop.sock_sendall(sock, frame(SEND_RR_DATA, RR_BODY, session, b"name\0\0\0\0"))
    command, reply_session, status, context, data = await read_frame(sock, buffer)
    # Interface 0, timeout 0, two items: Null Address, Unconnected Data with the reply 8E 00 00 00 04 "CENT".
    assert (command, reply_session, status, context) == (SEND_RR_DATA, session, 0, b"name\0\0\0\0")
    assert data == struct.pack("<IHHHHHH", 0, 0, 2, 0, 0, 0xB2, 9) + b"\x8e\x00\x00\x00\x04CENT"
    fd = served.sock.fileno()
    sock.close()
    await until(lambda: not adapter.server.connections)
    assert fd not in lane.readers
    assert adapter.server.limiter.open == 0
    assert not adapter.target.sessions


async def test_a_client_that_does_not_read_stops_the_reading_and_loses_no_reply(adapter: Adapter) -> None:
    """Pipelined requests, replies unread: once a reply cannot be sent the adapter reads nothing more
    from that client (what it holds stays one read's replies); when the client reads, every request
    is answered, in order."""
    loop = asyncio.get_running_loop()
    sock = await connect(adapter.port)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    await until(lambda: adapter.server.connections)
    [served] = adapter.server.connections
    assert isinstance(served, LaneTcpConnection)
    served.sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 4096)  # full after a few replies
    buffer = bytearray()
    contexts = (struct.pack("<Q", n) for n in itertools.count())
    sent: list[bytes] = []
    stats = adapter.target.stats

    def read_or_held() -> bool:
        return stats.frames >= len(sent) or served.write_buffer_size() > 0

    while not served.write_buffer_size():
        batch = [next(contexts) for _ in range(200)]
        sent += batch
        await asyncio.wait_for(loop.sock_sendall(sock, b"".join(frame(LIST_SERVICES, context=c) for c in batch)), 5)
        # The adapter reads each batch before the next is sent: a send the kernel takes whole does not
        # suspend, and from Python 3.12 ``wait_for`` runs it without a task of its own, so nothing else
        # would give the loop its turn (the batches would fill the socket buffers unread).
        await until(read_or_held)
    held, frames = served.write_buffer_size(), stats.frames
    assert held < 65536 * 4  # the replies to one read of requests at most
    # More requests: the kernel takes them, the adapter does not read them.
    extra = [next(contexts) for _ in range(200)]
    sent += extra
    await asyncio.wait_for(loop.sock_sendall(sock, b"".join(frame(LIST_SERVICES, context=c) for c in extra)), 5)
    await asyncio.sleep(0.1)           # the subject: the adapter reads none of them meanwhile
    assert (served.write_buffer_size(), stats.frames) == (held, frames)
    replies = [(await read_frame(sock, buffer))[3] for _ in sent]
    assert replies == sent
    assert stats.frames >= len(sent)
    sock.close()


async def test_a_connection_over_the_limit_is_reset_and_the_others_serve_on(adapter: Adapter) -> None:
    loop = asyncio.get_running_loop()
    kept = [await connect(adapter.port) for _ in range(4)]
    await until(lambda: len(adapter.server.connections) == 4)
    with pytest.raises(ConnectionError):  # reset at once: in the connect, or in the first read
        refused = await connect(adapter.port)
        try:
            if not await asyncio.wait_for(loop.sock_recv(refused, 100), 5):
                raise ConnectionError("closed")
        finally:
            refused.close()
    assert adapter.server.limiter.refused == 1 and adapter.server.limiter.open == 4
    buffer = bytearray()
    assert await register(kept[0], buffer)
    for sock in kept:
        sock.close()
    await until(lambda: adapter.server.limiter.open == 0)


async def test_closing_the_server_closes_its_lane_connections() -> None:
    lane = asyncio.get_running_loop().selector.lane  # type: ignore[attr-defined]
    before = set(lane.readers)
    adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0), device=identity_only_device())
    await adapter.start()
    try:
        socks = [await connect(adapter.port) for _ in range(3)]
        await until(lambda: len(adapter.server.connections) == 3)
    finally:
        await adapter.close()
    assert not adapter.server.connections
    assert set(lane.readers) == before
    loop = asyncio.get_running_loop()
    for sock in socks:
        assert await asyncio.wait_for(loop.sock_recv(sock, 100), 5) == b""
        sock.close()


async def test_a_request_that_waits_unread_through_a_stall_of_the_loop_keeps_the_connection(
        adapter: Adapter) -> None:
    """The loop stalls past the connection's inactivity deadline while a request, sent in time, waits
    in the socket: the timer reads it before it judges, so the connection is not closed for a
    silence there was not, and the request is answered."""
    loop = asyncio.get_running_loop()
    adapter.target.settings.inactivity_timeout = lambda: 0.3
    sock = await connect(adapter.port)
    buffer = bytearray()
    session = await register(sock, buffer)  # the connection's timer: 0.3 s after the accept
    sent = threading.Event()

    def send_during_the_stall() -> None:
        time.sleep(0.1)
        sock.sendall(frame(SEND_RR_DATA, RR_BODY, session))
        sent.set()

    sender = threading.Thread(target=send_during_the_stall)
    sender.start()
    loop.call_soon(time.sleep, 0.6)  # the loop stops for 0.6 s: past the 0.3 s deadline
    await asyncio.sleep(0)
    sender.join()
    assert sent.is_set()
    try:
        command, _session, status, _context, data = await read_frame(sock, buffer)
        assert (command, status) == (SEND_RR_DATA, 0)
        assert data[16:20] == b"\x8e\x00\x00\x00"  # Get_Attribute_Single, success
        assert len(adapter.server.connections) == 1
    finally:
        sock.close()
