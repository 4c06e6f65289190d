"""Explicit messaging over TLS with a device configured over the network (its TLS port pyOpenSSL's, so
that Send Certificate Chain can be honoured: ``security.peer_policy``) against one started with
``--security DIR`` (the standard library's ``ssl``), in one run.

```
python benchmarks/configured_tls.py                  # 2000 reads and 100 handshakes each way, 3 rounds
python benchmarks/configured_tls.py --json
```

Two adapters with the same lab CA: one started with ``--security DIR``, one started in Factory Default
and configured by ``push.configure`` (Verify Client Certificate on, the other attributes at their
defaults). Each round measures both with ``psk_tls.measure`` (the adapter's CPU per read in one session
and per session opened and closed, from ``/proc/PID/stat``); the figures are the ratios, configured to
folder, within the same round; the median round is printed.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from io_common import free_port, start_adapter, stop_adapter
from psk_tls import arguments, measure, report

FIGURES = ("cpu_per_read_us", "cpu_per_handshake_us")


def push(port: int, folder: Path) -> None:
    """Configure the factory-default adapter on ``port`` with the lab CA of ``folder``."""
    from cipstack.scanner import SyncScanner
    from cipstack.security.push import configure

    with SyncScanner(f"127.0.0.1:{port}", identify=False) as plain:
        def request(service: int, class_id: int, instance: int, attribute: int | None,
                    data: bytes) -> tuple[int, Any, bytes]:
            reply = plain.request(service, class_id, instance, attribute, data, check=False)
            return reply.general_status, reply.extended_status, reply.data
        configure(request, folder)


def main(argv: list[str] | None = None) -> int:
    args = arguments(__doc__, argv)

    from cipstack.security import Credentials
    from cipstack.security.provisioning import init

    root = Path(tempfile.mkdtemp())
    init(root / "lab")
    credentials = Credentials.load(root / "lab")
    ports = {way: (free_port(), free_port()) for way in ("folder", "configured")}
    adapters = {"folder": start_adapter(ports["folder"][0], 0, "--security", str(root / "lab"), "--security-port",
                                        str(ports["folder"][1])),
                "configured": start_adapter(ports["configured"][0], 0, "--security-port", str(ports["configured"][1]))}
    rounds = []
    try:
        push(ports["configured"][0], root / "lab")
        time.sleep(2.0)   # both TLS ports listen (a benchmark, not a test: no readiness probe needed)
        for _ in range(args.rounds):
            row: dict[str, Any] = {way: measure(ports[way][1], credentials, args.reads, args.handshakes,
                                                adapters[way].pid) for way in ("folder", "configured")}
            for figure in FIGURES:   # None: under one clock tick
                base = row["folder"][figure]
                row[f"ratio_{figure}"] = row["configured"][figure] / base if base else None
            rounds.append(row)
    finally:
        for adapter in adapters.values():
            stop_adapter(adapter)
        shutil.rmtree(root, ignore_errors=True)
    return report(args, rounds, ("folder", "configured"), "configured / folder")


if __name__ == "__main__":
    sys.exit(main())
