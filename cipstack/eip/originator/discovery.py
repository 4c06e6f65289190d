"""Discovery over UDP, asyncio: ListIdentity and ListServices sent to one address, several, or every
interface's broadcast address, and the replies collected, bounded and told apart. A thin shell over
``discovery_core.UdpQuery``, which the blocking form (``blocking_discovery``) runs too."""

from __future__ import annotations

import asyncio
import logging
import socket
from collections.abc import Sequence

from ..wire.encapsulation import DEFAULT_PORT, Command
from ..wire.identity_items import IdentityRecord, ServiceRecord
from .discovery_core import (
    LIMITED_BROADCAST,
    MAX_DISCOVERY_REPLIES,
    UdpQuery,
    broadcast_addresses,
    identities,
    services,
)

log = logging.getLogger(__name__)


class _DiscoveryProtocol(asyncio.DatagramProtocol):
    def __init__(self, query: UdpQuery) -> None:
        self.query = query

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        self.query.receive(data, addr)

    def error_received(self, exc: Exception) -> None:
        log.debug("discovery: %s", exc)


async def udp_query(command: int, address: str | Sequence[str] | None = None, port: int = DEFAULT_PORT,
                    timeout: float = 2.0, max_delay_ms: int | None = None) -> list[tuple[bytes, tuple[str, int]]]:
    """Send a ListIdentity/ListServices datagram and collect the reply bodies for ``timeout`` seconds.

    ``address``: one address (broadcast or unicast), several, or None for every interface's
    broadcast address (see ``broadcast_addresses``)."""
    loop = asyncio.get_running_loop()
    query = UdpQuery(command, address, port, timeout, loop.time(), max_delay_ms)
    transport, _ = await loop.create_datagram_endpoint(lambda: _DiscoveryProtocol(query), family=socket.AF_INET,
                                                       allow_broadcast=True)
    try:
        for datagram, destination in query.datagrams():
            try:
                transport.sendto(datagram, destination)
            except OSError as exc:  # an interface without a route: the others still count
                log.debug("discovery: cannot send to %s:%d: %s", destination[0], destination[1], exc)
        await asyncio.sleep(max(0.0, query.deadline - loop.time()))
    finally:
        transport.close()
    return query.bodies()


async def discover(address: str | Sequence[str] | None = None, port: int = DEFAULT_PORT,
                   timeout: float = 2.0) -> list[IdentityRecord]:
    """ListIdentity over UDP: every device that answers within ``timeout`` seconds, once each.

    ``address`` None: the broadcast address of every interface (loopback included). A device
    that answers twice (two broadcasts reached it, or it repeated its reply) is listed once:
    replies are told apart by the address they came from and the serial number."""
    return identities(await udp_query(Command.LIST_IDENTITY, address, port, timeout))


async def list_services_udp(address: str, port: int = DEFAULT_PORT, timeout: float = 1.0) -> list[ServiceRecord]:
    """ListServices over UDP: what the device at ``address`` says it carries (CIP over TCP, class 0/1
    over UDP), each reply that arrives within ``timeout`` seconds."""
    return services(await udp_query(Command.LIST_SERVICES, address, port, timeout))


__all__ = ["LIMITED_BROADCAST", "MAX_DISCOVERY_REPLIES", "broadcast_addresses", "discover", "list_services_udp",
           "udp_query"]
