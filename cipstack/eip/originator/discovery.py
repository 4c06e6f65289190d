"""Discovery over UDP: ListIdentity and ListServices sent to one address, several, or every
interface's broadcast address, and the replies collected, bounded and told apart."""

from __future__ import annotations

import asyncio
import logging
import socket
import struct
from collections.abc import Sequence

from ..interfaces import LIMITED_BROADCAST, directed_broadcasts
from ..wire.encapsulation import DEFAULT_PORT, HEADER, HEADER_SIZE, Command, EncapsulationError, EncapsulationHeader
from ..wire.identity_items import IdentityRecord, ServiceRecord, decode_list_identity, decode_list_services

log = logging.getLogger(__name__)

#: The sender context's first UINT: the longest reply delay a ListIdentity asks for, in ms.
_SEQ = struct.Struct("<H")


class _DiscoveryProtocol(asyncio.DatagramProtocol):
    def __init__(self) -> None:
        self.replies: list[tuple[bytes, tuple[str, int]]] = []

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if len(self.replies) < MAX_DISCOVERY_REPLIES:
            self.replies.append((data, addr))

    def error_received(self, exc: Exception) -> None:
        log.debug("discovery: %s", exc)


#: Replies kept from one query: far more devices than one subnet holds; the rest are dropped.
MAX_DISCOVERY_REPLIES = 4096


def broadcast_addresses() -> list[str]:
    """Where a broadcast with no address given goes: 255.255.255.255 and the directed broadcast
    address of every IPv4 interface, loopback included (127.255.255.255), so that devices on
    every attached subnet hear it. Linux reads the interfaces; elsewhere the limited broadcast alone."""
    return [LIMITED_BROADCAST, *(address for address in directed_broadcasts() if address != LIMITED_BROADCAST)]


async def udp_query(command: int, address: str | Sequence[str] | None = None, port: int = DEFAULT_PORT,
                    timeout: float = 2.0, max_delay_ms: int | None = None) -> list[tuple[bytes, tuple[str, int]]]:
    """Send a ListIdentity/ListServices datagram and collect the reply bodies for ``timeout`` seconds.

    ``address``: one address (broadcast or unicast), several, or None for every interface's
    broadcast address (see ``broadcast_addresses``)."""
    addresses = [address] if isinstance(address, str) else list(address) if address is not None else []
    addresses = addresses or broadcast_addresses()
    loop = asyncio.get_running_loop()
    transport, protocol = await loop.create_datagram_endpoint(_DiscoveryProtocol, family=socket.AF_INET,
                                                              allow_broadcast=True)
    try:
        delay = max_delay_ms if max_delay_ms is not None else max(500, min(int(timeout * 1000) - 100, 0xFFFF))
        context = _SEQ.pack(delay) + bytes(6)
        for destination in addresses:
            try:
                transport.sendto(HEADER.pack(command, 0, 0, 0, context, 0), (destination, port))
            except OSError as exc:  # an interface without a route: the others still count
                log.debug("discovery: cannot send to %s:%d: %s", destination, port, exc)
        await asyncio.sleep(timeout)
    finally:
        transport.close()
    bodies = []
    for data, addr in protocol.replies:
        if len(data) >= HEADER_SIZE:
            header = EncapsulationHeader.decode(data)
            if header.command == command and header.status == 0 and header.length == len(data) - HEADER_SIZE:
                bodies.append((data[HEADER_SIZE:], addr))
                continue
        log.debug("discovery: reply from %s:%d ignored: %s", addr[0], addr[1], data[:64].hex())
    return bodies


async def discover(address: str | Sequence[str] | None = None, port: int = DEFAULT_PORT,
                   timeout: float = 2.0) -> list[IdentityRecord]:
    """ListIdentity over UDP: every device that answers within ``timeout`` seconds, once each.

    ``address`` None: the broadcast address of every interface (loopback included). A device
    that answers twice (two broadcasts reached it, or it repeated its reply) is listed once:
    replies are told apart by the address they came from and the serial number."""
    records: list[IdentityRecord] = []
    seen: set[tuple[str, int]] = set()
    for body, addr in await udp_query(Command.LIST_IDENTITY, address, port, timeout):
        try:
            found = decode_list_identity(body)
        except (ValueError, struct.error, EncapsulationError) as exc:
            log.debug("discovery: malformed ListIdentity reply from %s ignored: %s", addr[0], exc)
            continue
        for record in found:
            key = (addr[0], record.serial_number)
            if key not in seen:
                seen.add(key)
                records.append(record)
    return records


async def list_services_udp(address: str, port: int = DEFAULT_PORT, timeout: float = 1.0) -> list[ServiceRecord]:
    """ListServices over UDP: what the device at ``address`` says it carries (CIP over TCP, class 0/1
    over UDP), each reply that arrives within ``timeout`` seconds."""
    records: list[ServiceRecord] = []
    for body, addr in await udp_query(Command.LIST_SERVICES, address, port, timeout):
        try:
            records.extend(decode_list_services(body))
        except (ValueError, struct.error, EncapsulationError) as exc:
            log.debug("malformed ListServices reply from %s ignored: %s", addr[0], exc)
    return records


__all__ = ["LIMITED_BROADCAST", "broadcast_addresses", "discover", "list_services_udp", "udp_query"]
