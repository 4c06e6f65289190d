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

from ..cip.epath import request_path
from ..eip.io_core import DEFAULT_IO_PORT
from ..eip.originator.io_originator import SEQUENCE_COUNT_SIZE, OtFormat, class1_path
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
from .model import CheckSpec, Outcome, Verdict
from .registry import Context, check, outcome
from .wire import Probe, Reply

CM = request_path(0x06, 1)
FORWARD_OPEN, LARGE_FORWARD_OPEN, FORWARD_CLOSE = 0x54, 0x5B, 0x4E
EXTENDED = "CIP Vol. 1 §3-5.5.2 and Table 3-5.33 (extended status); Wireshark packet-cip.c (cip_cm_ext_st_vals)"
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
        return class1_path(None if self.heartbeat else self.ot_point, self.to_point, self.config,
                           self.ot_point if self.heartbeat else None)

    @property
    def to_data_size(self) -> int:
        return self.to_size - SEQUENCE_COUNT_SIZE


def plans(ctx: Context) -> list[Plan]:
    """Every class 1 connection of the EDS, exclusive owners first."""
    if ctx.view is None or ctx.eds is None:
        return []
    from ..eds.generator import EXCLUSIVE_OWNER_KIND
    from ..scanner import _eds_ot_format

    found = []
    for info in ctx.view.connections:
        fmt = _eds_ot_format(ctx.eds, info.number) or (OtFormat.HEARTBEAT if info.heartbeat else OtFormat.RUN_IDLE)
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

    def __init__(self, probe: Probe, request: ForwardOpenRequest, reply: ForwardOpenReply, items: tuple[Item, ...]):
        self.probe, self.request, self.reply = probe, request, reply
        self.io_port = DEFAULT_IO_PORT
        for item in items:
            if item.type == ItemType.SOCKADDR_O_T:
                with contextlib.suppress(Exception):  # a malformed item: the default port
                    self.io_port = SockAddr.decode(item.data).port or DEFAULT_IO_PORT
        self.closed = False

    def close(self) -> Reply:
        self.closed = True
        return forward_close(self.probe, self.request.triad, self.request.connection_path)


def forward_close(probe: Probe, triad: ConnectionTriad, path: bytes) -> Reply:
    return probe.request(FORWARD_CLOSE, CM, ForwardCloseRequest(0x0A, 0x0E, triad, path).encode())


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
        ctx.pending_closes.append(lambda: forward_close(probe, request.triad, request.connection_path))
        return reply, None
    opened = Opened(probe, request, decoded, reply.items)
    ctx.pending_closes.append(lambda: None if opened.closed else opened.close())
    return reply, opened


def not_planned(ctx: Context, spec: CheckSpec, consequence: str = "") -> Outcome:
    """The outcome of a check that needs the EDS's main connection when there is none."""
    why = "no EDS given (--eds)" if ctx.eds is None else "the EDS declares no point-to-point exclusive owner"
    return outcome(spec, Verdict.NOT_APPLICABLE, f"not run: {why}{consequence}")


MainPlanCheck = Callable[[Context, CheckSpec, Plan, Probe, Endpoint], Outcome]


def _on_main_plan(body: MainPlanCheck) -> Callable[[Context, CheckSpec], Outcome]:
    """Run ``body`` with the main connection's plan, a registered probe and a T->O endpoint; not
    applicable without them."""

    @functools.wraps(body)
    def run(ctx: Context, spec: CheckSpec) -> Outcome:
        plan = main_plan(ctx)
        if plan is None:
            return not_planned(ctx, spec, ": the connection points are unknown")
        probe = ctx.probe()
        return body(ctx, spec, plan, probe, Endpoint(ctx, probe))

    return run


def _refusal(spec: CheckSpec, probe: Probe, reply: Reply, opened: Opened | None, codes: set[int],
             warn: set[int] = frozenset(), what: str = "") -> Outcome:  # type: ignore[assignment]
    if opened is not None:
        opened.close()
        return outcome(spec, False, f"{what}: accepted ({reply.describe()})", probe.exchanges)
    if reply.status == 0x01 and reply.extended in codes:
        return outcome(spec, True, f"{what}: {reply.describe()}", probe.exchanges)
    verdict = Verdict.WARNING if reply.status == 0x01 and reply.extended in warn else Verdict.FAIL
    return outcome(spec, verdict, f"{what}: {reply.describe()}", probe.exchanges)


def _refused(ctx: Context, spec: CheckSpec, probe: Probe, endpoint: Endpoint, request: ForwardOpenRequest,
             codes: set[int], warn: set[int], what: str) -> Outcome:
    """Send ``request``, which the target should refuse with one of the extended ``codes``."""
    reply, opened = send_forward_open(ctx, probe, endpoint, request)
    return _refusal(spec, probe, reply, opened, codes, warn, what)


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
       "status 0x01, extended 0x0127 (invalid O->T size)", EXTENDED)
@_on_main_plan
def ot_size(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = forward_open_request(replace(plan, ot_size=plan.ot_size + 2))
    return _refused(ctx, spec, probe, endpoint, request, {0x0127}, {0x0109}, f"O->T size {plan.ot_size + 2}")


@check("cm.forward_open.to_size", "Forward_Open with a T->O connection size 2 bytes too large",
       "status 0x01, extended 0x0128 (invalid T->O size)", EXTENDED)
@_on_main_plan
def to_size(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = forward_open_request(replace(plan, to_size=plan.to_size + 2))
    return _refused(ctx, spec, probe, endpoint, request, {0x0128}, {0x0109}, f"T->O size {plan.to_size + 2}")


@check("cm.forward_open.rpi", "Forward_Open with an RPI of 1 us",
       "status 0x01, extended 0x0111 (RPI not supported) or 0x0112 (RPI value not acceptable)", EXTENDED)
@_on_main_plan
def rpi(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = replace(forward_open_request(plan), ot_rpi_us=1, to_rpi_us=1)
    return _refused(ctx, spec, probe, endpoint, request, {0x0111, 0x0112}, set(), "RPI 1 us")


@check("cm.forward_open.duplicate", "the same Forward_Open (same triad) twice",
       "the second is refused with status 0x01, extended 0x0100 (connection in use)", EXTENDED)
@_on_main_plan
def duplicate(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = forward_open_request(plan)
    first, opened = send_forward_open(ctx, probe, endpoint, request)
    if opened is None:
        return outcome(spec, False, f"the first Forward_Open failed: {first.describe()}", probe.exchanges)
    return _refused(ctx, spec, probe, endpoint, request, {0x0100}, set(), "the same triad again")


@check("cm.forward_open.ownership", "a second exclusive owner of the same output, from another triad",
       "status 0x01, extended 0x0106 (ownership conflict)", EXTENDED)
@_on_main_plan
def ownership(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    first, opened = send_forward_open(ctx, probe, endpoint, forward_open_request(plan))
    if opened is None:
        return outcome(spec, False, f"the first Forward_Open failed: {first.describe()}", probe.exchanges)
    return _refused(ctx, spec, probe, endpoint, forward_open_request(plan), {0x0106}, set(), "a second exclusive owner")


def _unused_instance(ctx: Context, plan: Plan) -> int:
    used = {plan.config, plan.ot_point, plan.to_point}
    if ctx.view is not None:
        used |= {a.instance for a in ctx.view.assemblies.values() if a.instance is not None}
        used |= {p for c in ctx.view.connections for p in (c.config, c.o_t_point, c.t_o_point)}
    return next(i for i in range(0xFE, 0, -1) if i not in used)


@check("cm.forward_open.bad_segment", "Forward_Open whose connection path starts with a reserved segment (0xE0)",
       "status 0x01, extended 0x0315 (invalid segment in connection path) or 0x0316", EXTENDED)
@_on_main_plan
def bad_segment(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = replace(forward_open_request(plan), connection_path=b"\xE0\x00" + plan.path)
    return _refused(ctx, spec, probe, endpoint, request, {0x0315, 0x0316}, set(), "segment E0 00")


@check("cm.forward_open.consuming_point", "Forward_Open to an O->T (consuming) point the device does not have",
       "status 0x01, extended 0x012A (invalid consuming application path)", EXTENDED)
@_on_main_plan
def consuming_point(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    unused = _unused_instance(ctx, plan)
    request = forward_open_request(replace(plan, ot_point=unused))
    return _refused(ctx, spec, probe, endpoint, request, {0x012A}, {0x0117, 0x0315}, f"O->T point {unused}")


@check("cm.forward_open.producing_point", "Forward_Open to a T->O (producing) point the device does not have",
       "status 0x01, extended 0x012B (invalid producing application path)", EXTENDED)
@_on_main_plan
def producing_point(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    unused = _unused_instance(ctx, plan)
    request = forward_open_request(replace(plan, to_point=unused))
    return _refused(ctx, spec, probe, endpoint, request, {0x012B}, {0x0117, 0x0315}, f"T->O point {unused}")


@check("cm.forward_open.transport_class", "Forward_Open with transport class 2",
       "status 0x01, extended 0x0103 (transport class and trigger combination not supported); a device that "
       "implements class 2 is a warning", EXTENDED)
@_on_main_plan
def transport_class(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = replace(forward_open_request(plan), transport=TransportTrigger(2, TriggerType.CYCLIC))
    reply, opened = send_forward_open(ctx, probe, endpoint, request)
    if opened is not None:
        opened.close()
        return outcome(spec, Verdict.WARNING, f"transport class 2 accepted: {reply.describe()}", probe.exchanges)
    return _refusal(spec, probe, reply, opened, {0x0103}, set(), "transport class 2")


@check("cm.forward_open.null", "a null Forward_Open (both connection types null) for the configuration point",
       "status 0 (configuration accepted, no connection made) or status 0x01 with extended 0x0132 (null "
       "Forward_Open not supported)", f"CIP Vol. 1 §3-5.5.2.2 (null Forward_Open); {EXTENDED}")
@_on_main_plan
def null_forward_open(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    base = forward_open_request(plan)
    request = replace(base, ot_parameters=replace(base.ot_parameters, type=ConnectionType.NULL),
                      to_parameters=replace(base.to_parameters, type=ConnectionType.NULL))
    reply, opened = send_forward_open(ctx, probe, endpoint, request)
    if reply.status == 0:
        return outcome(spec, True, f"accepted: {reply.describe()}", probe.exchanges)
    return _refusal(spec, probe, reply, opened, {0x0132}, set(), "null Forward_Open")


@check("cm.large_forward_open", "Large_Forward_Open of the EDS's first exclusive owner connection",
       "status 0 and a well formed reply; 0x08 (service not supported) makes the check not applicable",
       "CIP Vol. 1 §3-5.5.3 (Large_Forward_Open, 0x5B); Wireshark packet-cip.c")
@_on_main_plan
def large_forward_open(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    request = forward_open_request(plan, large=True)
    reply, opened = send_forward_open(ctx, probe, endpoint, request)
    if reply.status == 0x08:
        return outcome(spec, Verdict.NOT_APPLICABLE, "Large_Forward_Open not supported (0x08)", probe.exchanges)
    if opened is None:
        return outcome(spec, False, f"{plan.name}: {reply.describe()}", probe.exchanges)
    closing = opened.close()
    return outcome(spec, closing.status == 0, f"opened; Forward_Close: {closing.describe()}", probe.exchanges)


@check("cm.forward_close.unknown", "Forward_Close of a connection that does not exist",
       "status 0x01, extended 0x0107 (target connection not found)", EXTENDED)
def close_unknown(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    reply = forward_close(probe, new_triad(), request_path(0x02, 1))
    ok = reply.status == 0x01 and reply.extended == 0x0107
    return outcome(spec, ok, reply.describe(), probe.exchanges)


@check("cm.forward_close.other_originator",
       "Forward_Close naming an open connection's serial with another originator serial",
       "status 0x01, extended 0x0107 (the triad names no connection); the connection stays open and its "
       "own Forward_Close then succeeds", f"CIP Vol. 1 §3-5.5.4 (Forward_Close matches the whole triad); {EXTENDED}")
@_on_main_plan
def close_other_originator(ctx: Context, spec: CheckSpec, plan: Plan, probe: Probe, endpoint: Endpoint) -> Outcome:
    first, opened = send_forward_open(ctx, probe, endpoint, forward_open_request(plan))
    if opened is None:
        return outcome(spec, False, f"Forward_Open failed: {first.describe()}", probe.exchanges)
    triad = opened.request.triad
    other = ConnectionTriad(triad.connection_serial, triad.vendor_id, (triad.originator_serial + 1) & 0xFFFFFFFF)
    stranger = ctx.probe()
    reply = forward_close(stranger, other, plan.path)
    own = opened.close()
    ok = reply.status == 0x01 and reply.extended == 0x0107 and own.status == 0
    return outcome(spec, ok, f"other originator: {reply.describe()}; own Forward_Close: {own.describe()}",
                   [*probe.exchanges, *stranger.exchanges])

