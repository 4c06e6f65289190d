"""Discovery over UDP for blocking code: ``discovery_core.UdpQuery`` on a plain UDP socket and
``select``, with no event loop (what ``discover_blocking`` and ``SyncScanner.discover`` run)."""

from __future__ import annotations

import select
import socket
import time
from collections.abc import Sequence

from ...logs import debug
from ..wire.encapsulation import DEFAULT_PORT, Command
from ..wire.identity_items import IdentityRecord, ServiceRecord
from .discovery_core import UdpQuery, identities, services

#: The largest UDP payload.
MAX_DATAGRAM = 65535


def udp_query_blocking(command: int, address: str | Sequence[str] | None = None, port: int = DEFAULT_PORT,
                       timeout: float = 2.0, max_delay_ms: int | None = None) -> list[tuple[bytes, tuple[str, int]]]:
    """``discovery.udp_query`` without asyncio: the reply bodies that arrive within ``timeout`` seconds."""
    clock = time.monotonic
    query = UdpQuery(command, address, port, timeout, clock(), max_delay_ms)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        sock.setblocking(False)
        for datagram, destination in query.datagrams():
            try:
                sock.sendto(datagram, destination)
            except OSError as exc:  # an interface without a route: the others still count
                debug(__name__, "discovery: cannot send to %s:%d: %s", destination[0], destination[1], exc)
        while (left := query.deadline - clock()) > 0:
            if not select.select([sock], [], [], left)[0]:
                continue
            while True:
                try:
                    data, source = sock.recvfrom(MAX_DATAGRAM)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError as exc:   # an ICMP error reported on the socket
                    debug(__name__, "discovery: %s", exc)
                    break
                query.receive(data, source)
    return query.bodies()


def discover_blocking(address: str | Sequence[str] | None = None, port: int = DEFAULT_PORT,
                      timeout: float = 2.0) -> list[IdentityRecord]:
    """``discovery.discover`` without asyncio: every device that answers ListIdentity within ``timeout``."""
    return identities(udp_query_blocking(Command.LIST_IDENTITY, address, port, timeout))


def list_services_blocking(address: str, port: int = DEFAULT_PORT, timeout: float = 1.0) -> list[ServiceRecord]:
    """``discovery.list_services_udp`` without asyncio."""
    return services(udp_query_blocking(Command.LIST_SERVICES, address, port, timeout))


__all__ = ["discover_blocking", "list_services_blocking", "udp_query_blocking"]
