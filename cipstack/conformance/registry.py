"""Where checks are declared and what they share while they run: the target, the options, the EDS,
and the connections they opened (closed on every exit path)."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from .model import CheckSpec, Exchange, Outcome, Verdict
from .wire import Probe

if TYPE_CHECKING:
    from ..eds.interpret import EdsView
    from ..eds.model import EdsDocument

#: Every check, by id, in declaration order (which is the order they run in).
CHECKS: dict[str, CheckSpec] = {}

CheckFunction = Callable[["Context", CheckSpec], "Outcome | Iterable[Outcome]"]
#: The check functions of each group, in order: (spec, function).
RUNNERS: dict[str, list[tuple[CheckSpec, CheckFunction]]] = {}


def check(id: str, title: str, expected: str, reference: str) -> Callable[[CheckFunction], CheckFunction]:
    """Declare a check and register the function that runs it."""
    spec = CheckSpec(id, title, expected, reference)
    if id in CHECKS:
        raise ValueError(f"check {id} declared twice")
    CHECKS[id] = spec

    def register(function: CheckFunction) -> CheckFunction:
        RUNNERS.setdefault(spec.group, []).append((spec, function))
        return function

    return register


@dataclass
class Context:
    """What the checks of one run share."""

    host: str
    port: int
    timeout: float = 5.0
    allow_writes: bool = False
    allow_reset: bool = False
    eds: EdsDocument | None = None
    view: EdsView | None = None
    #: Identity as the target reports it (ListIdentity over TCP), for the checks that compare.
    identity: dict[str, Any] | None = None
    #: Probes opened by checks, closed at the end of each check whatever happens.
    probes: list[Probe] = field(default_factory=list)
    #: Forward_Close requests to send for connections still open (``cm`` and ``class1`` register them).
    pending_closes: list[Callable[[], object]] = field(default_factory=list)  # what a close returns is unused
    #: What one check measured that the next ones judge too (one class 1 run serves three checks).
    cache: dict[str, Any] = field(default_factory=dict)

    def probe(self, register: bool = True) -> Probe:
        """A new TCP connection (and session) to the target, closed after the check."""
        probe = Probe(self.host, self.port, self.timeout)
        self.probes.append(probe)
        if register:
            probe.register()
        return probe

    def cleanup(self) -> None:
        """Close what the last check left open: connections first, then its TCP connections."""
        while self.pending_closes:
            close = self.pending_closes.pop()
            with contextlib.suppress(Exception):  # a close that fails must not stop the others
                close()
        while self.probes:
            self.probes.pop().close()


def outcome(spec: CheckSpec, verdict: Verdict | bool, observed: str, exchanges: Iterable[Exchange] = (),
            subject: str = "") -> Outcome:
    """An outcome; ``verdict`` True/False is pass/fail."""
    if isinstance(verdict, bool):
        verdict = Verdict.PASS if verdict else Verdict.FAIL
    return Outcome(spec, verdict, observed, subject, list(exchanges))
