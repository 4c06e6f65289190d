"""How loaded a fleet worker is, as its parent learns it with each heartbeat.

A worker's event loop carries its devices' class 1 productions; when they are more than its core can
carry, productions go late and slots are skipped (``ProductionSchedule``), and the loop turns later.
That is overload, not a failure: the devices go on serving. So the answer to the parent's ping comes
from a thread of its own (``answer_pings``), which a busy loop does not hold up, and it carries what
the loop last sampled (``LoadSampler``): the sums of the worker's productions and how late the loop ran
the sampling. The parent tells a dead worker (its process gone, or no answer at all for long: stopped,
or stuck in code that holds the interpreter) from a late one by those two things alone (``LoadWatch``).
"""

from __future__ import annotations

import asyncio
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Protocol

#: How often a worker's loop sums its devices' productions, and how many devices it reads between two
#: returns to the loop (a slice holds it tens of microseconds, well inside a production's tolerance).
SAMPLE_INTERVAL = 1.0
DEVICES_PER_SLICE = 64
#: A loop that has not run its sampling for this long is stuck, not late: the parent stops the worker.
LOOP_STUCK_TIMEOUT = 30.0
#: A worker is late when its loop ran the sampling this much after it was due, or when this share of
#: its production slots since the last answer were skipped.
LATE_LAG = 0.25
LATE_SHARE = 0.01
#: Answers in a row without lateness before a late worker counts as on time again.
ON_TIME_ANSWERS = 5
PING, PONG = "ping", "pong"

log = logging.getLogger("cipstack.fleet.workers")


class ProducingDevice(Protocol):
    def productions(self) -> tuple[int, int, int]:
        """(sent, late, missed) since the device started."""
        ...  # pragma: no cover - a protocol


@dataclass(frozen=True)
class LoadReport:
    """A worker's load as one heartbeat answer carries it."""

    #: Seconds since the worker's loop last finished a sampling (when the answer left).
    loop_age: float = 0.0
    #: How much later than due the loop began that sampling.
    lag: float = 0.0
    #: Its devices' class 1 productions since they started: sent, later than their tolerance, and
    #: slots skipped.
    sent: int = 0
    late: int = 0
    missed: int = 0

    def as_tuple(self) -> tuple[float, float, int, int, int]:
        return self.loop_age, self.lag, self.sent, self.late, self.missed


class LoadSampler:
    """In a worker: the sums of its devices' productions, sampled on its loop every ``SAMPLE_INTERVAL``,
    and read by the thread that answers the parent (``report``)."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        #: (finished at, lag, sent, late, missed): replaced whole, so the other thread reads one sampling.
        self._latest: tuple[float, float, int, int, int] = (clock(), 0.0, 0, 0, 0)

    async def run(self, devices: Sequence[ProducingDevice]) -> None:
        """Sample until cancelled."""
        self._latest = (self.clock(), 0.0, 0, 0, 0)   # the loop runs from now: the start-up is not its age
        while True:
            due = self.clock() + SAMPLE_INTERVAL
            await asyncio.sleep(SAMPLE_INTERVAL)
            lag = max(0.0, self.clock() - due)
            sent = late = missed = 0
            for index, device in enumerate(devices, start=1):
                s, lt, m = device.productions()
                sent, late, missed = sent + s, late + lt, missed + m
                if index % DEVICES_PER_SLICE == 0:
                    await asyncio.sleep(0)
            self._latest = (self.clock(), lag, sent, late, missed)

    def report(self) -> LoadReport:
        finished, lag, sent, late, missed = self._latest
        return LoadReport(max(0.0, self.clock() - finished), lag, sent, late, missed)


def answer_pings(channel: Connection, report: Callable[[], LoadReport], lock: threading.Lock) -> threading.Thread:
    """Answer each ping on ``channel`` with ``(PONG, report())`` from a thread of its own, until the
    channel ends (the parent is gone); ``lock`` is held for each answer, as for any other message the
    worker sends on the channel."""
    def run() -> None:
        while True:
            try:
                message = channel.recv()
            except (EOFError, OSError):
                return
            if message == PING:
                try:
                    with lock:
                        channel.send((PONG, report().as_tuple()))
                except OSError:
                    return

    thread = threading.Thread(target=run, name="cipstack fleet heartbeat", daemon=True)
    thread.start()
    return thread


class LoadWatch:
    """In the parent: one worker's load from its answers, and whether it is late."""

    def __init__(self) -> None:
        #: The last answer (None before the first).
        self.report: LoadReport | None = None
        #: While late: since when (monotonic).
        self.late_since: float | None = None
        #: Productions sent, late and missed between the last two answers.
        self.recent: tuple[int, int, int] = (0, 0, 0)
        self._on_time_answers = 0

    @property
    def late(self) -> bool:
        return self.late_since is not None

    @property
    def stuck(self) -> bool:
        """Its loop has not sampled for ``LOOP_STUCK_TIMEOUT``: it serves no more, though it answers."""
        return self.report is not None and self.report.loop_age > LOOP_STUCK_TIMEOUT

    def answered(self, report: LoadReport, now: float) -> str | None:
        """Take an answer; returns "late" or "on time" when the worker has just become so, else None."""
        before = self.report or LoadReport()
        self.report = report
        sent, late, missed = report.sent - before.sent, report.late - before.late, report.missed - before.missed
        self.recent = (sent, late, missed)
        # Skipped slots, not productions past their tolerance, say that a worker cannot keep up: the
        # tolerance is half a millisecond at most, which a busy machine's scheduler alone exceeds.
        # A sampling older than its interval is news too: a loop too busy to sample is behind.
        behind = (max(report.lag, report.loop_age - SAMPLE_INTERVAL) > LATE_LAG
                  or missed > LATE_SHARE * (sent + missed))
        if behind:
            self._on_time_answers = 0
            if self.late_since is None:
                self.late_since = now
                return "late"
            return None
        self._on_time_answers += 1
        if self.late_since is not None and self._on_time_answers >= ON_TIME_ANSWERS:
            self.late_since = None
            return "on time"
        return None

    def describe(self) -> str:
        """What a log line says of the lateness: the shares of the last answer's productions and the lag."""
        report = self.report or LoadReport()
        sent, late, missed = self.recent
        due = sent + missed
        share = (f"{missed} of {due} production slots missed ({100 * missed / due:.1f} %) and {late} late"
                 if due else "no production")
        behind = max(report.lag, report.loop_age - SAMPLE_INTERVAL, 0.0)
        return (f"{share} since the last answer, its loop {behind * 1000:.0f} ms behind "
                f"(in all: {report.missed} missed, {report.late} late of {report.sent + report.missed})")


def report_lateness(name: str, watch: LoadWatch, change: str | None) -> None:
    """One line when a worker goes late and one when it is on time again: an overloaded worker serves on."""
    if change == "late":
        log.warning("%s is late: %s; it goes on serving (fewer devices per worker, or a longer RPI, would "
                    "keep it on time)", name, watch.describe())
    elif change == "on time":
        log.warning("%s is on time again: %s", name, watch.describe())


def gauge_values(watch: LoadWatch) -> dict[str, float] | None:
    """What ``/metrics`` says of a worker's load (``WorkerGauges``), once it has been judged."""
    report = watch.report
    if report is None:
        return None
    return {"late": 1.0 if watch.late else 0.0, "lag": report.lag, "sent": report.sent,
            "late_productions": report.late, "missed": report.missed}


async def watch_own_load(name: str, sampler: LoadSampler, watch: LoadWatch, interval: float = SAMPLE_INTERVAL) -> None:
    """A fleet of one process judges its own load as a parent judges a worker's, until cancelled."""
    while True:
        await asyncio.sleep(interval)
        report_lateness(name, watch, watch.answered(sampler.report(), time.monotonic()))


__all__ = ["LOOP_STUCK_TIMEOUT", "PING", "PONG", "LoadReport", "LoadSampler", "LoadWatch", "answer_pings",
           "gauge_values", "report_lateness", "watch_own_load"]
