"""Group 6: the EDS file given with ``--eds`` against the device (the EDS specification (CIP Vol. 1, chapter 7); the EDS
specification, CIP Vol. 1 chapter 7, as the EDS reader of ``cipstack.eds`` reads it)."""

from __future__ import annotations

import functools
import struct
from collections.abc import Callable, Iterator
from dataclasses import replace
from typing import TYPE_CHECKING

from ..cip.epath import request_path
from ..eds import refusals
from ..eds.checker import ERROR, INFO, WARNING
from ..eds.generator import LISTEN_ONLY_KIND
from ..eds.refusals import ConnectionVerdict
from .connections import Endpoint, Opened, Plan, forward_open_request, plans_of_eds, send_forward_open
from .model import CheckSpec, Outcome, Verdict
from .registry import Context, check, outcome
from .wire import Exchange, Probe

if TYPE_CHECKING:
    from ..eds.interpret import ConnectionInfo, EdsView

#: A finding's severity of ``eds check`` as this battery's verdict: one judgement (``eds.refusals``)
#: for both tools; a note neither fails nor warns, and a check that does not count is n/a here.
VERDICTS = {ERROR: Verdict.FAIL, WARNING: Verdict.WARNING, INFO: Verdict.NOT_APPLICABLE}

EDS_REFERENCE = "CIP Vol. 1 §7 (EDS)"


def _no_eds(ctx: Context, spec: CheckSpec) -> Outcome | None:
    if ctx.eds is None or ctx.view is None:
        return outcome(spec, Verdict.NOT_APPLICABLE, "no EDS file: none given (--eds) and none found")
    return None


def _each_with_eds(body: Callable[[Context, CheckSpec, EdsView], Iterator[Outcome]],
                   ) -> Callable[[Context, CheckSpec], Iterator[Outcome]]:
    """A check with an outcome per EDS entry: not applicable, once, without an EDS."""

    @functools.wraps(body)
    def run(ctx: Context, spec: CheckSpec) -> Iterator[Outcome]:
        skipped = _no_eds(ctx, spec)
        if skipped is not None:
            yield skipped
            return
        assert ctx.view is not None
        yield from body(ctx, spec, ctx.view)

    return run


@check("eds.device.identity", "[Device] against the Identity object",
       "VendCode, ProdType, ProdCode, MajRev, MinRev and ProdName equal Identity attributes 1-4 and 7",
       f"{EDS_REFERENCE} [Device] section; CIP Vol. 1 §5-2.2")
def device_identity(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = _no_eds(ctx, spec)
    if skipped is not None:
        return skipped
    from ..eds.checker import check_eds
    from .objects import IDENTITY, number, read_attributes

    probe = ctx.probe()
    values, problems = read_attributes(probe, 0x01, {a: IDENTITY[a] for a in (1, 2, 3, 4, 7)}, shapes=False)
    if problems:
        return outcome(spec, False, "; ".join(problems), probe.exchanges)
    identity = {"vendor_id": number(values[1]), "device_type": number(values[2]), "product_code": number(values[3]),
                "revision": tuple(values[4][:2]), "product_name": values[7][1:].decode("latin-1")}
    assert ctx.eds is not None  # _no_eds skipped the check otherwise
    differ = [f.message for f in check_eds(ctx.eds, identity) if f.rule == "device-identity"]
    return outcome(spec, not differ, "; ".join(differ) or "[Device] matches", probe.exchanges)


@check("eds.param.link", "every ParamN with a link path, read from the device",
       "Get_Attribute_Single of the link path succeeds with the data size the ParamN declares (field 6)",
       f"{EDS_REFERENCE} [Params] (fields 3-6: link path, descriptor, type, size)")
@_each_with_eds
def param_links(ctx: Context, spec: CheckSpec, view: EdsView) -> Iterator[Outcome]:
    probe = ctx.probe()
    linked = [p for p in view.params.values() if p.link is not None]
    if not linked:
        yield outcome(spec, Verdict.NOT_APPLICABLE, "no ParamN has a link path")
    for param in linked:
        assert param.link is not None
        before = len(probe.exchanges)
        reply = probe.request(0x0E, request_path(*param.link))
        ok = reply.status == 0 and len(reply.data) == param.size
        observed = (f"{'/'.join(map(str, param.link))}: {reply.describe()}"
                    + ("" if reply.status != 0 else f", declared {param.size} ({param.type.name})"))
        yield outcome(spec, ok, observed, probe.exchanges[before:], subject=param.keyword)


@check("eds.assembly.size", "every AssemN with an instance, against Assembly attribute 4",
       "Get_Attribute_Single 4/N/4 (data size, UINT) equals the size the AssemN declares; 0x14 (attribute 4 not "
       "supported) is a warning", f"{EDS_REFERENCE} [Assembly]; CIP Vol. 1 §5-5 (Assembly attribute 4)")
@_each_with_eds
def assembly_sizes(ctx: Context, spec: CheckSpec, view: EdsView) -> Iterator[Outcome]:
    probe = ctx.probe()
    placed = [a for a in view.assemblies.values() if a.instance is not None]
    if not placed:
        yield outcome(spec, Verdict.NOT_APPLICABLE, "no AssemN names an instance")
    heartbeats = {c.o_t_point for c in view.connections if c.heartbeat}
    for assembly in placed:
        if assembly.size == 0 and assembly.instance in heartbeats:
            yield outcome(spec, Verdict.NOT_APPLICABLE, f"instance {assembly.instance} is a heartbeat connection "
                          "point: no data, nothing to size", subject=assembly.keyword)
            continue
        before = len(probe.exchanges)
        reply = probe.request(0x0E, request_path(0x04, assembly.instance, 4))
        exchanges = probe.exchanges[before:]
        if reply.status == 0x14:
            yield outcome(spec, Verdict.WARNING, f"instance {assembly.instance}: attribute 4 not supported (0x14)",
                          exchanges, assembly.keyword)
            continue
        size = struct.unpack("<H", reply.data)[0] if reply.status == 0 and len(reply.data) == 2 else None
        yield outcome(spec, size == assembly.size, f"instance {assembly.instance}: {reply.describe()}"
                      + ("" if size is None else f", size {size}, declared {assembly.size}"), exchanges,
                      assembly.keyword)


@check("eds.connection.open", "every class 1 ConnectionN opened and closed",
       "Forward_Open with the connection's points, sizes and RPI succeeds, and its Forward_Close succeeds; a "
       "connection the device refuses for its path while it has the assemblies and accepts another of the file's "
       "connections of the same kind is its configuration (n/a), as is a listener with no owner to listen to",
       f"{EDS_REFERENCE} [Connection Manager] ConnectionN; CIP Vol. 1 §3-5.5")
@_each_with_eds
def connections_open(ctx: Context, spec: CheckSpec, view: EdsView) -> Iterator[Outcome]:
    assert ctx.eds is not None  # _each_with_eds: there is one
    found = plans_of_eds(ctx.eds, view)
    if not found:
        yield outcome(spec, Verdict.NOT_APPLICABLE, "the EDS declares no class 1 connection")
        return
    infos = {f"Connection{c.number}": c for c in view.connections}
    probe = ctx.probe()
    endpoint = Endpoint(ctx, probe)
    outcomes: list[Outcome | None] = []
    #: Judged once every connection was tried (``eds.refusals``: whether another opened matters).
    pending: list[tuple[int, Plan, Callable[..., ConnectionVerdict], list[Exchange]]] = []
    opened_infos: list[ConnectionInfo] = []
    for plan in found:
        info = infos[plan.name]
        before = len(probe.exchanges)
        reply, opened = send_forward_open(ctx, probe, endpoint, forward_open_request(plan))
        owner: Opened | None = None
        owners_refused: list[tuple[ConnectionInfo, int, list[int]]] = []
        listener = info.kind == LISTEN_ONLY_KIND
        if opened is None and (listener or (reply.status == 0x01 and reply.extended == 0x0119)):
            # Listen only (or input only, on some devices) needs a connection that owns the data: open
            # the file's connection that produces it first, as a configuration tool would.
            owner, owners_refused = _open_owner(ctx, probe, endpoint, found, infos, plan, info)
            if owner is not None:
                reply, opened = send_forward_open(ctx, probe, endpoint, forward_open_request(plan))
        if opened is None:
            if owner is not None:
                owner.close()
            if reply.response is None:
                outcomes.append(outcome(spec, Verdict.FAIL, f"Forward_Open: {reply.describe()}",
                                        probe.exchanges[before:], plan.name))
                continue
            if listener and owner is None:
                verdict = refusals.unheard(info, owners_refused)
                outcomes.append(outcome(spec, VERDICTS[verdict.severity], verdict.message, probe.exchanges[before:],
                                        plan.name))
                continue
            general, extended = reply.response.general_status, list(reply.response.extended_status)
            exist = bool(extended) and extended[0] in refusals.PATH_REFUSALS and _assemblies_exist(probe, info)
            pending.append((len(outcomes), plan, functools.partial(
                refusals.refused, info, general, extended, assemblies_exist=exist), probe.exchanges[before:]))
            outcomes.append(None)
            continue
        closing = opened.close()
        if owner is not None:
            owner.close()
        if closing.status == 0:
            opened_infos.append(info)
        outcomes.append(outcome(spec, closing.status == 0, f"opened{' with its owner' if owner else ''}; "
                                f"Forward_Close: {closing.describe()}", probe.exchanges[before:], plan.name))
    for index, plan, judge, exchanges in pending:
        verdict = judge(opened=opened_infos)
        outcomes[index] = outcome(spec, VERDICTS[verdict.severity], verdict.message, exchanges, plan.name)
    yield from (o for o in outcomes if o is not None)


def _open_owner(ctx: Context, probe: Probe, endpoint: Endpoint, found: list[Plan], infos: dict[str, ConnectionInfo],
                plan: Plan, info: ConnectionInfo) -> tuple[Opened | None, list[tuple[ConnectionInfo, int, list[int]]]]:
    """The connection that produces ``plan``'s input, opened: for a listener, the file's connections
    that produce it by multicast (``refusals.owners_of``), asked for multicast; else its exclusive
    owners. What refused each, when none opens."""
    if info.kind == LISTEN_ONLY_KIND:
        owners = [p for p in found if infos[p.name] in refusals.owners_of(info, infos.values())]
        variants = [[replace(owner, multicast=True)] for owner in owners]
    else:
        owners = [p for p in found if p.exclusive_owner and p.to_point == plan.to_point]
        variants = [[replace(owner, multicast=plan.multicast), owner] for owner in owners]
    refused: list[tuple[ConnectionInfo, int, list[int]]] = []
    for owner, tries in zip(owners, variants, strict=True):
        reply = None
        for variant in tries:
            reply, opened = send_forward_open(ctx, probe, endpoint, forward_open_request(variant))
            if opened is not None:
                return opened, []
        if reply is not None and reply.response is not None:
            refused.append((infos[owner.name], reply.response.general_status, list(reply.response.extended_status)))
    return None, refused


def _assemblies_exist(probe: Probe, info: ConnectionInfo) -> bool:
    return all(probe.request(0x0E, request_path(0x04, point, 4)).status == 0 for point in refusals.data_points(info))
