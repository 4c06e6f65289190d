"""A fleet at scale: more than 1,024 devices where the machine allows (and one line where it does not),
and it overloads gracefully: a worker held up (SIGSTOP for less than the dead threshold, as a
CPU-starved one is) keeps every device up, its parent reports it late instead of stopping the fleet,
and the lateness shows on ``/metrics``, in ``drive status`` and in the log; a scanner opens hundreds of
class 1 connections against a fleet with many Forward_Opens in flight. Real subprocesses, real sockets
on loopback."""

from __future__ import annotations

import asyncio
import ipaddress
import os
import resource
import signal
import subprocess
import sys
import threading
import urllib.request
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("aiohttp", reason="aiohttp is not installed (the http extra): pip install '.[http]'")

from cipstack.async_scanner import open_io_connections
from cipstack.catalog import Catalog
from cipstack.devices.profiles import PROFILES
from cipstack.eip.io_server import run_precise
from cipstack.fleet.load import LATE_LAG, ON_TIME_ANSWERS, LoadReport, LoadWatch
from tests.ports import free_port
from tests.test_fleet import Fleet, alive, drive
from tests.test_fleet_http import Api, worker_pid
from tests.waiting import wait_for

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="any 127.x on loopback")


def addresses(block: int, count: int) -> list[str]:
    """``count`` consecutive loopback addresses from 127.93.BLOCK.1 (this file's own)."""
    first = ipaddress.IPv4Address(f"127.93.{block}.1")
    return [str(first + n) for n in range(count)]


def acg_catalog() -> Catalog:
    """The ACG's catalog, built once for all of a scanner's connections (no Identity round trip each)."""
    make = PROFILES["acg"].catalog
    assert make is not None
    return make()


def metric(text: str, name: str, worker: int) -> float:
    """The sample ``name{worker="N"}`` of a ``/metrics`` text."""
    prefix = f'{name}{{worker="{worker}"}} '
    values = [float(line[len(prefix):]) for line in text.splitlines() if line.startswith(prefix)]
    assert len(values) == 1, (name, worker, [line for line in text.splitlines() if name in line])
    return values[0]


def test_a_worker_goes_late_and_on_time_again_by_its_answers() -> None:
    watch = LoadWatch()
    assert watch.answered(LoadReport(0.0, 0.0, 1000, 0, 0), 1.0) is None and not watch.late
    # Late productions alone (past a tolerance of half a millisecond) are a busy machine, not overload.
    assert watch.answered(LoadReport(0.0, 0.0, 2000, 200, 0), 2.0) is None and not watch.late
    # 20 of 1,020 slots skipped since the last answer: 2 %, over the 1 % share.
    assert watch.answered(LoadReport(0.0, 0.0, 3000, 200, 20), 3.0) == "late" and watch.late
    assert watch.recent == (1000, 0, 20)
    assert watch.describe().startswith("20 of 1020 production slots missed (2.0 %) and 0 late since the last answer")
    assert watch.answered(LoadReport(0.0, LATE_LAG * 2, 4000, 200, 20), 4.0) is None and watch.late
    for n in range(ON_TIME_ANSWERS - 1):
        assert watch.answered(LoadReport(0.0, 0.0, 5000 + 1000 * n, 200, 20), 5.0 + n) is None and watch.late
    assert watch.answered(LoadReport(0.0, 0.0, 9000, 200, 20), 9.0) == "on time" and not watch.late
    assert not watch.stuck
    watch.answered(LoadReport(31.0, 0.0, 9000, 200, 20), 10.0)
    assert watch.stuck


class Connections:
    """Class 1 connections at RPI 10 ms to ``targets``, held open by a scanner on a thread of its own
    (its own precise loop) until ``close``; the timeout is RPI x 4 x 2^7 = 25.6 s, longer than the stop.
    At RPI 50 ms a worker of four drives is on time on a machine busy with other suites, so that being
    late is the stop's doing; the 2 s stop still skips 40 slots of each connection."""

    def __init__(self, targets: list[str]) -> None:
        self.targets = targets
        self.opened = threading.Event()
        self.closing = threading.Event()
        self.result: dict[str, Any] = {}
        self.thread = threading.Thread(target=lambda: run_precise(self._hold()), daemon=True)
        self.thread.start()

    async def _hold(self) -> None:
        try:
            async with open_io_connections(self.targets, output=21, input=71, rpi=0.050, timeout_multiplier=7,
                                           catalog=acg_catalog()) as handles:
                self.opened.set()
                await asyncio.get_running_loop().run_in_executor(None, self.closing.wait)
                self.result = {"timed_out": sum(1 for h in handles if h.timed_out),
                               "received": [h.stats.received for h in handles]}
        except Exception as exc:   # said to the test, never a silent thread
            self.result = {"error": f"{type(exc).__name__}: {exc}"}
            self.opened.set()

    def close(self) -> dict[str, Any]:
        self.closing.set()
        self.thread.join(30)
        return self.result


@pytest.mark.parametrize("workers", [2, 1])
def test_a_held_up_worker_stays_up_and_its_lateness_is_reported(tmp_path: Path, workers: int) -> None:
    """SIGSTOP for 2 s, less than the 5 s after which a silent worker counts as dead: every production
    slot of the pause is skipped. The parent says the worker is late (not that it stopped answering),
    every device stays up, the scanner's connections stay open, and the missed productions show on
    ``/metrics`` per worker, in the device's ``drive status``, and the worker is on time again after.
    A fleet of one process judges itself the same way, as its worker 1."""
    from cipstack.fleet.workers import HEARTBEAT_TIMEOUT

    hosts = addresses(workers - 1, 4)
    port, http = free_port(*hosts), free_port()
    fleet = Fleet(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*4", "--port", str(port),
                  "--io-port", "0", "--workers", str(workers), "--factory", "--http", f"127.0.0.1:{http}")
    name = f"worker 1 ({hosts[0]}-{hosts[1]})" if workers == 2 else f"the fleet ({hosts[0]}-{hosts[-1]})"
    connections = None
    try:
        fleet.wait_ready()
        api = Api(f"http://127.0.0.1:{http}", token=None)
        connections = Connections([f"{host}:{port}" for host in hosts])
        assert connections.opened.wait(30) and "error" not in connections.result, connections.result
        held = worker_pid(hosts[0], port)
        resumed = threading.Event()

        def resume() -> None:
            os.kill(held, signal.SIGCONT)
            resumed.set()

        pause = HEARTBEAT_TIMEOUT - 3.0
        os.kill(held, signal.SIGSTOP)
        threading.Timer(pause, resume).start()
        assert resumed.wait(pause + 5)
        wait_for(lambda: "is late" in fleet.err.read_text(), 15, "the parent to report the late worker")
        log = fleet.err.read_text()
        assert f"{name} is late: " in log and "it goes on serving" in log, log
        assert "stopped answering" not in log and alive(held)

        def scraped() -> str:
            with urllib.request.urlopen(f"http://127.0.0.1:{http}/metrics", timeout=30) as reply:
                return str(reply.read().decode())

        wait_for(lambda: metric(scraped(), "cipstack_fleet_worker_productions_missed_total", 1) > 0, 10,
                 "worker 1's missed productions on /metrics")
        text = scraped()
        assert metric(text, "cipstack_fleet_worker_productions_sent_total", 1) > 0
        assert metric(text, "cipstack_fleet_worker_productions_sent_total", workers) > 0
        assert f'cipstack_class1_productions_missed_total{{device="{hosts[0]}"}}' in text
        status, body = api("GET", f"/devices/{hosts[0]}/status")
        assert status == 200 and body["productions"]["missed"] > 0, body
        shown = drive("status", "--host", hosts[0], "--port", str(port))
        assert shown.returncode == 0 and "missed" in shown.stdout, shown
        for host in hosts:
            assert api("GET", f"/devices/{host}/status")[0] == 200
        wait_for(lambda: f"{name} is on time again" in fleet.err.read_text(), 30, "worker 1 to be on time again")
        result = connections.close()
        assert result["timed_out"] == 0 and all(received > 0 for received in result["received"]), result
        assert fleet.stop(signal.SIGINT) == 0, fleet.err.read_text()
        assert "Traceback" not in fleet.err.read_text()
    finally:
        if connections is not None:
            connections.closing.set()
        fleet.kill()


def test_hundreds_of_connections_open_against_a_fleet(tmp_path: Path) -> None:
    """256 drives on two workers: one exclusive owner each, opened with many Forward_Opens in flight;
    every one opens and every one brings input."""
    hosts = addresses(2, 256)
    port = free_port(hosts[0], hosts[-1])
    fleet = Fleet(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*256", "--port", str(port),
                  "--io-port", "0", "--workers", "2", "--factory")
    try:
        fleet.wait_ready(60)

        async def open_all() -> list[int]:
            async with open_io_connections([f"{host}:{port}" for host in hosts], output=21, input=71, rpi=0.100,
                                           catalog=acg_catalog(), timeout_multiplier=5) as handles:
                assert len(handles) == len(hosts)
                while not all(handle.stats.received for handle in handles):
                    await asyncio.sleep(0.05)
                return [handle.stats.received for handle in handles]

        received = run_precise(asyncio.wait_for(open_all(), 60))
        assert len(received) == 256 and min(received) > 0
        assert fleet.stop(signal.SIGINT) == 0, fleet.err.read_text()
    finally:
        fleet.kill()


@pytest.mark.overload  # 1,030 drives start on both CPUs at once
def test_more_than_1024_devices_where_the_machine_allows(tmp_path: Path) -> None:
    """1,024 is a default: ``--max-devices`` lets 1,030 drives serve on two workers, each of them found
    at its address."""
    hosts = addresses(8, 1030)
    port = free_port(hosts[0], hosts[-1])
    fleet = Fleet(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*1030", "--port", str(port),
                  "--io-port", "0", "--workers", "2", "--factory", "--max-devices", "1030")
    try:
        lines = fleet.wait_ready(120)
        assert len(lines) == 1030 and lines[-1].startswith(f"{hosts[-1]}:{port}  acg"), lines[-1]
        shown = drive("status", "--host", hosts[-1], "--port", str(port))
        assert shown.returncode == 0 and "class 1 0" in shown.stdout, shown
        assert fleet.stop(signal.SIGINT) == 0, fleet.err.read_text()
    finally:
        fleet.kill()


def test_a_fleet_the_open_file_limit_cannot_hold_is_one_line(tmp_path: Path) -> None:
    """Under a hard limit of 1,024 open files, 200 drives in one process (about 2,656 descriptors) are
    refused before anything listens, with the number of workers that would fit."""
    hosts = addresses(14, 200)

    def limited() -> None:
        resource.setrlimit(resource.RLIMIT_NOFILE, (1024, 1024))

    refused = subprocess.run([sys.executable, "-m", "cipstack", "fleet", "--addresses", f"{hosts[0]}-{hosts[-1]}",
                              "--device", "acg*200", "--factory"], capture_output=True, text=True, timeout=60,
                             preexec_fn=limited, stdin=subprocess.DEVNULL, cwd=tmp_path)
    assert refused.returncode == 2 and refused.stdout == "", refused
    lines = refused.stderr.splitlines()
    assert len(lines) == 1 and lines[0] == (
        "cipstack fleet: 200 devices on 1 worker(s): 200 in one process need about 2656 open files, and the hard "
        "limit here is 1024 (ulimit -Hn): give --workers 4 or more, or raise the limit"), lines


@pytest.mark.overload  # both CPUs saturated for seconds: the timing of any test beside it would suffer
def test_many_drives_at_a_tiny_rpi_overload_the_fleet_and_every_drive_stays_up(tmp_path: Path) -> None:
    """192 drives on two workers, one connection each at RPI 2 ms: 96,000 productions a second each way,
    more than the two cores carry. For a few seconds the workers go late; the fleet says so and serves
    on: none is reported dead or stuck, and once the connections close every device answers the
    grid's request with the productions it missed, the workers are on time again, and it stops cleanly."""
    hosts = addresses(20, 192)
    port, http = free_port(hosts[0], hosts[-1]), free_port()
    fleet = Fleet(tmp_path, "--addresses", f"{hosts[0]}-{hosts[-1]}", "--device", "acg*192", "--port", str(port),
                  "--io-port", "0", "--workers", "2", "--factory", "--http", f"127.0.0.1:{http}")
    try:
        fleet.wait_ready(60)

        async def overload() -> None:
            async with open_io_connections([f"{host}:{port}" for host in hosts], output=21, input=71, rpi=0.002,
                                           catalog=acg_catalog(), timeout=30.0, timeout_multiplier=7) as handles:
                assert len(handles) == len(hosts)
                await asyncio.get_running_loop().run_in_executor(
                    None, lambda: wait_for(lambda: "is late" in fleet.err.read_text(), 30, "a worker reported late"))

        run_precise(asyncio.wait_for(overload(), 120))
        api = Api(f"http://127.0.0.1:{http}", token=None)
        rows: list[dict[str, Any]] = []

        def every_device_answers() -> bool:
            rows[:] = api("GET", "/plant")[1]
            return len(rows) == 192 and not any("error" in row for row in rows)

        wait_for(every_device_answers, 30, "every device's row once the load is gone")
        assert sum(row["missed"] for row in rows) > 0
        wait_for(lambda: fleet.err.read_text().count("is on time again") >= 1, 30, "a worker on time again")
        log = fleet.err.read_text()
        assert "stopped answering" not in log and "stopping the fleet" not in log and "is stuck" not in log
        assert fleet.process.poll() is None
        assert fleet.stop(signal.SIGINT) == 0, fleet.err.read_text()[-2000:]
    finally:
        fleet.kill()
