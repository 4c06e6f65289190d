"""The TLS layer of one connection on the TLS port, in memory: ciphertext in, ciphertext out.

A server-side ``ssl.SSLObject`` over two ``ssl.MemoryBIO``s, and once its handshake is done the
``EncapsulationConnection`` its plaintext goes to. No socket, no loop: both shells of the TLS port
(asyncio's transports in ``tls_target``, the precise loop's lane in ``tls_lane``) give it what the
socket read, seal the replies it hands back (or hold them at the reply seam first) and send what
``data_to_send`` returns, so the two serve by the same rules.

A request costs one record opened and one sealed. The records waiting are read while ciphertext or
opened plaintext remains (``MemoryBIO.pending``, ``SSLObject.pending``): OpenSSL takes a stream's
records from the BIO one at a time, exactly (no read-ahead), so nothing is left behind, and no
``SSLWantReadError`` is raised and caught per request to find the end.
"""

from __future__ import annotations

import contextlib
import logging
import ssl
from collections.abc import Callable
from typing import TYPE_CHECKING

from .credentials import describe_tls_failure

if TYPE_CHECKING:
    from ..eip.target.core import EncapsulationConnection
    from .tls_psk import PskTlsContext, TlsObject

log = logging.getLogger("cipstack.security.tls_target")

#: Plaintext asked of the TLS layer per read: more than a record holds (16 KiB).
_READ_SIZE = 65536
#: Seconds a refused connection is kept half-closed, its alert sent and what still comes discarded,
#: before it is reset: closed at once, data the peer sent after its handshake would make the kernel
#: reset the connection, and the peer could lose the alert that says why.
LINGER = 2.0


class TlsSession:
    """One connection's TLS layer and, after its handshake, its encapsulation connection."""

    def __init__(self, context: ssl.SSLContext | PskTlsContext,
                 open_connection: Callable[[float], EncapsulationConnection], peer: str,
                 refusal: str | None = None) -> None:
        """``open_connection(now)``: the target's connection for this peer, made when the handshake is
        done (``EncapsulationTarget.connection`` with the peer's and the local address); ``refusal``:
        why the connection is refused before its first byte."""
        self._context = context
        self._incoming = ssl.MemoryBIO()
        self._outgoing = ssl.MemoryBIO()
        self._tls: ssl.SSLObject | TlsObject = context.wrap_bio(self._incoming, self._outgoing, server_side=True)
        self._open_connection = open_connection
        self.peer = peer
        #: The encapsulation connection, once the handshake is done.
        self.connection: EncapsulationConnection | None = None
        #: Why the handshake failed, in one line: the shell refuses the connection.
        self.refusal: str | None = refusal
        #: The TLS layer has ended (the peer's close_notify, a bad record): send what is out, then close.
        self.ended = False

    def receive(self, data: bytes, now: float) -> bytes:
        """Take ``data`` from the socket: the handshake goes on, or the records are opened and their
        plaintext served. Returns the encapsulation connection's replies in plaintext, for ``send``."""
        if self.refusal is not None or self.ended:
            return b""   # a refused or ended connection's last bytes are discarded
        self._incoming.write(data)
        connection = self.connection
        if connection is None:
            if not self._handshake(now):
                return b""
            connection = self.connection
            assert connection is not None
        plain = self._open_records()
        if not plain:
            return b""
        connection.receive(plain, now)
        return connection.data_to_send()

    def send(self, plain: bytes) -> None:
        """Seal reply bytes into records (``data_to_send`` then has them)."""
        if plain:
            try:
                self._tls.write(plain)
            except ssl.SSLError as exc:
                log.debug("%s: TLS write: %s", self.peer, exc)

    def data_to_send(self) -> bytes:
        """The ciphertext to send: handshake flights, alerts, sealed replies."""
        return self._outgoing.read()

    def close_notify(self) -> None:
        """Our close_notify (``data_to_send`` then has it), after a completed handshake."""
        if self.connection is not None and self.refusal is None:
            # SSLWantReadError when the peer's close_notify has not come: ours is written all the same.
            with contextlib.suppress(ssl.SSLError):
                self._tls.unwrap()

    # -- inside ---------------------------------------------------------------------------------------
    def _handshake(self, now: float) -> bool:
        """Go on with the handshake; True once it is done (the encapsulation connection then exists)."""
        tls = self._tls
        try:
            tls.do_handshake()
        except ssl.SSLWantReadError:
            return False
        except (ssl.SSLError, ValueError) as exc:
            refusal = _cause(tls, exc)   # its alert is in the outgoing BIO
            if refusal.startswith("no cipher suite in common"):
                from .authority import allowed_names

                refusal = f"{refusal}: the device allows {allowed_names(self._context)}"
            self.refusal = refusal
            return False
        self.connection = self._open_connection(now)
        if log.isEnabledFor(logging.INFO):
            log.info("%s: TLS connection accepted (%s, %s%s)", self.peer, tls.version(),
                     (tls.cipher() or ("?",))[0], named_identity(getattr(tls, "psk_identity", None)))
        return True

    def _open_records(self) -> bytes:
        tls, incoming = self._tls, self._incoming
        chunks = []
        try:
            while incoming.pending or tls.pending():
                chunk = tls.read(_READ_SIZE)
                if not chunk:   # close_notify: the peer is done; what came before it is served
                    self.ended = True
                    break
                chunks.append(chunk)
        except ssl.SSLWantReadError:   # the rest of a record is still on its way
            pass
        except ssl.SSLZeroReturnError:   # close_notify, as some versions of ``ssl`` tell it
            self.ended = True
        except ssl.SSLError as exc:
            log.info("%s: TLS connection closed: %s", self.peer, describe_tls_failure(exc))
            self.ended = True
            return b""
        return chunks[0] if len(chunks) == 1 else b"".join(chunks)


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


__all__ = ["LINGER", "TlsSession", "named_identity"]
