"""The check model: what a check is, what one run of it found, and the report of a whole battery.

A check is declared once (``CheckSpec``: id, group, title, what the specification expects and
where it says so); running it gives one ``Outcome`` per subject it looked at (most checks have
one subject, the target; the EDS checks have one per ``ParamN``, ``AssemN`` or ``ConnectionN``).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

from ..errors import UnknownKey


class Verdict(str, Enum):
    PASS = "pass"
    FAIL = "fail"
    WARNING = "warning"
    NOT_APPLICABLE = "n/a"
    #: Not run because the option it needs was not given (--allow-writes, --allow-reset,
    #: --allow-motion, --allow-stress), or because the target stopped answering before it: the device
    #: may well have what it checks, unlike a check that does not apply.
    NOT_RUN = "not run"


#: The groups in the order they run and are reported.
GROUPS: dict[str, str] = {
    "encap": "Encapsulation",
    "router": "Message router and errors",
    "objects": "Required objects",
    "cm": "Connection Manager",
    "class1": "Class 1 behaviour",
    "eds": "EDS against the device",
    "profile": "AC drive profile",
    "security": "CIP Security",
    "final": "The device as found",
}
#: The group run after every run, whatever the groups selected: the battery leaves the device as found.
FINAL = "final"


@dataclass(frozen=True)
class Code:
    """A status a check's target may answer with, as the specification permits: its value (general,
    extended or encapsulation status, as the check says), what it means, and where it is written.
    ``verdict`` is PASS, or WARNING for an answer that is allowed but less precise than another."""

    value: int
    meaning: str
    reference: str
    verdict: Verdict = Verdict.PASS

    def __str__(self) -> str:
        width = 4 if self.value > 0xFF else 2
        return f"0x{self.value:0{width}X} ({self.meaning}; {self.reference})"


@dataclass(frozen=True)
class Behaviour:
    """What a check's target may do, as the specification permits, where the check judges behaviour
    rather than a status (the drive profile's motion): a short name the check reports it by, what it
    is, and where it is written."""

    name: str
    meaning: str
    reference: str

    def __str__(self) -> str:
        return f"{self.name}: {self.meaning} ({self.reference})"


@dataclass(frozen=True)
class CheckSpec:
    """One check as declared: ``id`` is ``GROUP.WHAT[.DETAIL]``; ``codes``, every status the
    specification permits as the answer (the check judges by them: one source for both); ``stress``,
    for a check that exhausts a resource of the device on purpose (sessions, connections, a flood),
    what it does in words: such a check runs only with ``allow_stress``."""

    id: str
    title: str
    expected: str
    reference: str
    codes: tuple[Code, ...] = ()
    behaviours: tuple[Behaviour, ...] = ()
    stress: str = ""

    @property
    def group(self) -> str:
        return self.id.split(".", 1)[0]

    def verdict_for(self, value: int | None) -> Verdict:
        """PASS (or WARNING) for a permitted status, FAIL for any other and for none."""
        return next((c.verdict for c in self.codes if c.value == value), Verdict.FAIL)

    def permits(self, name: str) -> Behaviour:
        """The declared behaviour ``name``: a check reports only behaviours it declares (KeyError else)."""
        for behaviour in self.behaviours:
            if behaviour.name == name:
                return behaviour
        raise UnknownKey(f"{self.id} declares no behaviour {name!r}")

    @property
    def permitted(self) -> str:
        """The permitted statuses and behaviours in words, for the reports and the docs."""
        return "; ".join([*(str(c) for c in self.codes), *(str(b) for b in self.behaviours)])


@dataclass
class Exchange:
    """One thing sent and what came back (None: nothing came back)."""

    sent: bytes
    received: bytes | None
    transport: str = "tcp"
    #: A finding is about this exchange (a report shows these rather than the last ones).
    judged: bool = False

    def as_dict(self) -> dict[str, Any]:
        return {"transport": self.transport, "sent": self.sent.hex(),
                "received": None if self.received is None else self.received.hex(), "judged": self.judged}


@dataclass
class Outcome:
    """A check's result on one subject."""

    spec: CheckSpec
    verdict: Verdict
    #: What came back, in words (the bytes are in ``exchanges``).
    observed: str
    subject: str = ""
    exchanges: list[Exchange] = field(default_factory=list)

    @property
    def id(self) -> str:
        return self.spec.id

    @property
    def group(self) -> str:
        return self.spec.group

    def shown_exchanges(self, count: int = 2) -> list[Exchange]:
        """The exchanges a report shows: those a finding is about, else the last ``count``."""
        judged = [e for e in self.exchanges if e.judged]
        return judged[:count] if judged else self.exchanges[-count:]

    @property
    def name(self) -> str:
        """The id, with the subject when the check has several (``eds.param.link[Param3]``)."""
        return f"{self.spec.id}[{self.subject}]" if self.subject else self.spec.id

    def as_dict(self) -> dict[str, Any]:
        return {"id": self.spec.id, "group": self.group, "subject": self.subject or None, "title": self.spec.title,
                "verdict": self.verdict.value, "expected": self.spec.expected, "reference": self.spec.reference,
                "permitted": [{"code": c.value, "meaning": c.meaning, "reference": c.reference,
                               "verdict": c.verdict.value} for c in self.spec.codes],
                "behaviours": [{"name": b.name, "meaning": b.meaning, "reference": b.reference}
                               for b in self.spec.behaviours],
                "stress": self.spec.stress or None,
                "observed": self.observed, "exchanges": [e.as_dict() for e in self.exchanges]}


@dataclass
class Report:
    """Every outcome of one run against one target."""

    target: str
    outcomes: list[Outcome] = field(default_factory=list)
    groups: tuple[str, ...] = tuple(GROUPS)
    identity: dict[str, Any] | None = None
    duration_s: float = 0.0
    options: dict[str, Any] = field(default_factory=dict)
    #: The target stopped answering: ``after`` (the check it went silent in or after, its finding; or
    #: "the search for connection points"), ``reason``, and ``not_run``, how many checks that left out.
    stopped: dict[str, Any] | None = None

    def __iter__(self) -> Iterator[Outcome]:
        return iter(self.outcomes)

    def by_verdict(self, verdict: Verdict) -> list[Outcome]:
        return [o for o in self.outcomes if o.verdict is verdict]

    @property
    def failures(self) -> list[Outcome]:
        return self.by_verdict(Verdict.FAIL)

    @property
    def passed(self) -> bool:
        """Nothing failed (warnings and checks that do not apply are not failures)."""
        return not self.failures

    def counts(self) -> dict[str, int]:
        return {v.value: len(self.by_verdict(v)) for v in Verdict}

    def verdicts(self) -> dict[str, Verdict]:
        """Outcome name -> verdict."""
        return {o.name: o.verdict for o in self.outcomes}

    def as_dict(self) -> dict[str, Any]:
        return {"target": self.target, "identity": self.identity, "groups": list(self.groups),
                "options": self.options, "duration_s": round(self.duration_s, 3), "counts": self.counts(),
                "passed": self.passed, "stopped": self.stopped, "checks": [o.as_dict() for o in self.outcomes]}
