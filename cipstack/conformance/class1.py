"""Group 5: class 1 behaviour of the target on a live connection: production at the granted API,
sequence counts, data size, run/idle, and the connection's timeout (CIP Vol. 1 §3-4 and
Vol. 2 §3-4, as OpENer's cipioconnection.c and Wireshark's packet-cip.c (cipio) describe them)."""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable

from ..eip.io_core import seq16_newer
from .connections import Endpoint, Opened, Plan, forward_open_request, main_plan, not_planned, send_forward_open
from .io_run import Run, drive, judge_production
from .model import CheckSpec, Outcome, Verdict
from .registry import Context, check, outcome

IO_REFERENCE = "CIP Vol. 1 §3-4.4 (connection timeout = RPI x 4 x 2^multiplier); Vol. 2 §3-2 (class 1 over UDP)"


def _open(ctx: Context, spec: CheckSpec, multiplier: int) -> tuple[Plan, Endpoint, Opened] | Outcome:
    plan = main_plan(ctx)
    if plan is None:
        return not_planned(ctx, spec)
    probe = ctx.probe()
    endpoint = Endpoint(ctx, probe)
    reply, opened = send_forward_open(ctx, probe, endpoint, forward_open_request(plan, multiplier=multiplier))
    if opened is None:
        return outcome(spec, False, f"Forward_Open of {plan.name}: {reply.describe()}", probe.exchanges)
    return plan, endpoint, opened


def _production(ctx: Context, spec: CheckSpec) -> tuple[Plan, Run] | Outcome:
    """One second of a running connection, shared by the production, sequence and size checks."""
    if "production" not in ctx.cache:
        opened = _open(ctx, spec, multiplier=4)
        if isinstance(opened, Outcome):
            ctx.cache["production"] = opened
        else:
            plan, endpoint, connection = opened
            run = drive(ctx, plan, endpoint, connection, [(1.0, "run")])
            connection.close()
            ctx.cache["production"] = (plan, run)
    cached = ctx.cache["production"]
    if isinstance(cached, Outcome):
        return outcome(spec, cached.verdict, cached.observed, cached.exchanges)
    return cached  # type: ignore[no-any-return]  # the cache holds any check's results; this key, these


def _on_production(body: Callable[[Context, CheckSpec, Plan, Run], Outcome]) -> Callable[[Context, CheckSpec], Outcome]:
    """Run ``body`` on the shared production run; its failure to open is each check's outcome."""

    @functools.wraps(body)
    def judge(ctx: Context, spec: CheckSpec) -> Outcome:
        measured = _production(ctx, spec)
        if isinstance(measured, Outcome):
            return measured
        return body(ctx, spec, *measured)

    return judge


@check("class1.production", "T->O production at the granted API for 1 s",
       "packets arrive at the T->O API the Forward_Open reply granted: mean interval within 0.8-1.25 x API, "
       "at least 70 % of the production slots filled", f"CIP Vol. 1 §3-4.2 (cyclic production at the API); "
       f"{IO_REFERENCE}")
@_on_production
def production(ctx: Context, spec: CheckSpec, plan: Plan, run: Run) -> Outcome:
    ok, observed = judge_production(run, 1.0)
    return outcome(spec, ok, observed, run.exchanges())


@check("class1.sequence", "T->O sequence numbers",
       "the encapsulation sequence number grows by 1 with every packet; the CIP sequence count never goes back",
       "CIP Vol. 2 §3-2.1 (Sequenced Address item); Vol. 1 §3-4.4 (CIP sequence count)")
@_on_production
def sequence(ctx: Context, spec: CheckSpec, plan: Plan, run: Run) -> Outcome:
    problems = []
    for before, after in itertools.pairwise(run.arrivals):
        if (after.encap_sequence - before.encap_sequence) & 0xFFFFFFFF != 1:
            problems.append(f"encapsulation sequence {before.encap_sequence} then {after.encap_sequence}")
        if after.cip_sequence != before.cip_sequence and not seq16_newer(after.cip_sequence, before.cip_sequence):
            problems.append(f"CIP sequence {before.cip_sequence} then {after.cip_sequence}")
    if not run.arrivals:
        problems.append("no T->O packet")
    return outcome(spec, not problems, "; ".join(problems[:3]) or f"{len(run.arrivals)} packets in order",
                   run.exchanges())


@check("class1.data_size", "T->O data size",
       "every T->O packet carries the T->O connection size: the sequence count and the EDS's input size",
       "CIP Vol. 1 §3-5.5.2 (connection size); EDS ConnectionN T->O size")
@_on_production
def data_size(ctx: Context, spec: CheckSpec, plan: Plan, run: Run) -> Outcome:
    sizes = sorted({a.size for a in run.arrivals})
    ok = sizes == [plan.to_data_size]
    return outcome(spec, ok, f"data sizes {sizes}, the connection carries {plan.to_data_size}", run.exchanges())


@check("class1.run_idle", "O->T run, then idle for 0.5 s, then run",
       "idle does not close the connection: T->O production goes on through the idle phase and the "
       "Forward_Close after it succeeds", "CIP Vol. 1 §3-6.1 (32-bit run/idle header); OpENer cipioconnection.c")
def run_idle(ctx: Context, spec: CheckSpec) -> Outcome:
    opened = _open(ctx, spec, multiplier=4)
    if isinstance(opened, Outcome):
        return opened
    plan, endpoint, connection = opened
    if not plan.run_idle:
        connection.close()
        return outcome(spec, Verdict.NOT_APPLICABLE, f"{plan.name} sends no run/idle header")
    run = drive(ctx, plan, endpoint, connection, [(0.3, "run"), (0.5, "idle"), (0.3, "run")])
    closing = connection.close()
    counts = [len(run.in_phase(i)) for i in range(3)]
    due = 0.5 / run.api if run.api > 0 else 0
    ok = counts[1] >= 0.5 * due and counts[2] > 0 and closing.status == 0
    return outcome(spec, ok, f"T->O packets in the run/idle/run phases: {counts}; Forward_Close: "
                   f"{closing.describe()}", run.exchanges())


@check("class1.timeout", "O->T silence longer than the connection timeout",
       "the target stops producing within RPI x 4 x 2^multiplier (plus 0.5 s) after the last O->T packet",
       IO_REFERENCE)
def timeout(ctx: Context, spec: CheckSpec) -> Outcome:
    plan = main_plan(ctx)
    multiplier = 0
    while plan is not None and multiplier < 7 and plan.rpi_us * (4 << multiplier) < 200_000:
        multiplier += 1
    opened = _open(ctx, spec, multiplier=multiplier)
    if isinstance(opened, Outcome):
        return opened
    plan, endpoint, connection = opened
    limit = max(connection.request.ot_rpi_us, connection.reply.ot_api_us) * (4 << multiplier) / 1e6
    run = drive(ctx, plan, endpoint, connection, [(0.4, "run"), (limit + 1.0, "silent")])
    silent = run.in_phase(1)
    stopped_after = (silent[-1].at - run.starts[1]) if silent else 0.0
    connection.close()  # the target should answer 0x0107 now; one that did not time out is closed all the same
    ok = bool(run.in_phase(0)) and stopped_after <= limit + 0.5
    return outcome(spec, ok, f"timeout {limit * 1e3:.0f} ms; production stopped {stopped_after * 1e3:.0f} ms after "
                   f"the last O->T packet ({len(run.in_phase(0))} packets before)", run.exchanges())
