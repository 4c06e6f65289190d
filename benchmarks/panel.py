"""What an open front panel costs the device: class 1 timing at RPI 1 ms and 10 ms with two panels
open against none, and the adapter's CPU with one panel open against none, in one run.

Starts the adapter emulator with its HTTP API (``--http``) and opens one exclusive-owner class 1
connection (21/71) with cipstack's scanner. A "panel" is what the page keeps open on the device: its
live stream (``GET /stream``, Server-Sent Events), read by a process of its own (as a browser is),
plus what the page reads once (``/parameters``, ``/fault-table``, ``/trips``). The turns alternate
(none, panels, none, panels, ...) so that the machine's load falls on both alike; each figure is the
median of its turns, and each line ends with the ratio panels / none.

    python benchmarks/panel.py [--seconds N] [--turns N] [--json]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import Any

from io_common import cpu_seconds, free_port, start_adapter, stop_adapter  # benchmarks/ is on the path

from cipstack.scanner import Scanner

#: A panel's reader: the page's first reads, then its stream, until killed.
PANEL = """
import sys, urllib.request
base = sys.argv[1]
for path in ("/parameters", "/fault-table", "/trips"):
    urllib.request.urlopen(base + path, timeout=10).read()
with urllib.request.urlopen(base + "/stream", timeout=30) as stream:
    while stream.read(1024):
        pass
"""


def open_panels(count: int, base: str) -> list[subprocess.Popen[bytes]]:
    return [subprocess.Popen([sys.executable, "-c", PANEL, base], stderr=subprocess.DEVNULL) for _ in range(count)]


def close_panels(panels: list[subprocess.Popen[bytes]]) -> None:
    for panel in panels:
        panel.kill()
        panel.wait(10)


def share_within(intervals: Sequence[float], rpi: float, tolerance: float = 0.0005) -> float:
    return 100.0 * sum(1 for i in intervals if abs(i - rpi) <= tolerance) / len(intervals) if intervals else 0.0


async def timing(port: int, io_port: int, rpi: float, seconds: float) -> dict[str, float]:
    """One turn: T->O intervals as they arrive, lost packets, for ``seconds``."""
    async with await Scanner.connect(f"127.0.0.1:{port}") as scanner, \
            scanner.io_connection(output=21, input=71, rpi=rpi, target_io_port=io_port, keep_intervals=True,
                                  timeout_multiplier=3) as io:
        await asyncio.sleep(0.5)
        connection = io.connection
        connection.interval_samples.clear()
        connection.last_arrival = None
        lost_before = io.stats.lost
        await asyncio.sleep(seconds)
        intervals = list(connection.interval_samples)
        lost = io.stats.lost - lost_before
    ordered = sorted(intervals) or [0.0]
    return {"within_pct": round(share_within(intervals, rpi), 2),
            "p99_ms": round(ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))] * 1e3, 3), "lost": lost}


def cpu_turn(pid: int, seconds: float) -> float:
    """The adapter's CPU share (cores) over ``seconds`` with its class 1 connection idle of panels."""
    user, system = cpu_seconds(pid)
    started = time.monotonic()
    time.sleep(seconds)
    user2, system2 = cpu_seconds(pid)
    return round(max(0.0, (user2 + system2 - user - system) / (time.monotonic() - started)), 4)


def median(turns: list[dict[str, float]], key: str) -> float:
    return float(statistics.median(turn[key] for turn in turns))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=4.0, help="seconds a turn measures (default 4)")
    parser.add_argument("--turns", type=int, default=3, help="turns of each kind (default 3)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    port, io_port, http = free_port(), free_port(), free_port()
    adapter = start_adapter(port, io_port, "--http", f"127.0.0.1:{http}")
    base = f"http://127.0.0.1:{http}"
    results: dict[str, Any] = {}
    try:
        for rpi in (0.001, 0.010):
            turns: dict[int, list[dict[str, float]]] = {0: [], 2: []}
            for _ in range(args.turns):
                for count in (0, 2):
                    panels = open_panels(count, base)
                    try:
                        time.sleep(0.5 if count else 0.0)     # the panels' first reads done
                        turns[count].append(asyncio.run(timing(port, io_port, rpi, args.seconds)))
                    finally:
                        close_panels(panels)
            none, two = ({key: median(turns[c], key) for key in ("within_pct", "p99_ms", "lost")} for c in (0, 2))
            results[f"rpi_{round(rpi * 1e3)}ms"] = {
                "none": none, "two_panels": two,
                "within_ratio": round(two["within_pct"] / none["within_pct"], 3) if none["within_pct"] else None,
                "p99_ratio": round(two["p99_ms"] / none["p99_ms"], 3) if none["p99_ms"] else None}
        cpu: dict[int, list[float]] = {0: [], 1: []}
        for _ in range(args.turns):
            for count in (0, 1):
                panels = open_panels(count, base)
                try:
                    time.sleep(0.5 if count else 0.0)
                    cpu[count].append(cpu_turn(adapter.pid, args.seconds))
                finally:
                    close_panels(panels)
        idle, one = statistics.median(cpu[0]), statistics.median(cpu[1])
        results["adapter_cpu_cores"] = {"none": idle, "one_panel": one, "added": round(one - idle, 4)}
    finally:
        stop_adapter(adapter)
    if args.json:
        print(json.dumps(results))
        return 0
    for name in ("rpi_1ms", "rpi_10ms"):
        r = results[name]
        print(f"{name}: within +-0.5 ms {r['none']['within_pct']} % without a panel, {r['two_panels']['within_pct']} % "
              f"with two (ratio {r['within_ratio']}); p99 {r['none']['p99_ms']} / {r['two_panels']['p99_ms']} ms "
              f"(ratio {r['p99_ratio']}); lost {r['none']['lost']:g} / {r['two_panels']['lost']:g}")
    c = results["adapter_cpu_cores"]
    print(f"adapter CPU (idle device): {c['none']} cores without a panel, {c['one_panel']} with one "
          f"(+{c['added']})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
