"""The battery's last check, run after every other whatever the groups: the device is left as it was
found. Each connection point a Forward_Open of the run opened opens again (a new triad, the same path,
sizes and connection types, so an exclusive owner again where it was one) and closes, every write
is restored, and nothing the battery opened is still held. A target that keeps a connection after
its Forward_Close (or after a timeout) fails here, naming what is left and how to clear it.
"""

from __future__ import annotations

import random
from dataclasses import replace

from ..cip.epath import LogicalSegment, LogicalType, decode_path
from ..cip.status import CipError
from ..eip.wire.cm_messages import ForwardOpenRequest
from .connections import (
    CM,
    FORWARD_OPEN,
    LARGE_FORWARD_OPEN,
    Endpoint,
    Opened,
    close_connection,
    new_triad,
    send_forward_open,
)
from .model import CheckSpec, Outcome, Verdict
from .profile import clear_fault_of_the_run
from .registry import Context, check, outcome
from .wire import Probe

#: Extended statuses that mean "the target still holds a connection of this point".
HELD = {0x0100: "connection in use", 0x0106: "ownership conflict", 0x0113: "out of connections",
        0x011A: "target object out of connections"}
HOW_TO_CLEAR = ("close it with a Forward_Close naming its triad, or power-cycle the device (a target that keeps a "
                "timed-out owner releases it only then)")


def _key(request: ForwardOpenRequest) -> tuple[object, ...]:
    return (request.connection_path, request.ot_parameters.type, request.to_parameters.type,
            request.transport.transport_class, request.large)


def _points(ctx: Context) -> list[ForwardOpenRequest]:
    """The first accepted Forward_Open of each distinct connection (path and connection types)."""
    first: dict[tuple[object, ...], ForwardOpenRequest] = {}
    for request in ctx.accepted:
        first.setdefault(_key(request), request)
    return list(first.values())


def produced_point(path: bytes) -> int | None:
    """The last connection point of a connection path: the T->O (produced) point of a class 1 path."""
    try:
        segments = decode_path(path)
    except (CipError, ValueError):
        return None
    points = [s.value for s in segments if isinstance(s, LogicalSegment) and s.kind is LogicalType.CONNECTION_POINT]
    return points[-1] if points else None


def again(request: ForwardOpenRequest) -> ForwardOpenRequest:
    """The same connection with a new triad and T->O connection id."""
    return replace(request, triad=new_triad(), to_connection_id=random.randrange(1, 0xFFFFFFFF))


def _describe(request: ForwardOpenRequest) -> str:
    service = "Large_Forward_Open" if request.large else "Forward_Open"
    return (f"{service} of path {request.connection_path.hex(' ')} (O->T {request.ot_parameters.type.name.lower()}, "
            f"T->O {request.to_parameters.type.name.lower()})")


def _reopen_explicit(ctx: Context, probe: Probe, request: ForwardOpenRequest) -> str | None:
    """A class 3 connection opened again as it was, with no sockaddr item, and closed."""
    fresh = again(request)
    reply = probe.request(LARGE_FORWARD_OPEN if fresh.large else FORWARD_OPEN, CM, fresh.encode())
    if reply.status != 0:
        return f"{_describe(request)} (class 3) no longer opens: {reply.describe()}"
    closing = close_connection(ctx, probe, fresh.triad, fresh.connection_path)
    return None if closing.status == 0 else f"{_describe(request)} (class 3): Forward_Close {closing.describe()}"


def _reopen(ctx: Context, probe: Probe, endpoint: Endpoint, request: ForwardOpenRequest,
            points: list[ForwardOpenRequest]) -> str | None:
    """Open ``request`` again and close it; a problem in words, or None."""
    if request.transport.transport_class != 1:
        return _reopen_explicit(ctx, probe, request)
    reply, opened = send_forward_open(ctx, probe, endpoint, again(request))
    owner: Opened | None = None
    if opened is None and reply.status == 0x01 and reply.extended == 0x0119:
        # Listen or input only: it needs the owner of its input open, as it had during the run.
        point = produced_point(request.connection_path)
        for candidate in points:
            if candidate is request or produced_point(candidate.connection_path) != point:
                continue
            _, owner = send_forward_open(ctx, probe, endpoint, again(candidate))
            if owner is None:
                continue
            reply, opened = send_forward_open(ctx, probe, endpoint, again(request))
            if opened is not None:
                break
            owner.close()  # not the owner it needs (a listen-only one shares a multicast owner's data)
            owner = None
    problem = None
    if opened is None:
        problem = f"{_describe(request)} no longer opens: {reply.describe()}"
        if reply.status == 0x01 and reply.extended in HELD:
            problem += f" ({HELD[reply.extended]}: the target still holds a connection the battery opened)"
    else:
        closing = opened.close()
        if closing.status != 0:
            problem = f"{_describe(request)} opens again but its Forward_Close answers {closing.describe()}"
    if owner is not None:
        owner.close()
    return problem


@check("final.as_found", "the device as the battery found it: every connection point used opens again",
       "each connection the target accepted during the run opens again (a new triad, the same path, sizes and "
       "connection types: an exclusive owner where it was one) and closes; every Forward_Close of the run was "
       "answered on a live session; every write is restored",
       "CIP Vol. 1 §3-5.5.4 (Forward_Close releases a connection and its ownership); §3-5.5.2 (0x0106 ownership "
       "conflict while an owner is held)")
def as_found(ctx: Context, spec: CheckSpec) -> Outcome:
    points = _points(ctx)
    if not points and not ctx.restores and not ctx.left_behind:
        return outcome(spec, Verdict.NOT_APPLICABLE, "the run opened no connection and wrote nothing")
    problems = list(ctx.left_behind)
    probe = ctx.probe()
    restored = 0
    for restore in reversed(ctx.restores):
        problem = restore()
        if problem is None:
            restored += 1
        else:
            problems.append(problem)
    endpoint = Endpoint(ctx, probe)
    for request in points:
        problem = _reopen(ctx, probe, endpoint, request, points)
        if problem is not None:
            problems.append(problem)
    cleared, clear = clear_fault_of_the_run(ctx, probe)
    if not clear and (ctx.allow_writes or ctx.allow_motion):
        problems.append(cleared)
    if problems:
        return outcome(spec, False, "left behind: " + "; ".join(problems) + f". To clear it: {HOW_TO_CLEAR}",
                       probe.exchanges)
    # A fault the run caused and was not allowed to clear: allowed by the options, so a warning.
    return outcome(spec, Verdict.PASS if clear else Verdict.WARNING, f"{len(points)} connection point(s) opened "
                   f"again and closed; {restored} write(s) restored" + (f"; {cleared}" if cleared else ""),
                   probe.exchanges)

