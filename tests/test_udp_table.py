"""``cipstack.eip.udp_table``: the kernel's answer (sock_diag) for the UDP sockets bound to exactly one
address and port, checked against real sockets and the kernel's other account of them, /proc/net/udp."""

from __future__ import annotations

import contextlib
import os
import socket
import struct
import sys
from collections.abc import Iterator

import pytest

from cipstack.eip.udp_table import udp_inodes_bound_to
from tests.ports import free_port

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="sock_diag and /proc/net/udp are Linux's")


@contextlib.contextmanager
def bound(*addresses: tuple[str, int]) -> Iterator[list[socket.socket]]:
    """UDP sockets with SO_REUSEADDR, each bound to its address (two may share one, as Linux allows)."""
    sockets = []
    try:
        for address in addresses:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            sockets.append(sock)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind(address)
        yield sockets
    finally:
        for sock in sockets:
            sock.close()


def inode(sock: socket.socket) -> int:
    return os.fstat(sock.fileno()).st_ino


def proc_inodes(host: str, port: int) -> set[int]:
    wanted = f"{struct.unpack('=I', socket.inet_aton(host))[0]:08X}:{port:04X}"
    with open("/proc/net/udp", encoding="ascii") as table:
        rows = [line.split() for line in list(table)[1:]]
    return {int(row[9]) for row in rows if row[1] == wanted}


def test_only_the_sockets_on_exactly_that_address_and_port() -> None:
    port = free_port()
    with bound(("127.97.0.5", port), ("127.97.0.5", port), ("127.97.0.6", port), ("0.0.0.0", port)) as sockets:
        same, also, neighbour, wildcard = sockets
        found = udp_inodes_bound_to("127.97.0.5", port)
        assert found == {inode(same), inode(also)} == proc_inodes("127.97.0.5", port)
        assert udp_inodes_bound_to("127.97.0.6", port) == {inode(neighbour)}
        assert udp_inodes_bound_to("0.0.0.0", port) == {inode(wildcard)}
        assert udp_inodes_bound_to("127.97.0.7", port) == set()
    assert udp_inodes_bound_to("127.97.0.5", port) == set()


def test_many_sockets_answer_in_more_than_one_datagram() -> None:
    """Hundreds of sockets on one address and port: the kernel's answer runs over several netlink
    datagrams, and every socket is in it once."""
    port = free_port()
    with bound(*[("127.97.1.9", port)] * 300) as sockets:
        assert udp_inodes_bound_to("127.97.1.9", port) == {inode(s) for s in sockets}
