"""X.509 work of the device's side of CIP Security: its key, its certificate signing request, and the
checks a pushed certificate must pass. ``cryptography`` is imported on first use, never by a plain
device that nobody configures."""

from __future__ import annotations

import datetime
from typing import Any

from ..cip.status import CipError, GeneralStatus
from .attributes import MAX_CERTIFICATE
from .credentials import require_cryptography

#: The subject fields of a Create_CSR request, in the order of its nine SHORT_STRINGs (OpENer's
#: Create_CSR, Volume 8 5-5.7.1): empty ones take the device's defaults.
CSR_FIELDS = ("common name", "organization", "organizational unit", "locality", "state", "country", "email",
              "serial number", "subject alternative name")


def _crypto() -> None:
    try:
        require_cryptography()
    except Exception as exc:
        raise CipError(GeneralStatus.RESOURCE_UNAVAILABLE, message=str(exc)) from None


def new_key() -> bytes:
    """A new P-256 private key, PEM (PKCS#8): the curve of the ECDHE-ECDSA suites the device offers."""
    _crypto()
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric import ec

    key = ec.generate_private_key(ec.SECP256R1())
    return key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                             serialization.NoEncryption())


def certificate_signing_request(key_pem: bytes, fields: list[str], defaults: dict[str, str]) -> bytes:
    """A CSR (DER) for ``key_pem`` with the subject ``fields`` asks (``CSR_FIELDS`` order; an empty
    one takes ``defaults``); 0x20 (invalid parameter) for a country that is not two letters."""
    _crypto()
    import ipaddress

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.x509.oid import NameOID

    values = dict(zip(CSR_FIELDS, fields, strict=True))
    country = values["country"]
    if country and (len(country) != 2 or not country.isalpha()):
        raise CipError(GeneralStatus.INVALID_PARAMETER, message=f"country {country!r} is not an ISO 3166 code")
    for name, value in defaults.items():
        values[name] = values[name] or value
    oids = (("common name", NameOID.COMMON_NAME), ("organization", NameOID.ORGANIZATION_NAME),
            ("organizational unit", NameOID.ORGANIZATIONAL_UNIT_NAME), ("locality", NameOID.LOCALITY_NAME),
            ("state", NameOID.STATE_OR_PROVINCE_NAME), ("country", NameOID.COUNTRY_NAME),
            ("email", NameOID.EMAIL_ADDRESS), ("serial number", NameOID.SERIAL_NUMBER))
    try:
        subject = x509.Name([x509.NameAttribute(oid, values[name]) for name, oid in oids if values[name]])
    except ValueError as exc:
        raise CipError(GeneralStatus.INVALID_PARAMETER, message=f"subject refused: {exc}") from None
    key: Any = serialization.load_pem_private_key(key_pem, password=None)
    builder = x509.CertificateSigningRequestBuilder().subject_name(subject)
    alternative = values["subject alternative name"]
    if alternative:
        try:
            general: x509.GeneralName = x509.IPAddress(ipaddress.ip_address(alternative))
        except ValueError:
            general = x509.DNSName(alternative)
        builder = builder.add_extension(x509.SubjectAlternativeName([general]), critical=False)
    return builder.sign(key, hashes.SHA256()).public_bytes(serialization.Encoding.DER)


def load_certificate(der: bytes) -> Any:
    """A DER certificate as ``cryptography`` reads it; 0x09 (invalid attribute value) if it is not one."""
    _crypto()
    from cryptography import x509

    if len(der) > MAX_CERTIFICATE:
        raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message=f"certificate of {len(der)} octets")
    try:
        return x509.load_der_x509_certificate(der)
    except ValueError:
        raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message="not a DER X.509 certificate") from None


def verify(device_der: bytes, ca_der: bytes, key_pem: bytes, now: datetime.datetime | None = None,
           check_expiration: bool = True) -> str | None:
    """Why the device certificate is not usable with ``key_pem`` under the CA, or None when it is:
    signed by the CA, for this key, and (with ``check_expiration``) valid now."""
    _crypto()
    from cryptography.exceptions import InvalidSignature
    from cryptography.hazmat.primitives import serialization
    if not device_der:
        return "no device certificate"
    if not ca_der:
        return "no CA certificate"
    device, ca = load_certificate(device_der), load_certificate(ca_der)
    try:
        device.verify_directly_issued_by(ca)
    except (ValueError, TypeError, InvalidSignature):
        return "the device certificate is not signed by the CA certificate"
    if not key_pem:
        return "no private key: Create_CSR makes it"
    key: Any = serialization.load_pem_private_key(key_pem, password=None)
    if device.public_key().public_numbers() != key.public_key().public_numbers():
        return "the device certificate is not for the key of the device's last Create_CSR"
    if check_expiration:
        moment = now or datetime.datetime.now(datetime.timezone.utc)
        if not device.not_valid_before_utc <= moment <= device.not_valid_after_utc:
            return f"the device certificate is not valid now (valid until {device.not_valid_after_utc:%Y-%m-%d})"
    return None


def revocation_list_der(data: bytes) -> bytes:
    """A CRL file's octets (PEM or DER) as DER; 0x09 (invalid attribute value) for a file that holds no
    certificate revocation list."""
    _crypto()
    from cryptography import x509
    from cryptography.hazmat.primitives.serialization import Encoding

    try:
        if data.lstrip().startswith(b"-----BEGIN"):
            return x509.load_pem_x509_crl(data).public_bytes(Encoding.DER)
        return x509.load_der_x509_crl(data).public_bytes(Encoding.DER)
    except ValueError:
        raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message="not a certificate revocation list") from None


def revocation_list_problem(crl_der: bytes, ca_der: bytes) -> str | None:
    """Why a CRL cannot be checked against (none held, or not signed by the CA), or None."""
    _crypto()
    from cryptography import x509

    if not crl_der:
        return "the Certificate Revocation List names a file that holds no CRL"
    crl = x509.load_der_x509_crl(crl_der)
    if not ca_der or not crl.is_signature_valid(load_certificate(ca_der).public_key()):
        return "the certificate revocation list is not signed by the CA certificate"
    return None


def identity_bundle(data: bytes) -> bytes:
    """A Trusted Identities file's octets: one or more PEM certificates, returned as read; 0x09 (invalid
    attribute value) for a file that holds none."""
    _crypto()
    from cryptography import x509

    try:
        x509.load_pem_x509_certificates(data)
    except ValueError:
        raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message="not PEM certificates") from None
    return data


def identities(bundle: bytes) -> frozenset[str]:
    """The subjects (RFC 4514) of a Trusted Identities file's certificates."""
    _crypto()
    from cryptography import x509

    return frozenset(c.subject.rfc4514_string() for c in x509.load_pem_x509_certificates(bundle)) if bundle \
        else frozenset()


def pem(der: bytes, label: str = "CERTIFICATE") -> bytes:
    """DER octets as PEM (a certificate; ``label`` "CERTIFICATE REQUEST" for a CSR); none for none."""
    import base64

    if not der:
        return b""
    body = base64.encodebytes(der).replace(b"\n", b"")
    lines = [body[i:i + 64] for i in range(0, len(body), 64)]
    marker = label.encode()
    return (b"-----BEGIN " + marker + b"-----\n" + b"\n".join(lines) + b"\n-----END " + marker + b"-----\n")


def certificate_der(data: bytes) -> bytes:
    """A certificate file's octets (PEM, the Certificate Encoding 0 the device reports, or DER) as DER;
    0x09 (invalid attribute value) for a file that holds no certificate."""
    if data.lstrip().startswith(b"-----BEGIN"):
        try:
            return der_of_pem(data)
        except ValueError:
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message="not a PEM certificate") from None
    load_certificate(data)
    return data


def der_of_pem(data: bytes) -> bytes:
    """The DER octets of the first PEM certificate of ``data``."""
    _crypto()
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    return x509.load_pem_x509_certificate(data).public_bytes(serialization.Encoding.DER)


__all__ = ["CSR_FIELDS", "certificate_der", "certificate_signing_request", "der_of_pem", "load_certificate",
           "new_key", "pem", "verify"]
