"""Discovery without I/O: a ListIdentity or ListServices query over UDP as datagrams to send, replies
received (bounded) and told apart, and the moment the query ends.

``UdpQuery`` is the one query both shells run: the asyncio ``discovery.udp_query`` (a datagram
endpoint and a sleep) and the blocking ``blocking_discovery.udp_query_blocking`` (a plain UDP socket
and ``select``). It never touches a socket or a clock: the shells give it the time it starts.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from ...logs import debug
from ..interfaces import LIMITED_BROADCAST, directed_broadcasts
from ..wire.encapsulation import HEADER, HEADER_SIZE, Command, EncapsulationError, EncapsulationHeader
from ..wire.identity_items import IdentityRecord, ServiceRecord, decode_list_identity, decode_list_services

#: The sender context's first UINT: the longest reply delay a ListIdentity asks for, in ms.
_SEQ = struct.Struct("<H")

#: Replies kept from one query: far more devices than one subnet holds; the rest are dropped.
MAX_DISCOVERY_REPLIES = 4096


def broadcast_addresses() -> list[str]:
    """Where a broadcast with no address given goes: 255.255.255.255 and the directed broadcast
    address of every IPv4 interface, loopback included (127.255.255.255), so that devices on
    every attached subnet hear it. Linux reads the interfaces; elsewhere the limited broadcast alone."""
    return [LIMITED_BROADCAST, *(address for address in directed_broadcasts() if address != LIMITED_BROADCAST)]


class UdpQuery:
    """One ListIdentity/ListServices query: ``datagrams`` to send at ``now``, each reply to ``receive``
    until ``deadline``, then ``bodies`` (the replies to this command with status 0, whole)."""

    def __init__(self, command: int, address: str | Sequence[str] | None, port: int, timeout: float, now: float,
                 max_delay_ms: int | None = None) -> None:
        addresses = [address] if isinstance(address, str) else list(address) if address is not None else []
        self.command = command
        self.addresses = addresses or broadcast_addresses()
        self.port = port
        self.deadline = now + timeout
        delay = max_delay_ms if max_delay_ms is not None else max(500, min(int(timeout * 1000) - 100, 0xFFFF))
        self._frame = HEADER.pack(command, 0, 0, 0, _SEQ.pack(delay) + bytes(6), 0)
        self.replies: list[tuple[bytes, tuple[str, int]]] = []

    def datagrams(self) -> list[tuple[bytes, tuple[str, int]]]:
        """The query, once to each address."""
        return [(self._frame, (destination, self.port)) for destination in self.addresses]

    def receive(self, data: bytes, source: tuple[str, int]) -> None:
        """A datagram that came back (kept up to ``MAX_DISCOVERY_REPLIES``)."""
        if len(self.replies) < MAX_DISCOVERY_REPLIES:
            self.replies.append((data, source))

    def bodies(self) -> list[tuple[bytes, tuple[str, int]]]:
        """The bodies of the replies to this command (status 0, the length the header gives); the rest is
        logged at DEBUG and dropped."""
        bodies = []
        for data, addr in self.replies:
            if len(data) >= HEADER_SIZE:
                header = EncapsulationHeader.decode(data)
                if header.command == self.command and header.status == 0 and header.length == len(data) - HEADER_SIZE:
                    bodies.append((data[HEADER_SIZE:], addr))
                    continue
            debug(__name__, "discovery: reply from %s:%d ignored: %s", addr[0], addr[1], data[:64].hex())
        return bodies


def identities(bodies: list[tuple[bytes, tuple[str, int]]]) -> list[IdentityRecord]:
    """The devices in ListIdentity replies, once each: a device that answers twice (two broadcasts
    reached it, or it repeated its reply) is told apart by the address it answered from and its serial."""
    records: list[IdentityRecord] = []
    seen: set[tuple[str, int]] = set()
    for body, addr in bodies:
        try:
            found = decode_list_identity(body)
        except (ValueError, struct.error, EncapsulationError) as exc:
            debug(__name__, "discovery: malformed ListIdentity reply from %s ignored: %s", addr[0], exc)
            continue
        for record in found:
            key = (addr[0], record.serial_number)
            if key not in seen:
                seen.add(key)
                records.append(record)
    return records


def services(bodies: list[tuple[bytes, tuple[str, int]]]) -> list[ServiceRecord]:
    """The services in ListServices replies."""
    records: list[ServiceRecord] = []
    for body, addr in bodies:
        try:
            records.extend(decode_list_services(body))
        except (ValueError, struct.error, EncapsulationError) as exc:
            debug(__name__, "malformed ListServices reply from %s ignored: %s", addr[0], exc)
    return records


__all__ = ["LIMITED_BROADCAST", "MAX_DISCOVERY_REPLIES", "Command", "UdpQuery", "broadcast_addresses", "identities",
           "services"]
