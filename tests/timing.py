"""The suite's time: each test's CPU, the slowest tests, and a budget that fails a run that outgrew it.

Wall time depends on what else the machine does; CPU time much less. Each test's CPU is measured
where it runs: this process's (``time.process_time``, every thread) plus the processes it started
and waited for (``RUSAGE_CHILDREN``: each ``cipstack`` subprocess, each peer). A server started by
a module's fixture is counted where it is waited for, at the module's end; one never waited for is
not counted at all. The figures travel to the controlling process in the test report's
``user_properties`` (pytest-xdist carries them), so the summary holds every worker's tests.

``--time-budget SECONDS`` (`.ci/run` gives it): at the end of the run, the suite's wall time is
compared with the budget, and a run over it by more than ``BUDGET_SLACK`` fails, naming the
twenty slowest tests. docs/contributing.md says how to look at a slow test.
"""

from __future__ import annotations

import json
import resource
import time
from collections.abc import Generator
from pathlib import Path
from typing import Any

import pytest

#: A run may take this much more than its budget before it fails (machines differ, runs differ).
BUDGET_SLACK = 0.25
#: How many of the slowest tests the summary names.
SLOWEST = 20
_CPU_KEY = "cpu_s"
#: Where a test's measurement started: the CPU then, and the index of its figure in user_properties.
_started_key = pytest.StashKey[tuple[float, int]]()


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--time-budget", type=float, default=None, metavar="SECONDS",
                     help="fail the run when its wall time exceeds SECONDS by more than "
                          f"{BUDGET_SLACK:.0%}, and name the {SLOWEST} slowest tests (tests/timing.py)")
    parser.addoption("--timings", default=None, metavar="FILE",
                     help="write every test's wall and CPU seconds to FILE (JSON), slowest first")


def _cpu_now() -> float:
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Generator[None, Any, None]:
    # Before the reports are made: the call's figure goes into the last report (teardown's), which
    # carries ``user_properties`` as they are then.
    started = _cpu_now()
    item.user_properties.append((_CPU_KEY, 0.0))
    index = len(item.user_properties) - 1
    item.stash[_started_key] = (started, index)
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None) -> Generator[None, Any, None]:
    yield
    started, index = item.stash[_started_key]
    item.user_properties[index] = (_CPU_KEY, round(_cpu_now() - started, 3))


class SuiteClock:
    """Collects every test's wall and CPU time in the controlling process, and judges the budget."""

    def __init__(self, budget: float | None, timings: str | None) -> None:
        self.budget = budget
        self.timings = timings
        self.started = time.monotonic()
        self.wall: dict[str, float] = {}
        self.cpu: dict[str, float] = {}

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        self.wall[report.nodeid] = self.wall.get(report.nodeid, 0.0) + report.duration
        if report.when == "teardown":
            for key, value in report.user_properties:
                if key == _CPU_KEY:
                    self.cpu[report.nodeid] = float(value)

    def over_budget(self, elapsed: float) -> bool:
        return self.budget is not None and elapsed > self.budget * (1 + BUDGET_SLACK)

    @pytest.hookimpl(trylast=True)
    def pytest_sessionfinish(self, session: pytest.Session, exitstatus: int) -> None:
        elapsed = time.monotonic() - self.started
        if self.over_budget(elapsed) and session.exitstatus == pytest.ExitCode.OK:
            session.exitstatus = pytest.ExitCode.TESTS_FAILED
        if self.timings is not None:
            rows = [{"test": nodeid, "wall_s": round(seconds, 3), "cpu_s": self.cpu.get(nodeid)}
                    for nodeid, seconds in sorted(self.wall.items(), key=lambda item: -item[1])]
            Path(self.timings).write_text(json.dumps({"wall_s": round(elapsed, 1), "tests": rows}, indent=1),
                                          encoding="utf-8")

    def pytest_terminal_summary(self, terminalreporter: Any) -> None:
        elapsed = time.monotonic() - self.started
        if not self.wall:
            return
        write = terminalreporter.write_line
        terminalreporter.section(f"the {SLOWEST} slowest tests (wall s, CPU s incl. the processes they waited for)")
        for nodeid, seconds in sorted(self.wall.items(), key=lambda item: -item[1])[:SLOWEST]:
            write(f"{seconds:8.2f} {self.cpu.get(nodeid, 0.0):8.2f}  {nodeid}")
        total_cpu = sum(self.cpu.values())
        write(f"suite: {elapsed:.0f} s of wall time, {total_cpu:.0f} s of CPU in its tests")
        if self.budget is not None:
            verdict = "OVER BUDGET: the run fails" if self.over_budget(elapsed) else "within budget"
            write(f"budget: {self.budget:.0f} s (+{BUDGET_SLACK:.0%} allowed): {verdict}")


def pytest_configure(config: pytest.Config) -> None:
    if hasattr(config, "workerinput"):   # a worker of pytest-xdist: the controller sums up
        return
    config.pluginmanager.register(SuiteClock(config.getoption("--time-budget"), config.getoption("--timings")),
                                  "cipstack-suite-clock")
