"""The asyncio shell of class 1 I/O, both roles: one UDP endpoint (2222 by default) and a
loop timer at the core's next deadline.

Timing: the default asyncio loop on Linux waits in epoll_wait(), whose timeout has millisecond
granularity and is rounded up, so a 1 ms RPI would jitter by up to a millisecond. select() has
microsecond timeouts but takes no descriptor numbered 1024 or above and scans every socket on
each wait. The ``precise_event_loop`` keeps both strengths: sockets are registered with epoll
(any descriptor number, no scan), and the wait is a select() on the one epoll descriptor (it
becomes readable when any registered socket is ready) with the exact timeout; the ready events
are then harvested with a non-blocking epoll_wait(). It also lowers the thread's timer slack:
sends then leave within tens of microseconds of their slot.
"""

from __future__ import annotations

import asyncio
import ctypes
import ctypes.util
import logging
import math
import select
import selectors
import socket
import sys
import time
from collections.abc import Callable, Coroutine
from typing import Any, Protocol, TypeVar

log = logging.getLogger(__name__)

T = TypeVar("T")

_PR_SET_TIMERSLACK = 29


def _lower_timer_slack(nanoseconds: int = 1000) -> None:
    """Linux rounds sleeps up by the timer slack (50 us by default); 1 us keeps sends on time."""
    if not sys.platform.startswith("linux"):
        return
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        libc.prctl(_PR_SET_TIMERSLACK, nanoseconds, 0, 0, 0)
    except (OSError, AttributeError):
        pass


#: A firing also sends what falls due this soon after it (each production at most 1/16 of its RPI
#: early, ``io_target.EARLY_SHARE``): connections opened one after another are due a few
#: microseconds apart, and one wake-up for several of them costs less than one each.
COALESCE_S = 0.0002

#: select() takes descriptors below FD_SETSIZE only (1024 on Linux).
FD_SETSIZE = 1024


class PreciseEpollSelector(selectors.EpollSelector):
    """epoll for registration and readiness, with a microsecond-precise wait (see the module docstring)."""

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        if timeout is None or timeout > 0:
            epoll_fd = self._selector.fileno()  # type: ignore[attr-defined]
            if epoll_fd < FD_SETSIZE:
                # Returns when a registered socket is ready or at the timeout, to the microsecond.
                select.select((epoll_fd,), (), (), timeout)
            elif timeout is not None:
                # The epoll descriptor itself is numbered too high for select() (the loop was made
                # after 1,024 files were open): wait the whole milliseconds in epoll, then sleep
                # the remainder, so timers still fire on time (events wait at most that remainder).
                whole_ms = math.floor(timeout * 1000)
                if whole_ms:
                    ready = super().select((whole_ms - 0.5) / 1000)  # epoll rounds up: exactly whole_ms
                    if ready:
                        return ready
                remainder = timeout - whole_ms / 1000
                if remainder > 0:
                    time.sleep(remainder)
            else:
                return super().select(None)
        return super().select(0)


def precise_event_loop() -> asyncio.AbstractEventLoop:
    """An event loop whose timers fire within tens of microseconds and that takes any number of sockets."""
    _lower_timer_slack()
    return asyncio.SelectorEventLoop(PreciseEpollSelector())


def run_precise(coroutine: Coroutine[Any, Any, T]) -> T:
    """``asyncio.run`` on a precise event loop."""
    loop = precise_event_loop()
    asyncio.set_event_loop(loop)
    try:
        return loop.run_until_complete(coroutine)
    finally:
        try:
            loop.run_until_complete(loop.shutdown_asyncgens())
        finally:
            asyncio.set_event_loop(None)
            loop.close()


class IoCore(Protocol):
    """The sans-I/O side: ``IoTarget`` or an originator's connection set."""

    def receive(self, raw: bytes, source: tuple[str, int], now: float) -> None: ...

    def poll(self, now: float, horizon: float = 0.0) -> list[tuple[bytes, tuple[str, int]]]: ...

    def next_deadline(self) -> float | None: ...

    def expire(self, now: float) -> list[Any]: ...


class _UdpIo(asyncio.DatagramProtocol):
    def __init__(self, endpoint: IoEndpoint) -> None:
        self.endpoint = endpoint

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        endpoint = self.endpoint
        try:
            endpoint.core.receive(data, addr, endpoint.loop.time())
        except Exception:  # a datagram must never take the I/O path down
            log.exception("class 1 datagram from %s", addr)

    def error_received(self, exc: Exception) -> None:
        log.debug("class 1 UDP error: %s", exc)


class IoEndpoint:
    """UDP socket + timer around an ``IoCore``."""

    def __init__(self, core: IoCore, host: str = "127.0.0.1", port: int = 2222,
                 multicast_ttl: Callable[[], int] = lambda: 1, exclusive: bool = False) -> None:
        self.core = core
        #: Bind without SO_REUSEADDR, so that a second process cannot bind the same port and take
        #: the datagrams (a target's consuming port must be its own).
        self.exclusive = exclusive
        self.host = host
        self.port = port
        self.multicast_ttl = multicast_ttl
        #: The running loop, taken in ``start()`` (none is made here: one made outside a running loop
        #: would never be closed).
        self.loop: asyncio.AbstractEventLoop
        self.transport: asyncio.DatagramTransport | None = None
        #: The transport's socket, for the sends of a timer firing (see ``_on_timer``).
        self._sock: socket.socket | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at: float | None = None
        self._groups: dict[tuple[str, int], asyncio.DatagramTransport] = {}
        self.send_errors = 0

    async def start(self) -> None:
        self.loop = asyncio.get_running_loop()
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        if not self.exclusive:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((self.host, self.port))
            if self.host not in ("", "0.0.0.0"):
                sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(self.host))
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, self.multicast_ttl())
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
        except OSError:
            sock.close()
            raise
        transport, _ = await self.loop.create_datagram_endpoint(lambda: _UdpIo(self), sock=sock)
        self.transport = transport  # type: ignore[assignment]
        self._sock = sock
        self.port = sock.getsockname()[1]
        self.wakeup()
        log.info("class 1 I/O on UDP %s:%d", self.host, self.port)

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
        transport, _ = await self.loop.create_datagram_endpoint(lambda: _UdpIo(self), sock=sock)
        self._groups[key] = transport  # type: ignore[assignment]

    def wakeup(self) -> None:
        """Re-arm the timer (a connection opened, so a deadline may be earlier)."""
        deadline = self.core.next_deadline()
        if deadline is None:
            return
        if self._timer is not None:
            if self._timer_at is not None and self._timer_at <= deadline:
                return
            self._timer.cancel()
        self._timer_at = deadline
        self._timer = self.loop.call_at(deadline, self._on_timer)

    def _on_timer(self) -> None:
        self._timer = None
        self._timer_at = None
        now = self.loop.time()
        transport = self.transport
        if transport is None:
            return
        datagrams = self.core.poll(now, COALESCE_S)
        if datagrams:
            self._send(transport, datagrams)
        self.core.expire(now)
        self.wakeup()

    def _send(self, transport: asyncio.DatagramTransport, datagrams: list[tuple[bytes, tuple[str, int]]]) -> None:
        """The datagrams due in one firing, sent back to back on the socket itself (the transport's
        checks and bookkeeping cost more than the system call); whatever the socket cannot take at
        once goes through the transport, which queues it, and so does everything after it, in order."""
        sock = self._sock
        for index, (datagram, destination) in enumerate(datagrams):
            if sock is None or transport.get_write_buffer_size():
                for queued, where in datagrams[index:]:
                    transport.sendto(queued, where)
                return
            try:
                sock.sendto(datagram, destination)
            except (BlockingIOError, InterruptedError):
                sock = None
                transport.sendto(datagram, destination)
            except OSError as exc:
                self.send_errors += 1
                log.debug("class 1 send to %s failed: %s", destination, exc)

    async def close(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self.transport is not None:
            self.transport.close()
            self.transport = None
            self._sock = None
        for transport in self._groups.values():
            transport.close()
        self._groups.clear()
