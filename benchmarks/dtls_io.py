"""Secured class 1 (DTLS on UDP 2221) against plain class 1 (UDP 2222), in one run (issue 48).

```
python benchmarks/dtls_io.py                     # 32 connections at 10 ms, 10 s each way, 3 rounds
python benchmarks/dtls_io.py --connections 32 --rpi 0.010 --seconds 60 --rounds 1
python benchmarks/dtls_io.py --json
```

One adapter with ``--security`` (a lab folder made by ``security init`` in a temporary directory)
serves both. Each round holds N input-only connections (heartbeat 198 -> input 71) plain, then N over
DTLS (all in the scanner's one DTLS session, as ``Scanner.io_connection`` opens them with
``security=``), from the asyncio Scanner in this process, and reads the adapter's CPU time
(``/proc/PID/stat``) over the hold. Packets are what the originator sent and received; none may be
lost (the T->O sequence gaps the originator saw) and no connection may time out. The figure is the
ratio of the adapter's CPU per packet over DTLS to plain, both measured in the same round; the target
is 2x (issue 48). The median round is printed.

The issue's target is a 60 s hold (``--seconds 60``); the default's 10 s holds say so on the verdict
line.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from io_common import acg_class1, cpu_seconds, free_port, start_adapter, stop_adapter

INPUT = 71
RATIO_TARGET = 2.0
#: The hold issue 48 names.
ISSUE_HOLD_S = 60.0


async def hold(port: int, connections: int, rpi: float, seconds: float, security: Any,
               adapter_pid: int) -> dict[str, Any]:
    """Open ``connections`` input-only connections, hold them ``seconds``, and count."""
    from cipstack.scanner import Scanner

    heartbeat = acg_class1().input_only_point
    async with await Scanner.connect(f"127.0.0.1:{port}", timeout=20, security=security) as scanner:
        contexts = [scanner.io_connection(input=INPUT, heartbeat=heartbeat, rpi=rpi, input_size=4,
                                          timeout_multiplier=3) for _ in range(connections)]
        handles = []
        try:
            for context in contexts:
                handles.append(await context.__aenter__())
            await asyncio.sleep(0.5)   # every connection past its first packets
            before = [(h.stats.sent, h.stats.received, h.stats.lost) for h in handles]
            cpu_before = sum(cpu_seconds(adapter_pid))
            await asyncio.sleep(seconds)
            cpu = sum(cpu_seconds(adapter_pid)) - cpu_before
            after = [(h.stats.sent, h.stats.received, h.stats.lost) for h in handles]
            timeouts = sum(1 for h in handles if h.timed_out)
        finally:
            for context in reversed(contexts[:len(handles)]):
                await context.__aexit__(None, None, None)
    sent, received, lost = (sum(a[k] - b[k] for a, b in zip(after, before, strict=True)) for k in range(3))
    packets = sent + received
    return {"opened": len(handles), "sent": sent, "received": received, "lost": lost, "timeouts": timeouts,
            "adapter_cpu_s": cpu, "cpu_per_packet_us": cpu / packets * 1e6 if packets else None}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--connections", type=int, default=32)
    parser.add_argument("--rpi", type=float, default=0.010, help="seconds")
    parser.add_argument("--seconds", type=float, default=10.0, help="each hold, each way")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)

    from cipstack.security import Credentials
    from cipstack.security.provisioning import init

    folder = Path(tempfile.mkdtemp()) / "lab"
    init(folder)
    credentials = Credentials.load(folder)
    port, secure_port = free_port(), free_port()
    adapter = start_adapter(port, 0, "--security", str(folder), "--security-port", str(secure_port),
                            "--max-io-connections", str(max(64, args.connections)))
    rounds = []
    try:
        time.sleep(2.0)   # the adapter listens (a benchmark, not a test: no readiness probe needed)
        for _ in range(args.rounds):
            plain = asyncio.run(hold(port, args.connections, args.rpi, args.seconds, None, adapter.pid))
            secured = asyncio.run(hold(secure_port, args.connections, args.rpi, args.seconds, credentials,
                                       adapter.pid))
            ratio = (secured["cpu_per_packet_us"] / plain["cpu_per_packet_us"]
                     if secured["cpu_per_packet_us"] and plain["cpu_per_packet_us"] else None)
            rounds.append({"plain": plain, "dtls": secured, "ratio": ratio})
    finally:
        stop_adapter(adapter)
    ratios = [r["ratio"] for r in rounds if r["ratio"] is not None]
    median = statistics.median(ratios) if ratios else None
    none_lost = all(r[way]["lost"] == 0 and r[way]["timeouts"] == 0 and r[way]["opened"] == args.connections
                    for r in rounds for way in ("plain", "dtls"))
    passed = median is not None and median <= RATIO_TARGET and none_lost
    if args.json:
        print(json.dumps({"rounds": rounds, "median_ratio": median, "none_lost": none_lost, "passed": passed}))
        return 0 if passed else 1
    print(f"{args.connections} input-only connections at RPI {args.rpi * 1000:g} ms, {args.seconds:g} s each way, "
          f"{args.rounds} round(s)")
    print(f"{'round':>5}  {'way':<5}  {'sent':>7}  {'received':>8}  {'lost':>4}  {'timeouts':>8}  "
          f"{'adapter CPU s':>13}  {'us/packet':>9}")
    for index, r in enumerate(rounds, 1):
        for way in ("plain", "dtls"):
            w = r[way]
            per = f"{w['cpu_per_packet_us']:.1f}" if w["cpu_per_packet_us"] else "-"
            print(f"{index:>5}  {way:<5}  {w['sent']:>7}  {w['received']:>8}  {w['lost']:>4}  {w['timeouts']:>8}  "
                  f"{w['adapter_cpu_s']:>13.3f}  {per:>9}")
        print(f"{index:>5}  ratio  {r['ratio']:.2f}" if r["ratio"] is not None else f"{index:>5}  ratio  -")
    verdict = "PASS" if passed else "FAIL"
    shown = f"{median:.2f}x" if median is not None else "-"
    shorter = (f" (holds of {args.seconds:g} s, shorter than the issue's {ISSUE_HOLD_S:g} s: --seconds "
               f"{ISSUE_HOLD_S:g} for its target)" if args.seconds < ISSUE_HOLD_S else "")
    print(f"adapter CPU per packet, DTLS / plain: {shown} (target {RATIO_TARGET:g}x), none lost: {none_lost}: "
          f"{verdict}{shorter}")
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
