"""Connections of the TLS port served on the lane of a ``PreciseEventLoop``.

As 44818's connections are (``eip.target.tcp_lane``): the socket is read in the selector's wait, its
bytes go to the connection's ``TlsSession`` and what that has to send goes out with one ``send``,
with no asyncio handle, transport buffer or flow-control bookkeeping per request. Behaviour is that
of the asyncio path (``tls_target._TlsProtocol``), rule for rule:

* admission: the TLS server's ``ConnectionLimiter`` and refusal line;
* the handshake: ``HANDSHAKE_TIMEOUT`` from the accept; one that fails sends its alert, and the
  connection is half-closed (the alert goes out with a FIN), what still comes is read and dropped,
  and it is reset after ``LINGER`` seconds or when the peer closes;
* back-pressure: what the socket cannot take at once is kept, and nothing more is read until it has
  gone, so what is held is at most one read's replies;
* closing: what the session still has to send (an alert, a close_notify, the last replies) goes out
  before the socket closes;
* timers: one lane timer at the connection's next deadline (inactivity, class 3 timeouts), re-armed
  lazily; before it judges, the timer reads what waits unread on the socket.
"""

from __future__ import annotations

import contextlib
import logging
import select
import socket
from time import monotonic
from typing import TYPE_CHECKING

from ..eip.target.tcp_lane import RECEIVE_SIZE
from ..eip.wire.cpf import SockAddr
from .tls_session import LINGER

if TYPE_CHECKING:
    from ..eip.precise_loop import IoLane, LaneTimer
    from ..eip.target.core import EncapsulationConnection
    from .tls_target import TlsServer

log = logging.getLogger("cipstack.security.tls_target")

_READABLE = select.EPOLLIN
_WRITABLE = select.EPOLLOUT
#: SO_LINGER on, 0 s: close() resets the connection.
_RESET = b"\x01\x00\x00\x00\x00\x00\x00\x00"


class LaneTlsConnection:
    """One accepted connection of the TLS port, served on the lane."""

    def __init__(self, server: TlsServer, sock: socket.socket, host: str, peer: str, lane: IoLane) -> None:
        self.server = server
        self.sock = sock
        self.lane = lane
        self.host = host
        self.peer = peer
        self._fd = sock.fileno()
        local = sock.getsockname()
        self.session = server.session(peer, SockAddr(local[0], local[1]))
        #: Bytes the socket has not taken yet; reading waits until they are gone.
        self._unsent = b""
        self._close_when_sent = False
        self._closed = False
        self._refused = False
        self._timer: LaneTimer | None = lane.call_at(monotonic() + server.handshake_timeout, self._on_timer)

    @classmethod
    def accepted(cls, server: TlsServer, sock: socket.socket, peer: tuple[str, int],
                 lane: IoLane) -> LaneTlsConnection | None:
        host = peer[0] if peer else "?"
        if not server.limiter.admit(host):
            server.refuse(host, f"TLS connection from {host} refused: {server.limiter.reason(host)}")
            with contextlib.suppress(OSError):   # the peer may have reset it already
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, _RESET)
            sock.close()
            return None
        try:
            sock.setblocking(False)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            served = cls(server, sock, host, f"{peer[0]}:{peer[1]}", lane)
        except OSError as exc:   # reset before we looked at it
            server.limiter.release(host)
            sock.close()
            log.debug("TLS connection from %s lost at accept: %s", host, exc)
            return None
        server.connections.add(served)
        lane.add_reader(served._fd, served._on_ready)
        return served

    @property
    def connection(self) -> EncapsulationConnection | None:
        """The encapsulation connection, once the handshake is done."""
        return self.session.connection

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
            log.debug("%s: %s", self.peer, exc)
            self.close(notify=False)
            return
        if not data:
            self.close(notify=False)
            return
        if self._refused:
            return   # a refused connection's last bytes are discarded
        session = self.session
        handshaking = session.connection is None
        replies = session.receive(data, monotonic())
        if session.refusal is not None:
            self._refuse(f"TLS handshake from {self.peer} refused: {session.refusal}")
            return
        connection = session.connection
        if connection is None:
            self._send(session.data_to_send())   # the handshake's next flight
            return
        if handshaking and self._timer is not None:   # done: the connection's own timers from now on
            self._timer.cancel()
            self._timer = None
        self.server.deliver(self, session, replies)
        out = session.data_to_send()
        if out:
            self._send(out)
        if self._closed:
            return
        if session.ended or connection.closing:
            self._close_when_sent = True
            if not self._unsent:
                self.close(notify=False)
            return
        timer = self._timer
        if timer is None:
            self._arm()
        elif connection.frame_started is not None:
            # A frame has begun: its deadline may come before the timer's (the timer re-arms lazily).
            frame_deadline = connection.frame_deadline()
            if frame_deadline is not None and frame_deadline < timer.when:
                timer.cancel()
                self._arm()

    def _send(self, out: bytes) -> None:
        if not out:
            return
        try:
            sent = self.sock.send(out)
        except (BlockingIOError, InterruptedError):
            sent = 0
        except OSError as exc:
            log.debug("%s: %s", self.peer, exc)
            self.close(notify=False)
            return
        if sent < len(out):
            self._unsent = out[sent:]
            self.lane.watch(self._fd, _WRITABLE)   # and read nothing more until it has gone

    def _flush(self) -> None:
        unsent, self._unsent = self._unsent, b""
        self._send(unsent)
        if self._closed or self._unsent:
            return
        if self._close_when_sent:
            self.close(notify=False)
        else:
            self.lane.watch(self._fd, _READABLE)

    def send_reply(self, out: bytes) -> None:
        """Send reply bytes taken from the connection earlier (a reply the reply seam held back), after
        whatever is still unsent."""
        if self._closed or self._refused:
            return
        self.session.send(out)
        sealed = self.session.data_to_send()
        if self._unsent:
            self._unsent += sealed
        else:
            self._send(sealed)

    # -- refusals and timers ---------------------------------------------------------------------------
    def _refuse(self, line: str) -> None:
        """Count and log the refusal, send the alert and half-close: what the peer still sends is read
        and dropped until it closes too, or ``LINGER`` seconds pass."""
        self.server.refuse(self.host, line)
        self._refused = True
        self._send(self.session.data_to_send())
        if self._closed:
            return
        if self._timer is not None:
            self._timer.cancel()
        try:
            self.sock.shutdown(socket.SHUT_WR)
        except OSError:
            self.close(notify=False)
            return
        self._timer = self.lane.call_at(monotonic() + LINGER, self._abort)

    def _abort(self) -> None:
        """Closed without a word (asyncio's ``abort()`` on the other path): what the peer sent unread
        makes it a reset."""
        self._timer = None
        self.close(notify=False)

    def _arm(self) -> None:
        connection = self.session.connection
        assert connection is not None
        deadline = connection.next_deadline()
        self._timer = self.lane.call_at(deadline, self._on_timer) if deadline is not None else None

    def _on_timer(self) -> None:
        if self._closed:
            return
        connection = self.session.connection
        if connection is None:   # the handshake did not finish in time
            self._timer = None
            self.server.refuse(self.host, f"TLS handshake from {self.peer} refused: not complete after "
                                          f"{self.server.handshake_timeout:g} s")
            self._abort()
            return
        if not self._unsent:
            # What came in time but waits unread is traffic: it counts before the timers judge the
            # connection's silence (as on 44818's lane). ``_timer`` still names this timer, which has
            # fired: the read arms no other.
            self._on_ready()
        self._timer = None
        if self._closed:
            return
        connection.on_timer(monotonic())
        if connection.closing or self._close_when_sent:
            self.close(notify=False)
        else:
            self._arm()

    # -- the end ---------------------------------------------------------------------------------------
    def close(self, notify: bool = True) -> None:
        """Close the connection; ``notify``: our close_notify first (the server closing, not the peer)."""
        if self._closed:
            return
        if notify and not self._refused:
            self.session.close_notify()
            out = self._unsent + self.session.data_to_send()
            with contextlib.suppress(OSError):
                self.sock.send(out)
        self._closed = True
        self._unsent = b""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self.lane.remove_reader(self._fd)
        self.sock.close()
        self.server.closed(self, self.host, self.session.connection)


__all__ = ["LaneTlsConnection"]
