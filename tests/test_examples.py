"""Every script of examples/ runs as a reader runs it, against the emulator its docstring names, in a
private network namespace where the default ports (44818, 2222) are free (as the README's blocks do)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_docs import COMMAND_TIMEOUT, Namespace, _namespaces_available, emulator
from tests.test_docs import shell_env as shell_env

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
NETWORK_CONTROL = "cipstack adapter --factory --param drv=4 --param Frq=8"

#: script, the emulator it runs against, set-up commands, arguments, lines its output must have.
CASES = [
    ("ramp_sync.py", NETWORK_CONTROL, [], [],
     ["found CENT vendor 259 product code 100", "output frequency 0.00 Hz", "up to 45 Hz in 1.", "down to 0 Hz in 1.",
      "lost 0 packets"]),
    ("ramp_async.py", NETWORK_CONTROL, [], [],
     ["found CENT vendor 259 product code 100", "output frequency 0.00 Hz", "up to 45 Hz in 1.", "down to 0 Hz in 1.",
      "lost 0 packets"]),
    ("eds_io.py", "cipstack adapter", ["cipstack eds generate --profile acg -o eds"], ["eds/ACG-ET2_1.01.eds"],
     ["declarations: EDS file", "output fields: fault_reset, ", "input fields: ", "input: {"]),
    ("params_round_trip.py", "cipstack adapter --factory", [], [],
     ["409 parameters in drive.toml", "ACC in the recipe: 5.0 s (raw 50)",
      "differs: ACC Acceleration Time: device 7.5 s (75), file 5.0 s (50)", "written: ['ACC'] saved: True",
      "ACC now: 5.0 s"]),
    ("componet_route.py", "cipstack componet --nodes mx2:MX2-A2015-E@3", [], [],
     ["gateway: ", "node 3: ", "profile mx2 ", "accel time: 10000 ms", "accel time now: 2500 ms",
      "output current: 0.0 A"]),
]


def test_every_example_has_a_case() -> None:
    assert sorted(p.name for p in EXAMPLES.glob("*.py")) == sorted(case[0] for case in CASES)


@pytest.mark.parametrize(("script", "adapter", "setup", "arguments", "expected"), CASES, ids=[c[0] for c in CASES])
def test_example(script: str, adapter: str, setup: list[str], arguments: list[str], expected: list[str],
                 shell_env: dict[str, str], tmp_path: Path) -> None:
    reason = _namespaces_available()
    if reason:
        pytest.skip(reason)
    shell_env = {**shell_env, "XDG_DATA_HOME": str(tmp_path / "data")}   # saved parameters stay in this test
    namespace = Namespace()
    try:
        with emulator(namespace, adapter, shell_env, tmp_path) as log:
            for command in setup:
                subprocess.run(namespace.command(["sh", "-c", command]), check=True, env=shell_env, cwd=tmp_path,
                               capture_output=True, timeout=COMMAND_TIMEOUT)
            result = subprocess.run(namespace.command([sys.executable, str(EXAMPLES / script), *arguments]),
                                    capture_output=True, text=True, env=shell_env, cwd=tmp_path,
                                    timeout=COMMAND_TIMEOUT, stdin=subprocess.DEVNULL)
            output = result.stdout + result.stderr
            assert result.returncode == 0, f"{script} exited {result.returncode}\n{output}\n--- emulator ---\n" \
                                           f"{log.read_text()}"
    finally:
        namespace.close()
    for fragment in expected:
        assert fragment in output, f"{fragment!r} not in the output of {script}:\n{output}"
    if "--factory" in adapter:   # what the example wrote or saved left the user's saved drive alone
        assert not list((tmp_path / "data").rglob("*.json")), f"{script} wrote a state file"
