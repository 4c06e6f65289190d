"""Pre-shared keys in an OpenSSL handshake: the PSK callbacks of a pyOpenSSL context, both roles,
and the few other OpenSSL calls pyOpenSSL does not make public (``written``, ``unread``,
``verify_message``).

pyOpenSSL (26.x) has no PSK API. The ``cryptography`` package it is built on exposes OpenSSL's
``SSL_CTX_set_psk_server_callback``, ``SSL_CTX_set_psk_client_callback`` and
``SSL_CTX_use_psk_identity_hint`` in its bindings, which pyOpenSSL re-exports as
``OpenSSL._util.lib``/``ffi``, and they take the OpenSSL pointers pyOpenSSL keeps in its objects
(``Context._context``, ``Connection._ssl``, ``Connection._from_ssl``, ``Connection._into_ssl``):
private names, used here and nowhere else. What guards them:
``bindings()`` checks ``lib.Cryptography_HAS_PSK`` and each function, and a build without them is one
``SecurityError`` line, never an ``AttributeError`` in the middle of a handshake. The standard library
has ``SSLContext.set_psk_server_callback`` only from Python 3.13, and no DTLS at all: one path
through pyOpenSSL serves every supported Python and both transports (``tls_psk`` for TLS, ``dtls``
for DTLS).

The suites are TLS 1.2's (RFC 4279, RFC 5489): ECDHE-PSK-AES128-CBC-SHA256, the suite the public
write-ups of the EtherNet/IP Confidentiality Profile name, then the PSK AEAD suites as OpenSSL names
them. TLS 1.3 carries a PSK in another way (resumption and external PSKs, RFC 8446 4.2.11), which
those write-ups do not name: a context with a PSK is pinned to (D)TLS 1.2.
"""

from __future__ import annotations

import weakref
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

from ..errors import SecurityError

if TYPE_CHECKING:
    from OpenSSL import SSL

#: The PSK suites a context with a key offers and accepts, in OpenSSL's names, preferred first.
PSK_SUITES = ("ECDHE-PSK-AES128-CBC-SHA256", "ECDHE-PSK-CHACHA20-POLY1305", "PSK-AES128-GCM-SHA256",
              "PSK-AES256-GCM-SHA384")

_SERVER_CALLBACK = "unsigned int (*)(SSL *, const char *, unsigned char *, unsigned int)"
_CLIENT_CALLBACK = "unsigned int (*)(SSL *, const char *, char *, unsigned int, unsigned char *, unsigned int)"

#: The cffi callbacks of each context, kept as long as the context lives: OpenSSL holds bare function
#: pointers, and a callback collected while the context still calls it would crash the process.
_KEPT: weakref.WeakKeyDictionary[Any, list[Any]] = weakref.WeakKeyDictionary()
#: The bindings, once checked.
_BINDINGS: list[tuple[Any, Any]] = []
#: The device's keys of each context that accepts them.
_SERVERS: weakref.WeakKeyDictionary[Any, PskServer] = weakref.WeakKeyDictionary()


def bindings() -> tuple[Any, Any]:
    """``(lib, ffi)`` of the OpenSSL that pyOpenSSL uses, with the PSK functions; ``SecurityError``
    when this build of ``cryptography`` lacks them. Checked once, then kept (a record costs no check)."""
    if _BINDINGS:
        return _BINDINGS[0]
    try:
        from OpenSSL._util import ffi, lib
    except ImportError:
        raise SecurityError("pre-shared keys need the pyOpenSSL package: pip install 'cipstack[security]'") from None
    needed = ("SSL_CTX_set_psk_server_callback", "SSL_CTX_set_psk_client_callback", "SSL_CTX_use_psk_identity_hint")
    if not getattr(lib, "Cryptography_HAS_PSK", False) or not all(hasattr(lib, name) for name in needed):
        raise SecurityError("pre-shared keys: the OpenSSL bindings of this cryptography package have no PSK "
                            "functions (Cryptography_HAS_PSK)")
    from OpenSSL import SSL

    others = ("BIO_get_mem_data", "SSL_get_verify_result", "X509_verify_cert_error_string")
    connection = SSL.Connection(SSL.Context(SSL.TLS_METHOD), None)
    pointers = (hasattr(connection.get_context(), "_context") and hasattr(connection, "_ssl")
                and hasattr(connection, "_from_ssl") and hasattr(connection, "_into_ssl"))
    if not pointers or not all(hasattr(lib, name) for name in others):
        raise SecurityError("pre-shared keys: this pyOpenSSL keeps its OpenSSL pointers otherwise than "
                            "cipstack.security.psk expects (26.x does)")
    _BINDINGS.append((lib, ffi))
    return lib, ffi


class PskServer:
    """The device's keys by identity, and the identity each handshake asked for (for its refusal line)."""

    #: Identities remembered for refusal lines at most (a handshake that never reads its own is forgotten).
    REMEMBERED = 256

    def __init__(self, keys: Iterable[tuple[bytes, bytes]]) -> None:
        self.keys = dict(keys)
        self._asked: dict[int, bytes] = {}

    def identity_of(self, connection: Any) -> bytes | None:
        """The identity the peer of ``connection`` (a pyOpenSSL ``Connection``) named, once it did."""
        _, ffi = bindings()
        return self._asked.pop(int(ffi.cast("uintptr_t", connection._ssl)), None)

    def find(self, ssl: Any, identity: bytes) -> bytes | None:
        if len(self._asked) >= self.REMEMBERED:
            self._asked.clear()
        _, ffi = bindings()
        self._asked[int(ffi.cast("uintptr_t", ssl))] = identity
        return self.keys.get(identity)


def serve_psk(context: SSL.Context, keys: Iterable[tuple[bytes, bytes]]) -> PskServer:
    """Make ``context`` (a device's) accept the PSK suites with ``keys`` ((identity, key) pairs); an
    unknown identity is refused with OpenSSL's unknown_psk_identity alert (RFC 4279, 2)."""
    lib, ffi = bindings()
    server = PskServer(keys)

    def callback(ssl: Any, identity: Any, psk: Any, max_psk_len: int) -> int:
        try:
            key = server.find(ssl, ffi.string(identity) if identity != ffi.NULL else b"")
            if key is None or len(key) > max_psk_len:
                return 0   # OpenSSL then refuses with unknown_psk_identity
            ffi.memmove(psk, key, len(key))
            return len(key)
        except Exception:   # an exception must not cross into OpenSSL: refuse the handshake instead
            return 0

    handle = ffi.callback(_SERVER_CALLBACK, callback)
    _KEPT.setdefault(context, []).append(handle)
    _SERVERS[context] = server
    lib.SSL_CTX_set_psk_server_callback(context._context, handle)
    return server


def identity_asked(connection: SSL.Connection) -> bytes | None:
    """The PSK identity the peer of ``connection`` (a device's) named, if it named one."""
    server = _SERVERS.get(connection.get_context())
    return server.identity_of(connection) if server is not None else None


def offer_psk(context: SSL.Context, identity: bytes, key: bytes) -> None:
    """Make ``context`` (an originator's) offer the PSK suites with ``identity`` and ``key``."""
    lib, ffi = bindings()

    def callback(ssl: Any, hint: Any, identity_out: Any, max_identity_len: int, psk: Any, max_psk_len: int) -> int:
        try:
            # OpenSSL passes the room for the identity less its terminating NUL (its buffer is
            # PSK_MAX_IDENTITY_LEN + 1): an identity of exactly that length still fits with its NUL.
            if len(identity) > max_identity_len or len(key) > max_psk_len:
                return 0
            ffi.memmove(identity_out, identity + b"\0", len(identity) + 1)
            ffi.memmove(psk, key, len(key))
            return len(key)
        except Exception:   # an exception must not cross into OpenSSL: the handshake fails instead
            return 0

    handle = ffi.callback(_CLIENT_CALLBACK, callback)
    _KEPT.setdefault(context, []).append(handle)
    lib.SSL_CTX_set_psk_client_callback(context._context, handle)


def written(connection: Any) -> int:
    """Octets the TLS layer of ``connection`` (a pyOpenSSL ``Connection`` over memory BIOs) has
    written for the peer and not yet handed out: ``BIO_get_mem_data`` of its outgoing BIO, so that a
    shell asks for them only when there are some (``Connection.bio_read`` of an empty BIO raises)."""
    lib, ffi = bindings()
    return int(lib.BIO_get_mem_data(connection._from_ssl, ffi.NULL))


def unread(connection: Any) -> int:
    """Octets of ciphertext ``connection`` was given and has not read yet (``BIO_get_mem_data`` of its
    incoming BIO): the records after the one being read, which ``SSL_pending`` does not count."""
    lib, ffi = bindings()
    return int(lib.BIO_get_mem_data(connection._into_ssl, ffi.NULL))


def verify_message(connection: Any) -> str:
    """Why the peer's certificate of ``connection`` did not verify, in OpenSSL's words
    (``SSL_get_verify_result``; pyOpenSSL's error says only "certificate verify failed"), or the
    device's Trusted Identities' (``peer_policy``)."""
    from .peer_policy import untrusted

    note = untrusted(connection)
    if note is not None:
        return note
    lib, ffi = bindings()
    code = lib.SSL_get_verify_result(connection._ssl)
    return str(ffi.string(lib.X509_verify_cert_error_string(code)).decode())


def reason_code(text: str) -> str:
    """OpenSSL's reason string as the ``ssl`` module names it: ``tlsv1 alert unknown ca`` ->
    ``TLSV1_ALERT_UNKNOWN_CA``."""
    return text.strip().upper().replace(" ", "_")


def explain(reason: str, identity: bytes | None) -> str | None:
    """A PSK handshake's failure in the words a user searches for, from OpenSSL's reason (either
    form); None for a reason that is not about the key."""
    code = reason_code(reason)
    named = f" '{identity.decode('ascii', 'replace')}'" if identity else ""
    if code == "TLSV1_ALERT_UNKNOWN_PSK_IDENTITY":
        return f"PSK identity{named} unknown to the device (alert: unknown PSK identity)"
    if code == "PSK_IDENTITY_NOT_FOUND":
        return f"unknown PSK identity{named}"
    if "ALERT" in code and ("BAD_RECORD_MAC" in code or "DECRYPT_ERROR" in code):
        return (f"the peer could not check our Finished: wrong pre-shared key for identity{named} "
                f"(alert: {code.lower().replace('_', ' ')})")
    if code in ("DECRYPTION_FAILED_OR_BAD_RECORD_MAC", "BAD_RECORD_MAC", "DIGEST_CHECK_FAILED"):
        return f"wrong pre-shared key for identity{named} ({code.lower().replace('_', ' ')})"
    return None


__all__ = ["PSK_SUITES", "PskServer", "bindings", "explain", "identity_asked", "offer_psk", "reason_code",
           "serve_psk", "verify_message", "written"]
