"""Class 1 I/O timing: how evenly and how cheaply cyclic data flows.

Starts the adapter emulator (``python -m cipstack adapter``, default profile) as a subprocess on
free loopback ports and opens class 1 connections to it with cipstack's scanner:

(a) one exclusive-owner connection (output 21, input 71) at RPI 1 ms for ``--seconds`` (default
    10): packets per second in each direction, the distribution of the intervals (p50, p99, max),
    the share of intervals within +-0.5 ms of the RPI, late and lost packets;
(c) the same connection as (a) from synchronous code, ``SyncScanner.io_connection`` (served by the
    main thread, which reads the input every 10 ms and waits with ``io.sleep`` as a script does), measured
    back to back with the async handle (no capture): their shares within +-0.5 ms must agree within
    one point;
(b) 64 connections (one exclusive owner, 63 input-only on the heartbeat point; 64 is the ACG-ET2's
    station limit) at RPI 10 ms for ``--seconds``: connection timeouts, late and lost T->O packets,
    and the adapter's CPU share (utime + stime from /proc/PID/stat over the run).

Targets on a 2-core machine: (a) at least 99 % of the intervals within +-0.5 ms and no lost packet;
(b) no timeout, under 1 % late packets, the adapter under one core.

    python benchmarks/io.py [--seconds N] [--json] [--only a|b|c]

O->T intervals are measured where the packets leave (the originator's sends), T->O intervals where
they arrive (the originator's receptions); a T->O packet is late when it arrives more than half an
RPI after the one before it was due to be followed. When dumpcap and tshark are installed, part (a)
runs under a capture of the class 1 port on the loopback interface, and the wire's shares within
+-0.5 ms (both directions, the same window) are printed beside the originator's own T->O share,
which must agree with the wire's within one point. Timings are wall-clock on a shared machine:
compare runs made in the same conditions.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import os
import statistics
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from io_common import (  # benchmarks/ is on the path when a benchmark runs
    acg_class1,
    can_capture,
    class1_capture,
    cpu_seconds,
    free_port,
    start_adapter,
    stop_adapter,
    wire_times,
    within,
)

from cipstack.eip.io_server import run_precise
from cipstack.scanner import Scanner, SyncScanner

#: The ACG-ET2's station limit (one exclusive owner, the rest input only) and heartbeat point.
STATION_LIMIT = acg_class1().max_connections
INPUT_ONLY_POINT = acg_class1().input_only_point
#: The originator's own T->O share must agree with the capture's within this many points.
AGREEMENT_POINTS = 1.0


def cpu_total(pid: int) -> float:
    return sum(cpu_seconds(pid))


def distribution(intervals: Sequence[float], rpi: float) -> dict[str, Any]:
    if not intervals:
        return {"count": 0}
    ordered = sorted(intervals)

    def pct(p: float) -> float:
        return ordered[min(len(ordered) - 1, int(p * len(ordered)))] * 1e3

    within = sum(1 for i in intervals if abs(i - rpi) <= 0.0005)
    return {"count": len(intervals), "p50_ms": round(pct(0.50), 3), "p99_ms": round(pct(0.99), 3),
            "max_ms": round(ordered[-1] * 1e3, 3), "min_ms": round(ordered[0] * 1e3, 3),
            "within_0.5ms_pct": round(100.0 * within / len(intervals), 2)}


async def single_connection(port: int, io_port: int, seconds: float) -> dict[str, Any]:
    rpi = 0.001
    # Timeout multiplier 3: 1 ms x 4 x 2^3 = 32 ms, a usual choice at a 1 ms RPI (2 would be 16 ms).
    async with await Scanner.connect(f"127.0.0.1:{port}") as scanner, \
            scanner.io_connection(output=21, input=71, rpi=rpi, target_io_port=io_port, keep_intervals=True,
                                  timeout_multiplier=3) as io:
        await asyncio.sleep(0.5)  # settle, then measure from a clean start
        connection = io.connection
        connection.interval_samples.clear()
        connection.send_times.clear()
        connection.last_arrival = None
        stats_before = dict(io.stats.as_dict())
        window_start = time.time()
        await asyncio.sleep(seconds)
        window = (window_start, time.time())
        received = list(connection.interval_samples)
        sends = list(connection.send_times)
        stats = io.stats.as_dict()
        watchdog_expired = io.timed_out
    sent_intervals = [b - a for a, b in itertools.pairwise(sends)]
    delta = {k: stats[k] - stats_before[k] for k in ("sent", "received", "late", "lost", "skipped_slots")}
    return {
        "rpi_ms": rpi * 1e3, "seconds": seconds, "originator_watchdog_expired": watchdog_expired, "window": window,
        "o_to_t": {"packets_per_s": round(len(sends) / seconds, 1), "late": delta["late"],
                   "skipped_slots": delta["skipped_slots"], **distribution(sent_intervals, rpi)},
        "t_to_o": {"packets_per_s": round((len(received) + 1) / seconds, 1), "lost": delta["lost"],
                   **distribution(received, rpi)},
    }


def _figures(connection: Any, stats_before: dict[str, int], stats: dict[str, int], sends: list[float],
             received: list[float], rpi: float, seconds: float) -> dict[str, Any]:
    sent_intervals = [b - a for a, b in itertools.pairwise(sends)]
    delta = {k: stats[k] - stats_before[k] for k in ("sent", "received", "late", "lost", "skipped_slots")}
    return {
        "o_to_t": {"packets_per_s": round(len(sends) / seconds, 1), "late": delta["late"],
                   "skipped_slots": delta["skipped_slots"], **distribution(sent_intervals, rpi)},
        "t_to_o": {"packets_per_s": round((len(received) + 1) / seconds, 1), "lost": delta["lost"],
                   **distribution(received, rpi)},
    }


def sync_single_connection(port: int, io_port: int, seconds: float) -> dict[str, Any]:
    """(a)'s connection opened from blocking code: this thread serves it (no event loop, no thread),
    reading the input every 10 ms and waiting with ``io.sleep`` in between, as a script does."""
    rpi = 0.001
    with SyncScanner(f"127.0.0.1:{port}") as scanner, \
            scanner.io_connection(output=21, input=71, rpi=rpi, target_io_port=io_port, keep_intervals=True,
                                  timeout_multiplier=3) as io:
        io.sleep(0.5)
        connection = io.handle.connection
        connection.interval_samples.clear()
        connection.send_times.clear()
        connection.last_arrival = None
        stats_before = dict(io.handle.stats.as_dict())
        end = time.monotonic() + seconds
        reads = 0
        while time.monotonic() < end:
            _ = io.input.speed_actual
            reads += 1
            io.sleep(0.010)
        received = list(connection.interval_samples)
        sends = list(connection.send_times)
        stats = io.handle.stats.as_dict()
        expired = io.timed_out
    return {"rpi_ms": rpi * 1e3, "seconds": seconds, "originator_watchdog_expired": expired, "input_reads": reads,
            **_figures(connection, stats_before, stats, sends, received, rpi, seconds)}


def sync_against_async(port: int, io_port: int, seconds: float, rounds: int = 3) -> dict[str, Any]:
    """(c): the async handle and the sync one in turn, ``rounds`` times each for ``seconds`` / ``rounds``
    (first one, then the other, by turns: a drift of the machine's load weighs on both alike); the
    median share of each, and the gap in points."""
    runs: dict[str, list[dict[str, Any]]] = {"async": [], "sync": []}
    for index in range(rounds):
        order = ("async", "sync") if index % 2 == 0 else ("sync", "async")
        for kind in order:
            runs[kind].append(run_precise(single_connection(port, io_port, seconds / rounds)) if kind == "async"
                              else sync_single_connection(port, io_port, seconds / rounds))

    def median_share(kind: str, direction: str) -> float:
        return float(statistics.median(r[direction]["within_0.5ms_pct"] for r in runs[kind]))

    summary = {kind: {direction: {"within_0.5ms_pct": median_share(kind, direction),
                                  "lost": sum(r[direction].get("lost", 0) for r in runs[kind]),
                                  "late": sum(r[direction].get("late", 0) for r in runs[kind])}
                      for direction in ("o_to_t", "t_to_o")} for kind in runs}
    gaps = {direction: round(abs(summary["sync"][direction]["within_0.5ms_pct"]
                                 - summary["async"][direction]["within_0.5ms_pct"]), 2)
            for direction in ("o_to_t", "t_to_o")}
    return {**summary, "rounds": rounds, "gap_points": gaps,
            "agrees": all(gap <= AGREEMENT_POINTS for gap in gaps.values())}


async def station_limit(port: int, io_port: int, seconds: float, pid: int) -> dict[str, Any]:
    rpi = 0.010
    async with await Scanner.connect(f"127.0.0.1:{port}") as scanner:
        contexts = [scanner.io_connection(output=21, input=71, rpi=rpi, target_io_port=io_port, keep_intervals=True)]
        contexts += [scanner.io_connection(input=71, heartbeat=INPUT_ONLY_POINT, rpi=rpi, target_io_port=io_port,
                                           keep_intervals=True) for _ in range(STATION_LIMIT - 1)]
        handles = []
        try:
            for context in contexts:
                handles.append(await context.__aenter__())
            await asyncio.sleep(0.5)
            for handle in handles:
                handle.connection.interval_samples.clear()
                handle.connection.last_arrival = None
            lost_before = sum(h.stats.lost for h in handles)
            cpu_before, wall_before = cpu_total(pid), time.monotonic()
            await asyncio.sleep(seconds)
            cpu, wall = cpu_total(pid) - cpu_before, time.monotonic() - wall_before
            intervals = [i for h in handles for i in h.connection.interval_samples]
            timeouts = sum(1 for h in handles if h.timed_out)
            lost = sum(h.stats.lost for h in handles) - lost_before
        finally:
            for context in reversed(contexts[:len(handles)]):
                await context.__aexit__(None, None, None)
    late = sum(1 for i in intervals if i > 1.5 * rpi)
    return {
        "connections": len(handles), "rpi_ms": rpi * 1e3, "seconds": seconds, "timeouts": timeouts,
        "t_to_o_packets": len(intervals), "late": late,
        "late_pct": round(100.0 * late / len(intervals), 3) if intervals else None, "lost": lost,
        "adapter_cpu_share": round(cpu / wall, 3),
        **{f"t_to_o_{k}": v for k, v in distribution(intervals, rpi).items()},
    }


def single_connection_captured(port: int, io_port: int, seconds: float) -> dict[str, Any]:
    """Part (a), under a capture when dumpcap and tshark are here: the wire's share of intervals within
    +-0.5 ms each way, over the same window, beside the originator's own (the receive side's figure
    is only honest if it agrees with the wire's)."""
    if not can_capture():
        result = run_precise(single_connection(port, io_port, seconds))
        result["wire"] = None
        return result
    with tempfile.TemporaryDirectory() as tmp:
        os.chmod(tmp, 0o755)  # dumpcap may run as another user
        with class1_capture(io_port, Path(tmp) / "io.pcapng") as capture:
            result = run_precise(single_connection(port, io_port, seconds))
        ot, to = wire_times(capture, io_port, result["window"])
    rpi = result["rpi_ms"] / 1e3
    (ot_count, ot_share), (to_count, to_share) = within(ot, rpi), within(to, rpi)
    own = result["t_to_o"].get("within_0.5ms_pct")
    result["wire"] = {"o_to_t_intervals": ot_count, "o_to_t_within_pct": ot_share, "t_to_o_intervals": to_count,
                      "t_to_o_within_pct": to_share,
                      "agrees": own is not None and to_share is not None and abs(own - to_share) <= AGREEMENT_POINTS}
    return result


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="measured time of each part (default 10)")
    parser.add_argument("--only", choices=["a", "b", "c"], help="run one part")
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the text report")
    parser.add_argument("--http-poll", action="store_true",
                        help="with the HTTP control API enabled and GET /status polled at 10 Hz throughout")
    args = parser.parse_args(argv)
    port, io_port = free_port(), free_port()
    http_port = free_port() if args.http_poll else None
    adapter = start_adapter(port, io_port, *(["--http", f"127.0.0.1:{http_port}"] if http_port else []))
    results: dict[str, Any] = {"load_average": os.getloadavg()[0], "cpus": os.cpu_count()}
    poller = HttpPoller(http_port) if http_port else None
    try:
        if args.only in (None, "a"):
            results["a_one_connection_1ms"] = single_connection_captured(port, io_port, args.seconds)
        if args.only in (None, "c"):
            results["c_sync_against_async_1ms"] = sync_against_async(port, io_port, args.seconds)
        if args.only in (None, "b"):
            results["b_64_connections_10ms"] = run_precise(station_limit(port, io_port, args.seconds, adapter.pid))
    finally:
        if poller is not None:
            results["http_polls"] = poller.stop()
        stop_adapter(adapter)
    if args.json:
        print(json.dumps(results))
        return 0
    a = results.get("a_one_connection_1ms")
    if a:
        print(f"(a) one connection, RPI {a['rpi_ms']} ms, {a['seconds']} s")
        for direction, label in (("o_to_t", "O->T"), ("t_to_o", "T->O")):
            d = a[direction]
            print(f"    {label} {d['packets_per_s']:8.1f} packets/s  intervals p50 "
                  f"{d.get('p50_ms')} ms  p99 {d.get('p99_ms')} ms  max {d.get('max_ms')} ms  within +-0.5 ms "
                  f"{d.get('within_0.5ms_pct')} % (target >= 99 %)")
        wire = a["wire"]
        if wire is None:
            print("    on the wire: not captured (dumpcap and tshark are needed)")
        else:
            print(f"    on the wire: O->T {wire['o_to_t_within_pct']} %, T->O {wire['t_to_o_within_pct']} % within "
                  f"+-0.5 ms; the originator's own T->O figure {a['t_to_o'].get('within_0.5ms_pct')} % "
                  f"{'agrees' if wire['agrees'] else 'DISAGREES'} (within {AGREEMENT_POINTS:g} point)")
        print(f"    O->T late {a['o_to_t']['late']}, skipped slots {a['o_to_t']['skipped_slots']}; "
              f"T->O lost {a['t_to_o']['lost']} (target 0); originator watchdog expired: "
              f"{a['originator_watchdog_expired']}")
    c = results.get("c_sync_against_async_1ms")
    if c:
        print(f"(c) one connection, RPI 1.0 ms, {args.seconds:g} s each in {c['rounds']} turns: the async handle and "
              "SyncScanner's (medians)")
        for kind in ("async", "sync"):
            figures = c[kind]
            print(f"    {kind:<5} O->T within +-0.5 ms {figures['o_to_t'].get('within_0.5ms_pct')} %, T->O "
                  f"{figures['t_to_o'].get('within_0.5ms_pct')} %, T->O lost {figures['t_to_o']['lost']}, "
                  f"O->T late {figures['o_to_t']['late']}")
        print(f"    gap O->T {c['gap_points']['o_to_t']} points, T->O {c['gap_points']['t_to_o']} points: "
              f"{'within' if c['agrees'] else 'NOT within'} {AGREEMENT_POINTS:g} point")
    b = results.get("b_64_connections_10ms")
    if b:
        print(f"(b) {b['connections']} connections, RPI {b['rpi_ms']} ms, {b['seconds']} s")
        print(f"    timeouts {b['timeouts']} (target 0); T->O packets {b['t_to_o_packets']}, late {b['late']} "
              f"({b['late_pct']} %, target < 1 %), lost {b['lost']}")
        print(f"    adapter CPU share {b['adapter_cpu_share']} cores (target < 1.0)")
    if "http_polls" in results:
        polls = results["http_polls"]
        print(f"HTTP API polled at 10 Hz throughout: {polls['answered']} answers, {polls['failed']} failures")
    print(f"load average {results['load_average']:.2f} on {results['cpus']} CPUs")
    return 0


class HttpPoller:
    """GET /status of the adapter's HTTP control API ten times a second, on a thread, until ``stop``."""

    def __init__(self, port: int) -> None:
        import threading

        self.url = f"http://127.0.0.1:{port}/status"
        self.answered = self.failed = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import urllib.request

        while not self._stop.wait(0.1):
            try:
                with urllib.request.urlopen(self.url, timeout=2) as response:
                    json.loads(response.read())
                self.answered += 1
            except (OSError, ValueError):
                self.failed += 1

    def stop(self) -> dict[str, int]:
        self._stop.set()
        self._thread.join(5)
        return {"answered": self.answered, "failed": self.failed}


if __name__ == "__main__":
    raise SystemExit(main())
