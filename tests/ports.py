"""Ports for the emulators and peers a test starts (chosen by the OS, free for TCP and UDP alike), and
the ListIdentity probe that asks who answers on one."""

from __future__ import annotations

import asyncio
import collections
import socket
import struct

#: The numbers handed out last: the OS may pick a number it has just picked again, and two calls in
#: a row (an adapter's --port and --io-port) must not get the same one.
_GIVEN: collections.deque[int] = collections.deque(maxlen=256)


def free_port(*hosts: str) -> int:
    """A port number free for both TCP and UDP on every one of ``hosts`` (default 127.0.0.1): an
    adapter listens on both, and two loopback addresses may each need the same number. Never one of
    the last numbers it gave (they are free only until their caller binds them)."""
    hosts = hosts or ("127.0.0.1",)
    for _ in range(100):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.bind((hosts[0], 0))
            port = int(probe.getsockname()[1])
        if port in _GIVEN:
            continue
        sockets: list[socket.socket] = []
        try:
            for host in hosts:
                for kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM):
                    sockets.append(socket.socket(socket.AF_INET, kind))
                    sockets[-1].bind((host, port))
        except OSError:
            continue
        finally:
            for sock in sockets:
                sock.close()
        _GIVEN.append(port)
        return port
    raise RuntimeError(f"no port free for TCP and UDP on {', '.join(hosts)}")


#: A ListIdentity request (encapsulation command 0x0063, no session, sender context "\xf4\x01...").
LIST_IDENTITY = struct.pack("<HHII8sI", 0x0063, 0, 0, 0, struct.pack("<H", 500) + bytes(6), 0)


async def list_identity_replies(destination: str, port: int, seconds: float = 1.2) -> list[tuple[bytes, str]]:
    """Each reply, with the address it came from, to one ListIdentity sent over UDP to ``destination``
    (a broadcast address too) within ``seconds``."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
    sock.bind(("127.0.0.1", 0))
    sock.setblocking(False)
    loop = asyncio.get_running_loop()
    try:
        await loop.sock_sendto(sock, LIST_IDENTITY, (destination, port))
        replies = []
        deadline = loop.time() + seconds
        while (left := deadline - loop.time()) > 0:
            try:
                data, (host, _) = await asyncio.wait_for(loop.sock_recvfrom(sock, 2048), left)
            except asyncio.TimeoutError:
                break
            replies.append((data, host))
        return replies
    finally:
        sock.close()
