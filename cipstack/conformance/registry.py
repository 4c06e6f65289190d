"""Where checks are declared and what they share while they run: the target, the options, the EDS,
and the connections they opened (closed on every exit path)."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import BadRequest
from .model import Behaviour, CheckSpec, Code, Exchange, Outcome, Verdict
from .wire import Liveness, Probe

if TYPE_CHECKING:
    from ..eds.interpret import EdsView
    from ..eds.model import EdsDocument
    from ..eip.wire.cm_messages import ForwardOpenRequest
    from .connections import Plan

GET_ATTRIBUTE_SINGLE, SET_ATTRIBUTE_SINGLE = 0x0E, 0x10

#: Every check, by id, in declaration order (which is the order they run in).
CHECKS: dict[str, CheckSpec] = {}

CheckFunction = Callable[["Context", CheckSpec], "Outcome | Iterable[Outcome]"]
#: The check functions of each group, in order: (spec, function).
RUNNERS: dict[str, list[tuple[CheckSpec, CheckFunction]]] = {}


def check(id: str, title: str, expected: str, reference: str, codes: Iterable[Code] = (),
          behaviours: Iterable[Behaviour] = (), stress: str = "") -> Callable[[CheckFunction], CheckFunction]:
    """Declare a check and register the function that runs it; ``codes``: every status the
    specification permits as the answer, each with its reference; ``behaviours``: likewise, where
    the check judges what the target does; ``stress``: what the check exhausts on purpose, in words
    ("opens ..."), for a check that may take a device down: it runs only with ``allow_stress``."""
    spec = CheckSpec(id, title, expected, reference, tuple(codes), tuple(behaviours), stress)
    if id in CHECKS:
        raise BadRequest(f"check {id} declared twice")
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
    #: The connections the discovery found (``discovery``) when no EDS was given; None: the EDS's.
    discovered: list[Plan] | None = None
    #: Where the connection points came from, or what was tried, in words ("" with --eds).
    points_source: str = ""
    #: Every Forward_Open the target accepted, in order: the final self-check opens each point again.
    accepted: list[ForwardOpenRequest] = field(default_factory=list)
    #: What the battery could not undo (a Forward_Close refused, a write not restored), in words.
    left_behind: list[str] = field(default_factory=list)
    #: Undo the writes of the run, last first, at its end; each returns a problem in words or None.
    restores: list[Callable[[], str | None]] = field(default_factory=list)
    #: Run the drive profile's motion checks (``motion``): they run the motor.
    allow_motion: bool = False
    #: For a drive: whether it was faulted when the run began (None: not a drive, or not read).
    drive_faulted_at_start: bool | None = None
    #: Run the checks that exhaust the device's resources on purpose (``CheckSpec.stress``).
    allow_stress: bool = False
    #: Whether the target still answers, shared by every probe of the run (None: not asked).
    liveness: Liveness | None = None
    #: CIP Security: the credentials folder (``cipstack security init``) group security uses, and the
    #: target's TLS port (TCP) and DTLS port (UDP), one number as on a device (2221).
    security: Path | None = None
    security_port: int = 2221

    def probe(self, register: bool = True) -> Probe:
        """A new TCP connection (and session) to the target, closed after the check."""
        probe = Probe(self.host, self.port, self.timeout, self.liveness)
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


def restore_later(ctx: Context, path: bytes, original: bytes, what: str) -> None:
    """A write to ``path`` took effect: at the end of the run, write ``original`` back (on a new
    session) and read it again; the final self-check reports what does not come back."""

    def restore() -> str | None:
        probe = ctx.probe()
        reply = probe.request(SET_ATTRIBUTE_SINGLE, path, original)
        if reply.status != 0:
            return f"{what}: writing back {original.hex(' ')} answered {reply.describe()}"
        read = probe.request(GET_ATTRIBUTE_SINGLE, path)
        if read.status != 0 or read.data != original:
            return f"{what}: reads {read.data.hex(' ') or read.describe()} after writing back {original.hex(' ')}"
        return None

    ctx.restores.append(restore)


def outcome(spec: CheckSpec, verdict: Verdict | bool, observed: str, exchanges: Iterable[Exchange] = (),
            subject: str = "") -> Outcome:
    """An outcome; ``verdict`` True/False is pass/fail."""
    if isinstance(verdict, bool):
        verdict = Verdict.PASS if verdict else Verdict.FAIL
    return Outcome(spec, verdict, observed, subject, list(exchanges))
