"""The asyncio shell of class 1 I/O, both roles: one UDP endpoint (2222 by default) and a
loop timer at the core's next deadline.

Timing comes from the precise event loop (``precise_loop``, whose names this module also
exports as it always did). The class 1 lane: on that loop, each ``IoEndpoint`` hands its UDP socket and its timer to the
selector itself (``IoLane``), which reads the sockets that are ready and fires the timers that
are due inside its wait, before asyncio sees anything. A datagram then costs one ``recvfrom``
and the protocol core, and a production one heap entry: no callback handle, no transport and
no asyncio timer per packet, which is most of what a packet cost on asyncio's own path (a fleet
of drives or a scanner with hundreds of connections is made of little else). On any other loop
(a scanner inside an application's own loop) the endpoint uses asyncio's datagram transport.
The encapsulation server's TCP connections ride the same lane on that loop (``tcp_lane``). While
only the lane has work, the selector goes on waiting and serving it without handing back to
asyncio (whose round of bookkeeping costs more than a small request); it returns as soon as
asyncio has something to do: a socket of its own, its next timer, or work a lane callback gave it.
"""

from __future__ import annotations

import asyncio
import errno
import logging
import math
import os
import select
import socket
import struct
import sys
import time
from collections.abc import Callable
from typing import Any, Protocol

from ..errors import BadRequest

# The loop had its home here: FD_SETSIZE, PreciseEventLoop, run_precise, ... are still exported from here.
from .precise_loop import (  # noqa: F401
    FD_SETSIZE,
    IoLane,
    LaneTimer,
    PreciseEpollSelector,
    PreciseEventLoop,
    freeze_startup_objects,
    lane_of,
    precise_event_loop,
    run_precise,
)
from .udp_table import udp_inodes_bound_to

log = logging.getLogger(__name__)


#: A firing also sends what falls due this soon after it (each production at most 1/16 of its RPI
#: early, ``io_target.EARLY_SHARE``): connections opened one after another are due a few
#: microseconds apart, and one wake-up for several of them costs less than one each.
COALESCE_S = 0.0002


#: Datagrams one socket may deliver per wake-up before the others get their turn (epoll is level
#: triggered: what is left is reported again at once).
DRAIN_LIMIT = 64

#: A ``gather_within`` for the adapter (``AdapterSettings.io_gather``, ``--io-gather``; off by
#: default): while the next firing is this near, a datagram does not wake the process; the firing
#: reads what came first, then produces. A wake-up costs more than a datagram's whole protocol work
#: (benchmarks/README.md, "Where a class 1 packet's CPU goes"), and at an RPI of 10 ms or less a
#: production fires within one RPI anyway. The O->T data reaches the device at the next firing,
#: before the production that reports on it, and is timed when it is read, as a loop held up by
#: other work times it: the watchdog may run out up to this much later, never sooner. A longer wait
#: than this, and the socket wakes the process again. Off by default: on a loaded virtual machine a
#: wake-up by a timer alone came up to half a second late where the datagrams' wake-ups had kept
#: the productions going (benchmarks/README.md).
GATHER_WITHIN_S = 0.0125

#: The largest UDP payload: a Large_Forward_Open connection may carry up to this much.
MAX_DATAGRAM = 65535

#: Reads of ``DRAIN_LIMIT`` datagrams a socket not read to its end gets before a firing judges its
#: connections (``IoEndpoint._catch_up``): 64 x 64 = 4,096 datagrams, more small ones than its
#: receive buffer holds (``RECEIVE_BUFFER``).
CATCH_UP_READS = 64

#: A socket read to its end this recently holds nothing a watchdog could miss: less than the
#: shortest connection timeout (``io_core.connection_timeout``, RPI x 4 x 2^multiplier: 2 ms at the
#: 0.5 ms RPI ``cipstack io`` runs, with multiplier 0).
CATCH_UP_AFTER_S = 0.001

#: Linux's SO_TIMESTAMPNS, also the type of its control message (SCM_TIMESTAMPNS), which Python's
#: socket module does not name (35 in <asm-generic/socket.h>, the x86, ARM and RISC-V value): the
#: kernel stamps each datagram with the time it reached the socket.
SO_TIMESTAMPNS = 35
_TIMESPEC = struct.Struct("@ll")  # struct timespec: two C longs (8 bytes each on 64-bit Linux, 4 on 32-bit)
_STAMP_SPACE = socket.CMSG_SPACE(_TIMESPEC.size)


def _kernel_time(ancillary: list[tuple[int, int, bytes]], offset: float) -> float | None:
    """The kernel's receive time of a datagram (``recvmsg``'s control messages, SO_TIMESTAMPNS) on the
    monotonic clock, ``offset`` being wall clock minus monotonic; None when the message lacks it."""
    for level, kind, stamp in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(stamp) >= _TIMESPEC.size:
            seconds, nanoseconds = _TIMESPEC.unpack_from(stamp)
            return float(seconds - offset + nanoseconds * 1e-9)
    return None

#: The receive buffer asked for a class 1 socket. One socket takes every connection's datagrams
#: (an originator's, an adapter's 2222), and what arrives while the process is not scheduled waits
#: there: Linux's default (208 KiB) holds 256 small datagrams, 5 ms at 51,200 packets/s, and then
#: drops them; 1 MiB holds about 2,500 (50 ms). Linux doubles the value asked and caps it at
#: net.core.rmem_max.
RECEIVE_BUFFER = 1 << 20


class IoCore(Protocol):
    """The sans-I/O side: ``IoTarget`` or an originator's connection set."""

    def receive(self, raw: bytes, source: tuple[str, int], now: float) -> None: ...

    def poll(self, now: float, horizon: float = 0.0) -> list[tuple[bytes, tuple[str, int]]]: ...

    def next_deadline(self) -> float | None:
        """The earliest production slot or watchdog: a firing whose core has none due after its
        productions judges nothing, and ``expire`` is not called (``IoEndpoint._on_timer``)."""

    def expire(self, now: float) -> list[Any]: ...


class DatagramPaths:
    """Where T->O datagrams to some destinations go instead of the endpoint's UDP socket: the address
    of a DTLS session (``security.dtls_target``) maps to what sends a datagram in that session. Made
    by whoever builds the endpoint and given to it and to the DTLS shell, which adds and removes its
    sessions; while none is there, a datagram costs one test of an empty mapping."""

    def __init__(self) -> None:
        self.routes: dict[tuple[str, int], Callable[[bytes], None]] = {}
        #: What reads each path's socket (a DTLS port's, a DTLS session's): called before a firing
        #: judges the connections (``IoEndpoint._catch_up``), so that datagrams that came in time but
        #: wait unread after a stall of the loop are counted first, as those of the endpoint's own.
        self.catch_up: list[Callable[[], None]] = []


class _UdpIo(asyncio.DatagramProtocol):
    def __init__(self, endpoint: IoEndpoint) -> None:
        self.endpoint = endpoint

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        endpoint = self.endpoint
        try:
            receive = endpoint.core.receive   # a callable the core (or its seam) holds
            receive(data, addr, endpoint.loop.time())
        except Exception:  # a datagram must never take the I/O path down
            log.exception("class 1 datagram from %s", addr)

    def error_received(self, exc: Exception) -> None:
        log.debug("class 1 UDP error: %s", exc)


def udp_sockets_on(host: str, port: int) -> set[int] | None:
    """The inodes of the UDP sockets of this network namespace bound to exactly ``host:port``
    (Linux: sock_diag, ``udp_table``; else /proc/net/udp, whose local address is the 32-bit value
    in host order and the port in hex; the inode is the tenth column); None where neither can be read.
    The table is read in pages while other processes bind and close: a socket may be listed twice
    (hence a set)."""
    # The kernel's own filter first (sock_diag): the whole table, read at each of a fleet's thousand
    # binds, was most of a large fleet's start.
    inodes = udp_inodes_bound_to(host, port)
    if inodes is not None:
        return inodes
    wanted = f"{struct.unpack('=I', socket.inet_aton(host))[0]:08X}:{port:04X}"
    try:
        with open("/proc/net/udp", encoding="ascii") as table:
            next(table, None)  # the column headings
            rows = [line.split() for line in table if wanted in line]
    except OSError:
        return None
    return {int(row[9]) for row in rows if len(row) > 9 and row[1] == wanted}


def refuse_exact_sharer(sock: socket.socket) -> None:
    """Raise EADDRINUSE (``sock`` left to its caller to close) if another socket is bound to exactly
    the address and port ``sock`` has just bound.

    Linux lets two UDP sockets bind overlapping addresses (one on 0.0.0.0, one on 127.0.0.2, the
    same port) only if both set SO_REUSEADDR, and then lets a third bind exactly the address of
    one of them too (socket(7), SO_REUSEADDR; for UDP no listening state tells them apart). The
    class 1 socket sets it so that a scanner on 0.0.0.0:2222 can run beside the adapter; the exact
    duplicate, which would split the adapter's O->T datagrams with another process, is found here
    in the kernel's table and refused as a bind without the option would be."""
    host, port = sock.getsockname()
    others = (udp_sockets_on(host, port) or set()) - {os.fstat(sock.fileno()).st_ino}
    if others:
        raise OSError(errno.EADDRINUSE, os.strerror(errno.EADDRINUSE))


class IoEndpoint:
    """UDP socket + timer around an ``IoCore``: on the class 1 lane of a ``PreciseEventLoop``, or
    through asyncio's datagram transport and timers on any other loop."""

    def __init__(self, core: IoCore | None = None, host: str = "127.0.0.1", port: int = 2222,
                 multicast_ttl: Callable[[], int] = lambda: 1, exclusive: bool = False, *,
                 make_core: Callable[[IoEndpoint], IoCore] | None = None, gather_within: float = 0.0,
                 paths: DatagramPaths | None = None) -> None:
        """``core``, or ``make_core``: what makes the core around this endpoint, called once here with
        the endpoint, for a core that takes the endpoint's methods as its collaborators when it is made
        (a target's core wakes the endpoint when a Forward_Open adds a deadline; its filters send
        later through it), so that nothing is set on the core afterwards. ``paths``: the datagram
        paths besides the socket (DTLS sessions), by destination.

        ``gather_within`` (seconds, 0: off): while the endpoint's next firing is at most this far off,
        arriving datagrams do not wake the loop; the firing reads them all first, then produces and
        judges (``GATHER_WITHIN_S``). On the lane of a ``PreciseEventLoop`` only; elsewhere every
        datagram is read as it comes."""
        #: The address and port are this endpoint's alone: a second socket on exactly them is refused
        #: (a target's consuming port must be its own, see ``refuse_exact_sharer``), while a socket
        #: on the wildcard address and the same port may coexist (a scanner on 0.0.0.0:2222 beside
        #: an adapter on 127.0.0.2:2222). Elsewhere than Linux: bound without SO_REUSEADDR.
        self.exclusive = exclusive
        self.host = host
        self.port = port
        self.multicast_ttl = multicast_ttl
        #: The running loop, taken in ``start()`` (none is made here: one made outside a running loop
        #: would never be closed).
        self.loop: asyncio.AbstractEventLoop
        #: The loop's class 1 lane, or None on a loop without one.
        self._lane: IoLane | None = None
        #: Off the lane: the transport that queues what the socket cannot take at once.
        self.transport: asyncio.DatagramTransport | None = None
        #: The endpoint's socket (None once closed); sends go straight to it (see ``_send``).
        self._sock: socket.socket | None = None
        self._timer: LaneTimer | asyncio.TimerHandle | None = None
        self._timer_at: float | None = None
        #: Multicast groups joined: each socket, and off the lane its transport.
        self._groups: dict[tuple[str, int], tuple[socket.socket, asyncio.DatagramTransport | None]] = {}
        self.send_errors = 0
        #: Destinations whose datagrams go another way than the socket (a DTLS session's address).
        self.paths = paths or DatagramPaths()
        #: Datagrams are given to the core with the time the kernel received them (``stamp_arrivals``).
        self.kernel_arrival_times = False
        #: When each socket was last read to its end (``_catch_up``), by socket: the endpoint's own and
        #: each group's, every socket the endpoint reads.
        self._emptied_at: dict[socket.socket, float] = {}
        self.gather_within = gather_within
        #: A read stopped at ``DRAIN_LIMIT`` since the last catch-up: more may wait.
        self._left_unread = False
        #: Sockets read one datagram at a time (``_drain``), with when each was last read.
        self._lone: dict[socket.socket, float] = {}
        #: The sockets are left out of the wait until the next firing, which reads them (``_gather``).
        self._gathering = False
        if make_core is not None:
            core = make_core(self)   # last: the endpoint is whole when its core takes its methods
        if core is None:
            raise BadRequest("an IoEndpoint takes its core, or make_core to make it")
        self.core: IoCore = core

    async def start(self) -> None:
        self.loop = asyncio.get_running_loop()
        self._lane = lane_of(self.loop)
        if self._lane is None:
            self.gather_within = 0.0   # off the lane, asyncio's transport reads each datagram as it comes
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        # Sharing is for a port asked for by number (2222 beside a scanner on the wildcard). On port 0
        # Linux hands a SO_REUSEADDR socket a port another such socket holds (udp(7): sharing is allowed
        # when both set it), and two endpoints would then read each other's datagrams.
        chosen = self.port != 0
        shares_wildcard = chosen and self.exclusive and sys.platform.startswith("linux")
        if (chosen and not self.exclusive) or shares_wildcard:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((self.host, self.port))
            if shares_wildcard:
                refuse_exact_sharer(sock)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
            if self.host not in ("", "0.0.0.0"):
                sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(self.host))
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, self.multicast_ttl())
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
        except OSError:
            sock.close()
            raise
        self.transport = await self._serve(sock)
        self._sock = sock
        self._emptied_at[sock] = -math.inf
        self.port = sock.getsockname()[1]
        self.wakeup()
        # A target announces where it serves; an originator's socket is a detail of the command that
        # opened it (``cipstack io``, ``eds check --against``) and would only clutter its output.
        log.log(logging.INFO if self.exclusive else logging.DEBUG, "class 1 I/O on UDP %s:%d", self.host, self.port)

    @property
    def is_open(self) -> bool:
        """Started and not closed since."""
        return self._sock is not None

    @property
    def receive_buffer_size(self) -> int | None:
        """The receive buffer the kernel gave the endpoint's socket (``SO_RCVBUF``, bytes: Linux
        reports twice what was asked, ``RECEIVE_BUFFER``, capped at ``net.core.rmem_max``), or None
        when not open. Datagrams that come while the loop is held up wait there, or are lost."""
        sock = self._sock
        return None if sock is None else sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)

    def stamp_arrivals(self) -> bool:
        """From now on, give the core each datagram with the time the kernel received it, not the
        time the loop read it: what a capture shows, whatever delayed this process (on loopback, the
        moment the peer sent it). For measuring a target's timing; a socket read costs a little more.
        On the lane of a ``PreciseEventLoop`` under Linux only; returns whether it is so."""
        if self._lane is None or not sys.platform.startswith("linux"):
            return False
        if not self.kernel_arrival_times:
            self.kernel_arrival_times = True
            for sock in self._emptied_at:
                sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        return True

    async def _serve(self, sock: socket.socket) -> asyncio.DatagramTransport | None:
        """Feed what ``sock`` receives to the core: on the lane, or through a transport (returned)."""
        if self._lane is not None:
            sock.setblocking(False)
            if self.kernel_arrival_times:
                sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
            self._lane.add_reader(sock.fileno(), lambda: self._drain(sock), 0 if self._gathering else select.EPOLLIN)
            return None
        transport, _ = await self.loop.create_datagram_endpoint(lambda: _UdpIo(self), sock=sock)
        return transport

    def _drain(self, sock: socket.socket, whole: bool = False) -> None:
        """The lane's reader: what the socket holds, up to ``DRAIN_LIMIT`` datagrams, to the core, each
        with the time it was read, or with ``kernel_arrival_times`` the time the kernel received it.

        A socket that held one datagram at its last reading (a fleet drive's, whose one scanner sends
        once per RPI) is read one datagram at a time: the read that would find it empty is a system
        call and an exception per packet, and epoll, level-triggered, reports the socket again at once
        if more waits. Reported again that soon (within ``CATCH_UP_AFTER_S``), it is read to its end
        and judged again. ``whole``: read to the end whatever the socket held before (a catch-up, a
        gathering firing)."""
        receive, clock = self.core.receive, time.monotonic  # the lane's loop keeps time.monotonic()
        stamped = self.kernel_arrival_times
        if stamped:
            # The kernel stamps with the wall clock; the loop keeps the monotonic one. Their
            # difference, taken once per wake-up, converts (they drift apart by microseconds at most).
            offset = time.time() - clock()
        lone = self._lone
        single = False
        if not whole:
            lone_at = lone.get(sock)
            single = lone_at is not None and clock() - lone_at > CATCH_UP_AFTER_S
        for count in range(DRAIN_LIMIT):
            try:
                if stamped:
                    data, ancillary, _flags, source = sock.recvmsg(MAX_DATAGRAM, _STAMP_SPACE)
                else:
                    data, source = sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                emptied = self._emptied_at[sock] = clock()
                if count == 1:
                    lone[sock] = emptied
                else:
                    lone.pop(sock, None)
                return
            except OSError as exc:  # an ICMP error reported on the socket, or the socket closed
                log.debug("class 1 UDP error: %s", exc)
                self._emptied_at[sock] = clock()
                return
            now = _kernel_time(ancillary, offset) if stamped else None
            read_at = clock() if now is None else now
            try:
                receive(data, source, read_at)
            except Exception:  # a datagram must never take the I/O path down
                log.exception("class 1 datagram from %s", source)
            if single:
                lone[sock] = read_at if now is None else clock()
                return
        self._left_unread = True   # DRAIN_LIMIT read, and maybe more waiting

    def _catch_up(self, now: float) -> None:
        """Before any connection is judged silent, read what a socket not read to its end for
        ``CATCH_UP_AFTER_S`` still holds (at most what its receive buffer holds). After a stall of
        the loop (a long callback, a collection, a busy machine), datagrams that came in time wait
        unread, behind the first ``DRAIN_LIMIT`` of a wake-up or not yet seen at all; a watchdog
        judged first would close a connection whose peer kept its rate. On the lane, while datagrams
        flow, each wake-up reads to the end and this costs nothing; otherwise one read per firing.
        Off the lane, asyncio's transport reads one datagram per round of its loop, after which the
        due timers run: the firing reads the socket itself, which the transport then finds empty."""
        self._left_unread = False
        emptied = self._emptied_at
        for sock in emptied:
            for _ in range(CATCH_UP_READS):
                if now - emptied[sock] <= CATCH_UP_AFTER_S:
                    break
                self._drain(sock, whole=True)

    async def join_multicast(self, group: str, port: int) -> None:
        """Also receive what is sent to ``group:port`` (multicast T->O data), on this endpoint's interface.

        A socket bound to a unicast address never sees datagrams addressed to a group, so each
        group gets a socket of its own, bound to the group and port, feeding the same core."""
        key = (group, port)
        if key in self._groups:
            return
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((group, port))
            interface = self.host if self.host not in ("", "0.0.0.0") else "0.0.0.0"
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                            socket.inet_aton(group) + socket.inet_aton(interface))
        except OSError:
            sock.close()
            raise
        self._groups[key] = sock, await self._serve(sock)
        self._emptied_at[sock] = -math.inf

    def wakeup(self, deadline: float | None = None) -> None:
        """Re-arm the timer (a connection opened, so a deadline may be earlier); ``deadline``: the core's
        next deadline when the caller has just asked it (a firing that judged nothing)."""
        if deadline is None:
            deadline = self.core.next_deadline()
        if deadline is None or self._sock is None:
            return
        if self._timer is not None:
            if self._timer_at is not None and self._timer_at <= deadline:
                return
            self._timer.cancel()
        self._timer_at = deadline
        lane = self._lane
        self._timer = (lane.call_at(deadline, self._on_timer) if lane is not None
                       else self.loop.call_at(deadline, self._on_timer))

    def _on_timer(self) -> None:
        due_at = self._timer_at
        self._timer = None
        self._timer_at = None
        if self._sock is None:
            return
        now = self.loop.time()
        core = self.core
        poll, expire = core.poll, core.expire   # callables the seam holds: read as attributes, then called
        if self._gathering:
            for sock in self._emptied_at:   # what came since the last firing, before it is reported on
                self._drain(sock, whole=True)
        datagrams = poll(now, COALESCE_S)
        if datagrams:
            self._send(datagrams)
        # On the lane, a firing on time comes in the wake-up whose harvest read every socket that was
        # ready (level-triggered), or gathered them itself: only a late firing (the loop was held up)
        # or a read cut at ``DRAIN_LIMIT`` can leave datagrams unread, and only then is it worth a read
        # per socket (a system call and an exception when there is nothing). Unread datagrams matter
        # only to a watchdog or a silence judged now: with the productions moved on, a core whose next
        # deadline is still ahead judges nothing at this firing, and neither reads nor judges. That is
        # every firing of a process whose endpoints all fall due together (a fleet's drives on one
        # ``ProductionGrid``): the last of them fire milliseconds after their slot, behind the others,
        # and each read its socket once more for nothing.
        lane = self._lane
        deadline = None if lane is None else core.next_deadline()
        judged = lane is None or deadline is None or deadline <= now
        if judged:
            if lane is None or self._left_unread or due_at is None or now - due_at > CATCH_UP_AFTER_S:
                self._catch_up(now)
            # The other paths (DTLS sessions) are read before timeouts are judged.
            for read in self.paths.catch_up:
                read()
            expire(now)
            deadline = None   # what expire judged moved the deadlines: asked again
        self.wakeup(deadline)
        if self.gather_within:
            self._gather(self._timer_at is not None and self._timer_at - now <= self.gather_within)

    def _gather(self, gathering: bool) -> None:
        """Leave the sockets out of the wait (the next firing reads them) or put them back in."""
        if gathering is self._gathering or self._lane is None:
            return
        self._gathering = gathering
        events = 0 if gathering else select.EPOLLIN   # errors and hang-ups are always reported
        for sock in self._emptied_at:
            self._lane.watch(sock.fileno(), events)

    def send(self, datagrams: list[tuple[bytes, tuple[str, int]]]) -> None:
        """Send datagrams now, outside a firing (a production held back for a while), if still open."""
        if self._sock is not None:
            self._send(datagrams)

    def send_later(self, at: float, datagrams: list[tuple[bytes, tuple[str, int]]]) -> None:
        """Send datagrams at ``at`` on the running loop's clock (a delayed production), if open then."""
        asyncio.get_running_loop().call_at(at, self.send, datagrams)

    def _send(self, datagrams: list[tuple[bytes, tuple[str, int]]]) -> None:
        """The datagrams due in one firing, sent back to back on the socket itself (a transport's
        checks and bookkeeping cost more than the system call). Off the lane, whatever the socket
        cannot take at once goes through the transport, which queues it, and so does everything
        after it, in order; on the lane it is dropped and counted, as a full link drops it (the
        next production carries newer data anyway)."""
        sock, transport = self._sock, self.transport
        routes = self.paths.routes
        for index, (datagram, destination) in enumerate(datagrams):
            if routes:
                route = routes.get(destination)
                if route is not None:   # a connection opened over DTLS: its data flows in that session
                    route(datagram)
                    continue
            # asyncio's selector datagram transport has it; typeshed's DatagramTransport does not say so.
            if transport is not None and (sock is None or transport.get_write_buffer_size()):  # type: ignore[attr-defined]
                for queued, where in datagrams[index:]:
                    transport.sendto(queued, where)
                return
            try:
                sock.sendto(datagram, destination)  # type: ignore[union-attr]
            except (BlockingIOError, InterruptedError):
                if transport is None:
                    self.send_errors += 1
                    log.debug("class 1 send to %s dropped: the socket's buffer is full", destination)
                    continue
                sock = None
                transport.sendto(datagram, destination)
            except OSError as exc:
                self.send_errors += 1
                log.debug("class 1 send to %s failed: %s", destination, exc)

    async def close(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
            self._timer_at = None
        sockets = [(self._sock, self.transport)] if self._sock is not None else []
        sockets += self._groups.values()
        self._sock = self.transport = None
        self._groups.clear()
        self._emptied_at.clear()
        self._lone.clear()
        self._gathering = False
        for sock, transport in sockets:
            if transport is not None:
                transport.close()
            else:
                if self._lane is not None:
                    self._lane.remove_reader(sock.fileno())
                sock.close()


# What the loop's users import from here (the loop itself lives in precise_loop).
__all__ = [
    "CATCH_UP_AFTER_S",
    "CATCH_UP_READS",
    "COALESCE_S",
    "DRAIN_LIMIT",
    "GATHER_WITHIN_S",
    "MAX_DATAGRAM",
    "RECEIVE_BUFFER",
    "SO_TIMESTAMPNS",
    "DatagramPaths",
    "IoCore",
    "IoEndpoint",
    "freeze_startup_objects",
    "lane_of",
    "precise_event_loop",
    "refuse_exact_sharer",
    "run_precise",
    "udp_sockets_on"
]
