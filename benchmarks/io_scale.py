"""Class 1 at scale: how many packets per second one adapter process sustains, each way, and where it stops.

Starts the adapter emulator (default profile, ``--max-io-connections 1024``) as a subprocess on free
loopback ports, then for each step of a ladder (RPI, connections) opens that many input-only
connections (heartbeat 198 -> input 71, timeout multiplier 3 as ``io.py`` (a) uses at 1 ms) from
``--originators`` scanner processes (cipstack's ``Scanner`` on the precise event loop, the
connections split evenly; with two CPUs or more the adapter runs on one and the scanners on
another, ``--no-pin`` to let the scheduler place them) and measures ``--seconds``:

* T->O: packets received per second, late packets (an interval above 1.5 RPI: more than half an RPI
  after the packet was due), lost packets (gaps in the sequence), connections timed out. Packets
  are timed by the kernel as they reach the originator's socket (``kernel_arrival_times``; on
  loopback, the moment the adapter sent them), as a capture would show them: the lateness is the
  adapter's, not that of originator processes waiting for a core the adapter and they share;
* O->T: packets sent per second by the originators and their skipped slots;
* the adapter's CPU share (user + system) and the originators' (their sum), so that a step that
  fails is seen to fail in the adapter or in the scanners that load it, and the adapter's CPU per
  packet each way (one T->O sent, one O->T received): on a machine others load, the rates fail for
  want of a core while the cost per packet still says what one core would carry.

A step holds when nothing timed out and nothing was lost, under 1 % of T->O packets are late and
both directions carry at least 99 % of the packets their RPI asks for. The first step that does not
hold is the break point of that RPI; the steps after it are not run.

    python benchmarks/io_scale.py [--seconds N] [--originators P] [--ladder 10ms:128,256,384,512] [--no-pin] [--json]

Issue 16's targets: 512 connections at 10 ms and 64 at 1 ms hold (51,200 and 64,000 packets/s each
way): one process sustains >= 60,000 packets/s each way.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from io_common import (
    Verdict,
    acg_class1,
    core_pair,
    cpu_seconds,
    free_port,
    machine_busy,
    pin_to_cpu,
    start_adapter,
    stop_adapter,
)

INPUT = 71
INPUT_ONLY_POINT = acg_class1().input_only_point
DEFAULT_LADDER = ("10ms:128,256,384,512", "1ms:16,32,48,64")
#: Issue 16: one process sustains this many packets per second each way (512 at 10 ms, 64 at 1 ms).
PACKETS_TARGET = 60_000
TARGET_STEPS = ((0.010, 512), (0.001, 64))
LATE_LIMIT_PCT = 1.0
RATE_SHARE = 0.99


# -- the originator processes ------------------------------------------------------------------------------
async def originate(port: int, io_port: int, rpi: float, connections: int, seconds: float, settle: float
                    ) -> dict[str, Any]:
    import gc

    from cipstack.scanner import Scanner

    async with await Scanner.connect(f"127.0.0.1:{port}", timeout=20) as scanner:
        contexts = [scanner.io_connection(input=INPUT, heartbeat=INPUT_ONLY_POINT, rpi=rpi, input_size=4,
                                          target_io_port=io_port, keep_intervals=True, timeout_multiplier=3,
                                          kernel_arrival_times=True)
                    for _ in range(connections)]
        handles = []
        try:
            for context in contexts:
                handles.append(await context.__aenter__())
            gc.collect()
            gc.freeze()
            await asyncio.sleep(settle)
            for handle in handles:
                handle.connection.interval_samples.clear()
                handle.connection.send_times.clear()
            before = [(h.stats.received, h.stats.lost, h.stats.sent, h.stats.skipped_slots) for h in handles]
            print("measuring", flush=True)
            cpu_before, wall_before = time.process_time(), time.monotonic()
            await asyncio.sleep(seconds)
            cpu, wall = time.process_time() - cpu_before, time.monotonic() - wall_before
            print("measured", flush=True)  # the adapter's window ends here: not the teardown's Forward_Closes
            after = [(h.stats.received, h.stats.lost, h.stats.sent, h.stats.skipped_slots) for h in handles]
            kept = [len(h.connection.interval_samples) for h in handles]
            timeouts = sum(1 for h in handles if h.timed_out)
        finally:
            for context in reversed(contexts[:len(handles)]):
                await context.__aexit__(None, None, None)
    # Counted once the connections are closed: a scan of every interval (320,000 in 5 s of 64 at 1 ms)
    # would hold the loop up while they still run, long enough for their watchdogs.
    late = sum(1 for h, n in zip(handles, kept, strict=True) for i in h.connection.interval_samples[:n]
               if i > 1.5 * rpi)
    delta = [sum(a[k] - b[k] for a, b in zip(after, before, strict=True)) for k in range(4)]
    return {"opened": len(handles), "wall": wall, "cpu": cpu, "received": delta[0], "lost": delta[1],
            "sent": delta[2], "skipped": delta[3], "late": late, "timeouts": timeouts}


def originator_main(args: argparse.Namespace) -> int:
    from cipstack.eip.io_server import run_precise

    result = run_precise(originate(args.port, args.io_port, args.rpi, args.connections, args.seconds, args.settle))
    print(json.dumps(result), flush=True)
    return 0


# -- the ladder ----------------------------------------------------------------------------------------------
@dataclass
class Step:
    rpi_ms: float
    connections: int
    seconds: float
    t_to_o_per_s: float
    o_to_t_per_s: float
    expected_per_s: float
    late_pct: float
    lost: int
    timeouts: int
    skipped: int
    adapter_cpu: float
    originators_cpu: float
    holds: bool
    #: The adapter's CPU (user + system) per packet each way: one T->O sent and one O->T received.
    adapter_us_per_packet: float = 0.0

    @property
    def core_capacity(self) -> int:
        """Packets per second each way one whole core would carry at this cost (a projection)."""
        return round(1e6 / self.adapter_us_per_packet) if self.adapter_us_per_packet else 0

    originators: int = 1
    #: Share of the whole machine's CPU time that was busy during the step (every process, every core).
    machine_busy: float = 0.0
    #: The adapter ran on a CPU of its own and the originators together on another (``core_pair``).
    pinned: bool = False

    @property
    def limited_by(self) -> str:
        """Which side ran out of CPU, when a step fails: a process near a whole core is saturated; a
        machine busy nearly all the time had no core to give either; else the time went to latency."""
        if self.holds:
            return "-"
        if self.adapter_cpu >= 0.9:
            return "adapter"
        if self.originators_cpu >= 0.9 * (1 if self.pinned else self.originators):
            return "originators"
        if self.machine_busy >= 0.9:
            return f"the machine ({self.machine_busy:.0%} busy, its other load included)"
        return "no process saturated: wake-up latency"


def run_step(port: int, io_port: int, adapter_pid: int, rpi: float, connections: int, seconds: float,
             originators: int, settle: float, originator_cpu: int | None = None) -> Step:
    shares = [connections // originators + (1 if i < connections % originators else 0) for i in range(originators)]
    processes = [subprocess.Popen([sys.executable, os.path.abspath(__file__), "--originate", "--port", str(port),
                                   "--io-port", str(io_port), "--rpi", str(rpi), "--connections", str(share),
                                   "--seconds", str(seconds), "--settle", str(settle)],
                                  stdout=subprocess.PIPE, text=True) for share in shares if share]
    try:
        for process in processes:
            pin_to_cpu(process.pid, originator_cpu)
        for process in processes:  # every originator has opened and settled
            assert process.stdout is not None
            line = process.stdout.readline()
            if line.strip() != "measuring":
                raise RuntimeError(f"an originator failed before measuring: {line!r}")
        user, system = cpu_seconds(adapter_pid)
        busy, total = machine_busy()
        wall_before = time.monotonic()
        for process in processes:  # every originator's window is over
            assert process.stdout is not None
            line = process.stdout.readline()
            if line.strip() != "measured":
                raise RuntimeError(f"an originator failed while measuring: {line!r}")
        wall = time.monotonic() - wall_before
        user2, system2 = cpu_seconds(adapter_pid)
        busy2, total2 = machine_busy()
        results = []
        for process in processes:
            assert process.stdout is not None
            # The same buffered reader as the lines before: what it has read ahead is not lost (a
            # ``communicate`` with a timeout reads the pipe itself, and missed a result already read ahead).
            results.append(json.loads(process.stdout.readline()))
            process.wait(timeout=120)
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
                process.wait()
    # Each originator's window is ``seconds`` long; the adapter's spans them all (from the last one's
    # start to the last one's end: a little longer), and not their teardown.
    measured = sum(r["wall"] for r in results) / len(results)
    received, sent = sum(r["received"] for r in results), sum(r["sent"] for r in results)
    late, lost = sum(r["late"] for r in results), sum(r["lost"] for r in results)
    timeouts, skipped = sum(r["timeouts"] for r in results), sum(r["skipped"] for r in results)
    expected = connections / rpi
    late_pct = 100.0 * late / received if received else 100.0
    holds = (timeouts == 0 and lost == 0 and late_pct < LATE_LIMIT_PCT and received / measured >= RATE_SHARE * expected
             and sent / measured >= RATE_SHARE * expected)
    adapter_cpu = user2 - user + system2 - system
    pairs = (received + sent) / 2 * wall / measured
    return Step(rpi * 1e3, connections, round(measured, 2), round(received / measured), round(sent / measured),
                round(expected), round(late_pct, 3), lost, timeouts, skipped, round(adapter_cpu / wall, 3),
                round(sum(r["cpu"] for r in results) / measured, 3), holds,
                round(adapter_cpu / pairs * 1e6, 1) if pairs else 0.0, len(processes),
                round((busy2 - busy) / (total2 - total), 3) if total2 > total else 0.0, originator_cpu is not None)


def parse_ladder(text: str) -> tuple[float, list[int]]:
    rpi, _, counts = text.partition(":")
    scale = 1e-3 if rpi.endswith("ms") else 1e-6 if rpi.endswith("us") else 1.0
    return float(rpi.rstrip("msu")) * scale, [int(c) for c in counts.split(",")]


def run_ladder(ladders: Sequence[str], seconds: float, originators: int, settle: float = 1.0,
               every_step: bool = False, pin: bool = True) -> list[Step]:
    port, io_port = free_port(), free_port()
    cores = core_pair() if pin else None
    adapter_cpu, originator_cpu = cores if cores is not None else (None, None)
    adapter = start_adapter(port, io_port, "--max-io-connections", "1024", cpu=adapter_cpu)
    steps: list[Step] = []
    try:
        for ladder in ladders:
            rpi, counts = parse_ladder(ladder)
            for count in counts:
                step = run_step(port, io_port, adapter.pid, rpi, count, seconds, originators, settle, originator_cpu)
                steps.append(step)
                if not step.holds and not every_step:
                    break
    finally:
        stop_adapter(adapter)
    return steps


def verdicts(steps: Sequence[Step]) -> list[Verdict]:
    found = []
    for rpi, count in TARGET_STEPS:
        step = next((s for s in steps if s.rpi_ms == rpi * 1e3 and s.connections == count), None)
        held = [s for s in steps if s.rpi_ms == rpi * 1e3 and s.holds]
        broke = next((s for s in steps if s.rpi_ms == rpi * 1e3 and not s.holds), None)
        where = (f"holds up to {max(s.connections for s in held)} connections" if held else "holds no step")
        if broke is not None:
            where += (f", breaks at {broke.connections} ({broke.t_to_o_per_s:,} of {broke.expected_per_s:,}/s, "
                      f"{broke.late_pct} % late, {broke.lost} lost, {broke.timeouts} timeouts; "
                      f"adapter {broke.adapter_cpu} core, originators {broke.originators_cpu}: "
                      f"limited by: {broke.limited_by})")
        measured = None if step is None else float(min(step.t_to_o_per_s, step.o_to_t_per_s))
        found.append(Verdict(f"class 1, {count} connections at {rpi * 1e3:g} ms, packets/s each way",
                             measured, count / rpi, "/s", higher_is_better=True,
                             passed=step is not None and step.holds, note=where))
    best = max((min(s.t_to_o_per_s, s.o_to_t_per_s) for s in steps if s.holds), default=None)
    costs = sorted(s.adapter_us_per_packet for s in steps if s.adapter_us_per_packet)
    note = ""
    if costs:
        median = costs[len(costs) // 2]
        note = (f"the adapter spent {median} µs of CPU per packet each way (median of the steps): one whole core "
                f"would carry about {round(1e6 / median):,}/s each way (a projection, not a measurement)")
    found.append(Verdict("class 1, one adapter process sustains (best step that holds), each way",
                         None if best is None else float(best), PACKETS_TARGET, "/s", higher_is_better=True,
                         note=note))
    return found


def print_steps(steps: Sequence[Step]) -> None:
    print(f"{'RPI':>6} {'conns':>6} {'T->O/s':>8} {'O->T/s':>8} {'asked/s':>8} {'late %':>7} {'lost':>5} "
          f"{'t/o':>4} {'adapter':>8} {'scanners':>9} {'µs/pkt':>7} {'machine':>8}  holds")
    for s in steps:
        print(f"{s.rpi_ms:>4g}ms {s.connections:>6} {s.t_to_o_per_s:>8,} {s.o_to_t_per_s:>8,} {s.expected_per_s:>8,} "
              f"{s.late_pct:>7.3f} {s.lost:>5} {s.timeouts:>4} {s.adapter_cpu:>8.2f} {s.originators_cpu:>9.2f} "
              f"{s.adapter_us_per_packet:>7.1f} {s.machine_busy:>8.0%}  "
              f"{'yes' if s.holds else 'NO (' + s.limited_by + ')'}")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="measured time of each step (default 5)")
    parser.add_argument("--originators", type=int, default=2, help="scanner processes (default 2)")
    parser.add_argument("--ladder", action="append", metavar="RPI:N,N,...",
                        help=f"RPI and connection counts, repeatable (default {' '.join(DEFAULT_LADDER)})")
    parser.add_argument("--every-step", action="store_true",
                        help="run every step, also after the break point (the cost per packet as connections grow)")
    parser.add_argument("--no-pin", action="store_true",
                        help="let the scheduler place the adapter and the originators (default: the adapter on one "
                             "CPU, the originators on another)")
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the text report")
    parser.add_argument("--originate", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--port", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--io-port", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--rpi", type=float, help=argparse.SUPPRESS)
    parser.add_argument("--connections", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--settle", type=float, default=1.0, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.originate:
        return originator_main(args)
    steps = run_ladder(args.ladder or DEFAULT_LADDER, args.seconds, args.originators, every_step=args.every_step,
                       pin=not args.no_pin)
    if args.json:
        print(json.dumps({"steps": [asdict(s) for s in steps], "load_average": os.getloadavg(),
                          "cpus": os.cpu_count()}))
        return 0
    print_steps(steps)
    for verdict in verdicts(steps):
        print(verdict.line())
    placed = ("the adapter on one CPU, the originators on another" if steps and steps[0].pinned
              else "not pinned")
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; {placed}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
