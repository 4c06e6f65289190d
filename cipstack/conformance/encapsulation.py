"""Group 1: the encapsulation layer (CIP Vol. 2, chapter 2, as Wireshark's packet-enip.c and
OpENer's encap.c read it; CIP Vol. 2, chapter 2, as Wireshark's ENIP dissector and OpENer read it)."""

from __future__ import annotations

import contextlib
import struct

from ..eip.wire.cpf import Item, decode_items
from ..eip.wire.encapsulation import HEADER_SIZE, REGISTER_SESSION_DATA, Command
from ..eip.wire.identity_items import decode_identity_item
from .model import CheckSpec, Code, Exchange, Outcome, Verdict
from .registry import Context, check, outcome
from .wire import Frame, Probe, frame, rr_data, udp_exchange

VOL2 = "CIP Vol. 2 §2"
STATUS_TABLE = "CIP Vol. 2 §2-3.3 (encapsulation status); Wireshark packet-enip.c"


def _status(reply: Frame | None) -> str:
    if reply is None:
        return "no reply"
    return f"command 0x{reply.header.command:04X} status 0x{reply.header.status:04X}, {len(reply.body)} data bytes"


def encap(value: int, meaning: str, section: str) -> Code:
    """An encapsulation status the specification permits, with where it says so."""
    return Code(value, meaning, f"{VOL2}{section}; {STATUS_TABLE}")


def _expect_status(spec: CheckSpec, probe: Probe, raw: bytes, what: str) -> Outcome:
    """Send ``raw``; the reply must carry an encapsulation status the check permits (and echo the
    sender context)."""
    try:
        reply = probe.exchange(raw)
    except ConnectionError as exc:
        return outcome(spec, False, f"{what}: the target closed the connection instead ({exc})", probe.exchanges)
    if reply is None or reply.header.context != raw[12:20]:
        return outcome(spec, False, f"{what}: {_status(reply)}", probe.exchanges)
    return outcome(spec, spec.verdict_for(reply.header.status), f"{what}: {_status(reply)}", probe.exchanges)


def _list_items(spec: CheckSpec, probe: Probe, command: Command) -> list[Item] | Outcome:
    """Send a list command (no session needed); its reply's item list, or the failure as the outcome."""
    reply = probe.exchange(frame(command))
    if reply is None or reply.header.status != 0:
        return outcome(spec, False, _status(reply), probe.exchanges)
    try:
        return decode_items(reply.body)
    except Exception as exc:
        return outcome(spec, False, f"malformed CPF: {exc}", probe.exchanges)


@check("encap.register_session.version", "RegisterSession version 1, options 0",
       "status 0, a non-zero session handle, the reply data echoes version 1 and options 0",
       f"{VOL2}-4.5 RegisterSession; OpENer encap.c HandleReceivedRegisterSessionCommand")
def register_session(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe(register=False)
    reply = probe.exchange(frame(Command.REGISTER_SESSION, REGISTER_SESSION_DATA.pack(1, 0)))
    ok = (reply is not None and reply.header.status == 0 and reply.header.session != 0
          and reply.body == REGISTER_SESSION_DATA.pack(1, 0))
    if reply is not None:
        probe.session = reply.header.session
    observed = _status(reply) + (f", session 0x{reply.header.session:08X}, data {reply.body.hex()}" if reply else "")
    return outcome(spec, ok, observed, probe.exchanges)


@check("encap.register_session.options", "RegisterSession with option flags set",
       "status 0x0069 (unsupported protocol revision): option flags must be 0",
       f"{VOL2}-4.5 RegisterSession; {STATUS_TABLE}",
       codes=[encap(0x0069, "unsupported protocol revision", "-4.5 RegisterSession")])
def register_session_options(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe(register=False)
    return _expect_status(spec, probe, frame(Command.REGISTER_SESSION, REGISTER_SESSION_DATA.pack(1, 1)),
                          "options 0x0001")


@check("encap.register_session.protocol_version", "RegisterSession with protocol version 2",
       "status 0x0069 (unsupported protocol revision)", f"{VOL2}-4.5 RegisterSession; {STATUS_TABLE}",
       codes=[encap(0x0069, "unsupported protocol revision", "-4.5 RegisterSession")])
def register_session_version(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe(register=False)
    return _expect_status(spec, probe, frame(Command.REGISTER_SESSION, REGISTER_SESSION_DATA.pack(2, 0)),
                          "version 2")


@check("encap.register_session.second", "a second RegisterSession on the same connection",
       "status 0x0001 (invalid command): one session per TCP connection",
       f"{VOL2}-4.5 RegisterSession; OpENer encap.c (kEncapsulationProtocolInvalidCommand)",
       codes=[encap(0x0001, "invalid or unsupported command", "-4.5 RegisterSession")])
def register_session_second(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    return _expect_status(spec, probe, frame(Command.REGISTER_SESSION, REGISTER_SESSION_DATA.pack(1, 0)),
                          "second RegisterSession")


@check("encap.unregister_session", "UnRegisterSession",
       "no reply; the target closes the TCP connection", f"{VOL2}-4.6 UnRegisterSession")
def unregister_session(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    raw = frame(Command.UNREGISTER_SESSION, session=probe.session)
    probe.send(raw)
    record = Exchange(raw, None)
    try:
        reply = probe.receive(min(ctx.timeout, 2.0))
    except ConnectionError:
        probe.session = 0
        return outcome(spec, True, "no reply, connection closed by the target", [*probe.exchanges, record])
    record.received = None if reply is None else reply.raw
    if reply is not None:
        return outcome(spec, False, f"the target replied: {_status(reply)}", [*probe.exchanges, record])
    closed = probe.closed_by_target(1.0)
    probe.session = 0
    return outcome(spec, closed, "no reply; " + ("connection closed" if closed else "connection left open"),
                   [*probe.exchanges, record])


@check("encap.nop", "NOP with data",
       "no reply, and the connection keeps serving (a ListServices after it is answered)", f"{VOL2}-4.1 NOP")
def nop(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    raw = frame(Command.NOP, b"\x00" * 4, probe.session)
    record = Exchange(raw, None)
    exchanges = [*probe.exchanges, record]
    # The ListServices goes right after the NOP: on one TCP stream, whose requests a target answers in
    # order, a reply to the NOP would come ahead of the ListServices reply, so that reply ends the watch
    # for one (a fixed half second did before, whatever the target).
    try:
        probe.send(raw)
        after = probe.exchange(frame(Command.LIST_SERVICES))
    except ConnectionError:
        return outcome(spec, False, "the target closed the connection after a NOP", exchanges)
    if after is not None and after.header.command != Command.LIST_SERVICES:
        record.received = after.raw
        with contextlib.suppress(ConnectionError):
            probe.receive()  # the ListServices reply behind it, so that the next check starts clean
        return outcome(spec, False, f"the target replied to a NOP: {_status(after)}", exchanges)
    ok = after is not None and after.header.status == 0
    return outcome(spec, ok, "no reply; ListServices after it: " + _status(after), [record, *probe.exchanges[1:]])


def _identity_problems(body: bytes, port: int | None) -> tuple[list[str], dict[str, object] | None]:
    """What is wrong with a ListIdentity reply body (``port``: the port the sockaddr must name)."""
    try:
        items = decode_items(body)
    except Exception as exc:  # any decoding failure is the finding
        return [f"malformed CPF: {exc}"], None
    if len(items) != 1 or items[0].type != 0x000C:
        return [f"items {[hex(i.type) for i in items]}, expected one 0x000C"], None
    data = items[0].data
    try:
        record = decode_identity_item(data)
    except (ValueError, struct.error) as exc:
        return [f"identity item: {exc}"], None
    problems = []
    name_end = 2 + 16 + 14 + 1 + len(record.product_name.encode("latin-1"))
    if len(data) != name_end + 1:
        problems.append(f"item is {len(data)} bytes, its fields make {name_end + 1}")
    if record.protocol_version != 1:
        problems.append(f"protocol version {record.protocol_version}")
    family = struct.unpack_from(">h", data, 2)[0]
    if family != 2:
        problems.append(f"sin_family {family}, expected 2 (AF_INET, big-endian)")
    if port is not None and record.address is not None and record.address.port != port:
        problems.append(f"sockaddr names port {record.address.port}, the target listens on {port}")
    return problems, record.as_dict()


@check("encap.list_identity.tcp", "ListIdentity over TCP",
       "one item 0x000C: protocol version 1, sockaddr (AF_INET, the port the target listens on), identity, "
       "product name, state", f"{VOL2}-4.3 ListIdentity; Wireshark packet-enip.c (dissect_item_list_identity)")
def list_identity_tcp(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe(register=False)
    reply = probe.exchange(frame(Command.LIST_IDENTITY))
    if reply is None or reply.header.status != 0:
        return outcome(spec, False, _status(reply), probe.exchanges)
    problems, record = _identity_problems(reply.body, ctx.port)
    if record is not None and ctx.identity is None:
        ctx.identity = record
    return outcome(spec, not problems, "; ".join(problems) or f"identity {record}", probe.exchanges)


def _udp_identity(ctx: Context, max_delay_ms: int) -> tuple[bytes, bytes | None, float]:
    raw = frame(Command.LIST_IDENTITY, context=struct.pack("<H", max_delay_ms) + b"conf\x00\x00")
    reply, elapsed = udp_exchange(ctx.host, ctx.port, raw, max(2.5, max_delay_ms / 1000 + 1.0))
    return raw, reply, elapsed


@check("encap.list_identity.udp", "ListIdentity over UDP",
       "a reply datagram with status 0 and one item 0x000C as over TCP",
       f"{VOL2}-4.3 ListIdentity; Wireshark packet-enip.c")
def list_identity_udp(ctx: Context, spec: CheckSpec) -> Outcome:
    raw, reply, _ = _udp_identity(ctx, 500)
    exchanges = [Exchange(raw, reply, "udp")]
    if reply is None or len(reply) < HEADER_SIZE:
        return outcome(spec, False, "no reply datagram", exchanges)
    status = struct.unpack_from("<I", reply, 8)[0]
    if status != 0 or struct.unpack_from("<H", reply)[0] != Command.LIST_IDENTITY:
        return outcome(spec, False, f"reply header {reply[:HEADER_SIZE].hex()}", exchanges)
    problems, _ = _identity_problems(reply[HEADER_SIZE:], ctx.port)
    return outcome(spec, not problems, "; ".join(problems) or "one identity item", exchanges)


@check("encap.list_identity.max_response_delay", "ListIdentity over UDP with a 500 ms maximum response delay",
       "the reply comes within the delay the sender context's first UINT gives (500 ms), plus transit",
       f"{VOL2}-4.3.2 (MaxResponseDelay; 0 means 2000 ms, 1-499 mean 500 ms); OpENer encap.c "
       "(DetermineDelayTime)")
def list_identity_delay(ctx: Context, spec: CheckSpec) -> Outcome:
    raw, reply, elapsed = _udp_identity(ctx, 500)
    exchanges = [Exchange(raw, reply, "udp")]
    if reply is None:
        return outcome(spec, False, "no reply datagram within 2.5 s", exchanges)
    # 400 ms for transit and a busy host: a late reply is one that ignored the delay it was given.
    return outcome(spec, elapsed <= 0.9, f"reply after {elapsed * 1000:.0f} ms", exchanges)


@check("encap.list_services", "ListServices over TCP",
       "one item 0x0100, 20 bytes: version 1, capability flags with bit 5 (CIP over TCP), "
       "name \"Communications\" NUL-padded to 16 bytes",
       f"{VOL2}-4.2 ListServices; Wireshark packet-enip.c (dissect_item_list_services_response)")
def list_services(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe(register=False)
    items = _list_items(spec, probe, Command.LIST_SERVICES)
    if isinstance(items, Outcome):
        return items
    problems = []
    services = [i for i in items if i.type == 0x0100]
    if len(services) != 1:
        problems.append(f"{len(services)} items 0x0100")
    else:
        data = services[0].data
        if len(data) != 20:
            problems.append(f"item length {len(data)}, expected 20")
        if len(data) >= 4:
            version, flags = struct.unpack_from("<HH", data)
            if version != 1:
                problems.append(f"version {version}")
            if not flags & 0x0020:
                problems.append(f"capability flags 0x{flags:04X} lack bit 5 (CIP over TCP)")
        if data[4:20].split(b"\x00", 1)[0] != b"Communications":
            problems.append(f"name {data[4:20]!r}")
    return outcome(spec, not problems, "; ".join(problems) or "one item 0x0100 as expected", probe.exchanges)


@check("encap.list_interfaces", "ListInterfaces over TCP",
       "status 0 and a well formed item list (0 items is allowed)", f"{VOL2}-4.4 ListInterfaces")
def list_interfaces(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe(register=False)
    items = _list_items(spec, probe, Command.LIST_INTERFACES)
    if isinstance(items, Outcome):
        return items
    return outcome(spec, True, f"{len(items)} item(s)", probe.exchanges)


@check("encap.unsupported_command", "an unsupported command (0x0001)",
       "status 0x0001 (invalid or unsupported command), and the connection keeps serving", STATUS_TABLE,
       codes=[encap(0x0001, "invalid or unsupported command", "-3.3")])
def unsupported_command(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    result = _expect_status(spec, probe, frame(0x0001, session=probe.session), "command 0x0001")
    if result.verdict is Verdict.PASS:
        try:
            after = probe.exchange(frame(Command.LIST_SERVICES))
        except ConnectionError:
            after = None
        if after is None or after.header.status != 0:
            return outcome(spec, False, "status 0x0001, but the connection stopped serving", probe.exchanges)
    return result


@check("encap.wrong_length", "RegisterSession whose length field counts 2 bytes more than the command takes",
       "status 0x0065 (invalid length)", f"{VOL2}-4.5 RegisterSession (length 4); {STATUS_TABLE}",
       codes=[encap(0x0065, "invalid length", "-4.5 RegisterSession (length 4)")])
def wrong_length(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe(register=False)
    return _expect_status(spec, probe, frame(Command.REGISTER_SESSION, REGISTER_SESSION_DATA.pack(1, 0) + b"\x00\x00"),
                          "length 6")


@check("encap.send_rr_data.no_session", "SendRRData on a connection that registered no session",
       "status 0x0064 (invalid session handle)", f"{VOL2}-4.7 SendRRData; {STATUS_TABLE}",
       codes=[encap(0x0064, "invalid session handle", "-4.7 SendRRData")])
def send_rr_data_no_session(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe(register=False)
    raw = frame(Command.SEND_RR_DATA, rr_data(bytes((0x0E, 0x03, 0x20, 0x01, 0x24, 0x01, 0x30, 0x01))), 0x1234)
    return _expect_status(spec, probe, raw, "session 0x00001234 never registered")


@check("encap.send_rr_data.wrong_session", "SendRRData with a session handle other than the one registered",
       "status 0x0064 (invalid session handle)", f"{VOL2}-4.7 SendRRData; {STATUS_TABLE}",
       codes=[encap(0x0064, "invalid session handle", "-4.7 SendRRData")])
def send_rr_data_wrong_session(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    wrong = (probe.session ^ 0x5A5A0000) or 1
    raw = frame(Command.SEND_RR_DATA, rr_data(bytes((0x0E, 0x03, 0x20, 0x01, 0x24, 0x01, 0x30, 0x01))), wrong)
    return _expect_status(spec, probe, raw, f"session 0x{wrong:08X} instead of 0x{probe.session:08X}")

