"""Group security, the DTLS port: EtherNet/IP over DTLS 1.2 on UDP at the security port (2221), with
the credentials folder's CA and client certificate (``--security DIR``).

The port and the version are public: Wireshark's packet-enip.c registers its dissector for DTLS on
UDP 2221 (``ENIP_SECURE_PORT``), OpENer issue #232 names UDP 2221 and issue #228 (D)TLS 1.2 as the
least version. What a device without DTLS is, is cipstack's reading, since Volume 8 is not public:
DTLS carries the secured class 0/1 I/O, and a Forward_Open over TLS opens plain UDP 2222 I/O (OpENer
issue #234), so a device may secure its explicit messaging over TLS and serve no DTLS at all; one
that answers no ClientHello within the timeout, or whose host reports the port unreachable (ICMP),
is such a device and the checks do not apply to it.
"""

from __future__ import annotations

import importlib.util
import socket
import struct
from dataclasses import replace
from typing import TYPE_CHECKING

from ..eip.wire.encapsulation import HEADER, Command
from ..errors import CipstackError, NoReply, NothingListens, SecurityError
from .model import Behaviour, CheckSpec, Outcome, Verdict
from .registry import Context, check, outcome
from .security import BRANCH, SUITE_NAMES, allowed_suites, needs_certificates
from .wire import frame

if TYPE_CHECKING:
    from ..security.dtls_link import DtlsLink

SOURCES = ("packet-enip.c (ENIP_SECURE_PORT: DTLS on UDP 2221); OpENer issues #232 (UDP 2221), #228 "
           "(DTLS 1.2) and #234 (I/O over DTLS)")
#: What a device without a DTLS port does, as ``_open`` tells it.
NO_PORT = Behaviour("no DTLS port", "no answer to a DTLS ClientHello within the timeout, or ICMP port "
                    "unreachable: the device secures explicit messaging over TLS only and its I/O stays on UDP "
                    "2222; the check does not apply (cipstack's reading, Volume 8 is not public)", "OpENer issue #234")
#: The largest UDP payload.
_DATAGRAM = 65535


class NoDtlsPort(CipstackError):
    """Nothing answers a DTLS ClientHello at the security port."""


class UnusableFolder(CipstackError):
    """The credentials folder does not load (a file missing, expired ...): the battery's, not the device's."""


class NothingToOffer(CipstackError):
    """Allowed Cipher Suites lists no certificate suite the battery knows."""


def _open(ctx: Context) -> DtlsLink:
    """A DTLS session with the security port, offering the folder's client certificate and the
    certificate suites of Allowed Cipher Suites the battery knows (OpenSSL's own when the attribute
    does not read). ``NoDtlsPort`` when nothing answers; ``UnusableFolder`` when the folder does not
    load; ``NothingToOffer`` when no allowed suite is one the battery knows; ``SecurityError`` (naming
    the cause) when the device refuses."""
    from ..security.credentials import Credentials

    assert ctx.security is not None
    try:
        loaded = Credentials.load(ctx.security)
    except SecurityError as exc:
        raise UnusableFolder(str(exc)) from None
    # The certificate handshake only: the folder's key, if it holds one, is the PSK checks' business.
    credentials = replace(loaded, psk=None)
    allowed, _ = allowed_suites(ctx)
    known = [SUITE_NAMES[s] for s in allowed if s in SUITE_NAMES]
    if allowed and not known:
        raise NothingToOffer("no allowed certificate suite this battery can offer: "
                             + ", ".join(f"0x{s:04X}" for s in allowed))
    if known:
        credentials = credentials.offering(*known)
    try:
        return credentials.datagram_link(ctx.host, ctx.security_port, ctx.timeout)
    except (NoReply, NothingListens) as exc:
        # Nothing serves DTLS there: no answer to the handshake, or ICMP port unreachable; any other
        # failure (the device closed the association during the handshake) is a refusal.
        raise NoDtlsPort(str(exc)) from None


def _session(ctx: Context, spec: CheckSpec, failed: str = "") -> tuple[DtlsLink | None, Outcome | None]:
    """``_open``'s session, or the outcome of the check when there is none (``failed`` before a refusal)."""
    try:
        return _open(ctx), None
    except NoDtlsPort as exc:
        return None, outcome(spec, Verdict.NOT_APPLICABLE, f"{NO_PORT.name}: {exc}")
    except UnusableFolder as exc:
        return None, outcome(spec, Verdict.NOT_RUN, str(exc))
    except NothingToOffer as exc:
        return None, outcome(spec, Verdict.NOT_APPLICABLE, str(exc))
    except CipstackError as exc:
        return None, outcome(spec, False, failed + str(exc))


def needs_pyopenssl(ctx: Context, spec: CheckSpec) -> Outcome | None:
    """Not run without the folder's certificates, or without pyOpenSSL (DTLS and pre-shared keys)."""
    skipped = needs_certificates(ctx, spec)
    if skipped is None and importlib.util.find_spec("OpenSSL") is None:
        return outcome(spec, Verdict.NOT_RUN, "needs pyOpenSSL: pip install 'cipstack[security]'")
    return skipped


def _list_identity(link: DtlsLink, timeout: float) -> str | None:
    """ListIdentity in the session: None when its reply comes back in the session, else why not."""
    link.settimeout(timeout)
    link.sendall(frame(Command.LIST_IDENTITY))
    try:
        reply = link.recv(_DATAGRAM)
    except TimeoutError:
        return f"no reply to ListIdentity in the DTLS session within {timeout:g} s"
    if len(reply) < HEADER.size + 2:
        return f"ListIdentity in the DTLS session answered {len(reply)} bytes: {reply.hex()}"
    command, length, _, status = HEADER.unpack_from(reply)[:4]
    (items,) = struct.unpack_from("<H", reply, HEADER.size)
    if command != Command.LIST_IDENTITY or status != 0 or length != len(reply) - HEADER.size or items < 1:
        return f"ListIdentity in the DTLS session answered {reply[:HEADER.size + 2].hex()}"
    return None


@check("security.dtls.handshake", "a DTLS 1.2 handshake with an allowed suite, and a request inside it",
       "a DTLS 1.2 client offering the certificate suites of Allowed Cipher Suites (0x5E/1/4) the battery "
       "knows, with a client certificate of the trusted CA, completes the handshake on UDP at the security "
       "port, and a ListIdentity sent in the session is answered in the session (ListIdentity: any device "
       "answers it, no session or object needed)",
       SOURCES + "; RFC 6347; " + BRANCH,
       behaviours=(Behaviour("served", "the handshake completes and ListIdentity is answered in the session",
                             "packet-enip.c; OpENer issue #232"), NO_PORT))
def dtls_handshake(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = needs_pyopenssl(ctx, spec)
    if skipped is not None:
        return skipped
    link, verdict = _session(ctx, spec)
    if link is None:
        assert verdict is not None
        return verdict
    try:
        problem = _list_identity(link, ctx.timeout)
        described = link.channel.description()
    except CipstackError as exc:
        problem, described = str(exc), ""
    finally:
        link.close()
    return outcome(spec, problem is None, problem or f"served: {described}, ListIdentity answered in the session")


def _plain_answer(ctx: Context) -> tuple[bytes | None, str]:
    """Send a plain ListIdentity to the DTLS port: (what came back in plain, or None; how it was refused)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.connect((ctx.host, ctx.security_port))
        sock.settimeout(ctx.timeout)
        sock.send(frame(Command.LIST_IDENTITY))
        try:
            data = sock.recv(_DATAGRAM)
        except TimeoutError:
            return None, f"discarded: no answer within {ctx.timeout:g} s"
        except ConnectionRefusedError:
            return None, "the port then reported unreachable (ICMP)"
    if len(data) >= 13 and 20 <= data[0] <= 23 and data[1] == 0xFE:   # a DTLS record (RFC 6347, 4.1)
        return None, f"alert: a DTLS record of type {data[0]} came back"
    return data, ""


@check("security.dtls.plaintext", "plain EtherNet/IP on the DTLS port is refused without harm",
       "a plain ListIdentity datagram sent to UDP at the security port gets no plain reply (it is discarded, "
       "or answered by a DTLS alert); then port 44818 and a new DTLS handshake still answer",
       SOURCES + "; RFC 6347 4.1.2.7 (invalid records)",
       behaviours=(Behaviour("discarded", "nothing comes back", "RFC 6347 4.1.2.7: invalid records SHOULD be "
                             "silently discarded"),
                   Behaviour("alert", "a DTLS record (a fatal alert) comes back", "RFC 6347 4.1.2.7: an "
                             "implementation that generates an alert instead MUST make it fatal"), NO_PORT))
def dtls_plaintext(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = needs_pyopenssl(ctx, spec)
    if skipped is not None:
        return skipped
    # A handshake first: a port that never served DTLS is told from one the plain datagram broke.
    link, verdict = _session(ctx, spec, "the DTLS handshake before the plain datagram failed: ")
    if link is None:
        assert verdict is not None
        return verdict
    link.close()
    plain, refused = _plain_answer(ctx)
    if plain is not None:
        return outcome(spec, False, f"answered in plain: {plain[:HEADER.size].hex()}")
    probe = ctx.probe()
    try:
        _open(ctx).close()
    except CipstackError as exc:
        return outcome(spec, False, f"refused ({refused}), then the DTLS handshake failed: {exc}", probe.exchanges)
    return outcome(spec, True, f"refused ({refused}); 44818 and DTLS serve on", probe.exchanges)

__all__ = ["NO_PORT", "NoDtlsPort", "NothingToOffer", "UnusableFolder", "needs_pyopenssl"]
