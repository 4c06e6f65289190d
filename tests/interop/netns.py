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
