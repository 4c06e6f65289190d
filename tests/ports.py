"""Ports for the emulators and peers a test starts (free for TCP and UDP alike), and the ListIdentity
probe that asks who answers on one."""

from __future__ import annotations

import asyncio
import collections
import errno
import os
import random
import socket
import struct
from typing import Any

#: The numbers handed out last: a number may come up again, and two calls in a row (an adapter's
#: --port and --io-port) must not get the same one.
_GIVEN: collections.deque[int] = collections.deque(maxlen=256)


def _port_space() -> range:
    """Where ``free_port`` looks: below the kernel's ephemeral ports (``ip_local_port_range``, 32768
    and up by default), so that no socket bound to port 0 and no outgoing connection, of this
    process or of another test's, takes a number handed out and not bound yet. Empty where that
    range leaves no room below it: the kernel's own pick then."""
    try:
        with open("/proc/sys/net/ipv4/ip_local_port_range") as lines:
            ephemeral = int(lines.read().split()[0])
    except (OSError, ValueError, IndexError):
        ephemeral = 32768
    return range(10_000, ephemeral) if ephemeral - 10_000 >= 4_096 else range(0)


def _worker_share(space: range) -> range:
    """This pytest-xdist worker's numbers of ``space`` (every n-th, from its index): two workers never
    hand out the same number (the whole space outside pytest-xdist)."""
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
    index = int(worker[2:]) if worker[2:].isdigit() else 0
    return range(space.start + (index - space.start) % count, space.stop, count) if space else space


_SHARE = _worker_share(_port_space())
_RANDOM = random.Random()  # not the random module's: a test that seeds that one must not fix these


def _offer(host: str) -> int:
    """A number to try on ``host``: one of this worker's share, or the kernel's pick without one."""
    if _SHARE:
        return _RANDOM.choice(_SHARE)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind((host, 0))
        return int(probe.getsockname()[1])


def free_port(*hosts: str) -> int:
    """A port number free for both TCP and UDP on every one of ``hosts`` (default 127.0.0.1): an
    adapter listens on both, and two loopback addresses may each need the same number. Never one of
    the last numbers it gave (they are free only until their caller binds them)."""
    hosts = hosts or ("127.0.0.1",)
    for _ in range(100):
        port = _offer(hosts[0])
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


def refused(port: int) -> bool:
    """Whether a TCP connection to ``port`` on loopback is refused (nothing listens there)."""
    with socket.socket() as probe:
        return probe.connect_ex(("127.0.0.1", port)) == errno.ECONNREFUSED


#: A ListIdentity request (encapsulation command 0x0063, no session, sender context "\xf4\x01...").
LIST_IDENTITY = struct.pack("<HHII8sI", 0x0063, 0, 0, 0, struct.pack("<H", 500) + bytes(6), 0)


async def list_identity_replies(destination: str, port: int, seconds: float = 1.2) -> list[tuple[bytes, str]]:
    """Each reply, with the address it came from, to one ListIdentity sent over UDP to ``destination``
    (a broadcast address too) within ``seconds``."""
    replies: list[tuple[bytes, str]] = []

    class Collect(asyncio.DatagramProtocol):
        def datagram_received(self, data: bytes, addr: tuple[str | Any, int]) -> None:
            replies.append((data, addr[0]))

    # A datagram endpoint, not loop.sock_sendto/sock_recvfrom: those came with Python 3.11.
    transport, _ = await asyncio.get_running_loop().create_datagram_endpoint(
        Collect, local_addr=("127.0.0.1", 0), allow_broadcast=True)
    try:
        transport.sendto(LIST_IDENTITY, (destination, port))
        await asyncio.sleep(seconds)      # the subject: replies of any number of devices, for the window
        return replies
    finally:
        transport.close()
