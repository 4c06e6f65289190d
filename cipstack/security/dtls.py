"""DTLS 1.2 as bytes in, bytes out: pyOpenSSL's DTLS over two memory BIOs, for both roles.

``DtlsChannel`` is the sans-I/O record layer a shell feeds with the datagrams it reads and drains of
the datagrams to send; it never touches a socket or a clock of its own. Its retransmission deadline
(``DTLSv1_get_timeout``) is read by the shell, which calls ``on_timer`` when it passes, so a
handshake whose flight was lost is resent by the shell's own loop (no thread, no blocking read).

``dtls_context`` builds the pyOpenSSL context of either role from the same credentials folder TLS
uses (``Credentials``): DTLS 1.2 at least, the device's or the client's certificate, the peer's
certificate checked against the CA, and ``SSLKEYLOGFILE`` honoured through the key log callback
(Wireshark's DTLS dissector reads the same NSS key log format as its TLS dissector). A folder with a
pre-shared key adds the PSK suites of DTLS 1.2 (``psk``).

pyOpenSSL is imported only here, when DTLS is asked for: the ``security`` extra installs it.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from ..errors import SecurityError

if TYPE_CHECKING:
    from OpenSSL import SSL

    from .credentials import Credentials

#: DTLS 1.2's version number on the wire (RFC 6347, 4.1: {254, 253}); pyOpenSSL names no constant
#: for it, and OpenSSL's ``SSL_CTX_set_min_proto_version`` takes the number.
DTLS1_2_VERSION = 0xFEFD

#: The record header of DTLS 1.2 (RFC 6347, 4.1): type, version, epoch, sequence number, length.
RECORD_HEADER = 13

#: Datagrams a channel sends are made of whole records, at most this many bytes each unless one
#: record is longer: a handshake flight of a certificate chain then goes out in datagrams an Ethernet
#: path carries unfragmented (1500 less the IPv4 and UDP headers, with room to spare).
DATAGRAM_BUDGET = 1400

#: Plaintext asked of the DTLS layer per read: the largest record.
_READ_SIZE = 16384 + 2048


def require_pyopenssl() -> None:
    """``SecurityError`` naming the extra to install when pyOpenSSL is missing."""
    try:
        import OpenSSL  # noqa: F401 - only whether it is there
    except ImportError:
        raise SecurityError("CIP Security over DTLS needs the pyOpenSSL package: "
                            "pip install 'cipstack[security]'") from None


class KeyLog:
    """Appends NSS key log lines to one file (``SSLKEYLOGFILE``), as the ``ssl`` module does for TLS."""

    def __init__(self, path: str) -> None:
        self.path = path
        self._lock = threading.Lock()

    def __call__(self, connection: Any, line: bytes) -> None:
        with self._lock, open(self.path, "ab") as out:
            out.write(line + b"\n")


#: OpenSSL's text of the verification failures a device's certificate meets most (``X509_V_ERR_*``,
#: as ``openssl verify`` prints them): pyOpenSSL gives the number to the verify callback only.
VERIFY_ERRORS = {
    2: "unable to get issuer certificate",
    3: "unable to get certificate CRL",
    9: "certificate is not yet valid",
    10: "certificate has expired",
    11: "CRL is not yet valid",
    12: "CRL has expired",
    18: "self-signed certificate",
    19: "self-signed certificate in certificate chain",
    20: "unable to get local issuer certificate",
    21: "unable to verify the first certificate",
    23: "certificate revoked",
}


def _note_verify_failure(connection: Any, certificate: Any, number: int, depth: int, ok: int) -> bool:
    """The originator's verify callback: OpenSSL's verdict unchanged, its first failure noted on the
    connection (``DtlsChannel.verify_error``) so that the refusal names it."""
    notes = connection.get_app_data()
    if not ok and isinstance(notes, list):
        notes.append(number)
    return bool(ok)


def use_certificates(context: Any, credentials: Credentials, pair: Any, role: str) -> None:
    """Load ``pair`` (the device's or the client's certificate and key) and the folder's CA into a
    pyOpenSSL ``context``; ``SecurityError`` naming ``role`` where one is not usable."""
    from OpenSSL import SSL

    assert credentials.ca is not None
    try:
        context.use_certificate_chain_file(str(pair.certificate.path))
        context.use_privatekey_file(str(pair.key))
        context.load_verify_locations(str(credentials.ca.path))
    except SSL.Error as exc:
        raise SecurityError(f"{credentials.folder}: the {role}'s certificate, key or CA is not usable "
                            f"({exc})") from None


def dtls_context(credentials: Credentials, server: bool, verify_client: bool = True) -> SSL.Context:
    """The DTLS context of the device (``server``) or of the originator, from ``credentials``. With
    the folder's PSK it offers and accepts the PSK suites too (``psk``), before the certificate
    suites, and speaks DTLS 1.2 only; a folder with a PSK and no certificates gives a PSK-only side.
    Each side checks the other's certificate against ``crl.pem`` when the folder holds one
    (``Credentials.crl``; the device when it verifies clients), and the originator offers only the
    suites ``Credentials.offering`` chose, if it did."""
    require_pyopenssl()
    from OpenSSL import SSL

    role = "device" if server else "client"
    pair = credentials.device if server else credentials.client
    if (pair is None or credentials.ca is None) and credentials.psk is None:
        raise SecurityError(f"{credentials.folder}: no {role}.pem and {role}.key for the {role}'s side of DTLS")
    context = SSL.Context(SSL.DTLS_SERVER_METHOD if server else SSL.DTLS_CLIENT_METHOD)
    context.set_min_proto_version(DTLS1_2_VERSION)
    if credentials.psk is not None:
        _use_psk(context, credentials, server, with_certificates=pair is not None and credentials.ca is not None)
    if pair is None or credentials.ca is None:
        return _finish(context, credentials, server)
    use_certificates(context, credentials, pair, role)
    mode = SSL.VERIFY_PEER | (SSL.VERIFY_FAIL_IF_NO_PEER_CERT if server else 0)
    if server:
        context.set_verify(mode if verify_client else SSL.VERIFY_NONE)
        if verify_client:
            check_crl(context, credentials)
    else:
        context.set_verify(mode, _note_verify_failure)
        check_crl(context, credentials)
    return _finish(context, credentials, server)


def check_crl(context: SSL.Context, credentials: Credentials) -> None:
    """The check of the peer's certificate against the folder's ``crl.pem``, when it holds one
    (OpenSSL's leaf check): the originator's of the device's, a device's of its clients'; the
    pyOpenSSL contexts of TLS with a key use it too."""
    from OpenSSL import SSL, crypto

    crl = credentials.crl()
    if crl is None:
        return
    try:
        context.load_verify_locations(str(crl))
    except SSL.Error as exc:
        raise SecurityError(f"{crl}: not a usable CRL ({exc})") from None
    store = context.get_cert_store()
    assert store is not None   # a context has its store from the start
    store.set_flags(crypto.X509StoreFlags.CRL_CHECK)


def _finish(context: SSL.Context, credentials: Credentials, server: bool) -> SSL.Context:
    """The originator's chosen suites (``Credentials.offering``), and the key log of both roles."""
    if not server and credentials.suites:
        context.set_cipher_list(":".join(credentials.suites).encode())
    if credentials.keylog:
        context.set_keylog_callback(KeyLog(credentials.keylog))
    return context


def _use_psk(context: SSL.Context, credentials: Credentials, server: bool, with_certificates: bool) -> None:
    """The PSK callbacks and suites (DTLS 1.2 only: the PSK suites are (D)TLS 1.2's)."""
    from .declarations import CERTIFICATE_SUITE_NAMES
    from .psk import PSK_SUITES, offer_psk, serve_psk

    psk = credentials.psk
    assert psk is not None
    if server:
        serve_psk(context, [(psk.identity, psk.key)])
    else:
        offer_psk(context, psk.identity, psk.key)
    context.set_max_proto_version(DTLS1_2_VERSION)
    names = [*PSK_SUITES, *(CERTIFICATE_SUITE_NAMES.values() if with_certificates else ())]
    context.set_cipher_list(":".join(names).encode())


def describe_dtls_failure(exc: BaseException, identity: bytes | None = None, verify_error: int | None = None) -> str:
    """A DTLS failure in one line, in the words ``describe_tls_failure`` uses for TLS; ``identity``:
    the handshake's PSK identity (the one this side offered, or the one the peer named), named when
    the key is the cause; ``verify_error``: the X.509 failure the originator's verify callback noted
    (``DtlsChannel.verify_error``)."""
    text = str(exc)
    args = getattr(exc, "args", ())
    reasons = [entry[2] for entry in args[0] if isinstance(entry, tuple) and len(entry) == 3] if (
        args and isinstance(args[0], list)) else []
    from .psk import explain

    # OpenSSL queues the cause first and what it led to after: a cause about the key is named.
    for cause in reasons:
        about_key = explain(cause, identity)
        if about_key is not None:
            return about_key
    reason = reasons[-1] if reasons else ""
    lowered = reason.lower()
    if "certificate verify failed" in lowered:
        if verify_error is not None:
            return f"certificate verify failed: {VERIFY_ERRORS.get(verify_error, f'X.509 error {verify_error}')}"
        return "certificate verify failed: the peer's certificate is not signed by our CA"
    if "unknown ca" in lowered:
        return "the peer does not trust our certificate (alert: unknown CA)"
    if "certificate expired" in lowered:
        return "the peer refused our certificate: certificate expired"
    if "no shared cipher" in lowered or "handshake failure" in lowered:
        return f"no cipher suite in common with the peer ({reason})"
    if "peer did not return a certificate" in lowered or "certificate required" in lowered:
        return "the peer sent no certificate and one is required"
    return reason or text or type(exc).__name__


def split_records(data: bytes, budget: int = DATAGRAM_BUDGET) -> list[bytes]:
    """``data`` (whole DTLS records, as a memory BIO holds them) cut into datagrams of whole records,
    each at most ``budget`` bytes unless a single record is longer (RFC 6347, 4.1.1: a datagram may
    carry several records, and a record never spans two datagrams)."""
    out: list[bytes] = []
    start = offset = 0
    while offset + RECORD_HEADER <= len(data):
        length = int.from_bytes(data[offset + 11:offset + 13], "big")
        end = offset + RECORD_HEADER + length
        if end - start > budget and offset > start:
            out.append(data[start:offset])
            start = offset
        offset = end
    if start < len(data):
        out.append(data[start:])
    return out


def record_lengths(data: bytes) -> list[int]:
    """The lengths of the whole DTLS records ``data`` holds, by their headers (RFC 6347, 4.1)."""
    lengths = []
    offset = 0
    while offset + RECORD_HEADER <= len(data):
        length = int.from_bytes(data[offset + 11:offset + 13], "big")
        lengths.append(length)
        offset += RECORD_HEADER + length
    return lengths


class DtlsChannel:
    """One DTLS association in memory: ``feed`` it datagrams, ``send`` it plaintext, take what goes
    out from ``datagrams``. Each plaintext given to ``send`` is one record (one EtherNet/IP message
    or one class 1 datagram); each returned by ``feed`` is one record's plaintext."""

    def __init__(self, connection: SSL.Connection) -> None:
        """``connection``: a pyOpenSSL ``Connection(context, None)``, its state (accept or connect) set;
        a server's may come from ``DTLSv1_listen`` with the ClientHello already consumed."""
        from OpenSSL import SSL

        self._ssl = SSL
        self.connection = connection
        self.established = False
        #: Whether the peer sent close_notify, or a fatal alert ended the association.
        self.closed = False
        #: Whether the layer may have written since ``datagrams`` last took what it wrote.
        self._output = True

    @classmethod
    def client(cls, context: SSL.Context) -> DtlsChannel:
        from OpenSSL import SSL

        connection = SSL.Connection(context, None)
        connection.set_connect_state()
        connection.set_app_data([])   # the verify callback's notes (``verify_error``)
        channel = cls(connection)
        channel.handshake()
        return channel

    def handshake(self) -> bool:
        """Go on with the handshake; True once it is done. A failure raises ``SSL.Error``."""
        if self.established:
            return True
        try:
            self.connection.do_handshake()
        except self._ssl.WantReadError:
            return False
        self.established = True
        return True

    def feed(self, datagram: bytes) -> list[bytes]:
        """The plaintext records ``datagram`` completes (none during the handshake). A fatal alert or
        a handshake failure raises ``SSL.Error``; a record the layer discards (a replay, a bad MAC:
        RFC 6347, 4.1.2.7) is dropped silently, as DTLS does."""
        if datagram:
            self.connection.bio_write(datagram)
        if not self.established:
            self._output = True
            if not self.handshake():
                return []
        records = []
        # One read per record the datagram holds (their headers say how many and how long), so that
        # the common datagram of one record costs no WantReadError; what is left, if the count was
        # wrong (records buffered from before), is read until the layer says there is no more.
        wanted = record_lengths(datagram) or [_READ_SIZE]
        recv = self.connection.recv
        try:
            for length in wanted:
                records.append(recv(max(length, 1)))
        except self._ssl.WantReadError:
            self._output = True   # a record that was not data (an alert, a handshake message): maybe an answer
        except self._ssl.ZeroReturnError:
            self.closed = True
        return records

    def send(self, plain: bytes) -> None:
        """Encrypt ``plain`` as one record (taken out with ``datagrams``)."""
        self.connection.send(plain)
        self._output = True

    def datagrams(self) -> list[bytes]:
        """What the layer has to send, as datagrams of whole records. Once established, the layer
        writes only when a record was sent or one that was not data came (``_output``): a data record
        read costs no look at an empty buffer."""
        if not self._output:
            return []
        self._output = not self.established
        try:
            data = self.connection.bio_read(65536)
        except self._ssl.WantReadError:
            return []
        return split_records(data) if len(data) > DATAGRAM_BUDGET else [data]

    def timeout(self) -> float | None:
        """Seconds until a flight of the handshake is due again (``DTLSv1_get_timeout``); None when
        nothing waits for an answer."""
        return self.connection.DTLSv1_get_timeout()

    def on_timer(self) -> None:
        """The retransmission deadline passed: the last flight is queued again (``DTLSv1_handle_timeout``)."""
        self.connection.DTLSv1_handle_timeout()
        self._output = True

    def close(self) -> None:
        """Queue close_notify (the peer learns the association is over)."""
        with contextlib.suppress(self._ssl.Error):
            self.connection.shutdown()

    @property
    def verify_error(self) -> int | None:
        """The first X.509 failure the originator's check of the peer's certificate met (None: none)."""
        notes = self.connection.get_app_data()
        return notes[0] if isinstance(notes, list) and notes else None

    def description(self) -> str:
        """``DTLSv1.2, CIPHER`` once established."""
        return f"{self.connection.get_protocol_version_name()}, {self.connection.get_cipher_name()}"


#: A cookie function of the stateless exchange: the peer's address as bytes in, the cookie out.
CookieFunction = Callable[[bytes], bytes]

__all__ = ["DATAGRAM_BUDGET", "DTLS1_2_VERSION", "VERIFY_ERRORS", "CookieFunction", "DtlsChannel", "KeyLog",
           "check_crl", "describe_dtls_failure", "dtls_context", "record_lengths", "require_pyopenssl", "split_records"]
