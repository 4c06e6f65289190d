"""The lab CA of a device's security folder as faults use it, and the contexts of the handshakes a
fault changes.

``LabAuthority`` is what the fault controller reaches of CIP Security (``runtime.CipSecurity``): the
seam of the TLS and DTLS listeners (``SecuredSeam``) and the lab CA whose key ``cipstack security
init`` writes beside the device's certificate (``ca.key``). With it, a fault re-issues the device's
certificate (same subject, key and extensions) with its validity ended, or publishes a CRL that
lists the device's certificate as ``crl.pem`` in the same folder, where an originator loading the
folder reads it at each handshake (``Credentials.client_context``). The CRL entry's reason is
certificateHold, the one reason RFC 5280 (5.3.1) lets a CA lift, which clearing the fault does.

``tls_variant`` and ``dtls_variant`` make the context of the next handshakes from the listener's
own recipe while a handshake filter is in the seam: the other certificate, the refused suites left
out. Nothing here runs while no fault is active.
"""

from __future__ import annotations

import contextlib
import datetime
import os
import shutil
import ssl
import tempfile
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import BadRequest, StateRefused
from .credentials import CA_FILE, CA_KEY, CRL_FILE, CertificateFile, Credentials, KeyPair
from .suites import describe_suites, suite_id, suite_names

if TYPE_CHECKING:
    from OpenSSL import SSL

    from ..eip.target.seams import SecuredSeam
    from .tls_psk import PskTlsContext
    from .tls_target import Recipe, TlsServer

#: How long the validity of a re-issued expired certificate ended before now, and lasted.
EXPIRED_AGO = datetime.timedelta(days=1)
EXPIRED_SPAN = datetime.timedelta(days=30)
#: The next update a published CRL announces: long enough that a test never sees it expire.
CRL_NEXT_UPDATE = datetime.timedelta(days=30)


def accepted_suites(context: ssl.SSLContext | PskTlsContext) -> list[int]:
    """The TLS 1.2 suites a TLS context accepts, by IANA id, in its order."""
    return [c["id"] & 0xFFFF for c in context.get_ciphers() if c["protocol"] != "TLSv1.3"]


class ReissuedCertificate:
    """A certificate a fault made, in a private temporary folder of its own."""

    def __init__(self, folder: Path, certificate: Path, key: Path) -> None:
        self.folder = folder
        self.paths = (str(certificate), str(key))

    def discard(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)


class LabAuthority:
    """CIP Security's listeners and the lab CA of their folder, as faults reach them."""

    def __init__(self, seam: SecuredSeam, listener: Callable[[], TlsServer | None],
                 datagrams: Callable[[], bool]) -> None:
        """``listener()``: the TLS listener serving now (None: none, a factory-default device);
        ``datagrams()``: whether DTLS is served too."""
        self.seam = seam
        self.listener = listener
        self.datagrams = datagrams
        self._revoked = False

    def serving(self, datagrams: bool = False) -> None:
        server = self.listener()
        if server is None or not server.is_open:
            raise StateRefused("the device serves no CIP Security now (in Factory Default: configure it, or start "
                               "it with --security DIR)")
        if datagrams and not self.datagrams():
            raise StateRefused("the device serves no DTLS now")

    def _credentials(self) -> Credentials:
        server = self.listener()
        if server is None:
            raise StateRefused("the device serves no CIP Security now")
        return server.credentials

    def _authority(self, credentials: Credentials) -> tuple[Any, Any]:
        """The lab CA's certificate and key, from the folder the device's certificate came from."""
        from cryptography import x509
        from cryptography.hazmat.primitives import serialization

        folder = credentials.folder
        if not (folder / CA_KEY).exists():
            raise StateRefused(f"{folder / CA_KEY}: missing: the lab CA's key signs what this fault makes (a device "
                               "configured over the network holds none; start it with --security DIR, a folder of "
                               "`cipstack security init`)")
        try:
            ca = x509.load_pem_x509_certificate((folder / CA_FILE).read_bytes())
            key = serialization.load_pem_private_key((folder / CA_KEY).read_bytes(), password=None)
        except (OSError, ValueError) as exc:
            raise StateRefused(f"{folder}: the lab CA does not load ({exc})") from None
        return ca, key

    def _device_certificate(self, credentials: Credentials) -> Any:
        from cryptography import x509

        assert credentials.device is not None   # a TLS listener has the device's pair
        return x509.load_pem_x509_certificate(credentials.device.certificate.path.read_bytes())

    def expired_certificate(self) -> ReissuedCertificate:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization

        credentials = self._credentials()
        ca, ca_key = self._authority(credentials)
        original = self._device_certificate(credentials)
        now = datetime.datetime.now(datetime.timezone.utc)
        builder = (x509.CertificateBuilder().subject_name(original.subject).issuer_name(ca.subject)
                   .public_key(original.public_key()).serial_number(x509.random_serial_number())
                   .not_valid_before(now - EXPIRED_AGO - EXPIRED_SPAN).not_valid_after(now - EXPIRED_AGO))
        for extension in original.extensions:
            builder = builder.add_extension(extension.value, extension.critical)
        certificate = builder.sign(ca_key, hashes.SHA256())
        folder = Path(tempfile.mkdtemp(prefix="cipstack-expired-"))
        path = folder / "device.pem"
        path.write_bytes(certificate.public_bytes(serialization.Encoding.PEM))
        assert credentials.device is not None
        return ReissuedCertificate(folder, path, credentials.device.key)

    def revoke(self) -> Callable[[], None]:
        from cryptography import x509
        from cryptography.hazmat.primitives import hashes, serialization

        if self._revoked:
            raise StateRefused("the device's certificate is revoked already (a revoke-certificate is active)")
        credentials = self._credentials()
        ca, ca_key = self._authority(credentials)
        device = self._device_certificate(credentials)
        path = credentials.folder / CRL_FILE
        before = path.read_bytes() if path.exists() else None
        now = datetime.datetime.now(datetime.timezone.utc) - datetime.timedelta(minutes=1)
        entry = (x509.RevokedCertificateBuilder().serial_number(device.serial_number).revocation_date(now)
                 .add_extension(x509.CRLReason(x509.ReasonFlags.certificate_hold), critical=False).build())
        builder = (x509.CertificateRevocationListBuilder().issuer_name(ca.subject).last_update(now)
                   .next_update(now + CRL_NEXT_UPDATE).add_revoked_certificate(entry)
                   .add_extension(x509.CRLNumber(int(now.timestamp())), critical=False))
        if before is not None:   # what the lab CA revoked before stays revoked
            with contextlib.suppress(ValueError):
                for revoked in x509.load_pem_x509_crl(before):
                    if revoked.serial_number != device.serial_number:
                        builder = builder.add_revoked_certificate(revoked)
        _replace(path, builder.sign(ca_key, hashes.SHA256()).public_bytes(serialization.Encoding.PEM))
        self._revoked = True

        def undo() -> None:
            self._revoked = False
            if before is None:
                with contextlib.suppress(FileNotFoundError):
                    path.unlink()
            else:
                _replace(path, before)

        return undo

    def suite(self, name: str) -> int:
        server = self.listener()
        accepted = [i for i in accepted_suites(server.context) if i not in self.seam.refused()] if server else []
        wanted = suite_id(name)
        if wanted not in accepted:
            raise BadRequest(f"the device does not accept {name} now; it accepts {describe_suites(accepted)}")
        if len(accepted) == 1:
            raise StateRefused(f"{name} is the last TLS 1.2 suite the device accepts: refusing it too leaves none")
        return wanted


def _replace(path: Path, data: bytes) -> None:
    """Write ``path`` whole or not at all: a reader never sees half a CRL."""
    temporary = path.with_name(f".{path.name}.new")
    with contextlib.suppress(FileNotFoundError):
        temporary.unlink()
    descriptor = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
    with os.fdopen(descriptor, "wb") as file:
        file.write(data)
    temporary.replace(path)


# -- the contexts of the next handshakes -------------------------------------------------------------------
def presenting(credentials: Credentials, seam: SecuredSeam) -> Credentials:
    """``credentials`` with the device's certificate the seam's filters present instead, if any."""
    chosen = seam.certificate()
    if chosen is None or credentials.device is None:
        return credentials
    certificate, key = chosen
    own = credentials.device.certificate
    record = CertificateFile(Path(certificate), own.subject, own.not_before, own.not_after)
    return replace(credentials, device=KeyPair(record, Path(key)))


def tls_variant(credentials: Credentials, recipe: Recipe, seam: SecuredSeam) -> ssl.SSLContext | PskTlsContext:
    """The TLS context ``recipe`` makes, presenting the seam's certificate, without its refused suites
    (TLS 1.3's suites are the library's: Python's ``ssl`` cannot narrow them)."""
    context = recipe(presenting(credentials, seam))
    refused = seam.refused()
    if refused:
        kept = [c["name"] for c in context.get_ciphers()
                if c["protocol"] != "TLSv1.3" and (c["id"] & 0xFFFF) not in refused]
        context.set_ciphers(":".join(kept))
    return context


def dtls_variant(credentials: Credentials, recipe: Callable[[Credentials], SSL.Context],
                 seam: SecuredSeam) -> SSL.Context:
    """The DTLS context ``recipe`` makes, presenting the seam's certificate, without its refused suites."""
    from OpenSSL import SSL

    presented = presenting(credentials, seam)
    refused = {suite_names().get(i) for i in seam.refused()}
    if not refused:
        return recipe(presented)
    # A context that made a connection can no longer change (pyOpenSSL): its suites are read from another.
    names = SSL.Connection(recipe(presented), None).get_cipher_list()
    context = recipe(presented)
    context.set_cipher_list(":".join(n for n in names if n not in refused and not n.startswith("TLS_")).encode())
    return context


def allowed_names(context: ssl.SSLContext | PskTlsContext) -> str:
    """What the device accepts over TLS 1.2, for a refusal's line."""
    return ", ".join(suite_names().get(i, f"0x{i:04X}") for i in accepted_suites(context)) or "none"


__all__ = ["LabAuthority", "ReissuedCertificate", "accepted_suites", "allowed_names", "dtls_variant", "presenting",
           "tls_variant"]
