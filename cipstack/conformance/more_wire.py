"""More of the wire: class 3 connected explicit messaging, Unconnected_Send to a port the target does
not have, Get_Attribute_List, the session limit and a Forward_Close with the wrong serial (CIP
Vol. 1 §3-5 and Appendix A, Vol. 2 §2 and §3-2, as Wireshark's packet-enip.c / packet-cip.c and
OpENer read them). Each check belongs to the group of the layer it tests."""

from __future__ import annotations

import struct
import time
from dataclasses import replace

from ..cip.epath import request_path
from ..cip.messages import MessageRouterRequest, MessageRouterResponse
from ..eip.wire.cm_messages import (
    ConnectionTriad,
    ConnectionType,
    ForwardOpenReply,
    NetworkParameters,
    TransportTrigger,
    TriggerType,
    UnconnectedSendRequest,
)
from ..eip.wire.cpf import Item, ItemType, decode_items, encode_items
from ..eip.wire.encapsulation import REGISTER_SESSION_DATA, RR_PREFIX, Command
from .connections import (
    CM,
    EXTENDED,
    FORWARD_OPEN,
    Endpoint,
    Plan,
    _on_main_plan,
    close_with_wrong_triad,
    extended,
    forward_open_request,
    new_triad,
)
from .model import CheckSpec, Code, Outcome, Verdict
from .registry import Context, check, outcome
from .router import STATUS, general
from .wire import Probe, Reply, TargetUnreachable, frame

VENDOR_ID = request_path(0x01, 1, 1)
PRODUCT_NAME = request_path(0x01, 1, 7)
#: The message router, the target of a class 3 connection.
ROUTER_PATH = bytes((0x20, 0x02, 0x24, 0x01))
CLASS3 = ("CIP Vol. 1 §3-4.3 (class 3 connected explicit messaging); Vol. 2 §2-4.8 (SendUnitData); "
          "Wireshark packet-enip.c")
#: At most this many sessions are opened by ``encap.session_limit``.
SESSION_BOUND = 40
#: How long a target may take to free the sessions of closed TCP connections.
RECOVERY_S = 2.0


# -- class 3 ------------------------------------------------------------------------------------------
class Class3:
    """A class 3 connection to the message router, on its probe."""

    def __init__(self, ctx: Context, probe: Probe) -> None:
        self.ctx, self.probe = ctx, probe
        self.triad = new_triad()
        self.request = replace(
            forward_open_request(Plan("class 3", 1, 1, 1, 504, 504, 2_000_000, None, False, True, False)),
            triad=self.triad, transport=TransportTrigger(3, TriggerType.APPLICATION, server=True),
            connection_path=ROUTER_PATH, ot_parameters=NetworkParameters(504, ConnectionType.POINT_TO_POINT),
            to_parameters=NetworkParameters(504, ConnectionType.POINT_TO_POINT))
        self.reply: ForwardOpenReply | None = None
        self.opened = False
        self.refusal: Reply | None = None

    def open(self) -> str:
        """Forward_Open; "" when it is open, else what came back."""
        reply = self.probe.request(FORWARD_OPEN, CM, self.request.encode())
        if reply.status != 0:
            self.refusal = reply
            return f"Forward_Open (class 3): {reply.describe()}"
        try:
            self.reply = ForwardOpenReply.decode(reply.data)
        except ValueError as exc:
            return f"Forward_Open (class 3) reply unreadable: {exc}"
        self.opened = True
        self.ctx.accepted.append(self.request)
        self.ctx.pending_closes.append(self.close)
        return ""

    def send(self, sequence: int, request: bytes) -> tuple[int | None, int | None, MessageRouterResponse | None, str]:
        """One SendUnitData: (connection id, sequence count, reply) as they came back, or a problem."""
        assert self.reply is not None
        data = RR_PREFIX.pack(0, 0) + encode_items((
            Item(ItemType.CONNECTED_ADDRESS, struct.pack("<I", self.reply.ot_connection_id)),
            Item(ItemType.CONNECTED_DATA, struct.pack("<H", sequence) + request)))
        try:
            answer = self.probe.exchange(frame(Command.SEND_UNIT_DATA, data, self.probe.session))
        except ConnectionError as exc:
            return None, None, None, f"the target closed the connection ({exc})"
        if answer is None:
            return None, None, None, "no reply to SendUnitData"
        if answer.header.status != 0:
            return None, None, None, f"SendUnitData: encapsulation status 0x{answer.header.status:04X}"
        try:
            items = decode_items(answer.body, RR_PREFIX.size, strict=False)
            address = next(i.data for i in items if i.type == ItemType.CONNECTED_ADDRESS)
            connected = next(i.data for i in items if i.type == ItemType.CONNECTED_DATA)
            return (struct.unpack("<I", address)[0], struct.unpack_from("<H", connected)[0],
                    MessageRouterResponse.decode(connected[2:]), "")
        except (StopIteration, ValueError, struct.error) as exc:
            return None, None, None, f"malformed SendUnitData reply ({exc or 'items missing'})"

    def close(self) -> str:
        if not self.opened:
            return ""
        self.opened = False
        from .connections import close_connection

        reply = close_connection(self.ctx, self.probe, self.triad, ROUTER_PATH)
        return "" if reply.status == 0 else f"Forward_Close: {reply.describe()}"


def _open_class3(ctx: Context, spec: CheckSpec) -> tuple[Class3, Probe] | Outcome:
    """A class 3 connection open for the check; a target that refuses the transport class does not apply."""
    probe = ctx.probe()
    connection = Class3(ctx, probe)
    problem = connection.open()
    if problem:
        refusal = connection.refusal
        verdict = (spec.verdict_for(refusal.extended) if refusal is not None and refusal.status == 0x01
                   else Verdict.FAIL)
        return outcome(spec, Verdict.FAIL if verdict is Verdict.PASS else verdict, problem, probe.exchanges)
    return connection, probe


#: A target without class 3 refuses its transport class: the class 3 checks do not apply.
NO_CLASS3 = [extended(0x0103, "transport class not supported: no class 3", Verdict.NOT_APPLICABLE),
             extended(0x011C, "transport class not supported: no class 3", Verdict.NOT_APPLICABLE)]


@check("cm.class3.read", "a class 3 connection to the message router: open, read through SendUnitData, close",
       "Forward_Open (transport class 3, server, application trigger) to 20 02 24 01 succeeds; a Get_Attribute_Single "
       "of Identity attribute 1 in SendUnitData is answered in SendUnitData on the T->O connection ID with the same "
       "sequence count and the vendor ID; Forward_Close succeeds. A target refusing class 3 (0x0103, 0x011C) does "
       "not apply", CLASS3, codes=NO_CLASS3)
def class3_read(ctx: Context, spec: CheckSpec) -> Outcome:
    opened = _open_class3(ctx, spec)
    if isinstance(opened, Outcome):
        return opened
    connection, probe = opened
    unconnected = probe.request(0x0E, VENDOR_ID)
    connection_id, sequence, reply, problem = connection.send(1, MessageRouterRequest(0x0E, VENDOR_ID).encode())
    closing = connection.close()
    problems = [p for p in (problem, closing) if p]
    assert connection.reply is not None
    if not problem:
        if connection_id != connection.reply.to_connection_id:
            problems.append(f"reply on connection 0x{connection_id or 0:08X}, the T->O ID is "
                            f"0x{connection.reply.to_connection_id:08X}")
        if sequence != 1:
            problems.append(f"sequence count {sequence} in the reply to 1")
        if reply is None or reply.general_status != 0 or reply.data != unconnected.data:
            problems.append(f"vendor ID {reply.data.hex() if reply else None}, unconnected "
                            f"{unconnected.data.hex()}")
    return outcome(spec, not problems, "; ".join(problems) or "opened, read the vendor ID, closed", probe.exchanges)


@check("cm.class3.duplicate", "a class 3 request repeated with the same sequence count",
       "the target answers the repeat with its last reply and does not execute it: a Get_Attribute_Single of "
       "Identity attribute 7 sent with the sequence count of a read of attribute 1 is answered with the vendor ID",
       f"CIP Vol. 1 §3-4.3 (a repeated sequence count is a duplicate: the last reply is sent again); {CLASS3}",
       codes=NO_CLASS3)
def class3_duplicate(ctx: Context, spec: CheckSpec) -> Outcome:
    opened = _open_class3(ctx, spec)
    if isinstance(opened, Outcome):
        return opened
    connection, probe = opened
    _, _, first, problem = connection.send(7, MessageRouterRequest(0x0E, VENDOR_ID).encode())
    _, sequence, again, problem_again = connection.send(7, MessageRouterRequest(0x0E, PRODUCT_NAME).encode())
    closing = connection.close()
    problems = [p for p in (problem, problem_again, closing) if p]
    if not problems and (first is None or again is None or again.data != first.data or sequence != 7):
        problems.append(f"the repeat was answered {again.data.hex() if again else None} (sequence {sequence}), the "
                        f"first {first.data.hex() if first else None}")
    return outcome(spec, not problems, "; ".join(problems) or "the repeat got the last reply again", probe.exchanges)


# -- Unconnected_Send, Get_Attribute_List -------------------------------------------------------------
#: A port number no adapter has: 14, the highest of the one-nibble port segment.
MISSING_PORT = 14


@check("router.unconnected_send.missing_port", "Unconnected_Send routed through port 14, which the target lacks",
       "status 0x01, extended 0x0311 (port not available); 0x08 when the target has no Unconnected_Send does not "
       "apply", f"CIP Vol. 1 §3-5.5.4 (Unconnected_Send); {EXTENDED}",
       codes=[extended(0x0311, "port specified in port segment not available")])
def unconnected_send_missing_port(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    message = MessageRouterRequest(0x0E, VENDOR_ID).encode()
    request = UnconnectedSendRequest(0x0A, 0x0E, message, bytes((MISSING_PORT, 1)))
    reply = probe.request(0x52, CM, request.encode())
    if reply.status == 0x08:
        return outcome(spec, Verdict.NOT_APPLICABLE, "Unconnected_Send not supported (0x08)", probe.exchanges)
    verdict = spec.verdict_for(reply.extended) if reply.status == 0x01 else Verdict.FAIL
    return outcome(spec, verdict, f"route 0E 01: {reply.describe()}", probe.exchanges)


@check("router.get_attribute_list", "Get_Attribute_List of Identity attributes 1, 7 and 0xFE",
       "general status 0x0A (attribute list error, as one attribute fails): 3 entries, attribute 1 with status 0 and "
       "the vendor ID, 7 with status 0 and the product name, 0xFE with status 0x14; 0x08 does not apply",
       "CIP Vol. 1 Appendix A (Get_Attribute_List, 0x03) and Appendix B (0x0A); wire.md",
       codes=[general(0x0A, "attribute list error", f"{STATUS}; CIP Vol. 1 Appendix A")])
def get_attribute_list(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    vendor, name = probe.request(0x0E, VENDOR_ID), probe.request(0x0E, PRODUCT_NAME)
    reply = probe.request(0x03, request_path(0x01, 1), struct.pack("<4H", 3, 1, 7, 0xFE))
    if reply.status == 0x08:
        return outcome(spec, Verdict.NOT_APPLICABLE, "Get_Attribute_List not supported (0x08)", probe.exchanges)
    expected = (struct.pack("<3H", 3, 1, 0) + vendor.data + struct.pack("<2H", 7, 0) + name.data
                + struct.pack("<2H", 0xFE, 0x14))
    problems = []
    if spec.verdict_for(reply.status) is not Verdict.PASS:
        problems.append(reply.describe())
    if reply.response is not None and reply.data != expected:
        problems.append(f"entries {reply.data.hex(' ')}, expected {expected.hex(' ')}")
    return outcome(spec, not problems, "; ".join(problems) or f"{reply.describe()}; the 3 entries as expected",
                   probe.exchanges)


# -- sessions -----------------------------------------------------------------------------------------
@check("encap.session_limit", f"RegisterSession on up to {SESSION_BOUND} TCP connections at once",
       "each is granted, or refused with encapsulation status 0x0002 (insufficient memory) or by closing the TCP "
       "connection; once they are closed, a new session is granted", "CIP Vol. 2 §2-3.3 (0x0002 no session slot); "
       "§2-4.5 RegisterSession", codes=[Code(0x0002, "insufficient memory", "CIP Vol. 2 §2-3.3")],
       # Stock OpENer (its debug build) aborts on an assertion at its 21st TCP connection: a default run
       # must leave the device as found, so this runs only when asked.
       stress=f"opens up to {SESSION_BOUND} TCP connections and sessions at once")
def session_limit(ctx: Context, spec: CheckSpec) -> Outcome:
    granted, refusal, problems = 0, "", []
    held: list[Probe] = []
    for _ in range(SESSION_BOUND):
        try:
            probe = ctx.probe(register=False)
        except TargetUnreachable:
            refusal = "TCP connection refused"
            break
        held.append(probe)
        try:
            reply = probe.exchange(frame(Command.REGISTER_SESSION, REGISTER_SESSION_DATA.pack(1, 0)))
        except ConnectionError:
            refusal = "the TCP connection was closed"
            break
        if reply is None:
            problems.append(f"no reply to RegisterSession {granted + 1}")
            break
        if reply.header.status != 0:
            if spec.verdict_for(reply.header.status) is not Verdict.PASS:
                problems.append(f"RegisterSession {granted + 1}: status 0x{reply.header.status:04X}")
            refusal = f"status 0x{reply.header.status:04X}"
            break
        probe.session = reply.header.session
        granted += 1
    exchanges = [e for p in held[-2:] for e in p.exchanges]
    for probe in held:
        ctx.probes.remove(probe)
        probe.close()
    after_text = ""
    deadline = time.monotonic() + RECOVERY_S
    while not after_text:
        # A target frees a closed connection's session when it sees the close: give it a moment.
        try:
            after = ctx.probe()
            after_text = f"a new session 0x{after.session:08X} granted after closing them"
        except TargetUnreachable as exc:
            if time.monotonic() > deadline:
                problems.append(f"no session {RECOVERY_S:g} s after closing them: {exc}")
                break
            time.sleep(0.1)
    limit = f"limit reached after {granted} ({refusal})" if refusal else "no limit reached"
    # No new session after them: nothing to say of it (no empty part in the sentence).
    return outcome(spec, not problems, "; ".join(p for p in [*problems, f"{granted} sessions granted, {limit}",
                                                             after_text] if p), exchanges)


# -- Forward_Close ------------------------------------------------------------------------------------
@check("cm.forward_close.wrong_serial", "Forward_Close of an open connection with its connection serial + 1",
       "status 0x01, extended 0x0107 (the triad names no connection); the connection stays open and its own "
       "Forward_Close then succeeds", f"CIP Vol. 1 §3-5.5.4 (Forward_Close matches the whole triad); {EXTENDED}",
       codes=[extended(0x0107, "target connection not found")])
@_on_main_plan
def close_wrong_serial(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    return close_with_wrong_triad(ctx, spec, plan, probe, endpoint, "serial + 1", lambda t: ConnectionTriad(
        (t.connection_serial + 1) & 0xFFFF or 1, t.vendor_id, t.originator_serial), probe)
