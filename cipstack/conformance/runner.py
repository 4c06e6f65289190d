"""Running the battery: ``run(host, ...)`` checks the target group by group and returns a ``Report``."""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from ..eip.wire.encapsulation import DEFAULT_PORT, SECURE_PORT, Command
from ..errors import BadRequest
from . import (  # noqa: F401 - they declare checks
    as_found,
    class1,
    connections,
    eds_checks,
    encapsulation,
    more_wire,
    motion,
    objects,
    profile,
    router,
)
from . import security as security_checks  # noqa: F401 - it declares checks
from . import security_dtls as security_dtls_checks  # noqa: F401 - it declares checks
from . import security_psk as security_psk_checks  # noqa: F401 - it declares checks
from .discovery import DRIVE_DEVICE_TYPES
from .model import FINAL, GROUPS, CheckSpec, Outcome, Report, Verdict
from .profile import faulted
from .registry import CHECKS, RUNNERS, CheckFunction, Context, outcome
from .wire import Liveness, Probe, TargetUnreachable, frame

if TYPE_CHECKING:
    from ..eds.interpret import EdsView
    from ..eds.model import EdsDocument


def check_ids() -> list[str]:
    """Every check the battery has, in the order it runs them."""
    return list(CHECKS)


def parse_groups(text: str | Sequence[str] | None) -> tuple[str, ...]:
    """``encap,router`` (or a list) -> the groups in run order; ``ValueError`` names an unknown one."""
    if text is None:
        return tuple(GROUPS)
    names = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()]
    unknown = [n for n in names if n not in GROUPS]
    if unknown or not names:
        raise BadRequest(f"unknown group {', '.join(unknown) or '(none given)'} (known: {', '.join(GROUPS)})")
    return tuple(g for g in GROUPS if g in names)


def _load_eds(eds: str | os.PathLike[str] | EdsDocument | None) -> tuple[EdsDocument | None, EdsView | None]:
    if eds is None:
        return None, None
    from ..eds.interpret import read_view
    from ..eds.model import EdsDocument
    from ..eds.reader import read_eds

    doc = eds if isinstance(eds, EdsDocument) else read_eds(eds)
    return doc, read_view(doc)


def _preflight(context: Context) -> None:
    """The target must accept a TCP connection and a session, or the run stops with ``TargetUnreachable``."""
    with Probe(context.host, context.port, context.timeout) as probe:
        probe.register()
        try:
            reply = probe.exchange(frame(Command.LIST_IDENTITY))
        except ConnectionError:
            reply = None
    if reply is not None and reply.header.status == 0:
        _, record = encapsulation._identity_problems(reply.body, None)
        context.identity = record


#: The groups that need connection points (or an EDS) to run.
NEED_POINTS = {"cm", "class1", "eds"}
#: What ``Report.stopped`` names when the target went silent before any check, while the battery
#: looked for its connection points.
DISCOVERY = "the search for connection points"


def _discover(context: Context, report: Report, points: tuple[int, int, int] | None,
              eds_dir: str | os.PathLike[str] | None) -> None:
    """Find the connection points without an EDS and say where they came from (``discovery``)."""
    from ..eds.interpret import read_view
    from .discovery import discover

    try:
        found = discover(context, points, eds_dir)
    finally:
        context.cleanup()
    context.discovered = found.plans
    context.points_source = found.source if found.plans else "tried: " + "; ".join(found.tried)
    report.options["connection_points"] = context.points_source
    if found.eds is not None:
        context.eds, context.view = found.eds, read_view(found.eds)
        report.options["eds"] = found.eds_source


def _run_check(context: Context, liveness: Liveness, spec: CheckSpec, function: CheckFunction) -> list[Outcome]:
    if spec.stress and not context.allow_stress:
        # Declared once on the check: it exhausts what the device has (sessions, connections), and a
        # default run leaves the device as found.
        return [outcome(spec, Verdict.NOT_RUN, f"needs --allow-stress (this check {spec.stress})")]
    try:
        # A stress check makes the target refuse on purpose: whether it is still there is asked after.
        with liveness.hold() if spec.stress else contextlib.nullcontext():
            result = function(context, spec)
            outcomes = [result] if isinstance(result, Outcome) else list(result)
    except TargetUnreachable as exc:
        outcomes = [outcome(spec, Verdict.FAIL, f"a connection to the target failed: {exc}")]
    except Exception as exc:  # a check that cannot finish is a failure of the target's
        outcomes = [outcome(spec, Verdict.FAIL, f"the check could not finish: {type(exc).__name__}: {exc}")]
    finally:
        context.cleanup()
    if all(o.verdict is Verdict.NOT_RUN for o in outcomes) or not liveness.confirm():
        return outcomes
    # The target went silent in this check or right after it: that is the finding, and the check's own
    # verdicts (every request after it unanswered) are not.
    seen = next((o.observed for o in outcomes if o.verdict is not Verdict.PASS), outcomes[-1].observed if outcomes
                else "")
    return [outcome(spec, Verdict.FAIL, f"the target stopped answering after this check: {liveness.silent}"
                    + (f"; the check saw: {seen}" if seen else ""), [e for o in outcomes for e in o.exchanges])]


def run(host: str, port: int = DEFAULT_PORT, *, eds: str | os.PathLike[str] | EdsDocument | None = None,
        groups: str | Iterable[str] | None = None, allow_writes: bool = False, allow_reset: bool = False,
        timeout: float = 5.0, connection_points: tuple[int, int, int] | None = None,
        eds_dir: str | os.PathLike[str] | None = None, allow_motion: bool = False,
        allow_stress: bool = False, security: str | os.PathLike[str] | None = None,
        security_port: int = SECURE_PORT) -> Report:
    """Run the conformance battery against ``host:port``.

    ``eds``: an EDS file (or a read ``EdsDocument``) of the target, which enables group ``eds`` and
    gives ``cm`` and ``class1`` their connection points. Without one the battery finds the points
    itself (``discovery``): ``connection_points`` (output, input, configuration) names them, else
    the device's own EDS (File object), an EDS of ``eds_dir`` for its identity, the AC drive profile,
    bounded probing of its assemblies. ``groups``: the groups to run (default all). Nothing is
    written without ``allow_writes`` and the device is not reset without ``allow_reset``; the drive
    profile's motion checks (``motion``) run the motor only with ``allow_motion``, and the checks that
    exhaust the device's resources on purpose (``CheckSpec.stress``: 40 sessions at once) only with
    ``allow_stress``. ``security``: a CIP Security credentials folder (``cipstack security init``),
    which enables group ``security`` against the TLS and DTLS ports ``security_port``; without it that group's
    checks are not run. A target that stops answering stops the run: the
    check after which it went silent fails with that finding, every later one is not run
    (``Report.stopped`` says where and why). ``TargetUnreachable`` when the target does not accept a
    connection and a session.
    """
    selected = parse_groups(groups if groups is None or isinstance(groups, str) else list(groups))
    doc, view = _load_eds(eds)
    context = Context(host, port, timeout, allow_writes, allow_reset, doc, view, allow_motion=allow_motion,
                      allow_stress=allow_stress, security=None if security is None else Path(security),
                      security_port=security_port)
    started = time.monotonic()
    _preflight(context)
    liveness = context.liveness = Liveness(host, port, timeout)
    if (context.identity or {}).get("device_type") in DRIVE_DEVICE_TYPES:
        # A drive: whether it is faulted now, so that a fault the run causes is told from one it had.
        with Probe(host, port, timeout) as probe:
            probe.register()
            context.drive_faulted_at_start = faulted(probe)
    report = Report(f"{host}:{port}", groups=selected, identity=context.identity,
                    options={"eds": os.fspath(eds) if isinstance(eds, (str, os.PathLike)) else None,
                             "allow_writes": allow_writes, "allow_reset": allow_reset, "allow_motion": allow_motion,
                             "allow_stress": allow_stress, "timeout": timeout,
                             "security": None if security is None else os.fspath(security)})
    if doc is not None:
        report.options["connection_points"] = "the EDS given (--eds)"
    elif set(selected) & NEED_POINTS:
        try:
            _discover(context, report, connection_points, eds_dir)
        except TargetUnreachable:
            if not liveness.confirm():
                raise
        if liveness.silent:
            report.stopped = {"after": DISCOVERY, "reason": liveness.silent}
    left_out = 0

    def run_one(spec: CheckSpec, function: CheckFunction) -> None:
        """Run one check, or, once the target stopped answering, say why it does not run."""
        nonlocal left_out
        if report.stopped is not None:
            left_out += 1
            report.outcomes.append(outcome(spec, Verdict.NOT_RUN,
                                           f"the target stopped answering after {report.stopped['after']}"))
            return
        report.outcomes.extend(_run_check(context, liveness, spec, function))
        if liveness.silent:
            report.stopped = {"after": spec.id, "reason": liveness.silent}

    try:
        for group in selected:
            if group == FINAL:
                continue
            for spec, function in RUNNERS.get(group, []):
                run_one(spec, function)
    finally:
        context.cleanup()
        # Whatever happened: the device as found (every point used opens again, every write restored),
        # checked whenever the run opened or wrote anything, whatever the groups selected.
        if FINAL in selected or context.accepted or context.restores or context.left_behind:
            for spec, function in RUNNERS[FINAL]:
                run_one(spec, function)
    if report.stopped is not None:
        report.stopped["not_run"] = left_out
    report.duration_s = time.monotonic() - started
    return report
