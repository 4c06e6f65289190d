"""EtherNet/IP over TLS (TCP 2221) as a shell around the same sans-I/O target.

Each accepted connection runs a server-side ``ssl.SSLObject`` over two ``ssl.MemoryBIO``s: bytes
from the socket go into the incoming BIO, the plaintext the TLS layer yields goes to the same
``EncapsulationConnection`` a plain TCP connection on 44818 gets (``EncapsulationTarget.connection``),
and its replies go back through the TLS layer. Sessions, the message router, the Connection Manager
and the class 3 timers are the target's own: TLS adds transport, no behaviour.

A handshake that fails (plain EtherNet/IP or garbage on the port, no client certificate, one from
another CA, no suite in common) closes that connection only: it is counted in ``refused`` and logged
once per source per 10 s (``RateLimitedLog``), never a traceback; nothing else is disturbed.
A handshake has ``HANDSHAKE_TIMEOUT`` seconds to complete.

Port 2221 is Wireshark's ``ENIP_SECURE_PORT`` (epan/dissectors/packet-enip.c); TLS 1.2 is the least
version (OpENer issue #228).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import ssl
from collections.abc import Callable
from typing import TYPE_CHECKING

from ..eip.target.limits import DEFAULT_MAX_TCP_CONNECTIONS, ConnectionLimiter, RateLimitedLog
from ..eip.target.seams import ReplySeam
from ..eip.wire.cpf import SockAddr
from ..errors import CipstackError
from .credentials import SECURE_PORT, describe_tls_failure

if TYPE_CHECKING:
    from ..eip.target.core import EncapsulationConnection, EncapsulationTarget
    from ..eip.target.seams import SecuredSeam
    from .credentials import Credentials
    from .tls_psk import PskTlsContext, TlsObject

log = logging.getLogger(__name__)

#: How a listener's TLS context is made of credentials: Python's ``ssl``, or with pre-shared keys
#: pyOpenSSL's in ``ssl``'s shape (``tls_psk``).
Recipe = Callable[["Credentials"], "ssl.SSLContext | PskTlsContext"]

#: Seconds a TLS handshake has from the connection's accept.
HANDSHAKE_TIMEOUT = 10.0
#: Seconds a refused connection is kept half-closed, its alert sent and what still comes discarded,
#: before it is reset: closed at once, data the peer sent after its handshake would make the kernel
#: reset the connection, and the peer could lose the alert that says why.
LINGER = 2.0
#: Plaintext asked of the TLS layer per read.
_READ_SIZE = 65536


class _TlsProtocol(asyncio.Protocol):
    """One TCP connection on the TLS port: the TLS layer in memory, then the encapsulation core."""

    def __init__(self, server: TlsServer) -> None:
        self.server = server
        self.loop = server.loop
        self.transport: asyncio.Transport | None = None
        self.connection: EncapsulationConnection | None = None
        self.host = "?"
        self.peer = "?"
        self._admitted = False
        self._incoming = ssl.MemoryBIO()
        self._outgoing = ssl.MemoryBIO()
        self._tls: ssl.SSLObject | TlsObject | None = None
        self._context: ssl.SSLContext | PskTlsContext | None = None
        self._local = SockAddr("0.0.0.0", server.port)
        self._timer: asyncio.TimerHandle | None = None
        self._timer_at: float | None = None
        self._refused = False

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
        if sockname:
            self._local = SockAddr(sockname[0], sockname[1])
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        transport.set_write_buffer_limits(high=64 * 1024)
        try:
            self._context = self.server.handshake_context()
        except (CipstackError, ssl.SSLError, OSError) as exc:   # what a fault presents did not load
            self.server.refuse(self.host, f"TLS connection from {self.peer} refused: {exc}")
            transport.abort()
            return
        self._tls = self._context.wrap_bio(self._incoming, self._outgoing, server_side=True)
        self._timer_at = self.loop.time() + self.server.handshake_timeout
        self._timer = self.loop.call_at(self._timer_at, self._on_timer)

    def data_received(self, data: bytes) -> None:
        tls, transport = self._tls, self.transport
        if tls is None or transport is None or transport.is_closing() or self._refused:
            return   # a refused connection's last bytes are discarded
        self._incoming.write(data)
        if self.connection is None and not self._handshake(tls):
            return
        plain = []
        try:
            while True:
                chunk = tls.read(_READ_SIZE)
                if not chunk:
                    break
                plain.append(chunk)
        except ssl.SSLWantReadError:
            pass
        except ssl.SSLZeroReturnError:   # close_notify: the peer is done
            self._serve(b"".join(plain))
            self._flush()
            transport.close()
            return
        except ssl.SSLError as exc:
            log.info("%s: TLS connection closed: %s", self.peer, describe_tls_failure(exc))
            self._flush()
            transport.close()
            return
        if plain:
            self._serve(b"".join(plain))
        self._flush()

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
            self.server.limiter.release(self.host)
            self.server.connections.discard(self)
            if self.connection is not None:
                self.connection.connection_lost()
                log.info("%s: TLS connection closed", self.peer)

    # -- the TLS layer --------------------------------------------------------------------------------
    def _handshake(self, tls: ssl.SSLObject | TlsObject) -> bool:
        """Go on with the handshake; True once it is done (the core's connection then exists)."""
        assert self.transport is not None
        try:
            tls.do_handshake()
        except ssl.SSLWantReadError:
            self._flush()
            return False
        except (ssl.SSLError, ValueError) as exc:
            self._flush()   # the alert that tells the peer why
            cause = _cause(tls, exc)
            if cause.startswith("no cipher suite in common") and self._context is not None:
                from .authority import allowed_names

                cause = f"{cause}: the device allows {allowed_names(self._context)}"
            self.server.refuse(self.host, f"TLS handshake from {self.peer} refused: {cause}")
            self._linger()
            return False
        self._flush()
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self.connection = self.server.target.connection(self.peer, self._local, self.loop.time())
        identity = getattr(tls, "psk_identity", None)
        log.info("%s: TLS connection accepted (%s, %s%s)", self.peer, tls.version(), (tls.cipher() or ("?",))[0],
                 named_identity(identity))
        self._arm()
        return True

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

    def _serve(self, plain: bytes) -> None:
        connection, tls, transport = self.connection, self._tls, self.transport
        if connection is None or tls is None or transport is None or not plain:
            return
        connection.receive(plain, self.loop.time())
        out = connection.data_to_send()
        if out:
            held = self.server.replies.filter
            if held is None:
                self._write(out)
            else:   # a fault at the reply seam (delayed replies) acts on TLS as on 44818
                held.reply(self, out)
        if connection.closing:
            self._flush()
            transport.close()
        elif self._timer is None:
            self._arm()
        elif connection.frame_started is not None:
            frame_deadline = connection.frame_deadline()
            if frame_deadline is not None and self._timer_at is not None and frame_deadline < self._timer_at:
                self._timer.cancel()
                self._arm()

    def _write(self, out: bytes) -> None:
        if out and self._tls is not None:
            try:
                self._tls.write(out)
            except ssl.SSLError as exc:
                log.debug("%s: TLS write: %s", self.peer, exc)

    def send_reply(self, out: bytes) -> None:
        """Send reply bytes taken from the connection earlier (a reply the reply seam held back)."""
        if self.transport is not None and not self.transport.is_closing():
            self._write(out)
            self._flush()

    def _flush(self) -> None:
        out = self._outgoing.read()
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
            if self._tls is not None and self.connection is not None:
                with contextlib.suppress(ssl.SSLError):
                    self._tls.unwrap()
                self._flush()
            self.transport.close()


def named_identity(identity: bytes | None) -> str:
    """``, PSK identity 'x'`` for a handshake made with a pre-shared key, else nothing."""
    return f", PSK identity '{identity.decode('ascii', 'replace')}'" if identity else ""


def _cause(tls: ssl.SSLObject | TlsObject, exc: BaseException) -> str:
    """Why a handshake failed; with a pre-shared key, the identity the peer named."""
    identity = getattr(tls, "psk_identity", None)
    reason = getattr(exc, "reason", None)
    if identity and reason:
        from .psk import explain

        return explain(reason, identity) or describe_tls_failure(exc)
    return describe_tls_failure(exc)


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
        self.seam = seam
        self._variant: tuple[int, ssl.SSLContext | PskTlsContext] | None = None
        self.limiter = ConnectionLimiter(max_connections, max_connections_per_host)
        #: Seconds a handshake has from the accept (``HANDSHAKE_TIMEOUT``).
        self.handshake_timeout = HANDSHAKE_TIMEOUT
        self.refused_log = RateLimitedLog(log)
        #: Connections refused (limits, handshakes that failed or timed out) since the start.
        self.refused = 0
        self.connections: set[_TlsProtocol] = set()
        self.loop: asyncio.AbstractEventLoop
        self._server: asyncio.base_events.Server | None = None

    def handshake_context(self) -> ssl.SSLContext | PskTlsContext:
        """The context of a new connection: ``context``, or while a fault is in the seam the one made
        for it (once per change of the seam)."""
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

    @property
    def is_open(self) -> bool:
        return self._server is not None

    async def start(self) -> None:
        """Listen on the TLS port (0: any free one, read back in ``port``)."""
        self.loop = asyncio.get_running_loop()
        self._server = await self.loop.create_server(lambda: _TlsProtocol(self), self.host, self.port,
                                                     reuse_address=True)
        self.port = self._server.sockets[0].getsockname()[1]
        log.info("EtherNet/IP over TLS listening on %s:%d (TCP)", self.host, self.port)

    async def close(self) -> None:
        server, self._server = self._server, None
        if server is None:
            return
        server.close()
        for connection in list(self.connections):
            connection.close()
        await server.wait_closed()


__all__ = ["HANDSHAKE_TIMEOUT", "Recipe", "TlsServer", "named_identity"]
