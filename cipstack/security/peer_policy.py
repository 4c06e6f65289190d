"""What the EtherNet/IP Security object's settings make of the next TLS and DTLS handshakes of a device
configured over the network.

OpENer's CIP Security branch (``ethernetipsecurity.c``, Apply_Config, citing Volume 8 5-4.7.3) says the
device "shall begin using the new attribute settings when establishing new (D)TLS sessions"; the branch
declares each attribute with its name, type and factory default, and acts on none. What each does here
is read from its name (chosen here where no public source says more):

* Verify Client Certificate (9): on, the device asks for the client's certificate and refuses a client
  without one or with one its trusted authorities did not sign; off, it asks for none (branch default
  off; a device started with ``--security DIR`` shows it on, as its listeners have always done);
* Check Expiration (11): on, a client certificate outside its validity is refused; off, OpenSSL's time
  check alone is skipped (``X509_V_FLAG_NO_CHECK_TIME``), the signature still checked (branch default
  off; ``--security DIR`` shows it on, what OpenSSL always did there);
* Send Certificate Chain (10): on, the handshake carries the device certificate and the CA certificate
  the device holds; off, the device certificate alone (OpenSSL would otherwise build the chain from
  its trust store: ``SSL_MODE_NO_AUTO_CHAIN``) (branch default off; ``--security DIR`` shows it on);
* Certificate Revocation List (8): a path to the File object instance a tool downloaded a CRL into
  (``declarations.CRL_FILE``, chosen here); a client certificate it lists is refused (OpenSSL's leaf
  check, ``X509_V_FLAG_CRL_CHECK``); Apply_Config refuses a path to a file with no CRL of the CA;
* Trusted Identities (12): paths to the File object instance a tool downloaded certificates into
  (``declarations.TRUSTED_IDENTITIES_FILE``, chosen here); with Verify Client Certificate on, a client
  whose certificate's subject (the whole distinguished name) is not one of theirs is refused, however
  good its signature (chosen here: no public source says which part of a certificate is the identity).

Each is applied to a pyOpenSSL context: the TLS port of a configured device and its DTLS port are
both pyOpenSSL's (``tls_psk.openssl_context``), since Python's ``ssl`` cannot stop the chain building.
"""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING, Any

from ..errors import SecurityError

if TYPE_CHECKING:
    from .configuration import Configuration
    from .credentials import Credentials

#: OpenSSL's ``X509_V_FLAG_NO_CHECK_TIME`` (x509_vfy.h): verify without the validity dates. pyOpenSSL's
#: ``X509StoreFlags`` does not name it; the store takes the number.
NO_CHECK_TIME = 0x200000
#: OpenSSL's ``SSL_MODE_NO_AUTO_CHAIN`` (ssl.h): send the certificate alone, build no chain from the store.
NO_AUTO_CHAIN = 0x8


#: Connections whose client certificate Trusted Identities refused, and why: OpenSSL records only "unspecified
#: certificate verification error" when a verify callback says no (``psk.verify_message`` reads this).
_UNTRUSTED: weakref.WeakKeyDictionary[Any, str] = weakref.WeakKeyDictionary()


def untrusted(connection: Any) -> str | None:
    """Why Trusted Identities refused the client of ``connection``, or None when they did not."""
    return _UNTRUSTED.get(connection)


class IdentityCheck:
    """The verify callback of Trusted Identities: OpenSSL's verdict, and at the client's own certificate
    (depth 0) its subject among ``subjects`` (RFC 4514 strings)."""

    def __init__(self, subjects: frozenset[str]) -> None:
        self.subjects = subjects

    def __call__(self, connection: Any, certificate: Any, number: int, depth: int, ok: int) -> bool:
        if not ok or depth:
            return bool(ok)
        subject = certificate.to_cryptography().subject.rfc4514_string()
        if subject in self.subjects:
            return True
        _UNTRUSTED[connection] = f"subject {subject} is not one of the Trusted Identities"
        return False


def apply(context: Any, credentials: Credentials, configuration: Configuration) -> None:
    """Make ``context`` (a device's ``OpenSSL.SSL.Context`` with its certificate loaded) follow Check
    Expiration, the Certificate Revocation List, the Trusted Identities and Send Certificate Chain;
    Verify Client Certificate is its verify mode, set where it is made (``tls_psk.openssl_context``)."""
    if credentials.device is None or credentials.ca is None:
        return   # pre-shared keys alone: no certificate to check or send
    store = context.get_cert_store()
    if not configuration.check_expiration:
        store.set_flags(NO_CHECK_TIME)
    if configuration.revocation_list and configuration.crl:
        from cryptography import x509
        from OpenSSL import crypto

        # Apply_Config checked that it reads and that the CA signed it (``objects.usable``).
        store.add_crl(x509.load_der_x509_crl(configuration.crl))
        store.set_flags(crypto.X509StoreFlags.CRL_CHECK)   # the client's certificate: the leaf
    if configuration.trusted_identities and configuration.identity_certificates and configuration.verify_client:
        from .certificates import identities

        context.set_verify(context.get_verify_mode(), IdentityCheck(identities(configuration.identity_certificates)))
    if configuration.send_chain:
        from cryptography import x509

        try:
            authority = x509.load_pem_x509_certificate(credentials.ca.path.read_bytes())
        except (OSError, ValueError) as exc:
            raise SecurityError(f"{credentials.ca.path}: not a usable CA certificate ({exc})") from None
        context.add_extra_chain_cert(authority)
    else:
        context.set_mode(NO_AUTO_CHAIN)


__all__ = ["NO_AUTO_CHAIN", "NO_CHECK_TIME", "IdentityCheck", "apply", "untrusted"]
