"""Multicast T->O on the default I/O port, inside a private network namespace (root)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("unshare") or not shutil.which("ip"),
                                reason="needs root, unshare and ip for a private network namespace")

SCRIPT = textwrap.dedent('''
    import asyncio, json, sys
    sys.path[:0] = [{tests!r}, {root!r}]  # test_io_live, and the tests package it imports from
    from test_io_live import CATALOG, start_adapter
    from cipstack.scanner import Scanner

    async def main():
        adapter = await start_adapter("127.0.0.1", io_port=2222)
        try:
            owner_scanner = await Scanner.connect(f"127.0.0.1:{{adapter.port}}", catalog=CATALOG)
            listener_scanner = await Scanner.connect(f"127.0.0.1:{{adapter.port}}", catalog=CATALOG)
            async with owner_scanner, listener_scanner, \\
                    owner_scanner.io_connection(output=21, input=71, rpi=0.005, multicast=True) as owner, \\
                    listener_scanner.io_connection(input=71, heartbeat=199, rpi=0.005, multicast=True) as listener:
                owner.output.speed_reference = 777
                await owner.wait_input(lambda i: i.speed_actual == 777, 3)
                await listener.wait_input(lambda i: i.speed_actual == 777, 3)
                destinations = sorted({{c.destination for c in adapter.io.connections.values()}})
                shared = owner.connection.to_connection_id == listener.connection.to_connection_id
                # The owner's originator stops producing (a PLC that died): the owner times out at the
                # target (5 ms x 4 x 2^2 = 80 ms) and its listener goes with it.
                owner.connection.closed = True
                for _ in range(30):                    # within 0.3 s: both gone
                    if not adapter.io.connections:
                        break
                    await asyncio.sleep(0.01)
                left = len(adapter.io.connections)
            print(json.dumps({{"destinations": destinations, "shared": shared, "left": left,
                               "owner_received": owner.stats.received, "listener_received": listener.stats.received}}))
        finally:
            await adapter.close()

    asyncio.run(main())
''')


def test_multicast_owner_and_listener(tmp_path: Path) -> None:
    script = tmp_path / "multicast.py"
    tests = Path(__file__).parent
    script.write_text(SCRIPT.format(tests=str(tests), root=str(tests.parent)))
    result = subprocess.run(["unshare", "-n", "sh", "-c", f"ip link set lo up && exec {sys.executable} {script}"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.strip().splitlines()[-1])
    # 127.0.0.1/8 is host 1: the CIP default block starts at 239.192.1.0, port 2222.
    assert report["destinations"] == [["239.192.1.0", 2222]]
    assert report["shared"] is True
    assert report["left"] == 0
    assert report["owner_received"] > 0 and report["listener_received"] > 0
