"""A plant in one command: a fleet of ACG drives, each with one class 1 connection from the scanner.

Starts ``python -m cipstack fleet`` as a subprocess: N ACG drives, each on its own loopback address
(127.88.x.y), then opens one exclusive-owner connection (output 21, input 71) at RPI 10 ms to every
drive with cipstack's scanner, in other processes (``--scanners``, default one per fleet worker), and
measures for ``--seconds``: T->O packets, late ones (an arrival more than 1.5 RPI after the one
before), lost ones (the originator's count), connection timeouts, the fleet's CPU share and its
memory (RSS of the fleet's processes, per device; and, against a fleet of one device per worker
started in the same run, what each further device adds).

Targets (issue 15): 64 drives in one process, and 128 drives with ``--workers 2``: under 1 % late,
none lost, no timeout; printed with PASS/FAIL.

    python benchmarks/fleet.py [--seconds 20] [--only 64|128] [--json]

Timings are wall-clock on a shared machine: compare runs made in the same conditions.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import multiprocessing
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from multiprocessing.connection import Connection
from typing import Any

from io_common import CLOCK_TICKS, free_port, stop_adapter  # benchmarks/ is on the path when a benchmark runs

from cipstack.devices.profiles import PROFILES
from cipstack.eip.io_server import run_precise
from cipstack.scanner import Scanner

RPI = 0.010
#: The fleet sizes and worker counts of the issue's targets.
CASES = {64: 1, 128: 2}


def hosts(block: int, count: int) -> list[str]:
    return [f"127.88.{block + n // 200}.{10 + n % 200}" for n in range(count)]


def fleet_pids(parent: int) -> list[int]:
    """The fleet's parent and its worker processes."""
    found = [parent]
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            with contextlib.suppress(OSError, IndexError, ValueError), open(f"/proc/{entry}/stat") as stat:
                if int(stat.read().rsplit(")", 1)[1].split()[1]) == parent:
                    found.append(int(entry))
    return found


def rss_bytes(pids: Sequence[int]) -> int:
    total = 0
    for pid in pids:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1]) * 1024
    return total


def cpu_seconds(pids: Sequence[int]) -> float:
    total = 0.0
    for pid in pids:
        with open(f"/proc/{pid}/stat") as stat:
            fields = stat.read().rsplit(")", 1)[1].split()
        total += (int(fields[11]) + int(fields[12])) / CLOCK_TICKS
    return total


def start_fleet(addresses: list[str], port: int, io_port: int, workers: int, state: str) -> subprocess.Popen[bytes]:
    log = os.path.join(state, f"fleet-{len(addresses)}.log")   # a file: a pipe nobody reads would fill
    with open(log, "wb") as err:
        process = subprocess.Popen([sys.executable, "-m", "cipstack", "fleet", "--addresses",
                                    f"{addresses[0]}-{addresses[-1]}", "--device", f"acg*{len(addresses)}", "--port",
                                    str(port), "--io-port", str(io_port), "--workers", str(workers), "--state-dir",
                                    state], stdout=subprocess.DEVNULL, stderr=err, stdin=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        with open(log, "rb") as text:
            if b"emulating" in text.read():
                return process
        time.sleep(0.1)
    process.kill()
    with open(log, "rb") as text:
        raise RuntimeError(f"the fleet did not start (exit status {process.wait()}): {text.read()[-500:]!r}")


async def scan(addresses: list[str], port: int, io_port: int, seconds: float, channel: Connection) -> dict[str, Any]:
    """One exclusive owner per address; tells the parent when all run, measures ``seconds`` after its go."""
    make_catalog = PROFILES["acg"].catalog
    assert make_catalog is not None
    catalog = make_catalog()   # built once: building it takes tens of ms the running connections would miss
    async with contextlib.AsyncExitStack() as stack:
        handles = []
        for address in addresses:
            scanner = await stack.enter_async_context(await Scanner.connect(f"{address}:{port}", timeout=10,
                                                                            catalog=catalog))
            handles.append(await stack.enter_async_context(
                scanner.io_connection(output=21, input=71, rpi=RPI, target_io_port=io_port, keep_intervals=True)))
        channel.send("open")
        await asyncio.get_running_loop().run_in_executor(None, channel.recv)   # the parent's go
        await asyncio.sleep(1.0)                                                # settle
        for handle in handles:
            handle.connection.interval_samples.clear()
            handle.connection.last_arrival = None
        lost_before = sum(h.stats.lost for h in handles)
        cpu_before = time.process_time()
        await asyncio.sleep(seconds)
        cpu = time.process_time() - cpu_before
        intervals = [i for h in handles for i in h.connection.interval_samples]
        return {"connections": len(handles), "packets": len(intervals),
                "late": sum(1 for i in intervals if i > 1.5 * RPI),
                "lost": sum(h.stats.lost for h in handles) - lost_before,
                "timeouts": sum(1 for h in handles if h.timed_out),
                "max_interval_ms": round(max(intervals, default=0.0) * 1e3, 2),
                "cpu_share": round(cpu / seconds, 3)}


def scanner_process(addresses: list[str], port: int, io_port: int, seconds: float, channel: Connection) -> None:
    try:
        channel.send(run_precise(scan(addresses, port, io_port, seconds, channel)))
    except Exception as exc:  # one line to the parent, never a silent hang
        channel.send({"error": f"{type(exc).__name__}: {exc}"})


def run_case(devices: int, workers: int, scanners: int, seconds: float, block: int) -> dict[str, Any]:
    addresses = hosts(block, devices)
    port = free_port(addresses[0], addresses[-1])
    io_port = free_port(addresses[0], addresses[-1])
    with tempfile.TemporaryDirectory() as state:
        # The same fleet machinery with one device per worker: what the processes cost before devices.
        small = start_fleet(addresses[:workers], port, io_port, workers, state)
        try:
            time.sleep(1.0)
            base_rss = rss_bytes(fleet_pids(small.pid))
        finally:
            stop_adapter(small, 60)
        fleet = start_fleet(addresses, port, io_port, workers, state)
        try:
            pids = fleet_pids(fleet.pid)
            context = multiprocessing.get_context("fork")
            channels, processes = [], []
            for index in range(scanners):
                mine, theirs = context.Pipe()
                share = addresses[index::scanners]
                process = context.Process(target=scanner_process, args=(share, port, io_port, seconds, theirs))
                process.start()
                channels.append(mine)
                processes.append(process)
            for channel in channels:
                message = channel.recv()
                if message != "open":
                    raise RuntimeError(f"a scanner could not open its connections: {message}")
            for channel in channels:
                channel.send("go")
            time.sleep(1.0)
            cpu_before, wall_before = cpu_seconds(pids), time.monotonic()
            time.sleep(seconds * 0.5)
            rss = rss_bytes(pids)
            reports = [channel.recv() for channel in channels]
            cpu, wall = cpu_seconds(pids) - cpu_before, time.monotonic() - wall_before
            for process in processes:
                process.join(30)
            errors = [r["error"] for r in reports if "error" in r]
            if errors:
                raise RuntimeError(errors[0])
        finally:
            stop_adapter(fleet, 60)
    packets = sum(r["packets"] for r in reports)
    late = sum(r["late"] for r in reports)
    return {"devices": devices, "workers": workers, "scanner_processes": scanners, "rpi_ms": RPI * 1e3,
            "seconds": seconds, "connections": sum(r["connections"] for r in reports), "t_to_o_packets": packets,
            "late": late, "late_pct": round(100.0 * late / packets, 3) if packets else None,
            "lost": sum(r["lost"] for r in reports), "timeouts": sum(r["timeouts"] for r in reports),
            "max_interval_ms": max(r["max_interval_ms"] for r in reports),
            "fleet_cpu_share": round(cpu / wall, 3),
            "scanner_cpu_share": round(sum(r["cpu_share"] for r in reports), 3),
            "fleet_cpu_us_per_packet": round(1e6 * cpu / max(1, packets / seconds * wall), 1),
            "rss_mb": round(rss / 2**20, 1),
            "rss_per_device_mb": round(rss / devices / 2**20, 2),
            "rss_base_mb": round(base_rss / 2**20, 1),
            "rss_per_further_device_mb": round((rss - base_rss) / max(1, devices - workers) / 2**20, 2)}


def verdict(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="measured time of each case (default 20)")
    parser.add_argument("--only", type=int, choices=sorted(CASES), help="one case: 64 (1 process) or 128 (2 workers)")
    parser.add_argument("--devices", type=int, help="another case: this many drives (with --workers)")
    parser.add_argument("--workers", type=int, default=1, help="the fleet's worker processes with --devices")
    parser.add_argument("--scanners", type=int, help="scanner processes (default: one per fleet worker)")
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the text report")
    args = parser.parse_args(argv)
    results: dict[str, Any] = {"nproc": os.cpu_count(), "load_average_before": round(os.getloadavg()[0], 2),
                               "cases": []}
    cases = {args.devices: args.workers} if args.devices else CASES
    for block, (devices, workers) in enumerate(cases.items()):
        if args.devices or args.only in (None, devices):
            results["cases"].append(run_case(devices, workers, args.scanners or workers, args.seconds, 10 * block))
    results["load_average_after"] = round(os.getloadavg()[0], 2)
    failed = False
    if args.json:
        print(json.dumps(results))
    for case in results["cases"]:
        late_ok = case["late_pct"] is not None and case["late_pct"] < 1.0
        lost_ok, timeouts_ok = case["lost"] == 0, case["timeouts"] == 0
        failed |= not (late_ok and lost_ok and timeouts_ok)
        if args.json:
            continue
        print(f"{case['devices']} ACG drives, {case['workers']} fleet process(es), {case['connections']} "
              f"exclusive-owner connections at RPI {case['rpi_ms']:g} ms from {case['scanner_processes']} "
              f"scanner process(es), {case['seconds']:g} s")
        print(f"    T->O packets {case['t_to_o_packets']}, late {case['late']} ({case['late_pct']} %, target < 1 %) "
              f"[{verdict(late_ok)}], lost {case['lost']} (target 0) [{verdict(lost_ok)}], timeouts "
              f"{case['timeouts']} (target 0) [{verdict(timeouts_ok)}]; longest interval {case['max_interval_ms']} ms")
        print(f"    memory: RSS {case['rss_mb']} MB in all, {case['rss_per_device_mb']} MB per device; a fleet of "
              f"{case['workers']} device(s) {case['rss_base_mb']} MB, each further device "
              f"{case['rss_per_further_device_mb']} MB; fleet CPU {case['fleet_cpu_share']} cores, "
              f"{case['fleet_cpu_us_per_packet']} us per T->O packet (with its O->T one); scanner CPU "
              f"{case['scanner_cpu_share']} cores")
    if not args.json:
        print(f"nproc {results['nproc']}, load average {results['load_average_before']} before, "
              f"{results['load_average_after']} after")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
