"""Class 1 target cost without sockets: CPU per T->O packet of ``IoTarget`` as connections grow.

Opens N input-only connections (heartbeat 198 -> input 71 of the ACG-ET2) at RPI 10 ms, opened
one after another over one RPI ("staggered"; the target puts each on the first one's production
slots, ``ProductionGrid``) or all at the same instant ("aligned"), and simulates 2 s: each
connection's heartbeat arrives once per RPI, the timer fires at ``next_deadline()`` and runs
``poll`` and ``expire`` as the asyncio shell does. Prints the CPU time per produced packet for
N = 16, 64, 256, 512: a timer firing should cost what is due, not what is open (the per-packet
figure should stay flat as N grows).

    python benchmarks/io_core.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from cipstack.cip.router import RequestContext
from cipstack.devices.profiles import build_device
from cipstack.eip.target.io_target import IoTarget
from cipstack.eip.wire.cm_messages import ForwardOpenRequest
from tests.attacks import ACG_INPUT_ONLY_PATH, class1_open, io_datagram

RPI = 0.010


def run(n: int, staggered: bool, seconds: float = 2.0) -> tuple[int, float]:
    device = build_device()
    profile = device.io_profile()
    profile.max_connections = n
    io = IoTarget(profile, device, tick=device.advance)
    ids = []
    for index in range(n):
        raw = class1_open(0x100 + index, rpi_us=int(RPI * 1e6), multiplier=2, path=ACG_INPUT_ONLY_PATH, ot_size=2)
        opened_at = index * RPI / n if staggered else 0.0
        context = RequestContext(device.router, opened_at, "127.0.0.1:1", None)
        ids.append(io.forward_open(ForwardOpenRequest.decode(raw[6:], large=False), context).ot_connection_id)
    sequences = [0] * n
    sent, now, next_heartbeats = 0, 0.0, 0.0
    started = time.process_time()
    while now < seconds:
        deadline = io.next_deadline()
        now = next_heartbeats if deadline is None else min(deadline, next_heartbeats)
        if now >= next_heartbeats:
            for index, connection_id in enumerate(ids):
                sequences[index] += 1
                io.receive(io_datagram(connection_id, sequences[index], b""), ("127.0.0.1", 2222), now)
            next_heartbeats += RPI
        sent += len(io.poll(now))
        io.expire(now)
    cpu = time.process_time() - started
    assert len(io.connections) == n, "a connection timed out in the simulation"
    return sent, cpu


def main() -> int:
    print(f"{'connections':>11}  {'staggered us/packet':>20}  {'aligned us/packet':>18}")
    for n in (16, 64, 256, 512):
        figures = []
        for staggered in (True, False):
            sent, cpu = run(n, staggered)
            figures.append(cpu / sent * 1e6)
        print(f"{n:>11}  {figures[0]:>20.1f}  {figures[1]:>18.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
