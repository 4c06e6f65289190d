"""The asyncio shell of the target: moves bytes between sockets and the sans-I/O core.

On a ``PreciseEventLoop`` (the command line's) the TCP listener and connections are served on the
loop's lane (``tcp_lane``); on any other loop through asyncio's transports (``_TcpProtocol``), with
the same rules.

One TCP listener and one UDP endpoint on the same host and port (44818 by default), and, for a
target on one address, a UDP socket on the limited broadcast address and one on its subnet's
broadcast address (shared with every other target of the machine: each gets a copy of a
broadcast) whose datagrams are answered from the unicast endpoint, as a device answers the
broadcasts of its link. Each
TCP connection gets an ``EncapsulationConnection``; a loop timer at its next deadline runs
the inactivity and class 3 timeouts. Delayed ListIdentity replies wait in the target's bounded
``DelayedReplies``, sent by one loop timer at the earliest.

TCP connections are bounded in total and per host (``ConnectionLimiter``): one over a bound is
closed as soon as it is accepted, with one log line per 10 s whatever the rate. The listening
socket is a ``GuardedListener``: when accept() runs out of descriptors, the waiting connection is
closed at once and logged once per 10 s, never a traceback per attempt (see ``limits``).
"""

from __future__ import annotations

import asyncio
import errno
import logging
import socket
import struct
import sys

from ..interfaces import LIMITED_BROADCAST, subnet_broadcast
from ..io_server import lane_of
from ..wire.cpf import SockAddr
from ..wire.encapsulation import DEFAULT_PORT, HEADER_SIZE
from .core import EncapsulationConnection, EncapsulationTarget
from .limits import (
    DEFAULT_MAX_TCP_CONNECTIONS,
    LISTEN_BACKLOG,
    ConnectionLimiter,
    RateLimitedLog,
    fit_to_open_file_limit,
    guarded_listener,
    quiet_accept_errors,
)
from .seams import ReplySeam
from .tcp_lane import LaneListener, LaneTcpConnection

log = logging.getLogger(__name__)



class _TcpProtocol(asyncio.Protocol):
    def __init__(self, server: EncapsulationServer) -> None:
        self.server = server
        self.loop = server.loop
        self.transport: asyncio.Transport | None = None
        self.connection: EncapsulationConnection | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at: float | None = None
        self._admitted_host: str | None = None
        self.host = "?"

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        peer = transport.get_extra_info("peername")
        host = peer[0] if peer else "?"
        if not self.server.admit(host):
            transport.abort()
            return
        self._admitted_host = host
        self.host = host
        self.transport = transport
        sock = transport.get_extra_info("sockname")
        peer_text = f"{peer[0]}:{peer[1]}" if peer else "?"
        local = SockAddr(sock[0], sock[1]) if sock else SockAddr("0.0.0.0", self.server.port)
        sock_obj = transport.get_extra_info("socket")
        if sock_obj is not None:
            sock_obj.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        # Replies above 64 KiB unsent pause reading (see pause_writing).
        transport.set_write_buffer_limits(high=64 * 1024)
        self.connection = self.server.opened(self, peer_text, local)
        self._arm()

    def data_received(self, data: bytes) -> None:
        connection = self.connection
        if connection is None or self.transport is None:
            return  # refused at accept: its last bytes are not ours to read
        connection.receive(data, self.loop.time())
        out = connection.data_to_send()
        if out:
            held = self.server.replies.filter
            if held is None:
                self.transport.write(out)
            else:
                held.reply(self, out)
        if connection.closing:
            self.transport.close()
        elif self._timer is None:
            self._arm()
        elif connection.frame_started is not None:
            # A frame has begun: its deadline may come before the timer's (the timer re-arms lazily).
            frame_deadline = connection.frame_deadline()
            if frame_deadline is not None and self._timer_at is not None and frame_deadline < self._timer_at:
                self._timer.cancel()
                self._arm()

    # Back-pressure: a client that sends requests but does not read the replies stops being
    # read from until the replies drain, so replies never pile up in memory.
    def pause_writing(self) -> None:
        if self.transport is not None:
            self.transport.pause_reading()

    def resume_writing(self) -> None:
        if self.transport is not None and not self.transport.is_closing():
            self.transport.resume_reading()

    def connection_lost(self, exc: Exception | None) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self._admitted_host is not None:
            self.server.closed(self, self._admitted_host, self.connection)
            self._admitted_host = None

    def send_reply(self, out: bytes) -> None:
        """Send reply bytes taken from the connection earlier (a reply held back for a while)."""
        if self.transport is not None and not self.transport.is_closing():
            self.transport.write(out)

    def write_buffer_size(self) -> int:
        """Reply bytes the transport holds because the socket would not take them."""
        return self.transport.get_write_buffer_size() if self.transport is not None else 0

    def close(self) -> None:
        if self.transport is not None:
            self.transport.close()

    def evict(self) -> None:
        """Closed (reset) to make room for another host: its place is free at once."""
        host, self._admitted_host = self._admitted_host, None
        if host is not None:
            self.server.closed(self, host, self.connection)
        if self.transport is not None:
            self.transport.abort()

    def _arm(self) -> None:
        assert self.connection is not None
        deadline = self.connection.next_deadline()
        self._timer_at = deadline
        if deadline is not None:
            self._timer = self.loop.call_at(deadline, self._on_timer)
        else:
            self._timer = None

    def _on_timer(self) -> None:
        # Deadlines move forward with traffic; the timer fires at the old one and re-arms lazily,
        # so the hot path never reschedules a timer per packet.
        self._timer = None
        connection = self.connection
        if connection is None or self.transport is None:
            return
        connection.on_timer(self.loop.time())
        if connection.closing:
            self.transport.close()
        else:
            self._arm()


class _UdpProtocol(asyncio.DatagramProtocol):
    def __init__(self, server: EncapsulationServer) -> None:
        self.server = server
        self.transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: tuple[str, int], local: SockAddr | None = None) -> None:
        """``local``: the address the datagram arrived on, when the socket says (``_ArrivalAddresses``);
        else the target's own."""
        server = self.server
        try:
            reply = server.target.datagram_from(data, addr, local or server.local_address(), server.loop.time())
        except Exception:  # never let a datagram take the endpoint down
            log.exception("UDP datagram from %s", addr)
            return
        if reply is not None:
            self._send(reply, addr)
        self._arm()

    def _arm(self) -> None:
        """Keep one timer at the earliest delayed reply (never one per reply)."""
        server = self.server
        deadline = server.target.delayed.next_deadline()
        if deadline is None or (server._delayed_at is not None and server._delayed_at <= deadline):
            return
        if server._delayed_timer is not None:
            server._delayed_timer.cancel()
        server._delayed_at = deadline
        server._delayed_timer = server.loop.call_at(deadline, self._on_delayed)

    def _on_delayed(self) -> None:
        server = self.server
        server._delayed_timer = None
        server._delayed_at = None
        for reply, addr in server.target.delayed.due(server.loop.time()):
            self._send(reply, addr)
        self._arm()

    def _send(self, reply: bytes, addr: tuple[str, int]) -> None:
        if self.transport is not None and not self.transport.is_closing():
            try:
                self.transport.sendto(reply, addr)
            except OSError as exc:
                log.debug("UDP reply to %s failed: %s", addr, exc)

    def error_received(self, exc: Exception) -> None:
        log.debug("UDP error: %s", exc)


#: Linux's IP_PKTINFO (<linux/in.h>), absent from Python's socket module before 3.13: each datagram
#: then comes with a ``struct in_pktinfo`` (interface index, ``ipi_spec_dst``, ``ipi_addr``).
_IP_PKTINFO = getattr(socket, "IP_PKTINFO", 8)
_IN_PKTINFO = struct.Struct("=i4s4s")
#: Datagrams read per wake-up before the loop has its turn again.
_READS_PER_WAKEUP = 64


class _ArrivalAddresses:
    """The UDP endpoint of a target on every address (0.0.0.0), Linux: each datagram is read with the
    local address it arrived on (IP_PKTINFO's ``ipi_spec_dst``: the address a unicast was sent to,
    or for a broadcast the address of the interface it came in by), so that ListIdentity advertises
    the address the originator reached, not one chosen for every interface. Offers what
    ``_UdpProtocol`` uses of a datagram transport (``sendto``, ``is_closing``, ``close``)."""

    def __init__(self, sock: socket.socket, protocol: _UdpProtocol, loop: asyncio.AbstractEventLoop) -> None:
        self.sock = sock
        self.protocol = protocol
        self.loop = loop
        self._closed = False
        sock.setblocking(False)
        loop.add_reader(sock.fileno(), self._read)
        protocol.connection_made(self)  # type: ignore[arg-type]

    def _read(self) -> None:
        sock, port = self.sock, self.protocol.server.port
        for _ in range(_READS_PER_WAKEUP):
            try:
                data, ancillary, _flags, source = sock.recvmsg(65535, socket.CMSG_SPACE(_IN_PKTINFO.size))
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # an ICMP error reported on the socket
                log.debug("UDP socket error: %s", exc)
                return
            local = None
            for level, kind, value in ancillary:
                if level == socket.IPPROTO_IP and kind == _IP_PKTINFO and len(value) >= _IN_PKTINFO.size:
                    local = SockAddr(socket.inet_ntoa(_IN_PKTINFO.unpack_from(value)[1]), port)
            self.protocol.datagram_received(data, source, local)

    def sendto(self, data: bytes, addr: tuple[str, int]) -> None:
        try:
            self.sock.sendto(data, addr)
        except (BlockingIOError, InterruptedError):
            log.debug("UDP reply to %s dropped: the socket's buffer is full", addr)

    def is_closing(self) -> bool:
        return self._closed

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.loop.remove_reader(self.sock.fileno())
            self.sock.close()


class _BroadcastListener(asyncio.DatagramProtocol):
    """Hears the subnet's broadcasts; the unicast endpoint answers them, from the target's address."""

    def __init__(self, unicast: _UdpProtocol) -> None:
        self.unicast = unicast

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        self.unicast.datagram_received(data, addr)

    def error_received(self, exc: Exception) -> None:
        log.debug("UDP broadcast socket error: %s", exc)


def _last_activity(served: _TcpProtocol | LaneTcpConnection) -> float:
    """When a served connection last completed a frame (its idleness, for ``_close_idlest``)."""
    connection = served.connection
    return connection.last_activity if connection is not None else float("-inf")


def _peer_of(served: _TcpProtocol | LaneTcpConnection) -> str:
    connection = served.connection
    return connection.peer if connection is not None else served.host


#: Tries at a pair of free TCP and UDP ports of one number (port 0): the OS picks the TCP one, and
#: another process may hold that number in UDP.
_FREE_PORT_TRIES = 20


class EncapsulationServer:
    """TCP + UDP encapsulation endpoints for one target."""

    def __init__(self, target: EncapsulationTarget, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 udp: bool = True, max_tcp_connections: int = DEFAULT_MAX_TCP_CONNECTIONS,
                 max_tcp_connections_per_host: int | None = None, replies: ReplySeam | None = None) -> None:
        """``replies``: the seam TCP replies pass on their way out (``seams.ReplySeam``)."""
        self.target = target
        self.replies = replies or ReplySeam()
        self.host = host
        self.port = port
        self.udp = udp
        #: The running loop, taken in ``start()`` (none is made here: one made outside a running loop
        #: would never be closed).
        self.loop: asyncio.AbstractEventLoop
        self.connections: set[_TcpProtocol | LaneTcpConnection] = set()
        self.limiter = ConnectionLimiter(max_tcp_connections, max_tcp_connections_per_host)
        self.refused_log = RateLimitedLog(log)
        self.evicted_log = RateLimitedLog(log, level=logging.INFO)
        #: The listener: asyncio's server, or on a ``PreciseEventLoop`` the lane's (``tcp_lane``).
        self._tcp: asyncio.base_events.Server | LaneListener | None = None
        self._udp: asyncio.DatagramTransport | _ArrivalAddresses | None = None
        self._broadcasts: list[asyncio.DatagramTransport] = []
        self._local: SockAddr | None = None
        self._delayed_timer: asyncio.TimerHandle | None = None
        self._delayed_at: float | None = None

    # -- what both kinds of TCP connection (``_TcpProtocol``, ``LaneTcpConnection``) share ----------
    def admit(self, host: str) -> bool:
        """Whether a TCP connection from ``host`` may be served (``ConnectionLimiter``); a refusal is
        logged, at a bounded rate. An admitted host is released by ``closed``."""
        if self.limiter.admit_making_room(host, self._close_idlest):
            return True
        self.refused_log("TCP connection from %s refused: %s", host, self.limiter.reason(host), source=host)
        return False

    def _close_idlest(self, victim: str, host: str) -> bool:
        """Every slot taken: close the idlest connection (the longest without a complete frame) of
        ``victim`` to make room for ``host`` (``ConnectionLimiter.victim``); False if it has none."""
        idlest = min((served for served in self.connections if served.host == victim),
                     key=_last_activity, default=None)
        if idlest is None:
            return False
        self.evicted_log("TCP connection %s closed to make room for %s: %s held %d of the %d connections",
                         _peer_of(idlest), host, victim, self.limiter.by_host.get(victim, 0), self.limiter.total,
                         source=victim)
        idlest.evict()
        return True

    def opened(self, served: _TcpProtocol | LaneTcpConnection, peer_text: str,
               local: SockAddr) -> EncapsulationConnection:
        """The sans-I/O connection of an admitted TCP connection, which the server now holds."""
        connection = self.target.connection(peer_text, local, self.loop.time())
        self.connections.add(served)
        log.info("%s: TCP connection accepted", peer_text)
        return connection

    def closed(self, served: _TcpProtocol | LaneTcpConnection | None, host: str,
               connection: EncapsulationConnection | None) -> None:
        """An admitted TCP connection has ended (None: before it was ``opened``): its host's place,
        its session and its class 3 connections go."""
        self.limiter.release(host)
        if connection is not None:
            connection.connection_lost()
            log.info("%s: TCP connection closed", connection.peer)
        self.connections.discard(served)

    def local_address(self) -> SockAddr:
        if self._local is None or self._local.port != self.port:
            host = self.host if self.host not in ("", "0.0.0.0") else "127.0.0.1"
            self._local = SockAddr(socket.gethostbyname(host), self.port)
        return self._local

    async def start(self, serve: bool = True) -> None:
        """Take the TCP and UDP ports and serve them; with ``serve`` false the TCP port is only bound
        (nothing connects yet) until ``serve()``, so that a shell can ready its other ports first."""
        self.loop = asyncio.get_running_loop()
        quiet_accept_errors(self.loop)
        self.limiter.total = fit_to_open_file_limit(self.limiter.total)
        self.limiter.per_host = min(self.limiter.per_host, self.limiter.total)
        any_port = self.port == 0
        for attempt in range(_FREE_PORT_TRIES if any_port else 1):
            await self._listen_tcp(0 if any_port else self.port)
            try:
                await self._listen_udp()
            except OSError as exc:
                if not any_port or exc.errno != errno.EADDRINUSE or attempt == _FREE_PORT_TRIES - 1:
                    raise
                await self._close_tcp()   # that number is taken in UDP: another pair
                continue
            break
        if serve:
            await self.serve()

    async def serve(self) -> None:
        """Listen on the TCP port ``start(serve=False)`` bound: connections are accepted from now on."""
        tcp = self._tcp
        if isinstance(tcp, LaneListener):
            tcp.start_serving()
        elif tcp is not None:
            await tcp.start_serving()
        log.info("EtherNet/IP target listening on %s:%d (TCP%s)", self.host, self.port, " and UDP" if self.udp else "")

    async def _listen_tcp(self, port: int) -> None:
        listener = guarded_listener(self.host, port, listen=False)
        lane = lane_of(self.loop)
        try:
            if lane is not None:
                self._tcp = LaneListener(listener, lane, lambda sock, peer: LaneTcpConnection.accepted(
                    self, sock, peer, lane))
            else:
                self._tcp = await self.loop.create_server(lambda: _TcpProtocol(self), sock=listener,
                                                          backlog=LISTEN_BACKLOG, start_serving=False)
        except BaseException:
            listener.close()
            raise
        self.port = listener.getsockname()[1]

    async def _listen_udp(self) -> None:
        if not self.udp:
            return
        if self.host in ("", "0.0.0.0") and sys.platform.startswith("linux"):
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                sock.setsockopt(socket.IPPROTO_IP, _IP_PKTINFO, 1)
                sock.bind((self.host, self.port))
            except OSError:
                sock.close()
                raise
            self._udp = _ArrivalAddresses(sock, _UdpProtocol(self), self.loop)
            return
        transport, unicast = await self.loop.create_datagram_endpoint(lambda: _UdpProtocol(self),
                                                                      local_addr=(self.host, self.port))
        self._udp = transport
        self._broadcasts = await self._listen_broadcasts(unicast)

    async def _listen_broadcasts(self, unicast: _UdpProtocol) -> list[asyncio.DatagramTransport]:
        """A socket on each broadcast address a device on this address hears, on this port: the
        limited broadcast 255.255.255.255 (what many scanners send) and the subnet's directed
        broadcast. Each is shared (SO_REUSEADDR) with the other targets of the machine: Linux gives
        every socket bound to a broadcast's address and port a copy of it (udp(7); a socket bound to
        one unicast address never sees a broadcast), so each target answers once, from its own
        address. A target on every address (0.0.0.0) hears broadcasts on its own socket already."""
        if self.host in ("", "0.0.0.0"):
            return []
        transports: list[asyncio.DatagramTransport] = []
        for broadcast in (LIMITED_BROADCAST, subnet_broadcast(self.host)):
            if broadcast is None:
                continue
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                sock.bind((broadcast, self.port))
            except OSError as exc:
                sock.close()
                log.warning("broadcasts to %s:%d are not heard: %s", broadcast, self.port, exc.strerror or exc)
                continue
            transport, _ = await self.loop.create_datagram_endpoint(lambda: _BroadcastListener(unicast), sock=sock)
            transports.append(transport)
        return transports

    async def _close_tcp(self) -> None:
        tcp, self._tcp = self._tcp, None
        if tcp is not None:
            tcp.close()
            if not isinstance(tcp, LaneListener):
                await tcp.wait_closed()

    async def close(self) -> None:
        tcp = self._tcp
        if tcp is not None:
            tcp.close()
        for connection in list(self.connections):
            connection.close()
        if tcp is not None and not isinstance(tcp, LaneListener):
            await tcp.wait_closed()
        if self._udp is not None:
            self._udp.close()
        for broadcast in self._broadcasts:
            broadcast.close()
        self._broadcasts = []
        if self._delayed_timer is not None:
            self._delayed_timer.cancel()
            self._delayed_timer = None
            self._delayed_at = None
        self.target.delayed.clear()
        self._tcp = None
        self._udp = None

    @property
    def is_open(self) -> bool:
        """Its TCP port is bound (``start``) and not closed since."""
        return self._tcp is not None

    def close_connections(self) -> int:
        """Close every TCP connection (their sessions and class 3 connections go with them); how many."""
        served = list(self.connections)
        for connection in served:
            connection.close()
        return len(served)

    async def __aenter__(self) -> EncapsulationServer:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()


__all__ = ["DEFAULT_PORT", "HEADER_SIZE", "EncapsulationServer"]
