"""Running the battery: ``run(host, ...)`` checks the target group by group and returns a ``Report``."""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

from ..eip.wire.encapsulation import DEFAULT_PORT, Command
from . import class1, connections, eds_checks, encapsulation, objects, router  # noqa: F401 - they declare checks
from .model import GROUPS, Outcome, Report, Verdict
from .registry import CHECKS, RUNNERS, Context, outcome
from .wire import Probe, TargetUnreachable, frame

if TYPE_CHECKING:
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
        raise ValueError(f"unknown group {', '.join(unknown) or '(none given)'} (known: {', '.join(GROUPS)})")
    return tuple(g for g in GROUPS if g in names)


def _load_eds(eds: str | os.PathLike[str] | EdsDocument | None) -> tuple[EdsDocument | None, object]:
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


def _run_check(context: Context, spec: object, function: object) -> list[Outcome]:
    try:
        result = function(context, spec)  # type: ignore[operator]
        return [result] if isinstance(result, Outcome) else list(result)
    except TargetUnreachable as exc:
        return [outcome(spec, Verdict.FAIL, f"the target stopped answering: {exc}")]  # type: ignore[arg-type]
    except Exception as exc:  # a check that cannot finish is a failure of the target's
        return [outcome(spec, Verdict.FAIL, f"the check could not finish: {type(exc).__name__}: {exc}")]  # type: ignore[arg-type]
    finally:
        context.cleanup()


def run(host: str, port: int = DEFAULT_PORT, *, eds: str | os.PathLike[str] | EdsDocument | None = None,
        groups: str | Iterable[str] | None = None, allow_writes: bool = False, allow_reset: bool = False,
        timeout: float = 5.0) -> Report:
    """Run the conformance battery against ``host:port``.

    ``eds``: an EDS file (or a read ``EdsDocument``) of the target, which enables group ``eds`` and
    gives ``cm`` and ``class1`` their connection points. ``groups``: the groups to run (default
    all). Nothing is written without ``allow_writes`` and the device is not reset without
    ``allow_reset``. ``TargetUnreachable`` when the target does not accept a connection and a session.
    """
    selected = parse_groups(groups if groups is None or isinstance(groups, str) else list(groups))
    doc, view = _load_eds(eds)
    context = Context(host, port, timeout, allow_writes, allow_reset, doc, view)  # type: ignore[arg-type]
    started = time.monotonic()
    _preflight(context)
    report = Report(f"{host}:{port}", groups=selected, identity=context.identity,
                    options={"eds": os.fspath(eds) if isinstance(eds, (str, os.PathLike)) else None,
                             "allow_writes": allow_writes, "allow_reset": allow_reset, "timeout": timeout})
    try:
        for group in selected:
            for spec, function in RUNNERS.get(group, []):
                report.outcomes.extend(_run_check(context, spec, function))
    finally:
        context.cleanup()
    report.duration_s = time.monotonic() - started
    return report
