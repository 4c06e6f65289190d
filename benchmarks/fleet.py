"""A plant in one command: a fleet of ACG drives, each with one class 1 connection from the scanner.

Starts ``python -m cipstack fleet`` as a subprocess: N ACG drives, each on its own loopback address
(a contiguous run from 127.88.0.10, the one list the fleet is given and the scanner dials), then
opens one exclusive-owner connection (output 21, input 71) at ``--rpi`` (default 10 ms) to every
drive with cipstack's scanner, in other processes (``--scanners``, default one per fleet worker), and
measures for ``--seconds``: T->O packets, late ones (an arrival more than 1.5 RPI after the one
before), lost ones (the originator's count), connection timeouts, the fleet's and the scanners' CPU
(share of a core, and microseconds per packet pair: a T->O packet with its O->T one), the fleet's
start time (launch to "emulating"; per drive, what each further drive adds against a fleet of one
drive per worker started in the same run) and its memory (RSS of the fleet's processes, per device; and,
against a fleet of one device per worker started in the same run, what each further device adds).

Targets (issue 15): 64 drives in one process, and 128 drives with ``--workers 2``: under 1 % late,
none lost, no timeout; printed with PASS/FAIL.

``--matrix`` runs sizes x RPIs x worker counts (``--sizes``, ``--rpis``, ``--worker-counts``; by
default a small matrix: 64 and 128 drives, 10 and 50 ms, one worker, 5 s each) and prints one row
per case with issue 50's targets as [PASS]/[FAIL]: the case holds (under 1 % late, none lost, no
timeout: the issue asks it of 1,024 drives at 50 ms and 128 at 10 ms on one worker), the fleet at
35 us per pair or less (from 256 drives on), start-up at 5 ms per drive or less. Each row gives the
share of time the fleet waited for a CPU (the machine's other work) and its CPU per pair in user and
system time. ``--against TREE`` runs each case's fleet from another checkout too, by turns. Lateness
is timed by the kernel's arrival stamps (``--late-by read``: when the scanner read each packet).

    python benchmarks/fleet.py [--seconds 20] [--only 64|128] [--rpi 10ms] [--json]
    python benchmarks/fleet.py --devices 256 --workers 1 --rpi 50ms
    python benchmarks/fleet.py --matrix [--sizes 64,256,1024] [--rpis 10ms,50ms] [--worker-counts 1,2]
    python benchmarks/fleet.py --matrix --sizes 512 --rpis 50ms --against /tmp/old-tree   # two trees by turns

Timings are wall-clock on a shared machine: compare runs made in the same conditions.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import ipaddress
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
from cipstack.eip.io_server import freeze_startup_objects, run_precise
from cipstack.fleet.spec import describe_addresses
from cipstack.scanner import Scanner

RPI = 0.010
#: The fleet sizes and worker counts of the issue's targets.
CASES = {64: 1, 128: 2}
#: The first drive's address; each case of a run starts a block further (``BLOCK`` addresses, a /16:
#: more than any fleet), so that a case never meets the sockets of the one before.
FIRST = ipaddress.IPv4Address("127.88.0.10")
BLOCK = 1 << 16
#: The default matrix: small enough for a few minutes (each case starts two fleets).
MATRIX_SIZES = (64, 128)
MATRIX_RPIS = ("10ms", "50ms")
MATRIX_WORKERS = (1,)
#: Issue 50's targets: the fleet's CPU per packet pair from 256 drives on, start-up per drive, and a
#: case holds when under 1 % of its T->O packets are late, none is lost and no connection times out.
US_PER_PAIR_TARGET = 35.0
US_PER_PAIR_FROM = 256
START_MS_PER_DRIVE_TARGET = 5.0
LATE_PCT_TARGET = 1.0


def hosts(block: int, count: int) -> list[str]:
    """``count`` contiguous loopback addresses, block ``block``: the fleet is given exactly these
    (``fleet_addresses``, the fleet's own notation of them) and the scanner dials exactly these."""
    first = FIRST + block * BLOCK
    return [str(first + n) for n in range(count)]


def fleet_addresses(addresses: Sequence[str]) -> str:
    """``--addresses`` for ``addresses``: ranges where they run on, as the fleet reads them back."""
    return describe_addresses(addresses)


def parse_rpi(text: str) -> float:
    value = text.strip().lower()
    if value.endswith("ms"):
        return float(value[:-2]) / 1e3
    if value.endswith("us"):
        return float(value[:-2]) / 1e6
    return float(value.rstrip("s"))


def fleet_pids(parent: int) -> list[int]:
    """The fleet's parent and its worker processes."""
    found = [parent]
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            with contextlib.suppress(OSError, IndexError, ValueError), open(f"/proc/{entry}/stat") as stat:
                if int(stat.read().rsplit(")", 1)[1].split()[1]) == parent:
                    found.append(int(entry))
    return found


def user_system_seconds(pids: Sequence[int]) -> tuple[float, float]:
    """(user, system) CPU seconds of ``pids`` from ``/proc/PID/stat`` (clock ticks): the interpreter's
    work against the kernel's (system calls, and on loopback the delivery of what is sent)."""
    user = system = 0.0
    for pid in pids:
        with open(f"/proc/{pid}/stat") as stat:
            fields = stat.read().rsplit(")", 1)[1].split()
        user, system = user + int(fields[11]) / CLOCK_TICKS, system + int(fields[12]) / CLOCK_TICKS
    return user, system


def rss_bytes(pids: Sequence[int]) -> int:
    total = 0
    for pid in pids:
        with open(f"/proc/{pid}/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1]) * 1024
    return total


def cpu_seconds(pids: Sequence[int]) -> float:
    return scheduled(pids)[0]


def scheduled(pids: Sequence[int]) -> tuple[float, float]:
    """(CPU seconds, seconds spent ready to run but waiting for a CPU) of every thread of ``pids``, from
    the scheduler's own count (``/proc/PID/task/*/schedstat``, nanoseconds); the CPU from
    ``/proc/PID/stat``'s ticks and no wait where schedstat is missing. The wait tells a process starved
    of a CPU by the machine's other work from one late for a reason of its own."""
    cpu = wait = 0.0
    for pid in pids:
        try:
            for task in os.listdir(f"/proc/{pid}/task"):
                with open(f"/proc/{pid}/task/{task}/schedstat") as stat:
                    fields = stat.read().split()
                cpu, wait = cpu + int(fields[0]) / 1e9, wait + int(fields[1]) / 1e9
        except (OSError, ValueError, IndexError):
            with open(f"/proc/{pid}/stat") as stat:
                fields = stat.read().rsplit(")", 1)[1].split()
            cpu += (int(fields[11]) + int(fields[12])) / CLOCK_TICKS
    return cpu, wait


def tree_env(tree: str | None) -> dict[str, str] | None:
    """The environment of a fleet run from ``tree`` (another checkout, ``--against``); None: this one's."""
    if tree is None:
        return None
    env = dict(os.environ)
    env["PYTHONPATH"] = tree
    return env


def start_fleet(addresses: list[str], port: int, io_port: int, workers: int, state: str, tree: str | None = None
                ) -> tuple[subprocess.Popen[bytes], float]:
    """The fleet (with ``tree``'s code, else this tree's), and the seconds from its launch to its
    "emulating" line (start-up, 20 ms steps)."""
    log = os.path.join(state, f"fleet-{len(addresses)}.log")   # a file: a pipe nobody reads would fill
    started = time.monotonic()
    with open(log, "wb") as err:
        process = subprocess.Popen([sys.executable, "-m", "cipstack", "fleet", "--addresses",
                                    fleet_addresses(addresses), "--device", f"acg*{len(addresses)}", "--port",
                                    str(port), "--io-port", str(io_port), "--workers", str(workers), "--state-dir",
                                    state], stdout=subprocess.DEVNULL, stderr=err, stdin=subprocess.DEVNULL,
                                   env=tree_env(tree))
    deadline = started + 120 + 0.1 * len(addresses)
    while time.monotonic() < deadline and process.poll() is None:
        with open(log, "rb") as text:
            if b"emulating" in text.read():
                return process, time.monotonic() - started
        time.sleep(0.02)
    process.kill()
    with open(log, "rb") as text:
        raise RuntimeError(f"the fleet did not start (exit status {process.wait()}): {text.read()[-500:]!r}")


async def scan(addresses: list[str], port: int, io_port: int, seconds: float, channel: Connection,
               rpi: float = RPI, late_by: str = "wire") -> dict[str, Any]:
    """One exclusive owner per address; tells the parent when all run, measures ``seconds`` after its go.
    ``late_by``: "wire", each T->O packet timed when the kernel received it (on loopback, when the drive
    sent it: what a capture shows); "read", when this scanner's loop read it, which adds the scanner's
    own stalls (its collections, a CPU the machine gave to other work) to the drives' intervals."""
    make_catalog = PROFILES["acg"].catalog
    assert make_catalog is not None
    catalog = make_catalog()   # built once: building it takes tens of ms the running connections would miss
    async with contextlib.AsyncExitStack() as stack:
        handles = []
        for address in addresses:
            scanner = await stack.enter_async_context(await Scanner.connect(f"{address}:{port}", timeout=10,
                                                                            catalog=catalog))
            handles.append(await stack.enter_async_context(
                scanner.io_connection(output=21, input=71, rpi=rpi, target_io_port=io_port, keep_intervals=True,
                                      kernel_arrival_times=late_by == "wire")))
        # Out of the collector's reach, as a fleet puts its drives: a full collection over hundreds of
        # sessions held the scanner 20 to 40 ms, an interval late at RPI 50 ms when timed as read.
        freeze_startup_objects()
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
                "late": sum(1 for i in intervals if i > 1.5 * rpi),
                "lost": sum(h.stats.lost for h in handles) - lost_before,
                "timeouts": sum(1 for h in handles if h.timed_out),
                "max_interval_ms": round(max(intervals, default=0.0) * 1e3, 2),
                "cpu_share": round(cpu / seconds, 3), "cpu_s": cpu}


def scanner_process(addresses: list[str], port: int, io_port: int, seconds: float, channel: Connection,
                    rpi: float = RPI, late_by: str = "wire") -> None:
    try:
        channel.send(run_precise(scan(addresses, port, io_port, seconds, channel, rpi, late_by)))
    except Exception as exc:  # one line to the parent, never a silent hang
        channel.send({"error": f"{type(exc).__name__}: {exc}"})


def run_case(devices: int, workers: int, scanners: int, seconds: float, block: int, rpi: float = RPI,
             tree: str | None = None, late_by: str = "wire") -> dict[str, Any]:
    addresses = hosts(block, devices)
    port = free_port(addresses[0], addresses[-1])
    io_port = free_port(addresses[0], addresses[-1])
    with tempfile.TemporaryDirectory() as state:
        # The same fleet machinery with one device per worker: what the processes cost before devices.
        small, small_start_s = start_fleet(addresses[:workers], port, io_port, workers, state, tree)
        try:
            time.sleep(1.0)
            base_rss = rss_bytes(fleet_pids(small.pid))
        finally:
            stop_adapter(small, 60)
        fleet, start_s = start_fleet(addresses, port, io_port, workers, state, tree)
        try:
            pids = fleet_pids(fleet.pid)
            context = multiprocessing.get_context("fork")
            channels, processes = [], []
            for index in range(scanners):
                mine, theirs = context.Pipe()
                share = addresses[index::scanners]
                process = context.Process(target=scanner_process, args=(share, port, io_port, seconds, theirs, rpi,
                                                                           late_by))
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
            (cpu_before, wait_before), wall_before = scheduled(pids), time.monotonic()
            user_before, system_before = user_system_seconds(pids)
            time.sleep(seconds * 0.5)
            rss = rss_bytes(pids)
            reports = [channel.recv() for channel in channels]
            (cpu, wait), wall = scheduled(pids), time.monotonic() - wall_before
            user, system = user_system_seconds(pids)
            user, system = user - user_before, system - system_before
            cpu, wait = cpu - cpu_before, wait - wait_before
            for process in processes:
                process.join(30)
            errors = [r["error"] for r in reports if "error" in r]
            if errors:
                raise RuntimeError(errors[0])
        finally:
            stop_adapter(fleet, 60)
    packets = sum(r["packets"] for r in reports)
    late = sum(r["late"] for r in reports)
    pairs_per_s = packets / seconds
    return {"tree": tree or "this tree", "late_by": late_by, "devices": devices, "workers": workers,
            "scanner_processes": scanners, "rpi_ms": rpi * 1e3,
            "seconds": seconds, "connections": sum(r["connections"] for r in reports), "t_to_o_packets": packets,
            "late": late, "late_pct": round(100.0 * late / packets, 3) if packets else None,
            "lost": sum(r["lost"] for r in reports), "timeouts": sum(r["timeouts"] for r in reports),
            "max_interval_ms": max(r["max_interval_ms"] for r in reports),
            "fleet_cpu_share": round(cpu / wall, 3),
            # Ready to run but waiting for a CPU the machine's other processes held, share of the time.
            "fleet_cpu_wait_share": round(wait / wall, 3),
            "scanner_cpu_share": round(sum(r["cpu_share"] for r in reports), 3),
            "fleet_cpu_us_per_pair": round(1e6 * cpu / max(1, pairs_per_s * wall), 1),
            # The same split in user (the interpreter) and system (the kernel) time, from clock ticks.
            "fleet_user_us_per_pair": round(1e6 * user / max(1, pairs_per_s * wall), 1),
            "fleet_system_us_per_pair": round(1e6 * system / max(1, pairs_per_s * wall), 1),
            "scanner_cpu_us_per_pair": round(1e6 * sum(r["cpu_s"] for r in reports) / max(1, packets), 1),
            # What each further drive adds to the start, against the one-drive-per-worker fleet: the
            # processes' own start (Python, imports, the workers) is not the drives'.
            "start_s": round(start_s, 2), "start_base_s": round(small_start_s, 2),
            "start_ms_per_drive": round(1e3 * max(0.0, start_s - small_start_s) / max(1, devices - workers), 2),
            "rss_mb": round(rss / 2**20, 1),
            "rss_per_device_mb": round(rss / devices / 2**20, 2),
            "rss_base_mb": round(base_rss / 2**20, 1),
            "rss_per_further_device_mb": round((rss - base_rss) / max(1, devices - workers) / 2**20, 2)}


def verdict(ok: bool) -> str:
    return "PASS" if ok else "FAIL"


def holds(case: dict[str, Any]) -> bool:
    """Under 1 % of the T->O packets late, none lost, no connection timed out (a case that could not
    run holds nothing)."""
    return ("error" not in case and case["late_pct"] is not None and case["late_pct"] < LATE_PCT_TARGET
            and case["lost"] == 0 and case["timeouts"] == 0)


def matrix_verdicts(case: dict[str, Any]) -> list[tuple[str, bool]]:
    """Issue 50's targets a case is held to: it holds; from ``US_PER_PAIR_FROM`` drives on, the
    fleet's CPU per pair; start-up per drive."""
    found = [(f"holds (late < {LATE_PCT_TARGET:g} %, none lost, no timeout)", holds(case))]
    if "error" in case:
        return found
    if case["devices"] >= US_PER_PAIR_FROM:
        found.append((f"fleet <= {US_PER_PAIR_TARGET:g} us/pair", case["fleet_cpu_us_per_pair"] <= US_PER_PAIR_TARGET))
    found.append((f"start <= {START_MS_PER_DRIVE_TARGET:g} ms/drive",
                  case["start_ms_per_drive"] <= START_MS_PER_DRIVE_TARGET))
    return found


MATRIX_HEADER = (f"{'tree':<16} {'drives':>6} {'RPI':>6} {'workers':>7} {'late %':>7} {'lost':>5} {'t/o':>4} "
                 f"{'fleet CPU':>9} {'CPU wait':>8} {'scanner CPU':>11} {'fleet us/pair':>13} {'user/sys':>9} "
                 f"{'scanner us/pair':>15} "
                 f"{'start s':>7} {'ms/drive':>8} {'RSS MB':>7} {'MB/drive':>8}  targets")


def matrix_row(case: dict[str, Any]) -> str:
    """One case's row; ``CPU wait``: the share of the time the fleet was ready to run and waited for
    a CPU (the machine's other work), ``tree`` the checkout whose fleet ran (``--against``)."""
    tree = os.path.basename(case["tree"].rstrip("/")) or case["tree"]
    if "error" in case:
        return (f"{tree[:16]:<16} {case['devices']:>6} {case['rpi_ms']:>4g}ms {case['workers']:>7}  "
                f"[FAIL] {case['error']}")
    late = "-" if case["late_pct"] is None else f"{case['late_pct']:.3f}"
    targets = ", ".join(f"[{verdict(ok)}] {name}" for name, ok in matrix_verdicts(case))
    return (f"{tree[:16]:<16} {case['devices']:>6} {case['rpi_ms']:>4g}ms {case['workers']:>7} {late:>7} "
            f"{case['lost']:>5} {case['timeouts']:>4} {case['fleet_cpu_share']:>9.3f} "
            f"{case['fleet_cpu_wait_share']:>8.3f} {case['scanner_cpu_share']:>11.3f} "
            f"{case['fleet_cpu_us_per_pair']:>13.1f} "
            f"{case.get('fleet_user_us_per_pair', 0.0):>4.0f}/{case.get('fleet_system_us_per_pair', 0.0):<4.0f} "
            f"{case['scanner_cpu_us_per_pair']:>15.1f} {case['start_s']:>7.2f} "
            f"{case['start_ms_per_drive']:>8.2f} {case['rss_mb']:>7.1f} {case['rss_per_device_mb']:>8.2f}  {targets}")


def sizes_of(text: str) -> list[int]:
    try:
        found = [int(part) for part in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of counts such as 64,128") from None
    if not found or min(found) < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: every count is at least 1")
    return found


def rpi_of(text: str) -> str:
    try:
        if parse_rpi(text) <= 0:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an RPI such as 10ms") from None
    return text.strip()


def rpis_of(text: str) -> list[str]:
    return [rpi_of(part) for part in text.split(",")]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, help="measured time of each case (default 20; 5 with --matrix)")
    parser.add_argument("--only", type=int, choices=sorted(CASES), help="one case: 64 (1 process) or 128 (2 workers)")
    parser.add_argument("--devices", type=int, help="another case: this many drives (with --workers)")
    parser.add_argument("--workers", type=int, default=1, help="the fleet's worker processes with --devices")
    parser.add_argument("--scanners", type=int, help="scanner processes (default: one per fleet worker)")
    parser.add_argument("--rpi", type=rpi_of, default="10ms", help="the connections' RPI (default 10ms)")
    parser.add_argument("--matrix", action="store_true", help="sizes x RPIs x worker counts, one row each")
    parser.add_argument("--sizes", type=sizes_of, default=list(MATRIX_SIZES),
                        help=f"--matrix: drive counts (default {','.join(map(str, MATRIX_SIZES))})")
    parser.add_argument("--rpis", type=rpis_of, default=list(MATRIX_RPIS),
                        help=f"--matrix: RPIs (default {','.join(MATRIX_RPIS)})")
    parser.add_argument("--worker-counts", type=sizes_of, default=list(MATRIX_WORKERS),
                        help=f"--matrix: fleet worker counts (default {','.join(map(str, MATRIX_WORKERS))})")
    parser.add_argument("--against", action="append", default=[], metavar="TREE",
                        help="also run each case's fleet from another checkout (git worktree add), by turns with "
                             "this tree's; the scanners are this tree's (repeatable)")
    parser.add_argument("--late-by", choices=("wire", "read"), default="wire",
                        help="time each T->O packet when the kernel received it (wire, the default) or when the "
                             "scanner read it (read: the scanner's own stalls count as the drives' lateness)")
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the text report")
    args = parser.parse_args(argv)
    seconds = args.seconds if args.seconds is not None else 5.0 if args.matrix else 20.0
    results: dict[str, Any] = {"nproc": os.cpu_count(), "load_average_before": round(os.getloadavg()[0], 2),
                               "cases": []}
    if args.matrix:
        plan = [(devices, parse_rpi(rpi), workers) for devices in args.sizes for rpi in args.rpis
                for workers in args.worker_counts]
    else:
        cases = {args.devices: args.workers} if args.devices else CASES
        plan = [(devices, parse_rpi(args.rpi), workers) for devices, workers in cases.items()
                if args.devices or args.only in (None, devices)]
    trees: list[str | None] = [None, *(os.path.abspath(tree) for tree in args.against)]
    if args.matrix and not args.json:
        print(MATRIX_HEADER, flush=True)
    block = 0
    for devices, rpi, workers in plan:
        for tree in trees:
            try:
                case = run_case(devices, workers, args.scanners or workers, seconds, block, rpi, tree, args.late_by)
            except RuntimeError as exc:   # a case that cannot run (an overloaded fleet) fails; the others go on
                if not args.matrix:
                    raise
                case = {"tree": tree or "this tree", "devices": devices, "workers": workers, "rpi_ms": rpi * 1e3,
                        "error": str(exc).splitlines()[0][:200]}
            block += 1
            results["cases"].append(case)
            if args.matrix and not args.json:
                print(matrix_row(case), flush=True)   # each row as its case ends: a long matrix shows progress
    results["load_average_after"] = round(os.getloadavg()[0], 2)
    if args.json:
        print(json.dumps(results))
    elif args.matrix:
        pass
    else:
        for case in results["cases"]:
            print_case(case)
    if not args.json:
        print(f"nproc {results['nproc']}, load average {results['load_average_before']} before, "
              f"{results['load_average_after']} after")
    if args.matrix:
        return 0 if all(ok for case in results["cases"] for _, ok in matrix_verdicts(case)) else 1
    return 0 if all(holds(case) for case in results["cases"]) else 1


def print_case(case: dict[str, Any]) -> None:
    late_ok = case["late_pct"] is not None and case["late_pct"] < LATE_PCT_TARGET
    lost_ok, timeouts_ok = case["lost"] == 0, case["timeouts"] == 0
    print(f"{case['devices']} ACG drives, {case['workers']} fleet process(es), {case['connections']} "
          f"exclusive-owner connections at RPI {case['rpi_ms']:g} ms from {case['scanner_processes']} "
          f"scanner process(es), {case['seconds']:g} s; the fleet started in {case['start_s']} s "
          f"({case['start_ms_per_drive']} ms per further drive)")
    print(f"    T->O packets {case['t_to_o_packets']}, late {case['late']} ({case['late_pct']} %, target < 1 %) "
          f"[{verdict(late_ok)}], lost {case['lost']} (target 0) [{verdict(lost_ok)}], timeouts "
          f"{case['timeouts']} (target 0) [{verdict(timeouts_ok)}]; longest interval {case['max_interval_ms']} ms")
    print(f"    memory: RSS {case['rss_mb']} MB in all, {case['rss_per_device_mb']} MB per device; a fleet of "
          f"{case['workers']} device(s) {case['rss_base_mb']} MB, each further device "
          f"{case['rss_per_further_device_mb']} MB; fleet CPU {case['fleet_cpu_share']} cores, "
          f"{case['fleet_cpu_us_per_pair']} us per T->O packet with its O->T one; scanner CPU "
          f"{case['scanner_cpu_share']} cores, {case['scanner_cpu_us_per_pair']} us per pair")


if __name__ == "__main__":
    raise SystemExit(main())
