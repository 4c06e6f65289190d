"""Class 1 I/O during a save storm: parameter saves must not move cyclic packets.

Starts the adapter emulator (``python -m cipstack adapter`` with ``--modbus-port`` and a state file
in a temporary directory) and opens one class 1 connection (output 21, input 71) at RPI 2 ms with
cipstack's scanner. Two phases of ``--seconds`` each (default 5):

* baseline: nothing else happens;
* storm: a Modbus TCP client in another process writes 0x03E0 = 0 then 1 as fast as the replies
  come back (each 0 -> 1 is a parameter save: a state file written and fsynced); the saves counted
  are those of the whole storm, which lasts the phase and its half-second settling.

For each phase: saves done, T->O packets per second and their intervals (p50, p99, max), and the
late packets (an interval above 1.5 x RPI, the tolerance ``io.py`` uses). The saves are written off
the event loop's thread, so the storm phase should stay within the baseline's figures; the ratios
storm / baseline are printed.

    python benchmarks/save_storm.py [--seconds N] [--json]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from typing import Any

from io_common import free_port  # benchmarks/ is on the path when a benchmark runs

from cipstack.eip.io_server import run_precise
from cipstack.scanner import Scanner

RPI = 0.002


def start_adapter(port: int, io_port: int, modbus_port: int, state: str) -> subprocess.Popen[bytes]:
    process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--host", "127.0.0.1", "--port",
                                str(port), "--io-port", str(io_port), "--modbus-port", str(modbus_port),
                                "--log-level", "WARNING", "--quiet", "--state", state])
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", modbus_port), timeout=0.2).close()
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return process
        except OSError:
            time.sleep(0.05)
    process.kill()
    raise RuntimeError("adapter did not start")


#: The storm client, in its own process so that it takes nothing from the measuring one.
STORM = r"""
import socket, struct, sys, time
port, seconds = int(sys.argv[1]), float(sys.argv[2])

def recv_exactly(sock, size):
    data = b""
    while len(data) < size:
        chunk = sock.recv(size - len(data))
        if not chunk:
            raise SystemExit("connection closed")
        data += chunk
    return data

saves = errors = transaction = 0
deadline = time.monotonic() + seconds
with socket.create_connection(("127.0.0.1", port)) as sock:
    while time.monotonic() < deadline:
        for value in (0, 1):
            transaction = (transaction + 1) & 0xFFFF
            sock.sendall(struct.pack(">HHHBBHH", transaction, 0, 6, 0xFF, 6, 0x03E0, value))
            head = recv_exactly(sock, 8)                     # MBAP and function code
            recv_exactly(sock, 1 if head[7] & 0x80 else 4)
            if head[7] & 0x80:
                errors += 1
            elif value == 1:
                saves += 1
print(saves, errors)
"""


def start_storm(modbus_port: int, seconds: float) -> subprocess.Popen[str]:
    """Writes 0x03E0 = 0, 1, 0, 1, ... over Modbus TCP (function 6), one request in flight."""
    return subprocess.Popen([sys.executable, "-c", STORM, str(modbus_port), str(seconds)], stdout=subprocess.PIPE,
                            text=True)


def distribution(intervals: Sequence[float]) -> dict[str, Any]:
    if not intervals:
        return {"count": 0}
    ordered = sorted(intervals)

    def pct(p: float) -> float:
        return round(ordered[min(len(ordered) - 1, int(p * len(ordered)))] * 1e3, 3)

    return {"count": len(intervals), "p50_ms": pct(0.50), "p99_ms": pct(0.99), "max_ms": round(ordered[-1] * 1e3, 3),
            "late": sum(1 for i in intervals if i > 1.5 * RPI)}


async def measure(port: int, io_port: int, modbus_port: int, seconds: float) -> dict[str, Any]:
    results: dict[str, Any] = {}
    async with await Scanner.connect(f"127.0.0.1:{port}") as scanner, \
            scanner.io_connection(output=21, input=71, rpi=RPI, target_io_port=io_port, keep_intervals=True,
                                  timeout_multiplier=3) as io:
        for phase in ("baseline", "storm"):
            storm = start_storm(modbus_port, seconds + 1.0) if phase == "storm" else None
            await asyncio.sleep(0.5)
            io.connection.interval_samples.clear()
            io.connection.last_arrival = None
            await asyncio.sleep(seconds)
            intervals = list(io.connection.interval_samples)
            saves = errors = 0
            if storm is not None:
                output, _ = await asyncio.get_running_loop().run_in_executor(None, storm.communicate)
                saves, errors = (int(n) for n in output.split())
            results[phase] = {"saves": saves, "save_errors": errors,
                              "packets_per_s": round((len(intervals) + 1) / seconds, 1), **distribution(intervals)}
        results["originator_watchdog_expired"] = io.timed_out
    return results


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="measured time of each phase (default 5)")
    parser.add_argument("--json", action="store_true", help="one JSON object instead of the text report")
    args = parser.parse_args(argv)
    port, io_port, modbus_port = free_port(), free_port(), free_port()
    with tempfile.TemporaryDirectory() as directory:
        adapter = start_adapter(port, io_port, modbus_port, os.path.join(directory, "state.json"))
        try:
            results = run_precise(measure(port, io_port, modbus_port, args.seconds))
        finally:
            adapter.send_signal(signal.SIGTERM)
            adapter.wait(10)
    results.update(load_average=os.getloadavg()[0], cpus=os.cpu_count(), rpi_ms=RPI * 1e3, seconds=args.seconds)
    if args.json:
        print(json.dumps(results))
        return 0
    print(f"one class 1 connection, RPI {RPI * 1e3:g} ms, {args.seconds:g} s per phase")
    for phase in ("baseline", "storm"):
        r = results[phase]
        print(f"  {phase:<8} saves {r['saves']:5d}  T->O {r['packets_per_s']:7.1f} packets/s  p50 {r.get('p50_ms')} ms"
              f"  p99 {r.get('p99_ms')} ms  max {r.get('max_ms')} ms  late (> {1.5 * RPI * 1e3:g} ms) {r.get('late')}")
    base, storm = results["baseline"], results["storm"]
    if base.get("count") and storm.get("count"):
        print(f"  storm / baseline: packets {storm['packets_per_s'] / base['packets_per_s']:.3f}, "
              f"max interval {storm['max_ms'] / base['max_ms']:.2f}, late {storm['late']} vs {base['late']}")
    print(f"  originator watchdog expired: {results['originator_watchdog_expired']}; "
          f"load average {results['load_average']:.2f} on {results['cpus']} CPUs")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
