"""The files of a CIP Security folder, loaded into typed records, and the TLS contexts made of them.

``cipstack security init DIR`` writes the folder (``provisioning``); ``Credentials.load(DIR)`` reads
it back. Names in the folder:

* ``ca.pem``: the certificate authority both roles trust (Volume 8's Trusted Authorities);
* ``device.pem`` / ``device.key``: the target's certificate and private key (PEM, PKCS#8);
* ``client.pem`` / ``client.key``: the originator's certificate and private key;
* ``crl.pem``: a certificate revocation list of the CA (optional): the originator checks the
  device's certificate against it (OpenSSL's leaf check) when it is there, read at each handshake
  (the ``revoke-certificate`` fault publishes one);
* ``psk.txt``: a pre-shared key, one line ``IDENTITY:HEX`` (identity in ASCII, at most 128
  octets; the key in hexadecimal, 32 octets by default). With it, both roles offer the PSK suites of
  TLS 1.2 and DTLS 1.2 (``psk``, ``tls_psk``).

Each problem is one ``SecurityError`` line naming the file: missing, unreadable, not PEM, expired.
``cryptography`` is imported when a folder is loaded, never by the plain paths of the package.
"""

from __future__ import annotations

import datetime
import os
import ssl
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..eip.wire.encapsulation import SECURE_PORT
from ..errors import SecurityError

if TYPE_CHECKING:
    import socket

    from .tls_psk import PskTlsContext, TlsSocket

CA_FILE = "ca.pem"
#: The lab CA's private key: what signs a device's certificate request (``security configure``).
CA_KEY = "ca.key"
DEVICE_CERTIFICATE = "device.pem"
DEVICE_KEY = "device.key"
CLIENT_CERTIFICATE = "client.pem"
CLIENT_KEY = "client.key"
PSK_FILE = "psk.txt"
#: The CA's certificate revocation list, PEM: the originator checks the device's certificate against it.
CRL_FILE = "crl.pem"

#: Longest PSK identity: 128 octets (the EtherNet/IP Security object's Pre-Shared Keys attribute as
#: OpENer's CIP Security branch declares it).
MAX_PSK_IDENTITY = 128


@dataclass(frozen=True)
class CertificateFile:
    """One PEM certificate of the folder, with what a user asks of it first."""

    path: Path
    subject: str
    not_before: datetime.datetime
    not_after: datetime.datetime

    def expired(self, now: datetime.datetime | None = None) -> bool:
        """Whether ``now`` (UTC; default the present) is outside its validity."""
        now = now or datetime.datetime.now(datetime.timezone.utc)
        return not self.not_before <= now <= self.not_after


@dataclass(frozen=True)
class KeyPair:
    """A certificate and the file of its private key."""

    certificate: CertificateFile
    key: Path


@dataclass(frozen=True)
class PreSharedKey:
    """A pre-shared key: its identity and its octets."""

    identity: bytes
    key: bytes


@dataclass(frozen=True)
class Credentials:
    """A CIP Security folder: the CA, and whichever of the device's and the client's key pairs and the
    PSK it holds. Build one with ``Credentials.load(DIR)``; pass it as ``security=`` to a scanner, or
    give the folder to ``cipstack adapter --security DIR``."""

    folder: Path
    ca: CertificateFile | None
    device: KeyPair | None
    client: KeyPair | None
    psk: PreSharedKey | None
    #: Where both roles write their TLS secrets for Wireshark (``SSLKEYLOGFILE``, read at load).
    keylog: str | None = None
    #: The TLS 1.2 suites the originator offers, by OpenSSL's names (empty: every one it has; see
    #: ``offering``).
    suites: tuple[str, ...] = ()

    @classmethod
    def load(cls, folder: str | os.PathLike[str], now: datetime.datetime | None = None) -> Credentials:
        """Read ``folder``; a ``SecurityError`` naming the file for a missing, unreadable, malformed
        or expired one. A folder needs the CA and at least one key pair, or a PSK."""
        path = Path(folder)
        if not path.is_dir():
            raise SecurityError(f"{path}: no such folder (make one with `cipstack security init {path}`)")
        psk = _load_psk(path / PSK_FILE) if (path / PSK_FILE).exists() else None
        ca = _load_certificate(path / CA_FILE, now) if (path / CA_FILE).exists() else None
        device = _load_pair(path, DEVICE_CERTIFICATE, DEVICE_KEY, now)
        client = _load_pair(path, CLIENT_CERTIFICATE, CLIENT_KEY, now)
        if (device is not None or client is not None) and ca is None:
            raise SecurityError(f"{path / CA_FILE}: missing (the certificates need the CA that signed them)")
        if device is None and client is None and psk is None:
            raise SecurityError(f"{path}: no {CA_FILE} with {DEVICE_CERTIFICATE} or {CLIENT_CERTIFICATE}, "
                                f"and no {PSK_FILE} (make them with `cipstack security init {path}`)")
        return cls(path, ca, device, client, psk, os.environ.get("SSLKEYLOGFILE") or None)

    @classmethod
    def keys_only(cls, folder: str | os.PathLike[str]) -> Credentials:
        """Credentials of no file: a device configured with pre-shared keys alone, whose keys its
        configuration holds (``endpoint.server_context``)."""
        return cls(Path(folder), None, None, None, None, os.environ.get("SSLKEYLOGFILE") or None)

    def offering(self, *suites: str) -> Credentials:
        """These credentials with an originator that offers only ``suites`` (IANA names, OpenSSL names or
        0x ids), over TLS 1.2 and DTLS 1.2: what a test of the suites a device accepts needs. A name
        OpenSSL knows no TLS 1.2 suite by is a ``SecurityError``."""
        from dataclasses import replace

        from .suites import openssl_name

        names = []
        for suite in suites:
            name = openssl_name(suite)
            if name is None:
                raise SecurityError(f"{suite}: no TLS 1.2 cipher suite of that name or id")
            names.append(name)
        return replace(self, suites=tuple(names))

    def explain(self, cause: str) -> str:
        """A handshake's refusal, with what the originator offered when ``offering`` narrowed it and
        the device found no suite in common."""
        if self.suites and cause.startswith("no cipher suite in common"):
            return f"{cause}: we offered {', '.join(self.suites)}"
        return cause

    # -- TLS contexts -----------------------------------------------------------------------------
    def server_context(self, verify_client: bool = True) -> ssl.SSLContext:
        """The target's TLS context: TLS 1.2 at least (1.3 where the peer offers it), the device's
        certificate and key, client certificates required and verified against the CA (Volume 8's
        Verify Client Certificate, on by default)."""
        pair = self._pair(self.device, "device")
        context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        self._common(context)
        context.load_cert_chain(pair.certificate.path, pair.key)
        context.verify_mode = ssl.CERT_REQUIRED if verify_client else ssl.CERT_NONE
        if verify_client:
            self._check_crl(context)
        return context

    def client_context(self) -> ssl.SSLContext | PskTlsContext:
        """The originator's TLS context: the client's certificate and key, the device's certificate
        verified against the CA, and against the folder's ``crl.pem`` when there is one. Devices are
        reached by address and named by their certificate's subject, not by a host name: the chain is
        checked, the host name is not. With a PSK, a pyOpenSSL context of TLS 1.2 offering the PSK
        suites first (``tls_psk``), with ``wrap_bio`` as asyncio's TLS transport calls it (the
        certificate suites ``offering`` narrowed, if it did)."""
        if self.psk is not None:
            from .declarations import CIPHER_SUITE_NAMES
            from .tls_psk import psk_context

            return psk_context(self, server=False, suites=self.suites or tuple(CIPHER_SUITE_NAMES.values()))
        pair = self._pair(self.client, "client")
        context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
        context.check_hostname = False
        self._common(context)
        context.load_cert_chain(pair.certificate.path, pair.key)
        if self.suites:   # TLS 1.3's suites cannot be narrowed (Python's ssl): TLS 1.2 alone
            context.maximum_version = ssl.TLSVersion.TLSv1_2
            context.set_ciphers(":".join(self.suites))
        self._check_crl(context)
        return context

    def _check_crl(self, context: ssl.SSLContext) -> None:
        """The peer's certificate checked against the folder's ``crl.pem``, when there is one."""
        crl = self.crl()
        if crl is not None:
            try:
                context.load_verify_locations(cafile=crl)
            except (OSError, ssl.SSLError) as exc:
                raise SecurityError(f"{crl}: not a usable CRL ({exc})") from None
            context.verify_flags |= ssl.VERIFY_CRL_CHECK_LEAF

    def crl(self) -> Path | None:
        """The folder's certificate revocation list as it is now (read at each handshake: a CRL published
        while a scanner runs counts from its next connection), or None."""
        path = self.folder / CRL_FILE
        return path if path.is_file() else None

    def crl_stamp(self) -> tuple[int, int] | None:
        """What identifies the folder's ``crl.pem`` as it is now (modification time and size), or None
        without one: a device compares it at each handshake and remakes its contexts when it changed,
        so a CRL published or withdrawn while it runs counts from the next handshake."""
        try:
            stat = (self.folder / CRL_FILE).stat()
        except OSError:
            return None
        return stat.st_mtime_ns, stat.st_size

    def wrap_client(self, sock: socket.socket, host: str, port: int) -> ssl.SSLSocket | TlsSocket:
        """``sock`` (connected, blocking) after a TLS handshake as the originator; a handshake that
        fails closes it and raises ``SecurityError`` naming the cause."""
        try:
            context = self.client_context()
            tls: ssl.SSLSocket | TlsSocket
            if isinstance(context, ssl.SSLContext):
                tls = context.wrap_socket(sock, do_handshake_on_connect=False)
                tls.do_handshake()
            else:
                from .tls_psk import TlsSocket

                tls = TlsSocket(sock, context)
                tls.handshake()
        except ssl.SSLError as exc:
            sock.close()
            raise SecurityError(f"TLS with {host}:{port} failed: {self.explain(self.describe(exc))}") from None
        except TimeoutError:
            waited = sock.gettimeout()
            sock.close()
            raise self.unanswered(host, port, waited) from None
        except OSError as exc:
            sock.close()
            raise SecurityError(f"TLS with {host}:{port} failed: the device closed the connection during the "
                                f"handshake ({exc.strerror or exc})") from None
        return tls

    def refusal(self, failure: BaseException, host: str, port: int) -> SecurityError | None:
        """A ``SecurityError`` for a TLS alert that ended a connection after its handshake (TLS 1.3:
        the device refuses the client's certificate once the client has finished); None otherwise."""
        if isinstance(failure, ssl.SSLError) and not isinstance(failure, (ssl.SSLWantReadError, ssl.SSLWantWriteError)):
            return SecurityError(f"TLS with {host}:{port} failed: {self.explain(self.describe(failure))}")
        return None

    def describe(self, failure: BaseException) -> str:
        """``describe_tls_failure``, naming this folder's PSK identity when the key is the cause."""
        from .psk import explain

        reason = getattr(failure, "reason", None) or ""
        about_key = explain(reason, self.psk.identity) if self.psk is not None and reason else None
        return about_key or describe_tls_failure(failure)

    def unanswered(self, host: str, port: int, waited: float | None) -> SecurityError:
        """A TCP port that took the connection and did not answer the ClientHello within ``waited``
        seconds: a plain EtherNet/IP port does that (it waits for the rest of what it reads as an
        encapsulation header)."""
        within = f" within {waited:g} s" if waited else ""
        return SecurityError(f"TLS with {host}:{port} failed: no answer to the handshake{within}: a plain "
                             "EtherNet/IP port (44818) answers no TLS; the device's TLS port is 2221 unless it "
                             "was given another")

    def datagram_link(self, host: str, port: int, timeout: float) -> Any:
        """A DTLS session with the device's UDP ``port`` (2221), its handshake done within ``timeout``
        (``dtls_link.DtlsLink``): ``SecurityError`` naming the cause of a refusal, ``PeerUnreachable``
        when nothing answers."""
        from .dtls_link import DtlsLink

        return DtlsLink(self, host, port, timeout)

    async def open_datagram_link(self, host: str, port: int, timeout: float,
                                 protocol_factory: Any) -> tuple[Any, Any]:
        """``datagram_link`` on the running loop (``dtls_client.AsyncDtlsLink``), its encapsulation
        records given to the protocol ``protocol_factory`` makes: (the link, the protocol)."""
        from .dtls_client import AsyncDtlsLink

        return await AsyncDtlsLink.open(self, host, port, timeout, protocol_factory)

    def _common(self, context: ssl.SSLContext) -> None:
        context.minimum_version = ssl.TLSVersion.TLSv1_2
        assert self.ca is not None   # _pair checked it
        try:
            context.load_verify_locations(cafile=self.ca.path)
        except (OSError, ssl.SSLError) as exc:
            raise SecurityError(f"{self.ca.path}: not a usable CA certificate ({exc})") from None
        if self.keylog:
            context.keylog_filename = self.keylog

    def _pair(self, pair: KeyPair | None, role: str) -> KeyPair:
        if pair is None or self.ca is None:
            raise SecurityError(f"{self.folder}: no {role}.pem and {role}.key for the {role}'s side of TLS")
        return pair


def describe_tls_failure(exc: BaseException) -> str:
    """A TLS failure in one line that names its cause in the words a user searches for."""
    if isinstance(exc, ssl.SSLCertVerificationError):
        message = exc.verify_message or "the peer's certificate is not trusted"
        return f"certificate verify failed: {message}"
    reason = getattr(exc, "reason", None) or ""
    text = str(exc)
    if reason == "NO_SHARED_CIPHER" or "no shared cipher" in text.lower() or reason == "SSLV3_ALERT_HANDSHAKE_FAILURE":
        return f"no cipher suite in common with the peer ({reason or text})"
    if reason == "TLSV1_ALERT_UNKNOWN_CA":
        return "the peer does not trust our certificate (alert: unknown CA)"
    if reason == "SSLV3_ALERT_CERTIFICATE_EXPIRED":
        return "the peer refused our certificate: certificate expired"
    if reason in ("TLSV13_ALERT_CERTIFICATE_REQUIRED", "SSLV3_ALERT_BAD_CERTIFICATE"):
        return f"the peer refused our certificate ({reason.lower().replace('_', ' ')})"
    if "PSK" in reason or "BAD_RECORD_MAC" in reason or reason == "TLSV1_ALERT_DECRYPT_ERROR":
        from .psk import explain

        return explain(reason, None) or reason.lower().replace("_", " ")
    if reason == "WRONG_VERSION_NUMBER":
        return "the peer does not speak TLS here (wrong version number)"
    return reason.lower().replace("_", " ") if reason else (text or type(exc).__name__)


# -- reading the files ---------------------------------------------------------------------------------
def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise SecurityError(f"{path}: missing") from None
    except OSError as exc:
        raise SecurityError(f"{path}: unreadable ({exc.strerror or exc})") from None


def require_cryptography() -> None:
    """``SecurityError`` naming the extra to install when ``cryptography`` is missing."""
    try:
        import cryptography  # noqa: F401 - only whether it is there
    except ImportError:
        raise SecurityError("CIP Security needs the cryptography package: pip install 'cipstack[security]'") from None


def _load_certificate(path: Path, now: datetime.datetime | None) -> CertificateFile:
    require_cryptography()
    from cryptography import x509

    data = _read(path)
    try:
        certificate = x509.load_pem_x509_certificate(data)
    except ValueError:
        raise SecurityError(f"{path}: not a PEM certificate") from None
    record = CertificateFile(path, certificate.subject.rfc4514_string(), certificate.not_valid_before_utc,
                             certificate.not_valid_after_utc)
    moment = now or datetime.datetime.now(datetime.timezone.utc)
    if moment > record.not_after:
        raise SecurityError(f"{path}: certificate expired on {record.not_after:%Y-%m-%d %H:%M:%S} UTC")
    if moment < record.not_before:
        raise SecurityError(f"{path}: certificate not valid before {record.not_before:%Y-%m-%d %H:%M:%S} UTC")
    return record


def _load_key(path: Path) -> Any:
    from cryptography.hazmat.primitives.serialization import load_pem_private_key

    data = _read(path)
    try:
        return load_pem_private_key(data, password=None)
    except (ValueError, TypeError):
        raise SecurityError(f"{path}: not an unencrypted PEM private key") from None


def _load_pair(folder: Path, certificate: str, key: str, now: datetime.datetime | None) -> KeyPair | None:
    cert_path, key_path = folder / certificate, folder / key
    if not cert_path.exists() and not key_path.exists():
        return None
    record = _load_certificate(cert_path, now)
    _load_key(key_path)
    return KeyPair(record, key_path)


def _load_psk(path: Path) -> PreSharedKey:
    text = _read(path).decode("ascii", "replace").strip()
    identity, colon, key = text.partition(":")
    try:
        octets = bytes.fromhex(key)
    except ValueError:
        octets = b""
    if not colon or not identity or not octets:
        raise SecurityError(f"{path}: not one line IDENTITY:HEX")
    if len(identity.encode()) > MAX_PSK_IDENTITY:
        raise SecurityError(f"{path}: identity longer than {MAX_PSK_IDENTITY} octets")
    return PreSharedKey(identity.encode(), octets)


__all__ = ["CA_FILE", "CA_KEY", "CLIENT_CERTIFICATE", "CLIENT_KEY", "CRL_FILE", "DEVICE_CERTIFICATE", "DEVICE_KEY",
           "PSK_FILE", "SECURE_PORT", "CertificateFile", "Credentials", "KeyPair", "PreSharedKey",
           "describe_tls_failure", "require_cryptography"]
