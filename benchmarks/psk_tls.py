"""Explicit messaging over TLS with a pre-shared key (pyOpenSSL, ``security.tls_psk``) against TLS
with certificates (the standard library's ``ssl``), in one run.

```
python benchmarks/psk_tls.py                     # 2000 reads and 100 handshakes each way, 3 rounds
python benchmarks/psk_tls.py --reads 5000 --handshakes 200 --rounds 1
python benchmarks/psk_tls.py --json
```

Two adapters, each started with ``--security``: one with a certificates-only folder (its TLS port is
the standard library's), one with a PSK-only folder (its TLS port is pyOpenSSL's over memory BIOs).
Each round reads Identity's Product Name ``--reads`` times in one TLS session of the blocking scanner
on each, then opens and closes ``--handshakes`` sessions on each, and reads each adapter's CPU time
(``/proc/PID/stat``) over each part. The figures are the ratios, PSK to certificates, of the adapter's
CPU per read and per handshake, both measured in the same round; the median round is printed.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from io_common import cpu_seconds, free_port, start_adapter, stop_adapter


def measure(port: int, credentials: Any, reads: int, handshakes: int, pid: int) -> dict[str, float]:
    """The adapter's CPU per read in one session and per session opened and closed, in microseconds."""
    from cipstack.scanner import SyncScanner

    address = f"127.0.0.1:{port}"
    with SyncScanner(address, security=credentials, identify=False) as drive:
        drive.read(1, 1, 7)
        before = sum(cpu_seconds(pid))
        for _ in range(reads):
            drive.read(1, 1, 7)
        per_read = (sum(cpu_seconds(pid)) - before) / reads * 1e6
    before = sum(cpu_seconds(pid))
    for _ in range(handshakes):
        with SyncScanner(address, security=credentials, identify=False):
            pass
    per_handshake = (sum(cpu_seconds(pid)) - before) / handshakes * 1e6
    return {"cpu_per_read_us": per_read, "cpu_per_handshake_us": per_handshake}


def arguments(doc: str, argv: list[str] | None) -> argparse.Namespace:
    """The options of this benchmark and of ``configured_tls.py``, which runs the same measurement."""
    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("--reads", type=int, default=2000)
    parser.add_argument("--handshakes", type=int, default=100)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--json", action="store_true")
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = arguments(__doc__, argv)

    from cipstack.security import Credentials
    from cipstack.security.provisioning import init

    root = Path(tempfile.mkdtemp())
    init(root / "certificates")
    init(root / "psk", certificates=False, psk=True)
    certificates, psk = Credentials.load(root / "certificates"), Credentials.load(root / "psk")
    ports = {way: (free_port(), free_port()) for way in ("certificates", "psk")}
    adapters = {way: start_adapter(port, 0, "--security", str(root / way), "--security-port", str(secure))
                for way, (port, secure) in ports.items()}
    rounds = []
    try:
        time.sleep(2.0)   # both adapters listen (a benchmark, not a test: no readiness probe needed)
        for _ in range(args.rounds):
            row: dict[str, Any] = {
                way: measure(ports[way][1], credentials, args.reads, args.handshakes, adapters[way].pid)
                for way, credentials in (("certificates", certificates), ("psk", psk))}
            for figure in ("cpu_per_read_us", "cpu_per_handshake_us"):   # None: under one clock tick
                base = row["certificates"][figure]
                row[f"ratio_{figure}"] = row["psk"][figure] / base if base else None
            rounds.append(row)
    finally:
        for adapter in adapters.values():
            stop_adapter(adapter)
        shutil.rmtree(root, ignore_errors=True)
    return report(args, rounds, ("certificates", "psk"), "PSK / certificates")


def report(args: argparse.Namespace, rounds: list[dict[str, Any]], ways: tuple[str, str], ratio: str) -> int:
    """Each round's CPU per read and per handshake of both ``ways``, then the median ratios (JSON with
    ``--json``): what this benchmark and ``configured_tls.py`` print alike."""
    ratios = {figure: [r[f"ratio_{figure}"] for r in rounds if r[f"ratio_{figure}"] is not None]
              for figure in ("cpu_per_read_us", "cpu_per_handshake_us")}
    medians = {figure: statistics.median(values) if values else None
               for figure, values in ratios.items()}
    if args.json:
        print(json.dumps({"rounds": rounds, "median_ratios": medians}))
        return 0
    print(f"{args.reads} reads in one session and {args.handshakes} sessions each way, {args.rounds} round(s)")
    print(f"{'round':>5}  {'way':<12}  {'us/read':>8}  {'us/handshake':>12}")
    for index, r in enumerate(rounds, 1):
        for way in ways:
            w = r[way]
            print(f"{index:>5}  {way:<12}  {w['cpu_per_read_us']:>8.1f}  {w['cpu_per_handshake_us']:>12.1f}")
    shown = {figure: f"{value:.2f}x" if value is not None else "-" for figure, value in medians.items()}
    print(f"adapter CPU, {ratio}: per read {shown['cpu_per_read_us']}, "
          f"per handshake {shown['cpu_per_handshake_us']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
