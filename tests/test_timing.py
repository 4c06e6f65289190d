"""The suite's clock (tests/timing.py): a run over its budget fails and names its slowest tests; each
test's CPU counts the processes it waited for. Run as pytest in another process, on a suite of three
tests written here, with the plugin and without the project's conftest."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.inner_pytest import environment

ROOT = Path(__file__).resolve().parents[1]

SUITE = '''
import subprocess, sys, time

def test_sleeps():
    time.sleep(0.6)   # the subject: a test that waits without CPU

def test_burns_cpu_in_a_child():
    subprocess.run([sys.executable, "-c", "sum(range(15_000_000))"], check=True)

def test_quick():
    pass
'''


def run(tmp_path: Path, *options: str) -> subprocess.CompletedProcess[str]:
    (tmp_path / "test_three.py").write_text(SUITE, encoding="utf-8")
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "tests.timing",
                           "-n", "0", "--rootdir", str(tmp_path), "test_three.py", *options],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120,
                          env=environment(ROOT))


def _rows(stdout: str) -> dict[str, tuple[float, float]]:
    lines = stdout.splitlines()
    start = next(i for i, line in enumerate(lines) if "slowest tests" in line) + 1
    rows: dict[str, tuple[float, float]] = {}
    for line in lines[start:]:
        parts = line.split()
        if len(parts) != 3 or "::" not in parts[2]:
            break
        rows[parts[2].split("::")[1]] = (float(parts[0]), float(parts[1]))
    return rows


def test_a_run_within_its_budget_passes_and_names_its_slowest_tests(tmp_path: Path) -> None:
    result = run(tmp_path, "--time-budget", "600")
    assert result.returncode == 0, result.stdout + result.stderr
    rows = _rows(result.stdout)
    assert list(rows)[:1] in (["test_sleeps"], ["test_burns_cpu_in_a_child"]) and set(rows) == {
        "test_sleeps", "test_burns_cpu_in_a_child", "test_quick"}
    wall, cpu = rows["test_sleeps"]
    assert wall >= 0.6 and cpu < 0.3            # waiting is wall time, not CPU
    assert rows["test_burns_cpu_in_a_child"][1] > 0.1   # the child's CPU is the test's
    assert "budget: 600 s (+25% allowed): within budget" in result.stdout


def test_a_run_over_its_budget_fails_though_every_test_passed(tmp_path: Path) -> None:
    result = run(tmp_path, "--time-budget", "0.1")
    assert result.returncode == 1, result.stdout + result.stderr
    assert "3 passed" in result.stdout
    assert "budget: 0 s (+25% allowed): OVER BUDGET: the run fails" in result.stdout


def test_without_a_budget_nothing_is_judged_and_every_test_is_written_down(tmp_path: Path) -> None:
    result = run(tmp_path, "--timings", "timings.json")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "budget:" not in result.stdout and "test_sleeps" in result.stdout
    written = json.loads((tmp_path / "timings.json").read_text(encoding="utf-8"))
    tests = {row["test"].split("::")[1]: row for row in written["tests"]}
    assert set(tests) == {"test_sleeps", "test_burns_cpu_in_a_child", "test_quick"}
    assert tests["test_sleeps"]["wall_s"] >= 0.6 and written["wall_s"] >= 0.6
    assert [row["wall_s"] for row in written["tests"]] == sorted((row["wall_s"] for row in written["tests"]),
                                                                 reverse=True)
