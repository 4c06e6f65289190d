"""Class 1 originator cost without sockets: CPU per packet of ``class1.IoOriginator``.

The originator's side of ``io_core.py``: N point-to-point connections (21/71, 4 bytes each way) at
RPI 10 ms, simulated for a few seconds on a fake clock: every RPI the core's ``poll`` produces the
O->T datagrams due, a T->O datagram with new data arrives for each connection (``receive``, the
input-change path and the asyncio shell's update queue), ``expire`` and ``next_deadline`` run as
the shell's timer runs them. Prints the CPU time per packet (sent and received together), the best
of ``--rounds``.

    python benchmarks/io_originator_core.py [--connections 128] [--seconds 5] [--rounds 5]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from cipstack.eip.io_core import encode_io_datagram
from cipstack.eip.originator.class1 import Class1Request, IoOriginator, class1_path, new_connection
from cipstack.eip.originator.io_originator import QueueListener

RPI = 0.010


def run(n: int, seconds: float) -> float:
    """CPU seconds per packet, one round."""
    core = IoOriginator()
    request = Class1Request(4, 4, 10_000, 10_000, class1_path(21, 71, 1))
    listeners = [QueueListener() for _ in range(n)]
    for index, listener in enumerate(listeners):
        core.add(new_connection(request, "127.0.0.1", 2222, 0x100 + index, 0x200 + index, 10_000, 10_000, 0.0,
                                listener=listener))
    steps = int(seconds / RPI)
    frames = [[encode_io_datagram(0x200 + i, s, s, s.to_bytes(4, "little")) for s in range(1, steps + 1)]
              for i in range(n)]
    source = ("127.0.0.1", 2222)
    packets = 0
    started = time.process_time()
    for step in range(steps):
        now = step * RPI
        packets += len(core.poll(now, 0.0002))
        for index in range(n):
            core.receive(frames[index][step], source, now + 0.001)
        packets += n
        core.expire(now)
        core.next_deadline()
        for listener in listeners:   # a reader takes each update
            queue = listener.queue
            while not queue.empty():
                queue.get_nowait()
    return (time.process_time() - started) / packets


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--connections", type=int, default=128)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    best = min(run(args.connections, args.seconds) for _ in range(args.rounds))
    print(f"{args.connections} connections at {RPI * 1e3:g} ms: {best * 1e6:.3f} µs of CPU per packet "
          f"(best of {args.rounds})")


if __name__ == "__main__":
    main()
