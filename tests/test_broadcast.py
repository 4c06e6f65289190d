"""A target answers the broadcasts of its subnet (issue: an adapter on --host 127.0.0.2 did not
answer a ListIdentity sent to 127.255.255.255) and the limited broadcast 255.255.255.255 (what many
scanners send; issue 30, item 1), each target of a machine once with its own reply from its own
address, and still answers unicast; and a target asked for a free port (0) gets a number free
in both TCP and UDP even when the OS's first pick is taken in UDP."""

from __future__ import annotations

import asyncio
import ipaddress
import socket
import struct
import sys

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.eip.interfaces import ipv4_networks, subnet_broadcast
from cipstack.eip.target import server as server_module
from cipstack.scanner import discover
from tests.ports import free_port, list_identity_replies

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="loopback /8 and interface table")

#: ListIdentity (0x0063), no data, sender context asking for replies within 500 ms.


def test_the_loopback_subnet_broadcast() -> None:
    assert subnet_broadcast("127.0.0.2") == "127.255.255.255"
    assert subnet_broadcast("localhost") == "127.255.255.255"
    outside = next(f"198.51.100.{n}" for n in range(1, 255)
                   if not any(ipaddress.IPv4Address(f"198.51.100.{n}") in i.network for i in ipv4_networks()))
    assert subnet_broadcast(outside) is None                # no interface of this machine is there


async def test_each_target_answers_a_subnet_broadcast_once_from_its_own_address() -> None:
    port = free_port("127.0.0.2", "127.0.0.3")
    async with Adapter(AdapterSettings(host="127.0.0.2", port=port, io_port=0)) as first, \
            Adapter(AdapterSettings(host="127.0.0.3", port=port, io_port=0)) as second:
        # Three requests at once, each collecting its own window.
        replies, unicast, found = await asyncio.gather(list_identity_replies("127.255.255.255", port),
                                                       list_identity_replies("127.0.0.3", port),
                                                       discover("127.255.255.255", port, timeout=1.2))
        assert sorted(host for _, host in replies) == ["127.0.0.2", "127.0.0.3"]
        for data, _ in replies:
            assert struct.unpack_from("<H", data)[0] == 0x0063 and len(data) > 24
        # Unicast is still the target's own: only the one asked answers.
        assert [host for _, host in unicast] == ["127.0.0.3"]
        # The scanner's discovery, given the broadcast address, lists each device once.
        assert sorted(record.address.host for record in found if record.address) == ["127.0.0.2", "127.0.0.3"]
        assert first.server.port == second.server.port == port


async def test_each_target_answers_the_limited_broadcast_once_from_its_own_address() -> None:
    """A ListIdentity to 255.255.255.255 from a socket bound to 127.0.0.1 leaves by loopback (Linux
    routes a limited broadcast out of the interface of its source address), where it reaches every
    socket bound to 255.255.255.255 or 0.0.0.0 on its port, and no socket bound to one address."""
    port = free_port("127.0.0.2", "127.0.0.3")
    async with Adapter(AdapterSettings(host="127.0.0.2", port=port, io_port=0)), \
            Adapter(AdapterSettings(host="127.0.0.3", port=port, io_port=0)):
        # Both requests at once, each collecting its own window.
        replies, found = await asyncio.gather(list_identity_replies("255.255.255.255", port),
                                              discover("255.255.255.255", port, timeout=1.2))
        assert sorted(host for _, host in replies) == ["127.0.0.2", "127.0.0.3"]
        for data, host in replies:
            command, length = struct.unpack_from("<HH", data)
            assert command == 0x0063 and length == len(data) - 24
            # The item's sockaddr (after the item count, type, length and version) is the target's own.
            family, item_port, address = struct.unpack_from(">hH4s", data, 24 + 2 + 4 + 2)
            assert (family, item_port, socket.inet_ntoa(address)) == (2, port, host)
        assert sorted(record.address.host for record in found if record.address) == ["127.0.0.2", "127.0.0.3"]


async def test_a_free_port_is_free_in_udp_too(monkeypatch: pytest.MonkeyPatch) -> None:
    """The OS picks the TCP number; when that number is taken in UDP, another pair is taken."""
    # The clash is one of this worker's numbers, below the ephemeral range: free in TCP, so the first
    # listener does take it (a number the kernel picked for UDP may be some outgoing TCP connection's).
    clash = free_port()
    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", clash))
    picks: list[int] = []
    real = server_module.guarded_listener

    def first_pick_clashes(host: str, port: int, backlog: int = 100, listen: bool = True) -> socket.socket:
        listener = real(host, clash if port == 0 and not picks else port, backlog, listen)
        picks.append(listener.getsockname()[1])
        return listener

    monkeypatch.setattr(server_module, "guarded_listener", first_pick_clashes)
    try:
        async with Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0)) as adapter:
            assert picks[0] == clash and adapter.server.port == picks[-1] != clash
            assert [host for _, host in await list_identity_replies("127.0.0.1", adapter.server.port)] == ["127.0.0.1"]
    finally:
        taken.close()
