"""Admission limits of a TCP server, shared by every listener of the emulator (EtherNet/IP, Modbus TCP).

``ConnectionLimiter`` is sans-I/O bookkeeping: a total and a per-host bound on open connections.
A server asks ``admit(host)`` when a connection is accepted and closes it at once when refused,
and calls ``release(host)`` when an admitted connection ends.

``RateLimitedLog`` is the one rule of every refusal log line: each kind of refusal at most once per
10 s per source, the next line saying how many were held back (refused connections, sessions and
Forward_Opens, accept() failures, other users at the control socket, frames refused).

Running out of descriptors: asyncio (3.11) reports each ``EMFILE``/``ENFILE``/``ENOBUFS``/
``ENOMEM`` of accept() to the loop's exception handler with a traceback, and goes on trying the
rest of its accept batch (100), scheduling a retry for each failure: thousands of tracebacks and
timers per second under a connection flood. ``GuardedListener`` is a listening socket that never
lets that happen: it keeps one descriptor in reserve, and when accept() runs out it frees the
reserve, accepts the waiting connection, closes it at once (the client sees the close instead
of hanging in the backlog) and takes the reserve back, with one log line per 10 s.
``quiet_accept_errors`` is the second line of defence: any such report that still reaches the
loop (another listener) is one line per 10 s too, not a traceback.
"""

from __future__ import annotations

import asyncio
import errno
import logging
import os
import resource
import socket
import time
from collections.abc import Callable, Hashable
from typing import Any

from ...errors import BadRequest

log = logging.getLogger(__name__)

#: Default bound on open TCP connections per listener: well above what sessions need (32 by
#: default), well below the usual open-file limit (1,024).
DEFAULT_MAX_TCP_CONNECTIONS = 256

_OUT_OF_RESOURCES = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM})


def per_host_default(total: int) -> int:
    """Half of ``total`` (rounded up): one host can never hold every slot while there are two."""
    return max(1, (total + 1) // 2)


class ConnectionLimiter:
    """Open connections, in total and per host, against their bounds."""

    def __init__(self, total: int, per_host: int | None = None) -> None:
        if total < 1:
            raise BadRequest("the connection limit must be at least 1")
        self.total = total
        self.per_host = per_host if per_host is not None else per_host_default(total)
        if self.per_host < 1:
            raise BadRequest("the per-host connection limit must be at least 1")
        self.open = 0
        self.by_host: dict[str, int] = {}
        #: Connections refused since the start.
        self.refused = 0
        #: Connections closed to make room for another host (``admit_making_room``).
        self.evicted = 0

    def admit(self, host: str) -> bool:
        """Count a new connection from ``host`` in, or refuse it (nothing counted)."""
        held = self.by_host.get(host, 0)
        if self.open >= self.total or held >= self.per_host:
            self.refused += 1
            return False
        self.open += 1
        self.by_host[host] = held + 1
        return True

    def victim(self, host: str) -> str | None:
        """The host that should give up a connection so that ``host``, refused because every slot is
        taken, gets one; None when none should (``host`` is at its per-host limit, or nobody holds
        more than ``host`` would once admitted).

        Why eviction, and from whom: a fixed reserve of slots for new hosts only moves the wall (an
        attacker with as many addresses takes the reserve too); taking a slot from the host that holds
        the most, only while it holds more than the newcomer would (max-min fairness), lets every
        new host in as long as any host holds more than its fair share, costs nothing until the
        table is full, and never takes a connection from a host that holds as few as the newcomer.
        Which of its connections goes is the server's choice: the idlest."""
        held = self.by_host.get(host, 0)
        if self.open < self.total or held >= self.per_host or not self.by_host:
            return None
        biggest, count = max(self.by_host.items(), key=lambda item: item[1])
        return biggest if count > held + 1 else None

    def admit_making_room(self, host: str, close_idlest: Callable[[str, str], bool]) -> bool:
        """``admit``, and when every slot is taken, ``close_idlest(victim, host)`` (the server closes the
        idlest connection of ``victim`` and releases it; False if it had none) to let ``host`` in."""
        if self.admit(host):
            return True
        victim = self.victim(host)
        if victim is None or not close_idlest(victim, host):
            return False
        self.refused -= 1   # not refused after all: it takes the place made for it
        self.evicted += 1
        return self.admit(host)

    def release(self, host: str) -> None:
        held = self.by_host.get(host, 0)
        if held <= 0:
            return
        self.open -= 1
        if held == 1:
            del self.by_host[host]
        else:
            self.by_host[host] = held - 1

    def reason(self, host: str) -> str:
        """Why ``host`` was refused (for the log line)."""
        if self.by_host.get(host, 0) >= self.per_host:
            return f"{host} holds {self.by_host[host]} connections (per-host limit {self.per_host})"
        return f"{self.open} connections open (limit {self.total})"


#: The refusal log's interval: each kind of refusal is logged at most once per this many seconds
#: per source.
REFUSAL_LOG_INTERVAL = 10.0

#: Sources a ``RateLimitedLog`` keeps apart; past that, new sources share one line (``OTHER_SOURCES``)
#: until the entries of quiet ones can go, so a flood from many addresses cannot grow the table.
MAX_LOGGED_SOURCES = 256

#: The source that the sources past ``MAX_LOGGED_SOURCES`` share.
OTHER_SOURCES = "other sources"


class RateLimitedLog:
    """The one rule of every refusal log line: each kind of refusal (one ``RateLimitedLog``) is
    logged at most once per ``interval`` seconds per source; the next line of that source says how
    many were held back since its last one. A refusal is never silent for longer than the interval
    once it goes on, and a flood writes a bounded number of lines whatever its rate.

    ``source`` is whatever the refusal is from (an address, a user id; None: a refusal with no
    source, e.g. accept() out of descriptors); ``now`` is the time of a sans-I/O caller (else
    ``clock``)."""

    def __init__(self, logger: logging.Logger, interval: float = REFUSAL_LOG_INTERVAL, level: int = logging.WARNING,
                 clock: Callable[[], float] = time.monotonic, max_sources: int = MAX_LOGGED_SOURCES) -> None:
        self.logger = logger
        self.interval = interval
        self.level = level
        self.clock = clock
        self.max_sources = max_sources
        #: Per source: [time of its last line, refusals held back since].
        self._sources: dict[Hashable, list[float]] = {}
        #: Lines written and refusals held back since the start.
        self.written = 0
        self.held_back = 0

    @property
    def sources(self) -> tuple[Hashable, ...]:
        """The sources kept apart now, oldest first: at most ``max_sources`` of their own, then
        ``OTHER_SOURCES``, which those past the table share."""
        return tuple(self._sources)

    def __call__(self, message: str, *args: Any, source: Hashable = None, now: float | None = None) -> bool:
        """Log ``message % args`` unless a line of ``source`` went out less than ``interval`` ago;
        True when logged."""
        if now is None:
            now = self.clock()
        sources = self._sources
        entry = sources.get(source)
        if entry is None:
            if len(sources) >= self.max_sources:
                self._forget_quiet(now)
            if len(sources) >= self.max_sources:
                source = OTHER_SOURCES
                entry = sources.get(source)
            if entry is None:
                entry = sources[source] = [now, 0]
                return self._write(message, args, entry, now)
        if now - entry[0] < self.interval:
            entry[1] += 1
            self.held_back += 1
            return False
        return self._write(message, args, entry, now)

    def _write(self, message: str, args: tuple[Any, ...], entry: list[float], now: float) -> bool:
        if entry[1]:
            message += " (%d more like it in the last %.0f s)"
            args = (*args, int(entry[1]), now - entry[0])
        entry[0] = now
        entry[1] = 0
        self.written += 1
        self.logger.log(self.level, message, *args)
        return True

    def _forget_quiet(self, now: float) -> None:
        """Drop the sources whose interval has passed with nothing held back: nothing is lost."""
        for source in [s for s, (last, held) in self._sources.items() if not held and now - last >= self.interval]:
            del self._sources[source]


def quiet_accept_errors(loop: asyncio.AbstractEventLoop, interval: float = 10.0) -> None:
    """Make ``loop`` log accept() running out of descriptors or memory as one line per ``interval``
    instead of a traceback per failure; other errors go to the handler installed before."""
    if getattr(loop, "_cipstack_quiet_accept", False):
        return
    previous = loop.get_exception_handler()
    line = RateLimitedLog(log, interval)

    def handler(loop: asyncio.AbstractEventLoop, context: dict[str, Any]) -> None:
        exc = context.get("exception")
        if (isinstance(exc, OSError) and exc.errno in _OUT_OF_RESOURCES
                and "accept" in str(context.get("message", ""))):
            sock = context.get("socket")
            where = ""
            if sock is not None:
                try:
                    host, port = sock.getsockname()[:2]
                    where = f" on {host}:{port}"
                except OSError:
                    pass
            line("accept()%s failed: %s; new connections wait (lower --max-tcp-connections or raise "
                 "the open-file limit)", where, exc.strerror or exc)
            return
        if previous is not None:
            previous(loop, context)
        else:
            loop.default_exception_handler(context)

    loop.set_exception_handler(handler)
    loop._cipstack_quiet_accept = True  # type: ignore[attr-defined]


class GuardedListener(socket.socket):
    """A listening TCP socket whose accept() sheds connections instead of failing when the process
    is out of descriptors (see the module docstring). Pass it to ``loop.create_server(sock=...)``."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._reserve: int | None = _open_reserve()
        self.shed = 0
        self._line = RateLimitedLog(log)

    def accept(self) -> tuple[socket.socket, Any]:
        try:
            return super().accept()
        except OSError as exc:
            if exc.errno not in _OUT_OF_RESOURCES:
                raise
            self._shed(exc)
            # Nothing to hand the loop: to asyncio an empty accept queue, never an error.
            raise BlockingIOError(errno.EAGAIN, "connection shed") from None

    def _shed(self, exc: OSError) -> None:
        if self._reserve is not None:
            os.close(self._reserve)
            self._reserve = None
        try:
            conn, _ = super().accept()
        except OSError:
            conn = None
        if conn is not None:
            conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
            conn.close()
            self.shed += 1
        self._reserve = _open_reserve()
        host, port = self.getsockname()[:2]
        self._line("accept() on %s:%d failed: %s; the connection was closed (%d so far): lower "
                   "--max-tcp-connections or raise the open-file limit", host, port, exc.strerror or exc, self.shed)

    def close(self) -> None:
        if self._reserve is not None:
            os.close(self._reserve)
            self._reserve = None
        super().close()


def _open_reserve() -> int | None:
    try:
        return os.open(os.devnull, os.O_RDONLY)
    except OSError:
        return None


#: Connections the kernel holds for a listener until it accepts them (asyncio's default too).
LISTEN_BACKLOG = 100


def guarded_listener(host: str, port: int, backlog: int = LISTEN_BACKLOG, listen: bool = True) -> GuardedListener:
    """A ``GuardedListener`` bound to ``host:port`` and listening ("" or "0.0.0.0": every IPv4
    address; a name or an IPv6 address: its first address); with ``listen`` false only bound, so
    that it takes its port and accepts nothing yet (``listen()`` later)."""
    address: tuple[str, int] | tuple[str, int, int, int] | tuple[int, bytes]
    if host in ("", "0.0.0.0"):
        family, address = socket.AF_INET, ("0.0.0.0", port)
    else:
        family, _type, _proto, _name, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
    sock = GuardedListener(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        if listen:
            sock.listen(backlog)
        sock.setblocking(False)
    except OSError:
        sock.close()
        raise
    return sock


#: Descriptors kept free of TCP connections for everything else (UDP sockets, saves, control, Modbus).
DESCRIPTOR_RESERVE = 64


def fit_to_open_file_limit(limit: int, what: str = "--max-tcp-connections") -> int:
    """``limit``, raising the soft open-file limit toward the hard one if it is too low for it; if
    it still is, the largest limit that fits (with a warning line)."""
    try:
        soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    except (OSError, ValueError):
        return limit
    needed = limit + DESCRIPTOR_RESERVE
    if soft != resource.RLIM_INFINITY and soft < needed:
        target = needed if hard == resource.RLIM_INFINITY else min(needed, hard)
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
            soft = target
        except (OSError, ValueError):
            pass
    if soft != resource.RLIM_INFINITY and soft < needed:
        fitted = max(1, soft - DESCRIPTOR_RESERVE)
        log.warning("%s %d lowered to %d: the open-file limit is %d", what, limit, fitted, soft)
        return fitted
    return limit
