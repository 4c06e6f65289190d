"""Which UDP sockets of this network namespace are bound to exactly one address and port, asked of the
kernel by sock_diag(7) netlink (Linux): the kernel filters by the port and the address itself and
answers with those sockets alone. Reading /proc/net/udp instead costs the whole table each time, and a
fleet that checks each of its thousand class 1 sockets as it binds it read that table a thousand
times, most of a large fleet's start."""

from __future__ import annotations

import os
import socket
import struct

#: linux/sock_diag.h, linux/inet_diag.h, linux/netlink.h.
_NETLINK_SOCK_DIAG = 4
_SOCK_DIAG_BY_FAMILY = 20
_NLM_F_REQUEST, _NLM_F_DUMP = 0x01, 0x300
_NLMSG_ERROR, _NLMSG_DONE = 2, 3
_INET_DIAG_REQ_BYTECODE = 1
_INET_DIAG_BC_S_COND = 7
_NLMSG_HEADER = struct.Struct("=IHHII")
#: struct inet_diag_req_v2: family, protocol, ext, pad, states; then struct inet_diag_sockid: sport,
#: dport, src[4], dst[4] (all in network order), interface, cookie[2].
_REQUEST = struct.Struct("=BBBBIHH16s16sI8s")
#: struct inet_diag_msg: family, state, timer, retrans, sockid (48 bytes), expires, rqueue, wqueue, uid, inode.
_MESSAGE = struct.Struct("=BBBBHH4s12s4s12sI8sIIIII")
_ALL_STATES = 0xFFFFFFFF


def _bytecode(address: bytes, port: int) -> bytes:
    """A filter program of one instruction: the local address is ``address``/32 (and the port ``port``),
    else the socket is left out (a jump past the end)."""
    condition = struct.pack("=BBxxi", socket.AF_INET, 32, port) + address
    size = 4 + len(condition)
    return struct.pack("=BBH", _INET_DIAG_BC_S_COND, size, size + 4) + condition


def udp_inodes_bound_to(host: str, port: int) -> set[int] | None:
    """The inodes of the UDP sockets bound to exactly ``host:port`` (IPv4); None where the kernel does
    not answer sock_diag (not Linux, or a kernel without UDP diag): the caller reads /proc then."""
    address = socket.inet_aton(host)
    request = _REQUEST.pack(socket.AF_INET, socket.IPPROTO_UDP, 0, 0, _ALL_STATES, socket.htons(port), 0, address,
                            b"", 0, b"")
    program = _bytecode(address, port)
    attribute = struct.pack("=HH", 4 + len(program), _INET_DIAG_REQ_BYTECODE) + program
    body = request + attribute + b"\0" * (-len(attribute) % 4)
    message = _NLMSG_HEADER.pack(_NLMSG_HEADER.size + len(body), _SOCK_DIAG_BY_FAMILY,
                                 _NLM_F_REQUEST | _NLM_F_DUMP, 1, os.getpid()) + body
    try:
        with socket.socket(socket.AF_NETLINK, socket.SOCK_DGRAM, _NETLINK_SOCK_DIAG) as diag:
            diag.sendall(message)
            found: set[int] = set()
            while True:
                data = diag.recv(65536)
                if not data:
                    return None
                offset = 0
                while offset + _NLMSG_HEADER.size <= len(data):
                    length, kind, _, _, _ = _NLMSG_HEADER.unpack_from(data, offset)
                    if kind == _NLMSG_DONE:
                        return found
                    if kind == _NLMSG_ERROR or length < _NLMSG_HEADER.size:
                        return None
                    fields = _MESSAGE.unpack_from(data, offset + _NLMSG_HEADER.size)
                    if socket.ntohs(fields[4]) == port and fields[6] == address:
                        found.add(fields[-1])
                    offset += (length + 3) & ~3
    except (OSError, AttributeError, struct.error):   # AttributeError: no AF_NETLINK here
        return None


__all__ = ["udp_inodes_bound_to"]
