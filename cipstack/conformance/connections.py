"""Group 4: the Connection Manager's Forward_Open validation matrix, Large_Forward_Open and
Forward_Close (CIP Vol. 1 §3-5.5, extended status Table 3-5.33, as Wireshark's packet-cip.c
(cip_cm_ext_st_vals) and OpENer's cipconnectionmanager.c give them).

The connection the matrix starts from is the target's first class 1 ``ConnectionN`` of the EDS
given with ``--eds`` (its points, sizes and RPI): without an EDS the checks that need a valid
connection do not apply. Every connection a check opens is closed when the check ends.
"""

from __future__ import annotations

import contextlib
import functools
import random
import socket
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from ..cip.epath import request_path
from ..eip.io_core import DEFAULT_IO_PORT, SEQUENCE_COUNT_SIZE
from ..eip.originator.class1 import OtFormat, class1_path
from ..eip.wire.cm_messages import (
    ConnectionTriad,
    ConnectionType,
    ForwardCloseRequest,
    ForwardOpenReply,
    ForwardOpenRequest,
    NetworkParameters,
    TransportTrigger,
    TriggerType,
)
from ..eip.wire.cpf import Item, ItemType, SockAddr
from .io_run import drive, judge_production
from .model import CheckSpec, Code, Outcome, Verdict
from .registry import Context, check, outcome
from .wire import Probe, Reply, TargetUnreachable

if TYPE_CHECKING:
    from ..eds.interpret import EdsView
    from ..eds.model import EdsDocument

CM = request_path(0x06, 1)
MESSAGE_ROUTER = request_path(0x02, 1)
FORWARD_OPEN, LARGE_FORWARD_OPEN, FORWARD_CLOSE = 0x54, 0x5B, 0x4E
EXTENDED = "CIP Vol. 1 §3-5.5.2 and Table 3-5.33 (extended status); Wireshark packet-cip.c (cip_cm_ext_st_vals)"
#: Where each extended status is listed.
TABLE = "CIP Vol. 1 Table 3-5.33; Wireshark packet-cip.c cip_cm_ext_st_vals; OpENer ciperror.h"
#: How long an accepted RPI of 1 us is measured: long enough for a target producing every 10 ms.
RPI_MEASURE_S = 0.5
#: Our vendor id as an originator, as the scanner's (0xFFFE is not assigned).
VENDOR = 0xFFFE


@dataclass(frozen=True)
class Plan:
    """A class 1 connection the target should accept, from its EDS."""

    name: str
    config: int
    ot_point: int
    to_point: int
    #: Connection sizes as in the network parameters (sequence count and header included).
    ot_size: int
    to_size: int
    rpi_us: int
    rpi_min_us: int | None
    heartbeat: bool
    exclusive_owner: bool
    #: The O->T real-time format carries the run/idle header.
    run_idle: bool
    multicast: bool = False

    @property
    def path(self) -> bytes:
        if not self.ot_point and not self.to_point:
            return request_path(0x04, self.config)  # the configuration alone (``NO_POINTS``)
        return class1_path(None if self.heartbeat else self.ot_point, self.to_point, self.config,
                           self.ot_point if self.heartbeat else None)

    @property
    def to_data_size(self) -> int:
        return self.to_size - SEQUENCE_COUNT_SIZE


def plans(ctx: Context) -> list[Plan]:
    """The connections groups cm and class1 use: those the discovery found (``discovery``), else every
    class 1 connection of the EDS given."""
    if ctx.discovered is not None:
        return list(ctx.discovered)
    if ctx.view is None or ctx.eds is None:
        return []
    return plans_of_eds(ctx.eds, ctx.view)


def plans_of_eds(eds: EdsDocument, view: EdsView) -> list[Plan]:
    """Every class 1 connection of an EDS, exclusive owners first."""
    from ..eds.generator import EXCLUSIVE_OWNER_KIND
    from ..scanner import _eds_ot_format

    found = []
    for info in view.connections:
        fmt = _eds_ot_format(eds, info.number) or (OtFormat.HEARTBEAT if info.heartbeat else OtFormat.RUN_IDLE)
        ot_data = 0 if info.heartbeat else info.o_t_size
        rpi = info.rpi_us or 10_000
        if info.rpi_min_us:
            rpi = max(rpi, info.rpi_min_us)
        found.append(Plan(f"Connection{info.number}", info.config, info.o_t_point, info.t_o_point,
                          SEQUENCE_COUNT_SIZE + fmt.header_size + ot_data, SEQUENCE_COUNT_SIZE + info.t_o_size,
                          rpi, info.rpi_min_us, info.heartbeat, info.kind == EXCLUSIVE_OWNER_KIND,
                          fmt is OtFormat.RUN_IDLE,
                          info.t_o_multicast and not info.t_o_point_to_point))
    found.sort(key=lambda p: not p.exclusive_owner)
    return found


def main_plan(ctx: Context) -> Plan | None:
    found = [p for p in plans(ctx) if p.exclusive_owner and not p.multicast]
    return found[0] if found else None


def new_triad() -> ConnectionTriad:
    return ConnectionTriad(random.randrange(1, 0xFFFF), VENDOR, random.randrange(1, 0xFFFFFFFF))


def forward_open_request(plan: Plan, *, multiplier: int = 2, large: bool = False) -> ForwardOpenRequest:
    to_type = ConnectionType.MULTICAST if plan.multicast else ConnectionType.POINT_TO_POINT
    return ForwardOpenRequest(
        priority_tick=0x0A, timeout_ticks=0x0E, ot_connection_id=0, to_connection_id=random.randrange(1, 0xFFFFFFFF),
        triad=new_triad(), timeout_multiplier=multiplier, ot_rpi_us=plan.rpi_us,
        ot_parameters=NetworkParameters(plan.ot_size, ConnectionType.POINT_TO_POINT), to_rpi_us=plan.rpi_us,
        to_parameters=NetworkParameters(plan.to_size, to_type), transport=TransportTrigger(1, TriggerType.CYCLIC),
        connection_path=plan.path, large=large)


class Opened:
    """A connection the target accepted: closed by ``close`` or, failing that, when the check ends."""

    def __init__(self, ctx: Context, probe: Probe, request: ForwardOpenRequest, reply: ForwardOpenReply,
                 items: tuple[Item, ...]):
        self.ctx, self.probe, self.request, self.reply = ctx, probe, request, reply
        self.io_port = DEFAULT_IO_PORT
        for item in items:
            if item.type == ItemType.SOCKADDR_O_T:
                with contextlib.suppress(Exception):  # a malformed item: the default port
                    self.io_port = SockAddr.decode(item.data).port or DEFAULT_IO_PORT
        self.closed = False

    def close(self) -> Reply:
        self.closed = True
        return close_connection(self.ctx, self.probe, self.request.triad, self.request.connection_path)


def forward_close(probe: Probe, triad: ConnectionTriad, path: bytes) -> Reply:
    return probe.request(FORWARD_CLOSE, CM, ForwardCloseRequest(0x0A, 0x0E, triad, path).encode())


def close_connection(ctx: Context, probe: Probe, triad: ConnectionTriad, path: bytes) -> Reply:
    """Forward_Close of a connection the battery opened, on a live session: on ``probe``, or on a new
    session when the target closed that one (OpENer closes the TCP session of a class 1 connection
    that timed out, and keeps the connection's ownership until a Forward_Close comes). What cannot be
    closed is noted in ``ctx.left_behind`` for the final self-check to report."""
    reply = forward_close(probe, triad, path) if probe.alive else None
    if reply is None or reply.response is None:
        try:
            reply = forward_close(ctx.probe(), triad, path)
        except TargetUnreachable as exc:
            ctx.left_behind.append(f"connection {_triad_text(triad)} not closed: {exc}")
            return Reply(None, None, str(exc))
    # 0x0107: the target holds no such connection any more (it timed out, or a check closed it).
    if reply.status != 0 and not (reply.status == 0x01 and reply.extended == 0x0107):
        ctx.left_behind.append(f"connection {_triad_text(triad)} (path {path.hex(' ')}): Forward_Close answered "
                               f"{reply.describe()}")
    return reply


def _triad_text(triad: ConnectionTriad) -> str:
    return (f"serial 0x{triad.connection_serial:04X}, vendor 0x{triad.vendor_id:04X}, "
            f"originator serial 0x{triad.originator_serial:08X}")


class Endpoint:
    """The originator's UDP socket for T->O data, on the address the TCP connection uses."""

    def __init__(self, ctx: Context, probe: Probe) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((probe.local_host, 0))
        ctx.pending_closes.append(self.sock.close)
        self.host, self.port = self.sock.getsockname()

    @property
    def item(self) -> Item:
        return Item(ItemType.SOCKADDR_T_O, SockAddr(self.host, self.port).encode())


def send_forward_open(ctx: Context, probe: Probe, endpoint: Endpoint, request: ForwardOpenRequest,
                      raw: bytes | None = None) -> tuple[Reply, Opened | None]:
    """Send a Forward_Open (``raw``: these bytes as its data); a success is registered for closing."""
    service = LARGE_FORWARD_OPEN if request.large else FORWARD_OPEN
    reply = probe.request(service, CM, request.encode() if raw is None else raw, extra=(endpoint.item,))
    if reply.status != 0 or reply.response is None:
        return reply, None
    try:
        decoded = ForwardOpenReply.decode(reply.data)
    except ValueError:
        # Accepted, but the reply cannot be read: close by the triad sent all the same.
        ctx.accepted.append(request)
        ctx.pending_closes.append(lambda: close_connection(ctx, probe, request.triad, request.connection_path))
        return reply, None
    ctx.accepted.append(request)
    opened = Opened(ctx, probe, request, decoded, reply.items)
    ctx.pending_closes.append(lambda: None if opened.closed else opened.close())
    return reply, opened


def not_planned(ctx: Context, spec: CheckSpec, consequence: str = "") -> Outcome:
    """The outcome of a check that needs a point-to-point exclusive owner when none was found."""
    if ctx.points_source:
        why = f"no connection point found ({ctx.points_source})"
    elif ctx.eds is None:
        why = "no EDS given (--eds)"
    else:
        why = "the EDS declares no point-to-point exclusive owner"
    return outcome(spec, Verdict.NOT_APPLICABLE, f"{why}{consequence}")


MainPlanCheck = Callable[[Context, CheckSpec, Plan, Probe, Endpoint], Outcome]


#: For the checks that need no connection point of the device: the configuration instance 1 with no
#: connection point (a null Forward_Open configures, a refused transport class is refused before any path).
#: The connection size of a class 3 Forward_Open (that of ``more_wire.Class3``): what a request and its
#: reply need, well within what any target takes.
CLASS3_SIZE = 504

NO_POINTS = Plan("configuration instance 1", 1, 0, 0, SEQUENCE_COUNT_SIZE + 4, SEQUENCE_COUNT_SIZE, 10_000, None,
                 False, True, True)


def _on_main_plan(body: MainPlanCheck, fallback: Plan | None = None) -> Callable[[Context, CheckSpec], Outcome]:
    """Run ``body`` with the main connection's plan, a registered probe and a T->O endpoint; without a
    plan, with ``fallback``, else not applicable."""

    @functools.wraps(body)
    def run(ctx: Context, spec: CheckSpec) -> Outcome:
        plan = main_plan(ctx) or fallback
        if plan is None:
            return not_planned(ctx, spec, ": the connection points are unknown")
        probe = ctx.probe()
        return body(ctx, spec, plan, probe, Endpoint(ctx, probe))

    return run


def _with_or_without_points(body: MainPlanCheck) -> Callable[[Context, CheckSpec], Outcome]:
    """A check that runs on the main connection's plan, or without one on ``NO_POINTS``."""
    return _on_main_plan(body, NO_POINTS)


def _refusal(spec: CheckSpec, probe: Probe, reply: Reply, opened: Opened | None, what: str = "") -> Outcome:
    """A refusal judged by the extended statuses the check declares."""
    if opened is not None:
        opened.close()
        return outcome(spec, False, f"{what}: accepted ({reply.describe()})", probe.exchanges)
    verdict = spec.verdict_for(reply.extended) if reply.status == 0x01 else Verdict.FAIL
    return outcome(spec, verdict, f"{what}: {reply.describe()}", probe.exchanges)


def _refused(ctx: Context, spec: CheckSpec, probe: Probe, endpoint: Endpoint, request: ForwardOpenRequest,
             what: str) -> Outcome:
    """Send ``request``, which the target should refuse with one of the check's extended statuses."""
    reply, opened = send_forward_open(ctx, probe, endpoint, request)
    return _refusal(spec, probe, reply, opened, what)


def extended(value: int, meaning: str, verdict: Verdict = Verdict.PASS) -> Code:
    """An extended status of general status 0x01 the specification permits, with its reference."""
    return Code(value, meaning, TABLE, verdict)


@check("cm.forward_open.accepted", "Forward_Open of the EDS's first exclusive owner connection",
       "status 0; the reply echoes the connection triad and gives non-zero packet intervals",
       "CIP Vol. 1 §3-5.5.2 (Forward_Open reply); Wireshark packet-cip.c (dissect_cip_cm_fwd_open_rsp)")
@_on_main_plan
def accepted(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = forward_open_request(plan)
    reply, opened = send_forward_open(ctx, probe, endpoint, request)
    if opened is None:
        return outcome(spec, False, f"{plan.name}: {reply.describe()}", probe.exchanges)
    problems = []
    if opened.reply.triad != request.triad:
        problems.append(f"triad {opened.reply.triad} echoed for {request.triad}")
    if not opened.reply.ot_api_us or not opened.reply.to_api_us:
        problems.append(f"packet intervals O->T {opened.reply.ot_api_us} T->O {opened.reply.to_api_us} us")
    closing = opened.close()
    if closing.status != 0:
        problems.append(f"Forward_Close: {closing.describe()}")
    return outcome(spec, not problems, "; ".join(problems) or f"{plan.name} opened and closed", probe.exchanges)


@check("cm.forward_open.ot_size", "Forward_Open with an O->T connection size 2 bytes too large",
       "status 0x01, extended 0x0127 (invalid O->T size) or the general 0x0109 (invalid connection size)", EXTENDED,
       codes=[extended(0x0127, "invalid O->T connection size"), extended(0x0109, "invalid connection size")])
@_on_main_plan
def ot_size(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = forward_open_request(replace(plan, ot_size=plan.ot_size + 2))
    return _refused(ctx, spec, probe, endpoint, request, f"O->T size {plan.ot_size + 2}")


@check("cm.forward_open.to_size", "Forward_Open with a T->O connection size 2 bytes too large",
       "status 0x01, extended 0x0128 (invalid T->O size) or the general 0x0109 (invalid connection size)", EXTENDED,
       codes=[extended(0x0128, "invalid T->O connection size"), extended(0x0109, "invalid connection size")])
@_on_main_plan
def to_size(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = forward_open_request(replace(plan, to_size=plan.to_size + 2))
    return _refused(ctx, spec, probe, endpoint, request, f"T->O size {plan.to_size + 2}")


@check("cm.forward_open.rpi", "Forward_Open with an RPI of 1 us",
       "status 0x01, extended 0x0111 (RPI not supported) or 0x0112 (RPI value not acceptable); or an honest "
       "acceptance: T->O then comes at the API the reply granted, measured on the wire for 0.5 s", EXTENDED,
       codes=[extended(0x0111, "RPI not supported"), extended(0x0112, "RPI value not acceptable")])
@_on_main_plan
def rpi(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = replace(forward_open_request(plan), ot_rpi_us=1, to_rpi_us=1)
    reply, opened = send_forward_open(ctx, probe, endpoint, request)
    if opened is None:
        return _refusal(spec, probe, reply, None, "RPI 1 us")
    # Accepted: the target may grant another interval than the one asked (CIP Vol. 1 §3-5.5.2, the
    # actual packet interval), but must then produce at the interval it granted.
    run = drive(ctx, plan, endpoint, opened, [(RPI_MEASURE_S, "run")])
    opened.close()
    ok, measured = judge_production(run, RPI_MEASURE_S)
    return outcome(spec, ok, f"RPI 1 us accepted with APIs O->T {opened.reply.ot_api_us} us, T->O "
                   f"{opened.reply.to_api_us} us; {measured}", run.exchanges())


@check("cm.forward_open.duplicate", "the same Forward_Open (same triad) twice",
       "the second is refused with status 0x01, extended 0x0100 (connection in use)", EXTENDED,
       codes=[extended(0x0100, "connection in use or duplicate Forward_Open")])
@_on_main_plan
def duplicate(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = forward_open_request(plan)
    first, opened = send_forward_open(ctx, probe, endpoint, request)
    if opened is None:
        return outcome(spec, False, f"the first Forward_Open failed: {first.describe()}", probe.exchanges)
    return _refused(ctx, spec, probe, endpoint, request, "the same triad again")


@check("cm.forward_open.ownership", "a second exclusive owner of the same output, from another triad",
       "status 0x01, extended 0x0106 (ownership conflict)", EXTENDED,
       codes=[extended(0x0106, "ownership conflict")])
@_on_main_plan
def ownership(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    first, opened = send_forward_open(ctx, probe, endpoint, forward_open_request(plan))
    if opened is None:
        return outcome(spec, False, f"the first Forward_Open failed: {first.describe()}", probe.exchanges)
    return _refused(ctx, spec, probe, endpoint, forward_open_request(plan), "a second exclusive owner")


def _unused_instance(ctx: Context, plan: Plan) -> int:
    used = {plan.config, plan.ot_point, plan.to_point}
    if ctx.view is not None:
        used |= {a.instance for a in ctx.view.assemblies.values() if a.instance is not None}
        used |= {p for c in ctx.view.connections for p in (c.config, c.o_t_point, c.t_o_point)}
    return next(i for i in range(0xFE, 0, -1) if i not in used)


@check("cm.forward_open.bad_segment", "Forward_Open whose connection path starts with a reserved segment (0xE0)",
       "status 0x01, extended 0x0315 (invalid segment in connection path); without a connection point, the path "
       "is the segment then the message router's (20 02 24 01): the target refuses it at its first segment, "
       "before any application path (a device that refuses that class 1 Forward_Open 0x0103, as one without class 1 "
       "I/O may, is asked again on a class 3 one)", EXTENDED,
       codes=[extended(0x0315, "invalid segment in connection path")])
@_with_or_without_points
def bad_segment(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    # CIP Vol. 1 §3-5.5.2: the connection path is parsed from its first segment; a reserved one is
    # refused there, so no assembly is needed behind it.
    behind = MESSAGE_ROUTER if plan is NO_POINTS else plan.path
    request = replace(forward_open_request(plan), connection_path=b"\xE0\x00" + behind)
    what = f"segment E0 00 before {behind.hex(' ')}"
    reply, opened = send_forward_open(ctx, probe, endpoint, request)
    if plan is NO_POINTS and opened is None and reply.status == 0x01 and reply.extended == 0x0103:
        # A device that offers no class 1 I/O may refuse a class 1 Forward_Open (0x0103) before it reads
        # the path; the path to the message router is a class 3 connection's, which it takes: asked again so.
        request = replace(request, triad=new_triad(),
                          transport=TransportTrigger(3, TriggerType.APPLICATION, server=True),
                          ot_parameters=NetworkParameters(CLASS3_SIZE, ConnectionType.POINT_TO_POINT),
                          to_parameters=NetworkParameters(CLASS3_SIZE, ConnectionType.POINT_TO_POINT))
        reply, opened = send_forward_open(ctx, probe, endpoint, request)
        what = f"class 1 refused 0x0103 (no class 1 I/O); class 3, {what}"
    return _refusal(spec, probe, reply, opened, what)


@check("cm.forward_open.consuming_point", "Forward_Open to an O->T (consuming) point the device does not have",
       "status 0x01, extended 0x012A (invalid consuming application path) or the general 0x0117 (invalid "
       "produced or consumed application path); 0x0315 is a warning", EXTENDED,
       codes=[extended(0x012A, "invalid consuming application path"),
              extended(0x0117, "invalid produced or consumed application path"),
              extended(0x0315, "invalid segment in connection path: the segments are valid, the point is not",
                       Verdict.WARNING)])
@_on_main_plan
def consuming_point(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    unused = _unused_instance(ctx, plan)
    request = forward_open_request(replace(plan, ot_point=unused))
    return _refused(ctx, spec, probe, endpoint, request, f"O->T point {unused}")


@check("cm.forward_open.producing_point", "Forward_Open to a T->O (producing) point the device does not have",
       "status 0x01, extended 0x012B (invalid producing application path) or the general 0x0117 (invalid "
       "produced or consumed application path); 0x0315 is a warning", EXTENDED,
       codes=[extended(0x012B, "invalid producing application path"),
              extended(0x0117, "invalid produced or consumed application path"),
              extended(0x0315, "invalid segment in connection path: the segments are valid, the point is not",
                       Verdict.WARNING)])
@_on_main_plan
def producing_point(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    unused = _unused_instance(ctx, plan)
    request = forward_open_request(replace(plan, to_point=unused))
    return _refused(ctx, spec, probe, endpoint, request, f"T->O point {unused}")


@check("cm.forward_open.transport_class", "Forward_Open with transport class 2",
       "status 0x01, extended 0x0103 (transport class and trigger combination not supported) or 0x011C "
       "(transport class not supported); a device that implements class 2 is a warning", EXTENDED,
       codes=[extended(0x0103, "transport class and trigger combination not supported"),
              extended(0x011C, "transport class not supported")])
@_with_or_without_points
def transport_class(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = replace(forward_open_request(plan), transport=TransportTrigger(2, TriggerType.CYCLIC))
    reply, opened = send_forward_open(ctx, probe, endpoint, request)
    if opened is not None:
        opened.close()
        return outcome(spec, Verdict.WARNING, f"transport class 2 accepted: {reply.describe()}", probe.exchanges)
    return _refusal(spec, probe, reply, opened, "transport class 2")


@check("cm.forward_open.null", "a null Forward_Open (both connection types null) for the configuration point",
       "status 0 (configuration accepted, no connection made) or status 0x01 with extended 0x0132 (null "
       "Forward_Open not supported)", f"CIP Vol. 1 §3-5.5.2.2 (null Forward_Open); {EXTENDED}",
       codes=[extended(0x0132, "null Forward_Open function not supported")])
@_with_or_without_points
def null_forward_open(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    base = forward_open_request(plan)
    request = replace(base, ot_parameters=replace(base.ot_parameters, type=ConnectionType.NULL),
                      to_parameters=replace(base.to_parameters, type=ConnectionType.NULL))
    reply, opened = send_forward_open(ctx, probe, endpoint, request)
    if reply.status == 0:
        return outcome(spec, True, f"accepted: {reply.describe()}", probe.exchanges)
    return _refusal(spec, probe, reply, opened, "null Forward_Open")


@check("cm.large_forward_open", "Large_Forward_Open of the first point-to-point exclusive owner connection",
       "status 0 and a well formed reply, then a Forward_Close that succeeds; a target without Large_Forward_Open "
       "answers 0x08 (service not supported)", "CIP Vol. 1 §3-5.5.3 (Large_Forward_Open, 0x5B); Wireshark packet-cip.c",
       codes=[Code(0x08, "service not supported: no Large_Forward_Open", "CIP Vol. 1 Appendix B; §3-5.5.3")])
@_on_main_plan
def large_forward_open(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = forward_open_request(plan, large=True)
    reply, opened = send_forward_open(ctx, probe, endpoint, request)
    if opened is None:
        verdict = spec.verdict_for(reply.status) if reply.status else Verdict.FAIL
        return outcome(spec, verdict, f"{plan.name}: {reply.describe()}", probe.exchanges)
    closing = opened.close()
    return outcome(spec, closing.status == 0, f"opened; Forward_Close: {closing.describe()}", probe.exchanges)


@check("cm.forward_close.unknown", "Forward_Close of a connection that does not exist",
       "status 0x01, extended 0x0107 (target connection not found)", EXTENDED,
       codes=[extended(0x0107, "target connection not found")])
def close_unknown(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    reply = forward_close(probe, new_triad(), MESSAGE_ROUTER)
    return _refusal(spec, probe, reply, None, "serial of no connection")


@check("cm.forward_close.other_originator",
       "Forward_Close naming an open connection's serial with another originator serial",
       "status 0x01, extended 0x0107 (the triad names no connection); the connection stays open and its "
       "own Forward_Close then succeeds", f"CIP Vol. 1 §3-5.5.4 (Forward_Close matches the whole triad); {EXTENDED}",
       codes=[extended(0x0107, "target connection not found")])
@_on_main_plan
def close_other_originator(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    return close_with_wrong_triad(ctx, spec, plan, probe, endpoint, "other originator", lambda t: ConnectionTriad(
        t.connection_serial, t.vendor_id, (t.originator_serial + 1) & 0xFFFFFFFF), ctx.probe())


def close_with_wrong_triad(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint, what: str,
                           wrong: Callable[[ConnectionTriad], ConnectionTriad], closer: Probe) -> Outcome:
    """Open ``plan``, send a Forward_Close on ``closer`` with the triad ``wrong`` makes of the connection's,
    which the target must refuse with a code the check permits, then the connection's own Forward_Close,
    which must succeed."""
    first, opened = send_forward_open(ctx, probe, endpoint, forward_open_request(plan))
    if opened is None:
        return outcome(spec, False, f"Forward_Open failed: {first.describe()}", probe.exchanges)
    reply = forward_close(closer, wrong(opened.request.triad), plan.path)
    own = opened.close()
    ok = reply.status == 0x01 and spec.verdict_for(reply.extended) is Verdict.PASS and own.status == 0
    exchanges = probe.exchanges if closer is probe else [*probe.exchanges, *closer.exchanges]
    return outcome(spec, ok, f"{what}: {reply.describe()}; own Forward_Close: {own.describe()}", exchanges)
