"""Group security: CIP Security's objects and the TLS port, with the credentials folder of
``cipstack security init`` (``--security DIR``: its CA is the one the device trusts, its client
certificate the one the battery presents).

Volume 8 is not public: the objects' codes and layouts are those OpENer's CIP Security branch
declares and Wireshark's packet-enip.c decodes (docs/security.md lists them); TLS 1.2 is the least
version (OpENer issue #228), TCP 2221 the port (packet-enip.c, ``ENIP_SECURE_PORT``).
"""

from __future__ import annotations

import contextlib
import socket
import ssl
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Protocol

from ..cip.epath import request_path
from ..eip.wire.encapsulation import HEADER, REGISTER_SESSION_DATA, Command
from .model import CheckSpec, Code, Outcome, Verdict
from .registry import Context, check, outcome
from .wire import Probe, frame

GET_SINGLE = 0x0E
BEGIN_CONFIG, KICK_TIMER, ABORT_CONFIG = 0x4B, 0x4C, 0x4E
EIP_SECURITY, CIP_SECURITY, CERTIFICATES = 0x5E, 0x5D, 0x5F
BRANCH = "Volume 8 5-4 as OpENer's CIP Security branch declares it (ethernetipsecurity.h)"
#: OpenSSL's names of the TLS 1.2 suites a device may allow, by IANA id.
SUITE_NAMES = {0xC023: "ECDHE-ECDSA-AES128-SHA256", 0xC02B: "ECDHE-ECDSA-AES128-GCM-SHA256",
               0xC02C: "ECDHE-ECDSA-AES256-GCM-SHA384", 0xC009: "ECDHE-ECDSA-AES128-SHA",
               0xCCA9: "ECDHE-ECDSA-CHACHA20-POLY1305"}
#: A TLS record of type handshake (22) or alert (21): what a TLS port may send first.
TLS_RECORDS = (0x15, 0x16)


def _suites(data: bytes) -> str | None:
    return None if data and len(data) == 1 + 2 * data[0] else f"{len(data)} bytes, not a count and 2-octet ids"


def _paths(data: bytes) -> str | None:
    if not data:
        return "no count"
    offset = 1
    for _ in range(data[0]):
        if offset >= len(data):
            return f"{len(data)} bytes, cut short in path {_ + 1}"
        offset += 1 + 2 * data[offset]
    return None if offset == len(data) else f"{len(data)} bytes, the paths make {offset}"


def _path(data: bytes) -> str | None:
    return None if data and len(data) == 1 + 2 * data[0] else f"{len(data)} bytes, not a size and a padded EPATH"


def _certificate(data: bytes) -> str | None:
    """A certificate status (USINT), then a path to the File object instance holding it."""
    return None if len(data) >= 2 and _path(data[1:]) is None else f"{len(data)} bytes, not a status and a path"


def _fixed(size: int, name: str) -> Callable[[bytes], str | None]:
    return lambda data: None if len(data) == size else f"{len(data)} bytes, {name} is {size}"


def _short_string(data: bytes) -> str | None:
    return None if data and len(data) == 1 + data[0] else f"{len(data)} bytes, not a SHORT_STRING"


#: The attributes read, as the branch declares their types: (class, attribute) -> (name, shape).
ATTRIBUTES: dict[tuple[int, int], tuple[str, Callable[[bytes], str | None]]] = {
    (CIP_SECURITY, 1): ("CIP Security State", _fixed(1, "USINT")),
    (EIP_SECURITY, 1): ("State", _fixed(1, "USINT")), (EIP_SECURITY, 2): ("Capability Flags", _fixed(4, "DWORD")),
    (EIP_SECURITY, 3): ("Available Cipher Suites", _suites), (EIP_SECURITY, 4): ("Allowed Cipher Suites", _suites),
    (EIP_SECURITY, 6): ("Active Device Certificates", _paths), (EIP_SECURITY, 7): ("Trusted Authorities", _paths),
    (EIP_SECURITY, 8): ("Certificate Revocation List", _path),
    (EIP_SECURITY, 9): ("Verify Client Certificate", _fixed(1, "BOOL")),
    (EIP_SECURITY, 10): ("Send Certificate Chain", _fixed(1, "BOOL")),
    (EIP_SECURITY, 11): ("Check Expiration", _fixed(1, "BOOL")),
    (EIP_SECURITY, 12): ("Trusted Identities", _paths), (EIP_SECURITY, 13): ("Pull Model Enable", _fixed(1, "BOOL")),
    (EIP_SECURITY, 14): ("Pull Model Status", _fixed(2, "UINT")),
    (EIP_SECURITY, 15): ("DTLS Timeout", _fixed(2, "UINT")),
    (EIP_SECURITY, 16): ("UDP-only Policy", _fixed(1, "USINT")),
    (CERTIFICATES, 1): ("Name", _short_string), (CERTIFICATES, 2): ("State", _fixed(1, "USINT")),
    (CERTIFICATES, 3): ("Device Certificate", _certificate), (CERTIFICATES, 4): ("CA Certificate", _certificate),
    (CERTIFICATES, 5): ("Certificate Encoding", _fixed(1, "USINT")),
}


def needs_folder(ctx: Context, spec: CheckSpec) -> Outcome | None:
    if ctx.security is None:
        return outcome(spec, Verdict.NOT_RUN, "needs --security DIR (the CA the device trusts, a client certificate)")
    return None


def needs_certificates(ctx: Context, spec: CheckSpec) -> Outcome | None:
    """The TLS checks handshake with the folder's CA and client certificate: a folder of a pre-shared
    key alone (`security init --psk-only`) does not run them."""
    skipped = needs_folder(ctx, spec)
    if skipped is not None or ctx.security is None:
        return skipped
    missing = [name for name in ("ca.pem", "client.pem", "client.key") if not (ctx.security / name).exists()]
    if missing:
        return outcome(spec, Verdict.NOT_RUN, f"needs {', '.join(missing)} in {ctx.security} (the TLS checks "
                                              "handshake with certificates, not with a pre-shared key)")
    return None


def _read(probe: Probe, class_id: int, attribute: int) -> tuple[int | None, bytes]:
    reply = probe.request(GET_SINGLE, request_path(class_id, 1, attribute))
    return reply.status, reply.data


@check("security.objects.attributes", "the security objects' attributes read with their types",
       "EtherNet/IP Security 0x5E/1 attributes 1-4 and 6-16, CIP Security 0x5D/1 attribute 1 and "
       "Certificate Management 0x5F/1 attributes 1-5 answer success, each the size of its type",
       BRANCH + "; Wireshark packet-enip.c (dissect_eip_security_*, dissect_eip_cert_*)")
def attributes(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = needs_folder(ctx, spec)
    if skipped is not None:
        return skipped
    probe = ctx.probe()
    problems = []
    for (class_id, attribute), (name, shape) in ATTRIBUTES.items():
        status, data = _read(probe, class_id, attribute)
        problem = f"general status 0x{status:02X}" if status != 0 else shape(data)
        if problem is not None:
            problems.append(f"0x{class_id:02X}/1/{attribute} {name}: {problem}")
    return outcome(spec, not problems, "; ".join(problems) or f"{len(ATTRIBUTES)} attributes as declared",
                   probe.exchanges)


@check("security.objects.psk_unreadable", "the pre-shared keys are never read back",
       "a Get_Attribute_Single of 0x5E/1 attribute 5 (Pre-Shared Keys) is refused",
       BRANCH + " (attribute 5 is settable only)",
       codes=(Code(0x14, "attribute not supported", "Vol. 1 appendix B"),
              Code(0x08, "service not supported", "Vol. 1 appendix B"),
              Code(0x0F, "privilege violation", "Vol. 1 appendix B")))
def psk_unreadable(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = needs_folder(ctx, spec)
    if skipped is not None:
        return skipped
    probe = ctx.probe()
    status, data = _read(probe, EIP_SECURITY, 5)
    codes = {c.value for c in spec.codes}
    if status == 0:
        return outcome(spec, False, f"read back: {len(data)} bytes ({data[:1].hex()} keys)", probe.exchanges)
    return outcome(spec, status in codes, f"general status 0x{status:02X}" if status is not None
                   else "no reply", probe.exchanges)


@check("security.session.outside", "no configuration service outside a session",
       "Kick_Timer (0x4C) on 0x5E/1 from a connection that began no session answers 0x0C",
       BRANCH + " (Kick_Timer only while Configuration In Progress)",
       codes=(Code(0x0C, "object state conflict", "Volume 8 5-4.7.2"),))
def session_outside(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = needs_folder(ctx, spec)
    if skipped is not None:
        return skipped
    probe = ctx.probe()
    reply = probe.request(KICK_TIMER, request_path(EIP_SECURITY, 1))
    return outcome(spec, reply.status == 0x0C, reply.describe(), probe.exchanges)


@check("security.session.begin", "Begin_Config only from Factory Default, one session at a time",
       "on a Configured device Begin_Config (0x4B) answers 0x0C; on a factory-default one (with "
       "--allow-writes) it opens a session that a second connection's Begin_Config cannot, Kick_Timer "
       "keeps, and Abort_Config ends (state back to 0)",
       BRANCH + " (Begin_Config from Factory Default only, else 0x0C)",
       codes=(Code(0x0C, "object state conflict", "Volume 8 5-4.7.1"),))
def session_begin(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = needs_folder(ctx, spec)
    if skipped is not None:
        return skipped
    probe = ctx.probe()
    path = request_path(EIP_SECURITY, 1)
    status, state = _read(probe, EIP_SECURITY, 1)
    if status != 0 or len(state) != 1:
        return outcome(spec, False, f"State unreadable ({status})", probe.exchanges)
    if state[0] != 0:
        reply = probe.request(BEGIN_CONFIG, path)
        return outcome(spec, reply.status == 0x0C, f"state {state[0]}: Begin_Config answered {reply.describe()}",
                       probe.exchanges)
    if not ctx.allow_writes:
        return outcome(spec, Verdict.NOT_RUN, "the device is in Factory Default: opening a session needs "
                                              "--allow-writes")
    other = ctx.probe()
    steps = [("Begin_Config", probe, BEGIN_CONFIG, 0), ("a second connection's Begin_Config", other, BEGIN_CONFIG,
                                                        0x0C),
             ("Kick_Timer", probe, KICK_TIMER, 0), ("Abort_Config", probe, ABORT_CONFIG, 0)]
    for what, client, service, expected in steps:
        reply = client.request(service, path)
        if reply.status != expected:
            with contextlib.suppress(Exception):
                probe.request(ABORT_CONFIG, path)
            return outcome(spec, False, f"{what} answered {reply.describe()}, 0x{expected:02X} expected",
                           probe.exchanges + other.exchanges)
    status, state = _read(other, EIP_SECURITY, 1)
    return outcome(spec, state == b"\x00", f"after Abort_Config the state reads {state.hex() or status}",
                   probe.exchanges + other.exchanges)


# -- the TLS port ------------------------------------------------------------------------------------------
def _client_context(folder: Path, suite: str | None = None, client: Path | None = None) -> ssl.SSLContext:
    """TLS 1.2 as the originator: the folder's CA; the client certificate of ``client`` (a folder), else
    of ``folder``; only ``suite`` offered when given."""
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    context.check_hostname = False
    context.minimum_version = context.maximum_version = ssl.TLSVersion.TLSv1_2
    context.load_verify_locations(cafile=folder / "ca.pem")
    keys = client or folder
    context.load_cert_chain(keys / "client.pem", keys / "client.key")
    if suite is not None:
        context.set_ciphers(suite)
    return context


class Stream(Protocol):
    """What ``register_over`` uses of a TLS socket (the standard library's, or ``tls_psk.TlsSocket``)."""

    def sendall(self, data: bytes) -> None: ...

    def recv(self, size: int) -> bytes: ...


def register_over(tls: Stream, over: str = "TLS") -> str | None:
    """RegisterSession through an established TLS session: None when it is answered, else why not."""
    tls.sendall(frame(Command.REGISTER_SESSION, REGISTER_SESSION_DATA.pack(1, 0)))
    head = b""
    while len(head) < HEADER.size:
        chunk = tls.recv(HEADER.size - len(head))
        if not chunk:
            return f"the device closed the {over} connection before replying to RegisterSession"
        head += chunk
    command, _, session, status = HEADER.unpack(head)[:4]
    if command != Command.REGISTER_SESSION or status != 0 or not session:
        return f"RegisterSession over {over} answered {head.hex()}"
    return None


def _tls_register(ctx: Context, context: ssl.SSLContext) -> str | None:
    """Handshake on the TLS port and RegisterSession through it: None when both succeed, else why not."""
    try:
        with socket.create_connection((ctx.host, ctx.security_port), ctx.timeout) as sock, \
                context.wrap_socket(sock) as tls:
            return register_over(tls)
    except (OSError, ssl.SSLError) as exc:
        return f"{type(exc).__name__}: {exc}"


def allowed_suites(ctx: Context) -> tuple[list[int], Probe]:
    """The IANA ids of Allowed Cipher Suites (0x5E/1/4; empty when unreadable) and the probe that read them."""
    probe = ctx.probe()
    status, data = _read(probe, EIP_SECURITY, 4)
    if status != 0 or _suites(data) is not None:
        return [], probe
    return [int.from_bytes(data[i:i + 2], "big") for i in range(1, len(data), 2)], probe


@check("security.tls.allowed_suite", "a TLS 1.2 handshake with an allowed suite succeeds",
       "a client offering one suite of Allowed Cipher Suites (0x5E/1/4), with a certificate of the trusted "
       "CA, completes the handshake on the TLS port and its RegisterSession is answered",
       "OpENer issue #228 (TLS 1.2); packet-enip.c ENIP_SECURE_PORT; " + BRANCH)
def tlsallowed_suites(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = needs_certificates(ctx, spec)
    if skipped is not None:
        return skipped
    assert ctx.security is not None
    allowed, probe = allowed_suites(ctx)
    known = [s for s in allowed if s in SUITE_NAMES]
    if not known:
        return outcome(spec, Verdict.NOT_APPLICABLE, f"no allowed suite this battery can offer: "
                                                     f"{', '.join(f'0x{s:04X}' for s in allowed) or 'none read'}",
                       probe.exchanges)
    problem = _tls_register(ctx, _client_context(ctx.security, SUITE_NAMES[known[0]]))
    return outcome(spec, problem is None, problem or f"{SUITE_NAMES[known[0]]}: handshake and RegisterSession",
                   probe.exchanges)


@check("security.tls.disallowed_suite", "a suite outside the allowed ones is refused",
       "a TLS 1.2 client offering only an ECDHE-ECDSA suite that Allowed Cipher Suites (0x5E/1/4) does "
       "not list fails the handshake, for each such suite the battery knows",
       BRANCH + " (attribute 4: the suites the device may use)")
def tls_disallowed(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = needs_certificates(ctx, spec)
    if skipped is not None:
        return skipped
    assert ctx.security is not None
    allowed, probe = allowed_suites(ctx)
    if not allowed:
        return outcome(spec, False, "Allowed Cipher Suites unreadable", probe.exchanges)
    outside = [s for s in SUITE_NAMES if s not in allowed]
    if not outside:
        return outcome(spec, Verdict.NOT_APPLICABLE, "every suite this battery can offer is allowed", probe.exchanges)
    accepted = [f"{SUITE_NAMES[s]} (0x{s:04X})" for s in outside
                if _tls_register(ctx, _client_context(ctx.security, SUITE_NAMES[s])) is None]
    return outcome(spec, not accepted, ("accepted: " + ", ".join(accepted)) if accepted else
                   "refused: " + ", ".join(f"0x{s:04X}" for s in outside), probe.exchanges)


@check("security.tls.untrusted_client", "a client certificate of another CA is refused",
       "with Verify Client Certificate (0x5E/1/9) on, a TLS 1.2 client whose certificate another CA "
       "signed fails the handshake", BRANCH + " (attribute 9)")
def tls_untrusted(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = needs_certificates(ctx, spec)
    if skipped is not None:
        return skipped
    assert ctx.security is not None
    probe = ctx.probe()
    status, verify = _read(probe, EIP_SECURITY, 9)
    if status != 0 or verify != b"\x01":
        return outcome(spec, Verdict.NOT_APPLICABLE, f"Verify Client Certificate reads {verify.hex() or status}",
                       probe.exchanges)
    from ..security.provisioning import init

    with tempfile.TemporaryDirectory(prefix="cipstack-conform-") as folder:
        stranger = Path(folder) / "other"
        init(stranger)
        problem = _tls_register(ctx, _client_context(ctx.security, client=stranger))
    return outcome(spec, problem is not None, problem or "a certificate of another CA was accepted", probe.exchanges)


@check("security.tls.plaintext", "plain EtherNet/IP on the TLS port is refused without harm",
       "a plain RegisterSession sent to the TLS port gets no EtherNet/IP reply (a TLS alert or a close); "
       "then port 44818 and a TLS handshake still answer",
       "packet-enip.c (2221 carries TLS); OpENer issue #231")
def tls_plaintext(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = needs_certificates(ctx, spec)
    if skipped is not None:
        return skipped
    assert ctx.security is not None
    got = b""
    with contextlib.suppress(OSError), socket.create_connection((ctx.host, ctx.security_port), ctx.timeout) as sock:
        sock.settimeout(ctx.timeout)
        sock.sendall(frame(Command.REGISTER_SESSION, REGISTER_SESSION_DATA.pack(1, 0)))
        with contextlib.suppress(OSError):
            got = sock.recv(64)
    if got[:1] and got[0] not in TLS_RECORDS:
        return outcome(spec, False, f"answered in plain: {got[:HEADER.size].hex()}")
    probe = ctx.probe()
    problem = _tls_register(ctx, _client_context(ctx.security))
    return outcome(spec, problem is None, problem or "refused (" + (f"TLS record {got[0]}" if got else "closed")
                   + "); 44818 and TLS serve on", probe.exchanges)


__all__ = ["ATTRIBUTES", "BRANCH", "SUITE_NAMES", "Stream", "allowed_suites", "needs_certificates", "needs_folder",
           "register_over"]
