"""TLS 1.2 with pre-shared keys through pyOpenSSL, in the shape of the standard library's ``ssl``.

The TLS port and the originators speak TLS through ``ssl.SSLContext.wrap_bio`` and ``ssl.SSLObject``
over two ``ssl.MemoryBIO``s (sans-I/O; asyncio's own TLS transport does the same). Python's ``ssl``
offers PSK callbacks only from 3.13, and cipstack supports 3.10 and later, so a context that holds a
pre-shared key is a pyOpenSSL one (``psk``), for every Python version alike: one path, tested
wherever the package runs. ``PskTlsContext.wrap_bio`` returns a ``TlsObject`` with the methods of
``ssl.SSLObject`` those callers use, and raises the ``ssl`` module's exceptions (``SSLWantReadError``,
``SSLZeroReturnError``, ``SSLError`` with OpenSSL's reason in ``reason``), so ``tls_target``, asyncio
and ``describe_tls_failure`` serve it unchanged. ``TlsSocket`` is the blocking originator's socket
over it.

Such a context speaks TLS 1.2 only (the PSK suites are TLS 1.2's; ``psk``) and offers, beside the PSK
suites, the certificate suites of the EtherNet/IP Security object when the folder has certificates.
"""

from __future__ import annotations

import socket
import ssl
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

from ..errors import PeerUnreachable, SecurityError
from .dtls import KeyLog, check_crl, require_pyopenssl, use_certificates
from .psk import (
    PSK_SUITES,
    PskServer,
    explain,
    offer_psk,
    reason_code,
    serve_psk,
    unread,
    verify_message,
    written,
)

if TYPE_CHECKING:
    from OpenSSL import SSL

    from .credentials import Credentials

#: Ciphertext taken from the socket per read (the blocking originator's).
_CHUNK = 65536
#: The largest plaintext of one TLS record (RFC 5246, 6.2.1).
_RECORD = 16384


def _translate(exc: Exception, connection: Any) -> ssl.SSLError:
    """pyOpenSSL's error as the ``ssl`` module raises it: ``reason`` in its upper-case form."""
    entries = exc.args[0] if exc.args and isinstance(exc.args[0], list) else []
    reasons = [entry[2] for entry in entries if isinstance(entry, tuple) and len(entry) == 3 and entry[2]]
    # OpenSSL queues the cause first and what it led to after ("record layer failure"): a cause that
    # is about the key is the one to name; else the last, as the ssl module reports it.
    about_key = [reason for reason in reasons if explain(reason, None) is not None]
    text = (about_key or reasons or [str(exc) or type(exc).__name__])[-1]
    code = reason_code(text)
    if code.startswith("TLS_ALERT_"):   # OpenSSL 3's text for the alerts the ssl module names SSLV3_ALERT_
        code = "SSLV3_" + code[len("TLS_"):]
    if code == "CERTIFICATE_VERIFY_FAILED":
        error: ssl.SSLError = ssl.SSLCertVerificationError(1, f"[SSL: {code}] {text}")
        error.verify_message = verify_message(connection)   # type: ignore[attr-defined]  # as ssl sets it
    else:
        error = ssl.SSLError(1, f"[SSL: {code}] {text}")
    error.reason = code   # ssl.SSLError's attributes, set as _ssl sets them
    error.library = "SSL"
    return error


class TlsObject:
    """A pyOpenSSL ``Connection`` over two ``ssl.MemoryBIO``s, with ``ssl.SSLObject``'s methods."""

    def __init__(self, connection: SSL.Connection, incoming: ssl.MemoryBIO, outgoing: ssl.MemoryBIO,
                 server_side: bool, keys: PskServer | None) -> None:
        from OpenSSL import SSL

        self._ssl = SSL
        self.connection = connection
        self.incoming = incoming
        self.outgoing = outgoing
        self.server_side = server_side
        self.server_hostname: str | None = None
        self._keys = keys
        #: The identity the peer named (device side), once the handshake read it.
        self.psk_identity: bytes | None = None
        self._established = False

    def _call(self, operation: Any, *args: Any) -> Any:
        SSL = self._ssl
        data = self.incoming.read()
        if data:
            self.connection.bio_write(data)
        try:
            return operation(*args)
        except SSL.WantReadError:
            raise ssl.SSLWantReadError(ssl.SSL_ERROR_WANT_READ, "The operation did not complete (read)") from None
        except SSL.ZeroReturnError:
            raise ssl.SSLZeroReturnError(ssl.SSL_ERROR_ZERO_RETURN, "TLS/SSL connection has been closed (EOF)") \
                from None
        except SSL.SysCallError as exc:
            raise ssl.SSLEOFError(ssl.SSL_ERROR_EOF, f"EOF occurred in violation of protocol ({exc})") from None
        except SSL.Error as exc:
            raise _translate(exc, self.connection) from None
        finally:
            if self._keys is not None and self.psk_identity is None and not self._established:
                self.psk_identity = self._keys.identity_of(self.connection)
            self._drain()

    def _drain(self) -> None:
        pending = written(self.connection)
        while pending > 0:
            self.outgoing.write(self.connection.bio_read(pending))
            pending = written(self.connection)

    # -- ssl.SSLObject's methods ------------------------------------------------------------------------
    def do_handshake(self) -> None:
        self._call(self.connection.do_handshake)
        self._established = True

    def read(self, size: int = 1024, buffer: Any = None) -> Any:
        # One call yields one record's plaintext at most (2^14 octets, RFC 5246 6.2.1): pyOpenSSL
        # allocates the size asked for each call, so no more is asked.
        size = min(size, _RECORD) if size > 0 else _RECORD
        if buffer is not None:
            return self._call(self.connection.recv_into, buffer, size)
        return self._call(self.connection.recv, size)

    def write(self, data: bytes) -> int:
        return int(self._call(self.connection.send, bytes(data)))

    def unwrap(self) -> None:
        """Send close_notify (the peer's is not waited for)."""
        self._call(self.connection.shutdown)

    def pending(self) -> int:
        """Plaintext of the record being read, and the ciphertext of those after it: pyOpenSSL was
        given every octet the incoming BIO had (``_call``), so ``MemoryBIO.pending`` no longer counts
        them (``tls_session`` reads while either waits)."""
        return int(self.connection.pending()) + unread(self.connection)

    def version(self) -> str | None:
        return str(self.connection.get_protocol_version_name())

    def cipher(self) -> tuple[str, str, int] | None:
        name = self.connection.get_cipher_name()
        if name is None:
            return None
        return (name, str(self.connection.get_cipher_version()), int(self.connection.get_cipher_bits() or 0))

    def getpeercert(self, binary_form: bool = False) -> Any:
        certificate = self.connection.get_peer_certificate(as_cryptography=True)
        if certificate is None:
            return None
        if binary_form:
            from cryptography.hazmat.primitives.serialization import Encoding

            return certificate.public_bytes(Encoding.DER)
        return {"subject": ((("commonName", certificate.subject.rfc4514_string()),),)}

    def compression(self) -> None:
        return None

    def selected_alpn_protocol(self) -> None:
        return None


class PskTlsContext:
    """A pyOpenSSL TLS context with ``ssl.SSLContext.wrap_bio``'s signature (what the TLS port and
    asyncio's TLS transport call)."""

    def __init__(self, context: SSL.Context, server: PskServer | None, names: Sequence[str] = ()) -> None:
        self.context = context
        #: The device's keys (None on the originator's side).
        self.keys = server
        #: The suites of ``context``, OpenSSL's names (pyOpenSSL reads them only from a connection, after
        #: which the context no longer changes).
        self.names = list(names)

    def get_ciphers(self) -> list[dict[str, Any]]:
        """``ssl.SSLContext.get_ciphers``'s shape (name, IANA id, protocol), for the suites faults refuse
        and a refusal names (``authority``)."""
        from .suites import suite_id

        return [{"name": name, "id": 0x03000000 | (suite_id(name) or 0), "protocol": "TLSv1.2"}
                for name in self.names]

    def set_ciphers(self, names: str) -> None:
        """Narrow the suites (before the first connection), as ``ssl.SSLContext.set_ciphers``."""
        from OpenSSL import SSL

        try:
            self.context.set_cipher_list(names.encode())
        except SSL.Error as exc:
            raise ssl.SSLError(f"No cipher can be selected ({exc})") from None
        self.names = names.split(":")

    def wrap_bio(self, incoming: ssl.MemoryBIO, outgoing: ssl.MemoryBIO, server_side: bool = False,
                 server_hostname: str | None = None, session: Any = None) -> TlsObject:
        from OpenSSL import SSL

        connection = SSL.Connection(self.context, None)
        if server_side:
            connection.set_accept_state()
        else:
            connection.set_connect_state()
        return TlsObject(connection, incoming, outgoing, server_side, self.keys if server_side else None)


def psk_context(credentials: Credentials, server: bool, keys: Iterable[tuple[bytes, bytes]] = (),
                suites: Sequence[str] = (), verify_client: bool = True) -> PskTlsContext:
    """The TLS 1.2 context of the device (``server``, with ``keys``) or of the originator (with the
    folder's PSK): of ``suites`` (OpenSSL's names), the PSK suites with a key and the certificate
    suites with the folder's certificate, key and CA when it has them."""
    return PskTlsContext(*openssl_context(credentials, server, keys, suites, verify_client))


def openssl_context(credentials: Credentials, server: bool, keys: Iterable[tuple[bytes, bytes]] = (),
                    suites: Sequence[str] = (), verify_client: bool = True,
                    datagram: bool = False) -> tuple[SSL.Context, PskServer | None, list[str]]:
    """``psk_context``'s pyOpenSSL context, the device's keys and the suites' names; ``datagram``: DTLS 1.2 rather than
    TLS 1.2 (a device's DTLS port configured over the network, ``endpoint.dtls_server_context``)."""
    require_pyopenssl()
    from OpenSSL import SSL

    from .dtls import DTLS1_2_VERSION

    if datagram:
        context = SSL.Context(SSL.DTLS_SERVER_METHOD if server else SSL.DTLS_CLIENT_METHOD)
        version = DTLS1_2_VERSION
    else:
        context = SSL.Context(SSL.TLS_SERVER_METHOD if server else SSL.TLS_CLIENT_METHOD)
        version = SSL.TLS1_2_VERSION
    context.set_min_proto_version(version)
    context.set_max_proto_version(version)
    pair = credentials.device if server else credentials.client
    names: list[str] = []
    # ``suites`` may name PSK suites too (the device's Allowed Cipher Suites): the device offers those
    # it lists; the originator every PSK suite, or those ``Credentials.offering`` chose.
    chosen = server or bool(credentials.suites)
    psk_names = [name for name in suites if name in PSK_SUITES] if chosen else list(PSK_SUITES)
    suites = [name for name in suites if name not in PSK_SUITES]
    if pair is not None and credentials.ca is not None and suites:
        role = "device" if server else "client"
        use_certificates(context, credentials, pair, role)
        names += suites
        if server:
            context.set_verify(SSL.VERIFY_PEER | SSL.VERIFY_FAIL_IF_NO_PEER_CERT if verify_client else SSL.VERIFY_NONE)
        else:
            context.set_verify(SSL.VERIFY_PEER)
            check_crl(context, credentials)
    keeper: PskServer | None = None
    if server:
        keeper = serve_psk(context, keys)
        names = [*psk_names, *names] if keeper.keys else names
    elif credentials.psk is not None:
        offer_psk(context, credentials.psk.identity, credentials.psk.key)
        names = [*psk_names, *names]   # the originator prefers its key: the device picks among both
    if not names:
        raise SecurityError(f"{credentials.folder}: neither a pre-shared key nor certificates for TLS")
    try:
        context.set_cipher_list(":".join(names).encode())
    except SSL.Error as exc:
        raise SecurityError(f"this OpenSSL offers none of the suites {':'.join(names)} ({exc})") from None
    if credentials.keylog:
        context.set_keylog_callback(KeyLog(credentials.keylog))
    return context, keeper, names


class TlsSocket:
    """The blocking originator's socket after a TLS handshake through a ``TlsObject``: ``sendall`` and
    ``recv`` of plaintext, the socket's timeout (``TimeoutError``) and addresses."""

    def __init__(self, sock: socket.socket, context: PskTlsContext) -> None:
        self.sock = sock
        self._incoming = ssl.MemoryBIO()
        self._outgoing = ssl.MemoryBIO()
        self.tls = context.wrap_bio(self._incoming, self._outgoing, server_side=False)

    def handshake(self) -> None:
        """Complete the handshake: ``ssl.SSLError`` for a refusal, ``OSError`` for the socket's end."""
        while True:
            try:
                self.tls.do_handshake()
            except ssl.SSLWantReadError:
                self._flush()
                self._fill()
                continue
            self._flush()
            return

    def _flush(self) -> None:
        data = self._outgoing.read()
        if data:
            self.sock.sendall(data)

    def _fill(self) -> bool:
        data = self.sock.recv(_CHUNK)
        if not data:
            raise PeerUnreachable("the device closed the connection")
        self._incoming.write(data)
        return True

    def sendall(self, data: bytes) -> None:
        self.tls.write(data)
        self._flush()

    def recv(self, size: int) -> bytes:
        while True:
            try:
                return bytes(self.tls.read(size))
            except ssl.SSLWantReadError:
                self._flush()
            except ssl.SSLZeroReturnError:
                return b""
            data = self.sock.recv(_CHUNK)
            if not data:
                return b""
            self._incoming.write(data)

    def settimeout(self, timeout: float | None) -> None:
        self.sock.settimeout(timeout)

    def setsockopt(self, *args: Any) -> None:
        self.sock.setsockopt(*args)

    def getsockname(self) -> Any:
        return self.sock.getsockname()

    def getpeername(self) -> Any:
        return self.sock.getpeername()

    def close(self) -> None:
        """close_notify, then the socket."""
        try:
            self.tls.unwrap()
            self._flush()
        except (OSError, ssl.SSLError):
            pass
        self.sock.close()


__all__ = ["PskTlsContext", "TlsObject", "TlsSocket", "openssl_context", "psk_context"]
