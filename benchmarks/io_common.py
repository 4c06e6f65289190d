"""What the benchmarks share: free loopback ports, the adapter emulator as a subprocess, CPU times,
and captures of class 1 traffic on the loopback interface."""

from __future__ import annotations

import contextlib
import itertools
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING

# The tests' helpers serve the benchmarks too: one definition of a free port (TCP and UDP alike).
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from tests.ports import free_port

if TYPE_CHECKING:
    from cipstack.eip.target.io_target import IoProfile

__all__ = ["free_port"]

CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


@cache
def acg_class1() -> IoProfile:
    """The class 1 offer of the adapter's default profile (the ACG-ET2) as the device declares it:
    its connection limit, input-only heartbeat point and RPI range."""
    from cipstack.devices.profiles import build_device

    profile = build_device().io_profile()
    assert profile is not None
    return profile


def cpu_seconds(pid: int) -> tuple[float, float]:
    """(user, system) CPU seconds of a process, from /proc/PID/stat."""
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return int(fields[11]) / CLOCK_TICKS, int(fields[12]) / CLOCK_TICKS


def machine_busy() -> tuple[float, float]:
    """(busy, total) CPU time of the whole machine so far, from /proc/stat (all cores, in ticks)."""
    with open("/proc/stat") as stat:
        fields = [int(v) for v in stat.readline().split()[1:]]
    idle = fields[3] + fields[4]  # idle + iowait
    return sum(fields) - idle, sum(fields)


def core_pair() -> tuple[int, int] | None:
    """Two CPUs this process may run on: the server's and the clients' (None with fewer than two)."""
    allowed = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    return (allowed[0], allowed[1]) if len(allowed) >= 2 else None


def pin_to_cpu(pid: int, cpu: int | None) -> None:
    """Keep process ``pid`` on ``cpu`` (None: leave it where the scheduler puts it). Done right after
    the process is started, before it starts threads of its own, which inherit it."""
    if cpu is not None:
        os.sched_setaffinity(pid, {cpu})


def start_adapter(port: int, io_port: int, *extra: str, state: bool = True, cpu: int | None = None
                  ) -> subprocess.Popen[bytes]:
    """The adapter emulator on 127.0.0.1; ``state``: a state file of its own (a profile's, not ``--eds``);
    ``cpu``: the one CPU it runs on."""
    state_file = ["--state", os.path.join(tempfile.mkdtemp(), "state.json")] if state else []
    process = subprocess.Popen([sys.executable, "-m", "cipstack", "adapter", "--host", "127.0.0.1", "--port",
                                str(port), "--io-port", str(io_port), "--log-level", "WARNING", "--quiet",
                                *state_file, *extra])
    pin_to_cpu(process.pid, cpu)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
            return process
        except OSError:
            if process.poll() is not None:
                break
            time.sleep(0.05)
    process.kill()
    raise RuntimeError("adapter did not start")


def stop_adapter(process: subprocess.Popen[bytes], wait_s: float = 10.0) -> None:
    """SIGTERM, then SIGKILL if it has not ended within ``wait_s`` (a fleet writes its saves first)."""
    process.send_signal(signal.SIGTERM)
    try:
        process.wait(wait_s)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait(5)


@dataclass
class Verdict:
    """One target of a benchmark: what was measured against what was asked, PASS or FAIL.

    ``floor`` is the same figure for the asyncio echo server (the least an asyncio server spends),
    which stands in for a C stack measured elsewhere; ``higher_is_better`` for rates and shares."""

    name: str
    measured: float | None
    target: float
    unit: str
    floor: float | None = None
    higher_is_better: bool = False
    note: str = ""
    #: A target that needs more than one figure (e.g. "none lost" beside a rate) decides it here.
    passed: bool | None = None
    #: Decimals shown (a ratio's second one matters).
    digits: int = 1

    def __post_init__(self) -> None:
        if self.passed is None:
            if self.measured is None:
                self.passed = False
            elif self.higher_is_better:
                self.passed = self.measured >= self.target
            else:
                self.passed = self.measured <= self.target

    def line(self) -> str:
        measured = "-" if self.measured is None else f"{self.measured:,.{self.digits}f} {self.unit}"
        sign = ">=" if self.higher_is_better else "<="
        text = (f"[{'PASS' if self.passed else 'FAIL'}] {self.name}: {measured} "
                f"(target {sign} {self.target:,g} {self.unit}")
        if self.floor is not None and self.measured is not None:
            ratio = f"{self.measured / self.floor:.1f}x" if self.floor > 0 else "-"
            text += f"; echo floor {self.floor:,.1f} {self.unit}, {ratio} the floor"
        text += ")"
        return text + (f"; {self.note}" if self.note else "")


def can_capture() -> bool:
    """dumpcap and tshark (Wireshark's command-line tools) are both here."""
    return shutil.which("dumpcap") is not None and shutil.which("tshark") is not None


@contextlib.contextmanager
def class1_capture(io_port: int, path: Path) -> Iterator[Path]:
    """dumpcap on the loopback interface, UDP ``io_port`` only, into ``path`` while the block runs."""
    dumpcap = subprocess.Popen(["dumpcap", "-q", "-i", "lo", "-f", f"udp port {io_port}", "-w", str(path)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 10
        while not (path.exists() and path.stat().st_size > 0) and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(0.3)  # the filter is attached once the file has its header
        yield path
        time.sleep(0.3)
    finally:
        dumpcap.send_signal(signal.SIGTERM)
        dumpcap.wait(10)


def wire_times(capture: Path, io_port: int,
               window: tuple[float, float] | None = None) -> tuple[list[float], list[float]]:
    """Capture timestamps of the class 1 datagrams, (O->T, T->O) by the target's port; with ``window``
    (epoch seconds), only those within it."""
    done = subprocess.run(["tshark", "-r", str(capture), "-Y", f"udp.port == {io_port}", "-T", "fields",
                           "-e", "frame.time_epoch", "-e", "udp.srcport", "-e", "udp.dstport"],
                          capture_output=True, text=True, timeout=300, check=True)
    ot: list[float] = []
    to: list[float] = []
    for line in done.stdout.splitlines():
        stamp, source, destination = line.split("\t")
        at = float(stamp)
        if window is not None and not window[0] <= at <= window[1]:
            continue
        if int(destination) == io_port:
            ot.append(at)
        elif int(source) == io_port:
            to.append(at)
    return ot, to


def within(times: Sequence[float], rpi: float) -> tuple[int, float | None]:
    """How many intervals ``times`` make, and the share (%) within half an RPI of the RPI."""
    intervals = [b - a for a, b in itertools.pairwise(times)]
    if not intervals:
        return 0, None
    good = sum(1 for i in intervals if abs(i - rpi) <= rpi / 2)
    return len(intervals), round(100.0 * good / len(intervals), 2)
