"""Group security, pre-shared keys: TLS 1.2 on the security port offering the PSK suites alone, with
the identity and key of the credentials folder's ``psk.txt`` (``cipstack security init --psk``).

The suites are TLS 1.2's (RFC 4279, RFC 5489): ECDHE-PSK-AES128-CBC-SHA256, the one the public
write-ups of the EtherNet/IP Confidentiality Profile name, then the PSK AEAD suites; the key is the
one the EtherNet/IP Security object's Pre-Shared Keys attribute (0x5E/1/5) holds. A folder without
``psk.txt`` says nothing of the device's keys: the checks do not apply.
"""

from __future__ import annotations

import importlib.util
import secrets
import socket
from dataclasses import replace

from ..errors import CipstackError, SecurityError
from .model import Behaviour, CheckSpec, Outcome, Verdict
from .registry import Context, check, outcome
from .security import BRANCH, allowed_suites, needs_folder, register_over

SOURCES = "RFC 4279; RFC 5489 (ECDHE-PSK); " + BRANCH + " (attribute 5, Pre-Shared Keys)"


def _needs_key(ctx: Context, spec: CheckSpec) -> Outcome | None:
    skipped = needs_folder(ctx, spec)
    if skipped is not None or ctx.security is None:
        return skipped
    if not (ctx.security / "psk.txt").exists():
        return outcome(spec, Verdict.NOT_APPLICABLE, f"no psk.txt in {ctx.security} (`cipstack security init "
                                                     "--psk` writes one): the device's keys are not known")
    from ..security.credentials import Credentials

    try:
        Credentials.load(ctx.security)
    except SecurityError as exc:   # the battery's folder, not the device
        return outcome(spec, Verdict.NOT_RUN, str(exc))
    if importlib.util.find_spec("OpenSSL") is None:
        return outcome(spec, Verdict.NOT_RUN, "needs pyOpenSSL: pip install 'cipstack[security]'")
    if not _psk_suites(ctx):
        return outcome(spec, Verdict.NOT_APPLICABLE, "Allowed Cipher Suites (0x5E/1/4) lists no PSK suite: the "
                                                     "device is configured not to serve one")
    return None


def _psk_suites(ctx: Context) -> list[str]:
    """OpenSSL's names of the PSK suites of Allowed Cipher Suites (0x5E/1/4); all four the battery knows
    when the attribute does not read."""
    from ..security.declarations import PSK_SUITE_NAMES

    allowed, _ = allowed_suites(ctx)
    if not allowed:
        return list(PSK_SUITE_NAMES.values())
    return [PSK_SUITE_NAMES[s] for s in allowed if s in PSK_SUITE_NAMES]


def _offer(ctx: Context, identity: bytes | None = None, register: bool = True) -> tuple[str | None, str]:
    """A TLS 1.2 handshake on the security port offering only the PSK suites of Allowed Cipher Suites
    (all four when it lists none the battery knows), with the folder's key under its identity or
    ``identity``: (None, the suite) when it completes (and, with ``register``, RegisterSession
    through it is answered), else (why not, "")."""
    from ..security.credentials import Credentials, PreSharedKey

    assert ctx.security is not None
    credentials = Credentials.load(ctx.security)   # _needs_key loaded it once already
    assert credentials.psk is not None   # _needs_key saw psk.txt
    if identity is not None:
        credentials = replace(credentials, psk=PreSharedKey(identity, credentials.psk.key))
    credentials = credentials.offering(*_psk_suites(ctx))
    try:
        sock = socket.create_connection((ctx.host, ctx.security_port), ctx.timeout)
    except OSError as exc:
        return f"TLS port {ctx.host}:{ctx.security_port}: {exc.strerror or exc}", ""
    try:
        tls = credentials.wrap_client(sock, ctx.host, ctx.security_port)
    except CipstackError as exc:
        return str(exc), ""
    try:
        cipher = getattr(getattr(tls, "tls", None), "cipher", lambda: None)()
        suite = cipher[0] if cipher else "a PSK suite"
        return (register_over(tls) if register else None), suite
    except TimeoutError:
        return f"no reply to RegisterSession over TLS within {ctx.timeout:g} s", ""
    except (OSError, CipstackError) as exc:
        return f"{type(exc).__name__}: {exc}", ""
    finally:
        tls.close()


@check("security.psk.handshake", "a TLS 1.2 handshake with the pre-shared key, and a request inside it",
       "with psk.txt in the folder and a PSK suite in Allowed Cipher Suites (0x5E/1/4): a TLS 1.2 client "
       "offering only those PSK suites (all four the battery knows when the attribute does not read), with "
       "the folder's identity and key, completes the handshake on the TLS port and its RegisterSession is "
       "answered", SOURCES)
def psk_handshake(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = _needs_key(ctx, spec)
    if skipped is not None:
        return skipped
    problem, suite = _offer(ctx)
    return outcome(spec, problem is None, problem or f"{suite}: handshake and RegisterSession")


@check("security.psk.unknown_identity", "a PSK identity the device does not have is refused without harm",
       "with psk.txt in the folder: the same handshake under an identity the device does not have (the "
       "folder's key) fails; then port 44818 and the handshake with the folder's identity still answer",
       SOURCES + "; RFC 4279 2 (unknown identity)",
       behaviours=(Behaviour("unknown_psk_identity", "the device refuses with the unknown_psk_identity alert",
                             "RFC 4279 2"),
                   Behaviour("decrypt_error", "the device goes on as if the identity existed with another key, "
                             "and the handshake fails (decrypt_error, bad record MAC)", "RFC 4279 2")))
def psk_unknown_identity(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = _needs_key(ctx, spec)
    if skipped is not None:
        return skipped
    stranger = b"cipstack-conform-" + secrets.token_hex(4).encode()
    refused, suite = _offer(ctx, stranger, register=False)
    if refused is None:
        return outcome(spec, False, f"identity '{stranger.decode()}' accepted ({suite})")
    probe = ctx.probe()
    problem, _ = _offer(ctx, register=False)
    if problem is not None:
        return outcome(spec, False, f"refused ({refused}), then the folder's identity was: {problem}",
                       probe.exchanges)
    return outcome(spec, True, f"refused ({refused}); 44818 and the folder's identity serve on", probe.exchanges)


__all__ = ["SOURCES"]
