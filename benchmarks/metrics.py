"""What ``GET /metrics`` costs: nothing per packet, and one scrape's time on the event loop.

The collector reads counters the devices keep anyway, at scrape time (``cipstack.control.metrics``);
the class 1 path counts nothing more (a connection's counts are added up when it closes). The one
change on a per-request path is the key of the message router's reply counts: ``service << 8 |
status`` where it was ``status``, one shift and one or on an int. This prints:

* **request**: the adapter's work for one Get_Attribute_Single whose frame is parsed whole
  (``explicit_core.measure`` with two sender contexts), the baseline;
* **count by status** and **count by service and status**: the counting statement before and
  after, each alone in a loop, and the difference as a share of the request;
* **scrape**: one ``/metrics`` exposition of ``--devices`` ACG devices (built as a fleet builds them,
  not listening), as the route writes it (``DeviceCollector.render``, in slices with the loop's other
  work between): its whole time, and the longest slice, the longest the loop is held, against the
  tolerance of a 10 ms RPI's production (half the period, at most 0.5 ms).

    python benchmarks/metrics.py [--devices 64] [--rounds 7]

Best of ``--rounds`` rounds each (the least the machine's other load added); the scrape in CPU time of
its thread.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from explicit_core import measure

from cipstack.control.metrics import DeviceCollector
from cipstack.fleet.serve import api_addresses, build_adapter
from cipstack.fleet.spec import FleetDevice

COUNTS = 1_000_000


def counting(by_service: bool) -> float:
    """Seconds per counting statement, as the router runs it."""
    counts: dict[int, int] = {}
    service, status = 0x0E, 0
    started = time.perf_counter()
    if by_service:
        for _ in range(COUNTS):
            key = service << 8 | status
            counts[key] = counts.get(key, 0) + 1
    else:
        for _ in range(COUNTS):
            counts[status] = counts.get(status, 0) + 1
    return (time.perf_counter() - started) / COUNTS


def scrape(devices: int, rounds: int) -> tuple[float, float, int]:
    """Seconds per exposition of ``devices`` devices, its longest slice, and its size in bytes."""
    adapters = [build_adapter(FleetDevice(f"127.90.{n // 250}.{n % 250 + 1}", "acg"), 0, 0) for n in range(devices)]
    try:
        collector = DeviceCollector(api_addresses(adapters))
        best = longest = float("inf")
        size = 0
        for _ in range(rounds):
            # Driven by hand, each step timed: a step is what runs between two returns to the loop. CPU
            # time of this thread, not wall-clock: on a shared machine the scheduler's own pauses (a
            # few milliseconds under load) would be counted as the scrape's.
            steps = collector.render()
            slices: list[float] = []
            while True:
                started = time.thread_time()
                try:
                    steps.send(None)
                except StopIteration as end:
                    slices.append(time.thread_time() - started)
                    size = len(end.value)
                    break
                slices.append(time.thread_time() - started)
            best, longest = min(best, sum(slices)), min(longest, max(slices))
        return best, longest, size
    finally:
        for adapter in adapters:
            adapter.device.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--devices", type=int, default=64)
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args()
    request = asyncio.run(measure(20_000, args.rounds, new_context=True))
    before = min(counting(False) for _ in range(args.rounds))
    after = min(counting(True) for _ in range(args.rounds))
    scraped, longest, size = scrape(args.devices, args.rounds)
    print(f"request (baseline)          {request * 1e6:8.2f} us")
    print(f"count by status             {before * 1e9:8.1f} ns")
    print(f"count by service and status {after * 1e9:8.1f} ns   difference {(after - before) * 1e9:+.1f} ns, "
          f"{(after - before) / request:+.2%} of a request")
    print(f"scrape of {args.devices} devices        {scraped * 1e3:8.2f} ms   {scraped / args.devices * 1e6:.1f} us a "
          f"device, {size} bytes")
    print(f"longest slice               {longest * 1e3:8.3f} ms   {longest / 0.0005:.0%} of a 10 ms RPI's tolerance "
          f"(0.5 ms)")


if __name__ == "__main__":
    main()
