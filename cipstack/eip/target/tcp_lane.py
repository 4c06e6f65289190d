"""Encapsulation TCP connections served on the lane of a ``PreciseEventLoop``.

On that loop the ``EncapsulationServer`` accepts its connections and serves their bytes in the
selector's wait (``precise_loop.IoLane``), as the class 1 sockets are: a request costs one
``recv``, the sans-I/O ``EncapsulationConnection`` and one ``send``, with no asyncio handle,
transport buffer or flow-control bookkeeping between them. That bookkeeping was most of the
server's own time per Get_Attribute_Single; what is left is the system calls and the CIP work.

Behaviour is that of the asyncio path (``server._TcpProtocol``), rule for rule:

* admission: the same ``ConnectionLimiter``, the same refusal log line; the listener is the same
  ``GuardedListener``, so running out of descriptors sheds the waiting connection;
* back-pressure: a reply the socket cannot take at once is kept, the connection then waits for
  the socket to be writable and reads nothing until that reply has gone, so what is held is at
  most one read's replies, whatever a client that never reads sends;
* closing: what the connection still has to send (a 0x0065 reply to an oversized frame) goes
  out before the socket closes;
* timers: one lane timer per connection at its next deadline (inactivity, class 3 timeouts),
  re-armed lazily as on the asyncio path; before it judges, the timer reads what waits unread on
  the socket, so a request that came in time is not lost to a stall of the loop.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import select
import socket
from collections.abc import Callable
from time import monotonic
from typing import TYPE_CHECKING

from ..precise_loop import IoLane, LaneTimer
from ..wire.cpf import SockAddr
from .limits import LISTEN_BACKLOG

if TYPE_CHECKING:
    from .core import EncapsulationConnection
    from .limits import GuardedListener
    from .server import EncapsulationServer

log = logging.getLogger(__name__)

#: Bytes asked of the socket per readiness: the largest frame the target takes is 4,224 bytes by
#: default, and a pipelining client's requests are taken several at a time.
RECEIVE_SIZE = 65536

#: Connections accepted per readiness of the listener before other sockets get their turn.
ACCEPT_BATCH = 32

_READABLE = select.EPOLLIN
_WRITABLE = select.EPOLLOUT


class LaneListener:
    """A listening socket on the lane: accepts and hands each connection to ``accepted(sock, peer)``
    (``LaneTcpConnection.accepted`` for 44818, the TLS port's own for 2221). Made on a bound socket;
    ``start_serving`` listens."""

    def __init__(self, sock: GuardedListener, lane: IoLane,
                 accepted: Callable[[socket.socket, tuple[str, int]], object]) -> None:
        self.sock = sock
        self.lane = lane
        self.accepted = accepted
        self._fd = sock.fileno()

    def start_serving(self) -> None:
        self.sock.listen(LISTEN_BACKLOG)
        self.lane.add_reader(self._fd, self._accept)

    def _accept(self) -> None:
        for _ in range(ACCEPT_BATCH):
            try:
                sock, peer = self.sock.accept()  # a shed connection is BlockingIOError (``limits``)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # the peer gave up in the backlog (ECONNABORTED), and the like
                log.debug("accept() on %s: %s", self.sock.getsockname(), exc)
                if exc.errno not in (errno.ECONNABORTED, errno.EPROTO, errno.EPERM):
                    return
                continue
            self.accepted(sock, peer)

    def close(self) -> None:
        self.lane.remove_reader(self._fd)
        self.sock.close()


class LaneTcpConnection:
    """One accepted TCP connection of the encapsulation server, served on the lane."""

    def __init__(self, server: EncapsulationServer, sock: socket.socket, host: str, peer_text: str,
                 lane: IoLane) -> None:
        self.server = server
        self.sock = sock
        self.lane = lane
        self.host = host
        self._fd = sock.fileno()
        local = sock.getsockname()
        self.connection: EncapsulationConnection = server.opened(self, peer_text, SockAddr(local[0], local[1]))
        #: Reply bytes the socket has not taken yet; reading waits until they are gone.
        self._unsent = b""
        self._close_when_sent = False
        self._closed = False
        self._timer: LaneTimer | None = None

    @classmethod
    def accepted(cls, server: EncapsulationServer, sock: socket.socket, peer: tuple[str, int],
                 lane: IoLane) -> LaneTcpConnection | None:
        host = peer[0] if peer else "?"
        if not server.admit(host):
            with contextlib.suppress(OSError):  # the peer may have reset it already
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
            sock.close()  # a reset, as asyncio's abort() gives on the other path
            return None
        try:
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            peer_text = f"{peer[0]}:{peer[1]}"
            served = cls(server, sock, host, peer_text, lane)
        except OSError as exc:  # reset before we looked at it
            server.closed(None, host, None)
            sock.close()
            log.debug("TCP connection from %s lost at accept: %s", host, exc)
            return None
        lane.add_reader(served._fd, served._on_ready)
        served._arm()
        return served

    # -- the lane's callbacks --------------------------------------------------------------------
    def _on_ready(self) -> None:
        if self._unsent:
            self._flush()
            return
        try:
            data = self.sock.recv(RECEIVE_SIZE)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            log.debug("%s: %s", self.connection.peer, exc)
            self.close()
            return
        if not data:
            self.close()
            return
        connection = self.connection
        connection.receive(data, monotonic())  # the lane's loop keeps time.monotonic()
        out = connection.data_to_send()
        if out:
            held = self.server.replies.filter
            if held is None:
                self._send(out)
            else:
                held.reply(self, out)
        if connection.closing:
            self._close_when_sent = True
            if not self._unsent:
                self.close()
                return
        if self._timer is None:
            self._arm()
        elif connection.frame_started is not None:
            # A frame has begun: its deadline may come before the timer's (the timer re-arms lazily).
            frame_deadline = connection.frame_deadline()
            if frame_deadline is not None and frame_deadline < self._timer.when:
                self._timer.cancel()
                self._arm()

    def _send(self, out: bytes) -> None:
        try:
            sent = self.sock.send(out)
        except (BlockingIOError, InterruptedError):
            sent = 0
        except OSError as exc:
            log.debug("%s: %s", self.connection.peer, exc)
            self.close()
            return
        if sent < len(out):
            self._unsent = out[sent:]
            self.lane.watch(self._fd, _WRITABLE)  # and read nothing more until it has gone

    def send_reply(self, out: bytes) -> None:
        """Send reply bytes taken from the connection earlier (a reply held back for a while), after
        whatever is still unsent."""
        if self._closed:
            return
        if self._unsent:
            self._unsent += out
        else:
            self._send(out)

    def _flush(self) -> None:
        unsent = self._unsent
        self._unsent = b""
        self._send(unsent)
        if self._closed or self._unsent:
            return
        if self._close_when_sent:
            self.close()
        else:
            self.lane.watch(self._fd, _READABLE)

    def _arm(self) -> None:
        deadline = self.connection.next_deadline()
        self._timer = self.lane.call_at(deadline, self._on_timer) if deadline is not None else None

    def _on_timer(self) -> None:
        # Deadlines move forward with traffic; the timer fires at the old one and re-arms lazily.
        if not self._closed and not self._unsent:
            # What came in time but waits unread (the loop stalled past this deadline, and the wait
            # runs due timers before it reads sockets) is traffic: it counts before the timers judge
            # the connection's silence (inactivity, class 3 timeouts). Nothing waiting: one recv.
            # ``_timer`` still names this timer, which has fired: the read arms no other.
            self._on_ready()
        self._timer = None
        if self._closed:
            return
        connection = self.connection
        connection.on_timer(monotonic())
        if connection.closing or self._close_when_sent:
            # Idle past the inactivity timeout; or closing with a reply its peer has not read for as
            # long: nothing more is owed.
            self.close()
        else:
            self._arm()

    # -- the end ---------------------------------------------------------------------------------------
    def write_buffer_size(self) -> int:
        """Reply bytes held because the socket would not take them."""
        return len(self._unsent)

    def evict(self) -> None:
        """Closed (reset) to make room for another host: its place is free at once."""
        with contextlib.suppress(OSError):
            self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
        self.close()

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._unsent = b""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self.lane.remove_reader(self._fd)
        self.sock.close()
        self.server.closed(self, self.host, self.connection)

