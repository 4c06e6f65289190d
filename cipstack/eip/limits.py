"""Admission limits of a TCP server, shared by every listener of the emulator (EtherNet/IP, Modbus TCP).

``ConnectionLimiter`` is sans-I/O bookkeeping: a total and a per-host bound on open connections.
A server asks ``admit(host)`` when a connection is accepted and closes it at once when refused,
and calls ``release(host)`` when an admitted connection ends.

``RateLimitedLog`` turns a flood of identical events (refused connections, accept() failures)
into one log line per interval that says how many happened.

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
from collections.abc import Callable
from typing import Any

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
            raise ValueError("the connection limit must be at least 1")
        self.total = total
        self.per_host = per_host if per_host is not None else per_host_default(total)
        if self.per_host < 1:
            raise ValueError("the per-host connection limit must be at least 1")
        self.open = 0
        self.by_host: dict[str, int] = {}
        #: Connections refused since the start.
        self.refused = 0

    def admit(self, host: str) -> bool:
        """Count a new connection from ``host`` in, or refuse it (nothing counted)."""
        held = self.by_host.get(host, 0)
        if self.open >= self.total or held >= self.per_host:
            self.refused += 1
            return False
        self.open += 1
        self.by_host[host] = held + 1
        return True

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


class RateLimitedLog:
    """At most one log line per ``interval`` seconds; the next line says how many were held back."""

    def __init__(self, logger: logging.Logger, interval: float = 10.0, level: int = logging.WARNING,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.logger = logger
        self.interval = interval
        self.level = level
        self.clock = clock
        self._last: float | None = None
        self._held_back = 0

    def __call__(self, message: str, *args: Any) -> bool:
        """Log ``message % args`` unless a line went out less than ``interval`` ago; True when logged."""
        now = self.clock()
        if self._last is not None and now - self._last < self.interval:
            self._held_back += 1
            return False
        if self._held_back:
            message += " (%d more like it in the last %.0f s)"
            args = (*args, self._held_back, now - self._last if self._last is not None else 0.0)
        self._last = now
        self._held_back = 0
        self.logger.log(self.level, message, *args)
        return True


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
