"""TCP/IP Interface object (class 0xF5) and Ethernet Link object (class 0xF6).

The TCP/IP object's attribute 13 (encapsulation inactivity timeout, seconds, default 120,
0 disables) is read live by the encapsulation server, so setting it over the network takes
effect for the next idle check. Attribute 9 (multicast configuration) feeds the class 1
multicast address allocation.
"""

from __future__ import annotations

import socket
from dataclasses import dataclass

from ..cip.messages import Service
from ..cip.model import Access, AttributeSpec, CipObject, ClassSpec
from ..cip.types import DWORD, STRING, UDINT, UINT, USINT, OctetString, RemainingBytes, StructType

TCPIP_CLASS_ID = 0xF5
ETHERNET_LINK_CLASS_ID = 0xF6

INTERFACE_CONFIGURATION = StructType("INTERFACE_CONFIGURATION", [
    ("ip_address", UDINT), ("network_mask", UDINT), ("gateway_address", UDINT),
    ("name_server", UDINT), ("name_server_2", UDINT), ("domain_name", STRING),
])
PHYSICAL_LINK_PATH = StructType("PHYSICAL_LINK_PATH", [("path_size", UINT), ("path", RemainingBytes("EPATH"))])
MULTICAST_CONFIGURATION = StructType("MULTICAST_CONFIGURATION", [
    ("alloc_control", USINT), ("reserved", USINT), ("num_mcast", UINT), ("mcast_start_addr", UDINT),
])

_GET_SERVICES = frozenset({Service.GET_ATTRIBUTE_SINGLE, Service.GET_ATTRIBUTES_ALL})

TCPIP_SPEC = ClassSpec(
    TCPIP_CLASS_ID, "TCP/IP Interface", revision=4,
    instance_attributes=(
        AttributeSpec(1, "Status", DWORD, default=1, help="1: configured from non-volatile storage"),
        AttributeSpec(2, "Configuration Capability", DWORD, default=0),
        AttributeSpec(3, "Configuration Control", DWORD, default=0),
        AttributeSpec(4, "Physical Link Object", PHYSICAL_LINK_PATH,
                      default={"path_size": 2, "path": bytes.fromhex("20f62401")}),
        AttributeSpec(5, "Interface Configuration", INTERFACE_CONFIGURATION),
        AttributeSpec(6, "Host Name", STRING, default=""),
        AttributeSpec(8, "TTL Value", USINT, default=1, in_get_all=False),
        AttributeSpec(9, "Multicast Config", MULTICAST_CONFIGURATION, in_get_all=False,
                      default={"alloc_control": 0, "reserved": 0, "num_mcast": 0, "mcast_start_addr": 0}),
        AttributeSpec(13, "Encapsulation Inactivity Timeout", UINT, Access.GET_SET, default=120,
                      minimum=0, maximum=3600, unit="s", in_get_all=False,
                      help="Seconds of inactivity before an encapsulation TCP connection is closed; 0 disables"),
    ),
    class_services=frozenset({Service.GET_ATTRIBUTE_SINGLE}),
    instance_services=_GET_SERVICES | {Service.SET_ATTRIBUTE_SINGLE, Service.GET_ATTRIBUTE_LIST,
                                       Service.SET_ATTRIBUTE_LIST},
)

ETHERNET_LINK_SPEC = ClassSpec(
    ETHERNET_LINK_CLASS_ID, "Ethernet Link", revision=3,
    instance_attributes=(
        AttributeSpec(1, "Interface Speed", UDINT, default=100, unit="Mbit/s"),
        AttributeSpec(2, "Interface Flags", DWORD, default=0x0F,
                      help="bit 0 link active, bit 1 full duplex, bits 2-4 negotiation status 3: success"),
        AttributeSpec(3, "Physical Address", OctetString(6, "MAC"), default=bytes(6)),
    ),
    class_services=frozenset({Service.GET_ATTRIBUTE_SINGLE}),
    instance_services=_GET_SERVICES,
)


def ip_to_udint(address: str) -> int:
    return int.from_bytes(socket.inet_aton(address), "big")


@dataclass(frozen=True)
class NetworkInterface:
    ip_address: str = "127.0.0.1"
    network_mask: str = "255.0.0.0"
    gateway_address: str = "0.0.0.0"
    host_name: str = ""
    mac: bytes = bytes.fromhex("0200c1a00001")


class TcpIpObject(CipObject):
    def __init__(self, interface: NetworkInterface) -> None:
        super().__init__(TCPIP_SPEC)
        self.add_instance(1, interface_configuration={
            "ip_address": ip_to_udint(interface.ip_address),
            "network_mask": ip_to_udint(interface.network_mask),
            "gateway_address": ip_to_udint(interface.gateway_address),
            "name_server": 0, "name_server_2": 0, "domain_name": "",
        }, host_name=interface.host_name)

    @property
    def inactivity_timeout(self) -> int:
        return int(self.get(1, 13))


class EthernetLinkObject(CipObject):
    def __init__(self, interface: NetworkInterface) -> None:
        super().__init__(ETHERNET_LINK_SPEC)
        self.add_instance(1, physical_address=interface.mac)


__all__ = ["ETHERNET_LINK_CLASS_ID", "TCPIP_CLASS_ID", "EthernetLinkObject", "NetworkInterface", "TcpIpObject",
           "ip_to_udint"]
