"""EtherNet/IP over TLS (TCP 2221) as a shell around the same sans-I/O target.

Each accepted connection runs a ``TlsSession`` (``tls_session``): a server-side ``ssl.SSLObject``
over two ``ssl.MemoryBIO``s, whose plaintext goes to the same ``EncapsulationConnection`` a plain
TCP connection on 44818 gets (``EncapsulationTarget.connection``), and whose replies go back through
the TLS layer. Sessions, the message router, the Connection Manager and the class 3 timers are the
target's own: TLS adds transport, no behaviour.

On a ``PreciseEventLoop`` (the command line's) the listener and its connections are served on the
loop's lane (``tls_lane``), as 44818's are (``tcp_lane``): a request costs one ``recv``, one record
opened, the core, one record sealed and one ``send``, with no asyncio handle or transport between
them. On any other loop they go through asyncio's transports (``_TlsProtocol``), by the same rules.

A handshake that fails (plain EtherNet/IP or garbage on the port, no client certificate, one from
another CA, no suite in common) closes that connection only: it is counted in ``refused`` and logged
once per source per 10 s (``RateLimitedLog``), never a traceback; nothing else is disturbed.
A handshake has ``HANDSHAKE_TIMEOUT`` seconds to complete.

Port 2221 is Wireshark's ``ENIP_SECURE_PORT`` (epan/dissectors/packet-enip.c); TLS 1.2 is the least
version (OpENer issue #228).
"""

from __future__ import annotations

import asyncio
import logging
import socket
import ssl
from collections.abc import Callable
from typing import TYPE_CHECKING

from ..eip.precise_loop import lane_of
from ..eip.target.limits import DEFAULT_MAX_TCP_CONNECTIONS, ConnectionLimiter, RateLimitedLog, guarded_listener
from ..eip.target.seams import ReplySeam
from ..eip.target.tcp_lane import LaneListener
from ..eip.wire.cpf import SockAddr
from ..errors import CipstackError, SecurityError
from .credentials import SECURE_PORT
from .tls_lane import LaneTlsConnection
from .tls_session import LINGER, TlsSession, named_identity

if TYPE_CHECKING:
    from ..eip.target.core import EncapsulationConnection, EncapsulationTarget
    from ..eip.target.seams import SecuredSeam
    from .credentials import Credentials
    from .tls_psk import PskTlsContext

log = logging.getLogger(__name__)

#: How a listener's TLS context is made of credentials: Python's ``ssl``, or with pre-shared keys
#: pyOpenSSL's in ``ssl``'s shape (``tls_psk``).
Recipe = Callable[["Credentials"], "ssl.SSLContext | PskTlsContext"]

#: Seconds a TLS handshake has from the connection's accept.
HANDSHAKE_TIMEOUT = 10.0


class _TlsProtocol(asyncio.Protocol):
    """One TCP connection on the TLS port served through asyncio's transport (on a loop other than the
    precise one): its ``TlsSession`` between the transport and the encapsulation core."""

    def __init__(self, server: TlsServer) -> None:
        self.server = server
        self.loop = server.loop
        self.transport: asyncio.Transport | None = None
        self.session: TlsSession | None = None
        self.host = "?"
        self.peer = "?"
        self._admitted = False
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at: float | None = None
        self._refused = False

    @property
    def connection(self) -> EncapsulationConnection | None:
        return self.session.connection if self.session is not None else None

    # -- asyncio's callbacks ------------------------------------------------------------------------
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        peer = transport.get_extra_info("peername")
        self.host = peer[0] if peer else "?"
        self.peer = f"{peer[0]}:{peer[1]}" if peer else "?"
        if not self.server.limiter.admit(self.host):
            self.server.refuse(self.host, f"TLS connection from {self.host} refused: "
                                          f"{self.server.limiter.reason(self.host)}")
            transport.abort()
            return
        self._admitted = True
        self.transport = transport
        self.server.connections.add(self)
        sockname = transport.get_extra_info("sockname")
        local = SockAddr(sockname[0], sockname[1]) if sockname else SockAddr("0.0.0.0", self.server.port)
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        transport.set_write_buffer_limits(high=64 * 1024)
        self.session = self.server.session(self.peer, local)
        self._timer_at = self.loop.time() + self.server.handshake_timeout
        self._timer = self.loop.call_at(self._timer_at, self._on_timer)

    def data_received(self, data: bytes) -> None:
        session, transport = self.session, self.transport
        if session is None or transport is None or transport.is_closing() or self._refused:
            return   # a refused connection's last bytes are discarded
        handshaking = session.connection is None
        replies = session.receive(data, self.loop.time())
        if session.refusal is not None:
            self._flush()   # the alert that tells the peer why
            self.server.refuse(self.host, f"TLS handshake from {self.peer} refused: {session.refusal}")
            self._linger()
            return
        connection = session.connection
        if connection is None:
            self._flush()   # the handshake's next flight
            return
        if handshaking and self._timer is not None:   # done: the connection's own timers from now on
            self._timer.cancel()
            self._timer = None
        self.server.deliver(self, session, replies)
        self._flush()
        if session.ended or connection.closing:
            transport.close()
        elif self._timer is None:
            self._arm()
        elif connection.frame_started is not None:
            frame_deadline = connection.frame_deadline()
            if frame_deadline is not None and self._timer_at is not None and frame_deadline < self._timer_at:
                self._timer.cancel()
                self._arm()

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
        if self._admitted:
            self._admitted = False
            self.server.closed(self, self.host, self.connection)

    def _linger(self) -> None:
        """Half-close a refused connection: the alert goes out with a FIN, what the peer still sends is
        read and dropped until it closes too, or ``LINGER`` seconds pass."""
        transport = self.transport
        assert transport is not None
        self._refused = True
        if self._timer is not None:
            self._timer.cancel()
        if not transport.can_write_eof():
            transport.close()
            return
        transport.write_eof()
        self._timer = self.loop.call_later(LINGER, transport.abort)

    def eof_received(self) -> bool | None:
        return None   # the transport closes: a refused peer is done, or an accepted one closed its side

    def send_reply(self, out: bytes) -> None:
        """Send reply bytes taken from the connection earlier (a reply the reply seam held back)."""
        if self.session is not None and self.transport is not None and not self.transport.is_closing():
            self.session.send(out)
            self._flush()

    def _flush(self) -> None:
        out = self.session.data_to_send() if self.session is not None else b""
        if out and self.transport is not None and not self.transport.is_closing():
            self.transport.write(out)

    # -- timers ---------------------------------------------------------------------------------------
    def _arm(self) -> None:
        assert self.connection is not None
        deadline = self.connection.next_deadline()
        self._timer_at = deadline
        self._timer = self.loop.call_at(deadline, self._on_timer) if deadline is not None else None

    def _on_timer(self) -> None:
        self._timer = None
        transport = self.transport
        if transport is None or transport.is_closing():
            return
        connection = self.connection
        if connection is None:   # the handshake did not finish in time
            self.server.refuse(self.host, f"TLS handshake from {self.peer} refused: not complete after "
                                          f"{self.server.handshake_timeout:g} s")
            transport.abort()
            return
        connection.on_timer(self.loop.time())
        self._flush()
        if connection.closing:
            transport.close()
        else:
            self._arm()

    def close(self) -> None:
        if self.transport is not None:
            if self.session is not None:
                self.session.close_notify()
                self._flush()
            self.transport.close()


class TlsServer:
    """The TLS listener of one target: ``EncapsulationServer``'s TCP side on the secure port."""

    def __init__(self, target: EncapsulationTarget, credentials: Credentials, host: str = "127.0.0.1",
                 port: int = SECURE_PORT, verify_client: bool = True,
                 max_connections: int = DEFAULT_MAX_TCP_CONNECTIONS,
                 max_connections_per_host: int | None = None, replies: ReplySeam | None = None,
                 context: ssl.SSLContext | PskTlsContext | None = None, seam: SecuredSeam | None = None,
                 recipe: Recipe | None = None) -> None:
        """``replies``: the seam replies pass on their way out, the plain server's (``seams.ReplySeam``);
        ``recipe``: how the TLS context is made of credentials (a configuration applied over the
        network narrows the suites; one with pre-shared keys makes a ``tls_psk.PskTlsContext``), else
        the credentials' own; ``context``: one made already; ``seam``: where faults change what the
        next handshakes present (``SecuredSeam``)."""
        self.target = target
        self.replies = replies or ReplySeam()
        self.credentials = credentials
        self.host = host
        self.port = port
        self.recipe: Recipe = recipe or (lambda made: made.server_context(verify_client))
        #: The TLS context every connection's ``SSLObject`` is made from, while no fault changes it.
        self.context: ssl.SSLContext | PskTlsContext = context or self.recipe(credentials)
        #: The folder's ``crl.pem`` the context was made with (``Credentials.crl_stamp``); a context given
        #: ready-made is not remade.
        self._crl = credentials.crl_stamp() if context is None else False
        self.seam = seam
        self._variant: tuple[int, ssl.SSLContext | PskTlsContext] | None = None
        self.limiter = ConnectionLimiter(max_connections, max_connections_per_host)
        #: Seconds a handshake has from the accept (``HANDSHAKE_TIMEOUT``).
        self.handshake_timeout = HANDSHAKE_TIMEOUT
        self.refused_log = RateLimitedLog(log)
        #: Connections refused (limits, handshakes that failed or timed out) since the start.
        self.refused = 0
        self.connections: set[_TlsProtocol | LaneTlsConnection] = set()
        self.loop: asyncio.AbstractEventLoop
        #: The listener: asyncio's server, or on a ``PreciseEventLoop`` the lane's (``tls_lane``).
        self._server: asyncio.base_events.Server | LaneListener | None = None

    def handshake_context(self) -> ssl.SSLContext | PskTlsContext:
        """The context of a new connection: ``context``, or while a fault is in the seam the one made
        for it (once per change of the seam); both remade when the folder's CRL changed."""
        if self._crl is not False and (stamp := self.credentials.crl_stamp()) != self._crl:
            self._crl = stamp
            try:
                self.context, self._variant = self.recipe(self.credentials), None
            except SecurityError as exc:
                log.error("the TLS port keeps the contexts it had: %s", exc)
        seam = self.seam
        if seam is None or not seam.handshake:
            return self.context
        if self._variant is None or self._variant[0] != seam.generation:
            from .authority import tls_variant

            self._variant = (seam.generation, tls_variant(self.credentials, self.recipe, seam))
        return self._variant[1]

    def refuse(self, source: str, line: str) -> None:
        """Count one refused connection; its line is logged at most once per source per 10 s."""
        self.refused += 1
        self.refused_log("%s", line, source=source)

    # -- what both kinds of connection (``_TlsProtocol``, ``LaneTlsConnection``) share -------------------
    def session(self, peer: str, local: SockAddr) -> TlsSession:
        """The TLS layer of a connection accepted from ``peer`` on ``local``, with the context a fault in
        the seam makes; one that does not load refuses the connection (``TlsSession.refusal``)."""
        target = self.target
        try:
            return TlsSession(self.handshake_context(), lambda now: target.connection(peer, local, now), peer)
        except (CipstackError, ssl.SSLError, OSError) as exc:   # what a fault presents did not load
            return TlsSession(self.context, lambda now: target.connection(peer, local, now), peer,
                              refusal=f"what the fault presents did not load: {exc}")

    def deliver(self, served: _TlsProtocol | LaneTlsConnection, session: TlsSession, replies: bytes) -> None:
        """Seal ``replies`` of ``served``'s session, or hand them to a fault at the reply seam (delayed
        replies act on TLS as on 44818); after the peer's close_notify, ours, behind the replies."""
        if replies:
            held = self.replies.filter
            if held is None:
                session.send(replies)
            else:
                held.reply(served, replies)
        if session.ended:
            session.close_notify()

    def closed(self, served: _TlsProtocol | LaneTlsConnection, host: str,
               connection: EncapsulationConnection | None) -> None:
        """An admitted connection has ended: its host's place is free, its sessions end with it."""
        self.limiter.release(host)
        self.connections.discard(served)
        if connection is not None:
            connection.connection_lost()
            log.info("%s: TLS connection closed", connection.peer)

    @property
    def is_open(self) -> bool:
        return self._server is not None

    async def start(self) -> None:
        """Listen on the TLS port (0: any free one, read back in ``port``)."""
        self.loop = asyncio.get_running_loop()
        lane = lane_of(self.loop)
        if lane is not None:
            listener = guarded_listener(self.host, self.port, listen=False)
            self.port = listener.getsockname()[1]
            self._server = LaneListener(listener, lane, lambda sock, peer: LaneTlsConnection.accepted(
                self, sock, peer, lane))
            self._server.start_serving()
        else:
            server = await self.loop.create_server(lambda: _TlsProtocol(self), self.host, self.port,
                                                   reuse_address=True)
            self.port = server.sockets[0].getsockname()[1]
            self._server = server
        log.info("EtherNet/IP over TLS listening on %s:%d (TCP)", self.host, self.port)

    async def close(self) -> None:
        server, self._server = self._server, None
        if server is None:
            return
        server.close()
        for connection in list(self.connections):
            connection.close()
        if not isinstance(server, LaneListener):
            await server.wait_closed()


__all__ = ["HANDSHAKE_TIMEOUT", "Recipe", "TlsServer", "named_identity"]
