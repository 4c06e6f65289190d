"""The IPv4 networks of this machine's interfaces (Linux: every address of every interface, as
getifaddrs(3) lists them, secondary addresses included), for the two sides of a broadcast: where a
scanner sends one, and which one an adapter hears; and for the netmask a device reports."""

from __future__ import annotations

import ctypes
import ctypes.util
import ipaddress
import socket
import sys
from functools import lru_cache

#: The limited broadcast: every host of the link the datagram is sent on, whatever its subnet.
LIMITED_BROADCAST = "255.255.255.255"


class _SockaddrIn(ctypes.Structure):
    """Linux's ``struct sockaddr_in`` (family in host order, port and address in network order)."""

    _fields_ = [("sin_family", ctypes.c_ushort), ("sin_port", ctypes.c_uint16), ("sin_addr", ctypes.c_uint8 * 4)]


class _Ifaddrs(ctypes.Structure):
    pass


_Ifaddrs._fields_ = [
    ("ifa_next", ctypes.POINTER(_Ifaddrs)), ("ifa_name", ctypes.c_char_p), ("ifa_flags", ctypes.c_uint),
    ("ifa_addr", ctypes.POINTER(_SockaddrIn)), ("ifa_netmask", ctypes.POINTER(_SockaddrIn)),
    ("ifa_ifu", ctypes.c_void_p), ("ifa_data", ctypes.c_void_p),
]


@lru_cache(maxsize=1)
def _libc() -> ctypes.CDLL | None:
    """The C library, found once: ``find_library`` runs ldconfig in a subprocess, milliseconds each
    time, and a fleet asks for the interfaces twice per device."""
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
    except OSError:
        return None


def ipv4_networks() -> list[ipaddress.IPv4Interface]:
    """Every IPv4 address of every interface with its netmask (loopback's 127.0.0.1/8 included, and
    each address a fleet adds to an interface); empty where the platform does not say (not Linux).
    An address given to an interface with ``ip addr add`` is not the one SIOCGIFADDR answers for
    it: only getifaddrs (netlink underneath) lists them all, each with its own mask."""
    if not sys.platform.startswith("linux"):
        return []
    libc = _libc()
    if libc is None:
        return []
    head = ctypes.POINTER(_Ifaddrs)()
    if libc.getifaddrs(ctypes.byref(head)) != 0:
        return []
    found: list[ipaddress.IPv4Interface] = []
    try:
        entry = head
        while entry:
            ifa = entry.contents
            if ifa.ifa_addr and ifa.ifa_netmask and ifa.ifa_addr.contents.sin_family == socket.AF_INET:
                address = bytes(ifa.ifa_addr.contents.sin_addr)
                netmask = bytes(ifa.ifa_netmask.contents.sin_addr)
                interface = ipaddress.IPv4Interface(f"{socket.inet_ntoa(address)}/{socket.inet_ntoa(netmask)}")
                if interface not in found:
                    found.append(interface)
            entry = ifa.ifa_next
    finally:
        libc.freeifaddrs(head)
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


def interface_of(host: str) -> ipaddress.IPv4Interface | None:
    """The interface address (with its netmask) that ``host`` is, or else whose subnet it is in (any
    127.x is loopback's 127.0.0.1/8 on Linux); None where no interface of this machine says."""
    try:
        address = ipaddress.IPv4Address(socket.gethostbyname(host))
    except (OSError, ValueError):
        return None
    interfaces = ipv4_networks()
    for interface in interfaces:
        if interface.ip == address:
            return interface
    for interface in interfaces:
        if address in interface.network:
            return ipaddress.IPv4Interface(f"{address}/{interface.netmask}")
    return None


__all__ = ["LIMITED_BROADCAST", "directed_broadcasts", "interface_of", "ipv4_networks", "subnet_broadcast"]
