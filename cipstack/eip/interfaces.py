"""The IPv4 networks of this machine's interfaces (Linux: read with SIOCGIFADDR/SIOCGIFNETMASK),
for the two sides of a broadcast: where a scanner sends one, and which one an adapter hears."""

from __future__ import annotations

import ipaddress
import socket
import struct

_SIOCGIFADDR, _SIOCGIFNETMASK = 0x8915, 0x891B
#: The limited broadcast: every host of the link the datagram is sent on, whatever its subnet.
LIMITED_BROADCAST = "255.255.255.255"


def ipv4_networks() -> list[ipaddress.IPv4Interface]:
    """Every interface's IPv4 address with its netmask (loopback's 127.0.0.1/8 included); empty where
    the platform does not say (not Linux)."""
    try:
        import fcntl

        names = [name for _, name in socket.if_nameindex()]
    except (ImportError, OSError, AttributeError):
        return []
    found: list[ipaddress.IPv4Interface] = []
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for name in names:
            request = struct.pack("256s", name.encode()[:15])
            try:
                address = fcntl.ioctl(sock.fileno(), _SIOCGIFADDR, request)[20:24]
                netmask = fcntl.ioctl(sock.fileno(), _SIOCGIFNETMASK, request)[20:24]
            except OSError:
                continue  # no IPv4 address on this interface
            found.append(ipaddress.IPv4Interface(f"{socket.inet_ntoa(address)}/{socket.inet_ntoa(netmask)}"))
    return found


def directed_broadcasts() -> list[str]:
    """The directed broadcast address of every interface's subnet (127.255.255.255 for loopback)."""
    addresses: list[str] = []
    for interface in ipv4_networks():
        network = interface.network
        if network.prefixlen < 31 and str(network.broadcast_address) not in addresses:
            addresses.append(str(network.broadcast_address))
    return addresses


def subnet_broadcast(host: str) -> str | None:
    """The directed broadcast address of the subnet ``host`` is on (an address of this machine, any
    127.x on Linux's loopback), or None: not an interface address, or a /31 or /32 with none."""
    try:
        address = ipaddress.IPv4Address(socket.gethostbyname(host))
    except (OSError, ValueError):
        return None
    for interface in ipv4_networks():
        network = interface.network
        if address in network and network.prefixlen < 31:
            return str(network.broadcast_address)
    return None


__all__ = ["LIMITED_BROADCAST", "directed_broadcasts", "ipv4_networks", "subnet_broadcast"]
