"""Soak: the attack cases of ``tests/attacks.py`` at length against the adapter emulator.

Starts ``python -m cipstack adapter`` (default profile, the limits of ``attacks.OPTIONS``) on free
loopback ports and runs every case at its soak scale (``--scale`` multiplies it), seeded. For each
case it prints its figures, whether it held (no broken rule, the adapter alive and serving), and
the adapter's RSS and open descriptors before and after; at the end the adapter's log is scanned
for tracebacks and its size reported. Exit status 1 if any case failed or the adapter died.

    python benchmarks/soak.py                       # every case, a few minutes
    python benchmarks/soak.py --scale 0.1           # the same, a tenth of the load
    python benchmarks/soak.py --case list_identity_flood --case connection_flood --json

The suite runs the same cases at a small scale (``tests/test_hardening.py``). Timings are
wall-clock on a shared machine.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import socket
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from io_common import free_port  # benchmarks/ is on the path when a benchmark runs

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tests.attacks import CASES, OPTIONS, AttackTarget, Client, served  # noqa: E402


def rss_bytes(pid: int) -> int:
    with open(f"/proc/{pid}/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    return 0


def open_fds(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def start_adapter(port: int, io_port: int, log_path: Path, modbus_port: int | None) -> subprocess.Popen[bytes]:
    directory = tempfile.mkdtemp(prefix="soak-")
    argv = [sys.executable, "-m", "cipstack", "adapter", "--host", "127.0.0.1", "--port", str(port), "--io-port",
            str(io_port), "--log-level", "WARNING", "--quiet", "--state", os.path.join(directory, "state.json"),
            "--control", os.path.join(directory, "control")]
    for name, value in OPTIONS.items():
        argv += [f"--{name.replace('_', '-')}", str(value)]
    if modbus_port is not None:
        argv += ["--modbus-port", str(modbus_port)]
    log = open(log_path, "wb")  # noqa: SIM115 (the adapter writes it for the whole run)
    process = subprocess.Popen(argv, stderr=log, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return process
        except OSError:
            time.sleep(0.05)
    process.kill()
    raise RuntimeError(f"adapter did not start: {log_path.read_text()[-2000:]}")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--case", action="append", choices=[case.name for case in CASES],
                        help="run this case (repeatable; default all)")
    parser.add_argument("--scale", type=float, default=1.0, help="multiply every case's soak scale (default 1)")
    parser.add_argument("--seed", default="soak", help="seed of the cases' randomness (default 'soak')")
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the text report")
    args = parser.parse_args(argv)
    cases = [case for case in CASES if not args.case or case.name in args.case]
    port, io_port = free_port(), free_port()
    modbus_port = free_port() if any("modbus" in case.needs for case in cases) else None
    log_path = Path(tempfile.mkdtemp(prefix="soak-log-")) / "adapter.log"
    adapter = start_adapter(port, io_port, log_path, modbus_port)
    pid = adapter.pid
    target = AttackTarget(port, io_port, rss=lambda: rss_bytes(pid), fds=lambda: open_fds(pid),
                          log_lines=lambda: log_path.read_text(errors="replace").splitlines(),
                          extra={"modbus_port": modbus_port} if modbus_port is not None else {})
    results: dict[str, Any] = {"cpus": os.cpu_count(), "load_average": os.getloadavg()[0], "options": OPTIONS,
                               "cases": []}
    start_rss, start_fds = target.rss(), target.fds()
    failures = 0
    try:
        for case in cases:
            scale = max(1, int(case.soak_scale * args.scale))
            before = {"rss": target.rss(), "fds": target.fds()}
            started = time.monotonic()
            record: dict[str, Any] = {"case": case.name, "scale": scale}
            try:
                record["figures"] = case.run(target, scale, random.Random(f"{args.seed}-{case.name}"))
                with Client(port) as good:
                    served(target, good)
                record["held"] = True
            except Exception as exc:  # a broken rule or a dead adapter: report it, go on
                record["held"] = False
                record["error"] = "".join(traceback.format_exception_only(exc)).strip()[:500]
                failures += 1
            record["seconds"] = round(time.monotonic() - started, 1)
            if adapter.poll() is not None:
                record["held"] = False
                record["error"] = f"adapter exited with {adapter.returncode}"
                results["cases"].append(record)
                failures += 1
                break
            time.sleep(0.5)  # let closed connections go before counting
            record["rss_before"], record["fds_before"] = before["rss"], before["fds"]
            record["rss_after"], record["fds_after"] = target.rss(), target.fds()
            results["cases"].append(record)
            if not args.json:
                print_case(record)
    finally:
        alive = adapter.poll() is None
        end_rss, end_fds = (target.rss(), target.fds()) if alive else (0, 0)
        if alive:
            adapter.send_signal(signal.SIGTERM)
            adapter.wait(10)
    log_text = log_path.read_text(errors="replace")
    results.update(adapter_alive=alive, rss_start=start_rss, rss_end=end_rss, fds_start=start_fds, fds_end=end_fds,
                   log_bytes=len(log_text), log_tracebacks=log_text.count("Traceback"))
    failures += results["log_tracebacks"] > 0 or not alive
    if args.json:
        print(json.dumps(results))
    else:
        print(f"adapter {'alive' if alive else 'DEAD'}: RSS {start_rss / 2**20:.1f} MB -> {end_rss / 2**20:.1f} MB, "
              f"descriptors {start_fds} -> {end_fds}; log {len(log_text)} bytes, "
              f"{results['log_tracebacks']} tracebacks")
        print(f"{len(results['cases'])} cases, {failures} failed; load average {results['load_average']:.2f} "
              f"on {results['cpus']} CPUs")
    return 1 if failures else 0


def print_case(record: dict[str, Any]) -> None:
    verdict = "held" if record["held"] else "FAILED"
    print(f"{record['case']:<30} {verdict:<7} scale {record['scale']:>7}  {record['seconds']:>6.1f} s  "
          f"RSS {record['rss_before'] / 2**20:6.1f} -> {record['rss_after'] / 2**20:6.1f} MB  "
          f"fds {record['fds_before']:>5} -> {record['fds_after']:<5}")
    if "figures" in record:
        figures = {k: (round(v / 2**20, 1) if k.startswith("rss") else v) for k, v in record["figures"].items()}
        print(f"    {figures}")
    if "error" in record:
        print(f"    {record['error']}")


if __name__ == "__main__":
    raise SystemExit(main())
