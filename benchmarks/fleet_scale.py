"""A fleet at scale: what a drive costs to start, and how fast a scanner opens a plant's connections.

``start``: builds and starts N ACG drives in this process, as one fleet worker does (``DeviceSet``),
and prints the CPU time per drive (``time.process_time``: the machine's other load does not count).
Target (issue 50): 5 ms or less per drive, at 256 and 1,024 drives.

``opens``: starts ``python -m cipstack fleet`` with N drives on loopback addresses (127.98.x.y) and W
workers, then opens one exclusive owner (output 21, input 71) to every drive with
``open_io_connections`` at each RPI, holds them ``--hold`` seconds, and prints how long the opens took,
the connections that timed out, whether the fleet still ran (it never stops itself for being slow) and
the lines it logged about late workers. Target (issue 50): 1,024 connections open within 10 s at any RPI.

    python benchmarks/fleet_scale.py start [--sizes 256 1024]
    python benchmarks/fleet_scale.py opens [--devices 1024] [--workers 2] [--rpis 1000 100 10] [--in-flight 512]

Timings are wall-clock on a shared machine for ``opens``: compare runs made in the same conditions.
"""

from __future__ import annotations

import argparse
import asyncio
import ipaddress
import logging
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

from cipstack.async_scanner import OPENS_IN_FLIGHT, open_io_connections
from cipstack.devices.profiles import PROFILES
from cipstack.eip.io_core import DEFAULT_IO_PORT
from cipstack.eip.io_server import run_precise
from cipstack.eip.wire.encapsulation import DEFAULT_PORT
from cipstack.fleet.serve import DeviceSet
from cipstack.fleet.spec import assign, parse_group

#: The targets of issue 50.
START_MS_PER_DRIVE = 5.0
OPEN_SECONDS = 10.0


def hosts(count: int, first: str = "127.98.0.1") -> list[str]:
    start = ipaddress.IPv4Address(first)
    return [str(start + n) for n in range(count)]


def verdict(ok: bool) -> str:
    return "[PASS]" if ok else "[FAIL]"


def start_cost(size: int) -> float:
    """CPU milliseconds per drive to build and start ``size`` drives in one process."""
    pool = [ipaddress.IPv4Address(h) for h in hosts(size)]
    devices = assign([parse_group(f"acg*{size}")], pool, None, limit=size)

    async def run() -> float:
        fleet = DeviceSet(devices, DEFAULT_PORT, DEFAULT_IO_PORT)   # as a fleet listens: each class 1 bind checked
        began = time.process_time()
        await fleet.start()
        took = time.process_time() - began
        await fleet.stop()
        return took

    return run_precise(run()) * 1000 / size


def open_plant(addresses: Sequence[str], port: int, rpi: float, in_flight: int, hold: float) -> tuple[float, int]:
    """Seconds to open one connection to each address, and how many had timed out after ``hold`` s."""
    make = PROFILES["acg"].catalog
    assert make is not None
    catalog = make()

    async def run() -> tuple[float, int]:
        began = time.monotonic()
        async with open_io_connections([f"{a}:{port}" for a in addresses], output=21, input=71, rpi=rpi,
                                       in_flight=in_flight, catalog=catalog, timeout=60.0,
                                       timeout_multiplier=7) as handles:
            took = time.monotonic() - began
            await asyncio.sleep(hold)
            return took, sum(1 for handle in handles if handle.timed_out)

    return run_precise(run())


def opens(devices: int, workers: int, rpis: Sequence[float], in_flight: int, hold: float) -> bool:
    # The scanner's connections say, each, that an overloaded fleet produces slower than its RPI: the
    # benchmark counts what matters of that (timeouts, the fleet's own lines), a thousand lines would hide it.
    logging.getLogger("cipstack").setLevel(logging.ERROR)
    addresses = hosts(devices)
    ok = True
    for rpi_ms in rpis:
        with tempfile.TemporaryDirectory() as directory:
            log = Path(directory) / "fleet.err"
            with log.open("w") as err:
                fleet = subprocess.Popen([sys.executable, "-m", "cipstack", "fleet", "--addresses",
                                          f"{addresses[0]}-{addresses[-1]}", "--device", f"acg*{devices}",
                                          "--workers", str(workers), "--factory", "--max-devices", str(devices)],
                                         stdout=subprocess.DEVNULL, stderr=err, stdin=subprocess.DEVNULL)
            try:
                began = time.monotonic()
                while "emulating" not in log.read_text():
                    if fleet.poll() is not None:
                        raise SystemExit(f"the fleet did not start: {log.read_text()[-500:]}")
                    time.sleep(0.05)
                started = time.monotonic() - began
                took, timed_out = open_plant(addresses, 44818, rpi_ms / 1000, in_flight, hold)
                running = fleet.poll() is None
            finally:
                fleet.send_signal(signal.SIGINT)
                status = fleet.wait(60)
            late = [line.split("WARNING cipstack.fleet.workers: ", 1)[1][:110]
                    for line in log.read_text().splitlines() if "is late" in line]
        passed = took <= OPEN_SECONDS and running and status == 0 and timed_out == 0
        ok = ok and passed
        print(f"{verdict(passed)} {devices} drives on {workers} worker(s) at RPI {rpi_ms:g} ms: fleet up in "
              f"{started:.1f} s; {devices} opens ({in_flight} in flight) in {took:.2f} s; {timed_out} timed out "
              f"after {hold:g} s; fleet {'still ran' if running else 'had stopped'}, exit {status}; "
              f"{len(late)} late-worker line(s)")
        for line in late[:4]:
            print(f"    {line}...")
    return ok


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    sub = parser.add_subparsers(dest="what", required=True)
    start = sub.add_parser("start")
    start.add_argument("--sizes", type=int, nargs="+", default=[256, 1024])
    opening = sub.add_parser("opens")
    opening.add_argument("--devices", type=int, default=1024)
    opening.add_argument("--workers", type=int, default=2)
    opening.add_argument("--rpis", type=float, nargs="+", default=[1000.0, 100.0, 10.0], metavar="MS")
    opening.add_argument("--in-flight", type=int, default=OPENS_IN_FLIGHT)
    opening.add_argument("--hold", type=float, default=5.0)
    args = parser.parse_args(argv)
    if args.what == "start":
        ok = True
        for size in args.sizes:
            cost = start_cost(size)
            ok = ok and cost <= START_MS_PER_DRIVE
            print(f"{verdict(cost <= START_MS_PER_DRIVE)} {size} drives: {cost:.2f} ms of CPU per drive to start "
                  f"(target {START_MS_PER_DRIVE:g})")
        return 0 if ok else 1
    return 0 if opens(args.devices, args.workers, args.rpis, args.in_flight, args.hold) else 1


if __name__ == "__main__":
    sys.exit(main())
