"""``cipstack security init DIR``: a lab CA and the device's and the client's certificates, or a PSK.

Keys are ECDSA on P-256 (the curve of the ECDHE-ECDSA suites the EtherNet/IP Confidentiality Profile
names), certificates X.509 v3 signed with SHA-256. Private keys and the PSK are written mode 0600.
A lab CA signs for a test bench; a plant's own CA replaces it by writing its files in the folder.
"""

from __future__ import annotations

import datetime
import os
import secrets
from pathlib import Path
from typing import Any

from ..errors import SecurityError
from .credentials import (
    CA_FILE,
    CA_KEY,
    CLIENT_CERTIFICATE,
    CLIENT_KEY,
    DEVICE_CERTIFICATE,
    DEVICE_KEY,
    PSK_FILE,
    require_cryptography,
)

#: Validity of what ``init`` makes, in days.
CA_DAYS = 3650
LEAF_DAYS = 825
#: Octets of a generated PSK (a 256-bit key).
PSK_SIZE = 32
PSK_IDENTITY = "cipstack-lab"


def init(folder: str | os.PathLike[str], *, certificates: bool = True, psk: bool = False, force: bool = False,
         device_name: str = "cipstack device", client_name: str = "cipstack originator",
         days: int = LEAF_DAYS, now: datetime.datetime | None = None) -> list[Path]:
    """Write the files into ``folder`` (made if missing); the paths written. ``SecurityError`` if one
    of them exists and ``force`` is false: nothing is then written. ``now`` and ``days`` set the
    certificates' validity (a test makes an expired one with a ``now`` in the past)."""
    path = Path(folder)
    names = [CA_FILE, CA_KEY, DEVICE_CERTIFICATE, DEVICE_KEY, CLIENT_CERTIFICATE, CLIENT_KEY] if certificates else []
    if psk:
        names.append(PSK_FILE)
    if not names:
        raise SecurityError("nothing to write: certificates, a PSK, or both")
    existing = [name for name in names if (path / name).exists()]
    if existing and not force:
        raise SecurityError(f"{path}: {', '.join(existing)} already there (--force replaces them)")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SecurityError(f"{path}: cannot make the folder ({exc.strerror or exc})") from None
    written: list[Path] = []
    if certificates:
        written += _certificates(path, device_name, client_name, days, now)
    if psk:
        identity = PSK_IDENTITY
        written.append(_write(path / PSK_FILE, f"{identity}:{secrets.token_hex(PSK_SIZE)}\n".encode(), secret=True))
    return written


def _certificates(path: Path, device_name: str, client_name: str, days: int,
                  now: datetime.datetime | None) -> list[Path]:
    require_cryptography()
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    start = (now or datetime.datetime.now(datetime.timezone.utc)) - datetime.timedelta(minutes=5)

    def name(common: str) -> x509.Name:
        return x509.Name([x509.NameAttribute(NameOID.ORGANIZATION_NAME, "cipstack lab"),
                          x509.NameAttribute(NameOID.COMMON_NAME, common)])

    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = name("cipstack lab CA")
    ca_identifier = x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key())
    ca = (x509.CertificateBuilder().subject_name(ca_name).issuer_name(ca_name).public_key(ca_key.public_key())
          .serial_number(x509.random_serial_number()).not_valid_before(start)
          .not_valid_after(start + datetime.timedelta(days=max(days, CA_DAYS)))
          .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
          .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=False, key_encipherment=False,
                                       data_encipherment=False, key_agreement=False, key_cert_sign=True,
                                       crl_sign=True, encipher_only=False, decipher_only=False), critical=True)
          .add_extension(ca_identifier, critical=False)
          .sign(ca_key, hashes.SHA256()))

    def leaf(common: str, usage: x509.ObjectIdentifier, alternative: list[x509.GeneralName]) -> tuple[bytes, bytes]:
        key = ec.generate_private_key(ec.SECP256R1())
        builder = (x509.CertificateBuilder().subject_name(name(common)).issuer_name(ca_name)
                   .public_key(key.public_key()).serial_number(x509.random_serial_number())
                   .not_valid_before(start).not_valid_after(start + datetime.timedelta(days=days))
                   .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
                   .add_extension(x509.KeyUsage(digital_signature=True, content_commitment=False,
                                                key_encipherment=False, data_encipherment=False, key_agreement=True,
                                                key_cert_sign=False, crl_sign=False, encipher_only=False,
                                                decipher_only=False), critical=True)
                   .add_extension(x509.ExtendedKeyUsage([usage]), critical=False)
                   .add_extension(x509.AuthorityKeyIdentifier.from_issuer_subject_key_identifier(ca_identifier),
                                  critical=False))
        if alternative:
            builder = builder.add_extension(x509.SubjectAlternativeName(alternative), critical=False)
        certificate = builder.sign(ca_key, hashes.SHA256())
        key_pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                    serialization.NoEncryption())
        return certificate.public_bytes(serialization.Encoding.PEM), key_pem

    import ipaddress

    device_cert, device_key = leaf(device_name, ExtendedKeyUsageOID.SERVER_AUTH,
                                   [x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))])
    client_cert, client_key = leaf(client_name, ExtendedKeyUsageOID.CLIENT_AUTH, [])
    ca_key_pem = ca_key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                                      serialization.NoEncryption())
    return [_write(path / CA_FILE, ca.public_bytes(serialization.Encoding.PEM)),
            _write(path / CA_KEY, ca_key_pem, secret=True),
            _write(path / DEVICE_CERTIFICATE, device_cert), _write(path / DEVICE_KEY, device_key, secret=True),
            _write(path / CLIENT_CERTIFICATE, client_cert), _write(path / CLIENT_KEY, client_key, secret=True)]


def sign_csr(folder: str | os.PathLike[str], csr_der: bytes, days: int = LEAF_DAYS,
             now: datetime.datetime | None = None) -> bytes:
    """The lab CA of ``folder`` (``ca.pem`` and ``ca.key``) signs a device's certificate signing request
    (PEM or DER, as a device's CSR file holds it): a server certificate with the request's subject and alternative
    name, for ``days``. ``SecurityError`` for a request that does not read or whose signature is wrong,
    or a folder without the CA's key."""
    require_cryptography()
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.x509.oid import ExtendedKeyUsageOID

    path = Path(folder)
    if not (path / CA_KEY).exists():
        raise SecurityError(f"{path / CA_KEY}: missing (the CA's key signs; `cipstack security init` writes it)")
    try:
        ca = x509.load_pem_x509_certificate((path / CA_FILE).read_bytes())
        ca_key: Any = serialization.load_pem_private_key((path / CA_KEY).read_bytes(), password=None)
    except (OSError, ValueError) as exc:
        raise SecurityError(f"{path}: the CA does not load ({exc})") from None
    try:
        pem_form = csr_der.lstrip().startswith(b"-----BEGIN")
        request = x509.load_pem_x509_csr(csr_der) if pem_form else x509.load_der_x509_csr(csr_der)
        valid = request.is_signature_valid
    except ValueError:
        raise SecurityError("the device's certificate signing request does not read (not a PEM or DER CSR)") from None
    if not valid:
        raise SecurityError("the device's certificate signing request has a wrong signature")
    start = (now or datetime.datetime.now(datetime.timezone.utc)) - datetime.timedelta(minutes=5)
    builder = (x509.CertificateBuilder().subject_name(request.subject).issuer_name(ca.subject)
               .public_key(request.public_key()).serial_number(x509.random_serial_number())
               .not_valid_before(start).not_valid_after(start + datetime.timedelta(days=days))
               .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
               .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH]), critical=False))
    try:
        alternative = request.extensions.get_extension_for_class(x509.SubjectAlternativeName)
        builder = builder.add_extension(alternative.value, critical=False)
    except x509.ExtensionNotFound:
        pass
    return builder.sign(ca_key, hashes.SHA256()).public_bytes(serialization.Encoding.DER)


def _write(path: Path, data: bytes, secret: bool = False) -> Path:
    """Write ``data``: a secret is created mode 0600 (never readable by others, even for a moment)."""
    mode = 0o600 if secret else 0o644
    try:
        if path.exists():
            path.unlink()
        descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
        with os.fdopen(descriptor, "wb") as file:
            file.write(data)
    except OSError as exc:
        raise SecurityError(f"{path}: cannot write ({exc.strerror or exc})") from None
    return path


__all__ = ["init", "sign_csr"]
