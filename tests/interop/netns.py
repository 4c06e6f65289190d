"""A helper script run in a private network namespace (its own loopback, so 44818 and 2222 are
free and a capture on ``lo`` sees only the test's traffic), for the tshark tests."""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

#: The display filter a capture is judged by: a malformed frame, or an expert warning. A frame that
#: carries no EtherNet/IP and whose warnings are TCP's own analysis (a D-SACK, a duplicate ACK after a
#: retransmission on the namespace's loopback under CPU load) is the transport's, not the stack's.
JUDGED = ("_ws.malformed || (_ws.expert.severity >= warning "
          "&& !((tcp.analysis.flags || tcp.options.sack.dsack) && !enip))")

#: The head of a helper script: the adapter's address in the namespace, where its findings go
#: (``seen``, written to seen.json by the script), and whether the adapter listens yet.
PRELUDE = r'''
import asyncio, json, os, signal, socket, subprocess, sys, time, traceback
from pathlib import Path

from waiting import wait_for  # tests/waiting.py, copied next to this script

OUT = Path(sys.argv[1])
PY = sys.executable
ADAPTER = "127.0.0.2"
seen = {"errors": []}


def listening():
    local = f"{socket.inet_aton(ADAPTER)[::-1].hex().upper()}:{44818:04X}"
    with open("/proc/net/tcp") as lines:
        return any(f[1] == local and f[3] == "0A" for f in (line.split() for line in lines))
'''


def require_namespace() -> None:
    """Skip unless tshark, unshare and ip are installed and we may make a namespace (root)."""
    missing = [tool for tool in ("tshark", "unshare", "ip") if shutil.which(tool) is None]
    if missing:
        pytest.skip(f"{' and '.join(missing)} not installed")
    if os.geteuid() != 0:
        pytest.skip("a private network namespace (unshare -n) and a loopback capture need root")


def run_in_namespace(out: Path, name: str, helper: str, *, timeout: float = 120,
                     env: dict[str, str] | None = None) -> dict[str, Any]:
    """Run ``helper`` as ``out/name`` (argument: ``out``; tests/waiting.py beside it) in a new network
    namespace with loopback up; it must exit 0. What it wrote to ``out/seen.json``."""
    script = out / name
    script.write_text(helper)
    shutil.copy(Path(__file__).parents[1] / "waiting.py", out / "waiting.py")
    command = " ".join(shlex.quote(str(part)) for part in (sys.executable, script, out))
    result = subprocess.run(["unshare", "-n", "sh", "-c", f"ip link set lo up && exec {command}"],
                            capture_output=True, text=True, timeout=timeout, check=False, cwd=out, env=env)
    assert result.returncode == 0, f"{result.stdout}\n{result.stderr}"
    return json.loads((out / "seen.json").read_text())  # type: ignore[no-any-return]
