"""A live class 1 connection driven by the battery: O->T sent at the granted API, every T->O datagram
of the connection recorded with its arrival time; and the judgement of its production, which the
class 1 checks and the RPI check of the Connection Manager share."""

from __future__ import annotations

import itertools
import select
import statistics
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..eip.io_core import IoDatagramError, decode_io_datagram, encode_io_datagram
from .model import Exchange

if TYPE_CHECKING:
    from .connections import Endpoint, Opened, Plan
    from .registry import Context


@dataclass
class Arrival:
    at: float
    phase: int
    encap_sequence: int
    cip_sequence: int
    size: int


@dataclass
class Run:
    """One class 1 connection driven through phases of (seconds, "run" | "idle" | "silent")."""

    opened: Opened
    phases: list[tuple[float, str]]
    starts: list[float] = field(default_factory=list)
    arrivals: list[Arrival] = field(default_factory=list)
    foreign: int = 0
    first_datagram: bytes | None = None
    sent_example: bytes | None = None

    @property
    def api(self) -> float:
        return self.opened.reply.to_api_us / 1e6

    def in_phase(self, index: int) -> list[Arrival]:
        return [a for a in self.arrivals if a.phase == index]

    def exchanges(self) -> list[Exchange]:
        """The TCP exchanges of the connection, and a class 1 datagram sent with the first received."""
        return [*self.opened.probe.exchanges, Exchange(self.sent_example or b"", self.first_datagram, "udp")]


def drive(ctx: Context, plan: Plan, endpoint: Endpoint, opened: Opened, phases: list[tuple[float, str]]) -> Run:
    """Send O->T at the granted O->T API in the run and idle phases (nothing in silent ones) and record
    every T->O datagram of the connection."""
    run = Run(opened, phases)
    ot_api = max(opened.reply.ot_api_us, 1000) / 1e6
    header = 4 if plan.run_idle else 0
    data = bytes(max(0, plan.ot_size - 2 - header))
    destination = (ctx.host, opened.io_port)
    sequence = 0
    sock = endpoint.sock
    for index, (duration, mode) in enumerate(phases):
        start = time.monotonic()
        run.starts.append(start)
        end, due = start + duration, start
        while True:
            now = time.monotonic()
            if now >= end:
                break
            if mode != "silent" and now >= due:
                sequence += 1
                run_idle = (1 if mode == "run" else 0) if plan.run_idle else None
                datagram = encode_io_datagram(opened.reply.ot_connection_id, sequence, sequence, data, run_idle)
                run.sent_example = run.sent_example or datagram
                sock.sendto(datagram, destination)
                due += ot_api
                if due < now:
                    due = now + ot_api
            wait = min(end, due if mode != "silent" else end) - time.monotonic()
            ready, _, _ = select.select([sock], [], [], max(0.0, wait))
            if ready:
                raw = sock.recv(65536)
                at = time.monotonic()
                try:
                    datagram_in = decode_io_datagram(raw)
                except IoDatagramError:
                    run.foreign += 1
                    continue
                if datagram_in.connection_id != opened.reply.to_connection_id:
                    run.foreign += 1
                    continue
                run.first_datagram = run.first_datagram or raw
                run.arrivals.append(Arrival(at, index, datagram_in.encap_sequence, datagram_in.cip_sequence,
                                            len(datagram_in.payload)))
    return run


def judge_production(run: Run, seconds: float) -> tuple[bool, str]:
    """Whether T->O came at the granted API over ``seconds`` of running: a mean interval within
    0.8-1.25 x API and at least 70 % of the production slots filled; and what was seen, in words."""
    arrivals = run.arrivals
    expected = seconds / run.api if run.api > 0 else 0
    if len(arrivals) < 2:
        return False, f"{len(arrivals)} T->O packets in {seconds:g} s at an API of {_interval(run.api)}"
    intervals = [b.at - a.at for a, b in itertools.pairwise(arrivals)]
    mean = statistics.fmean(intervals)
    ok = 0.8 * run.api <= mean <= 1.25 * run.api and len(arrivals) >= 0.7 * expected
    return ok, (f"{len(arrivals)} packets (about {expected:.0f} due), mean interval {mean * 1e3:.2f} ms, "
                f"max {max(intervals) * 1e3:.2f} ms, API {_interval(run.api)}")


def _interval(seconds: float) -> str:
    return f"{seconds * 1e3:.2f} ms" if seconds >= 1e-3 else f"{seconds * 1e6:.0f} us"
