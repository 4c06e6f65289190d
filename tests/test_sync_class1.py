"""Class 1 from blocking code without an event loop (issue 54): ``SyncScanner.io_connection`` is a shell
over the sans-I/O originator core on a plain UDP socket, served by the calling thread, or by a thread
of its own only when the caller asks for a callback."""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time

import pytest

from cipstack.devices.acg.device import build_acg_device
from cipstack.eip.originator.blocking import BlockingEncapsulationClient
from cipstack.eip.originator.blocking_io import io_connection
from cipstack.eip.originator.class1 import IoTimeoutError
from cipstack.scanner import SyncScanner
from tests.library_support import adapter_process, threaded_adapter

#: Opens a class 1 connection from blocking code, then says whether asyncio was loaded and how many
#: threads ran. The fields are named by the drive profile's schemas, given: identifying the device
#: (its profile's catalog) is not class 1, and is held to its own import test.
SCRIPT = """
import json, sys, threading
from cipstack.assemblies.drive_profile import extended_speed_control_input, extended_speed_control_output
from cipstack.scanner import SyncScanner

address, io_port = sys.argv[1], int(sys.argv[2])
with SyncScanner(address, identify=False) as scanner, \\
        scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=5, target_io_port=io_port,
                              output_schema=extended_speed_control_output(),
                              input_schema=extended_speed_control_input()) as io:
    io.update(speed_reference=300)
    image = io.wait_input(lambda i: True, timeout=10)
    io.sleep(0.2)
    threads = threading.active_count()
    stats = io.statistics()
print(json.dumps({"asyncio": "asyncio" in sys.modules, "threads": threads, "received": stats["received"],
                  "sent": stats["sent"], "fields": sorted(image.fields())}))
"""


def test_sync_io_connection_imports_no_asyncio_and_runs_no_thread() -> None:
    with adapter_process() as (address, io_port):
        done = subprocess.run([sys.executable, "-c", SCRIPT, address, str(io_port)], capture_output=True, text=True,
                              timeout=60)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert report["asyncio"] is False
    assert report["threads"] == 1
    assert report["received"] > 0 and report["sent"] > 0 and "speed_actual" in report["fields"]


def test_sleep_keeps_the_connection_running() -> None:
    """At 10 ms and multiplier 0 the target times out after 40 ms of silence: ``io.sleep`` for ten times
    that keeps producing, and the target's data keeps coming."""
    with threaded_adapter(build_acg_device()) as adapter, SyncScanner(f"127.0.0.1:{adapter.port}") as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=2,
                                  target_io_port=adapter.io_endpoint.port) as io:
        io.sleep(0.4)
        stats = io.statistics()
        assert not io.timed_out
        assert stats["sent"] >= 20 and stats["received"] >= 20
        assert len(adapter.io.connections) == 1


def test_a_callback_runs_the_connection_on_a_thread_of_its_own() -> None:
    seen: list[int] = []
    with threaded_adapter(build_acg_device()) as adapter, SyncScanner(f"127.0.0.1:{adapter.port}") as scanner:
        before = threading.active_count()
        with scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=5,
                                   target_io_port=adapter.io_endpoint.port,
                                   on_input=lambda image: seen.append(image.speed_actual)) as io:
            assert threading.active_count() == before + 1
            time.sleep(0.3)                                         # the connection's thread serves it meanwhile
            assert not io.timed_out and io.statistics()["sent"] >= 10
            assert io.wait_input(lambda i: True, timeout=5) is not None
        assert seen and threading.active_count() == before         # the thread ended with the connection


def test_a_silent_target_times_the_connection_out() -> None:
    """The shell's clock moved past the watchdog: the next call raises ``IoTimeoutError``, and the
    connection still closes cleanly."""
    skew = [0.0]
    with threaded_adapter(build_acg_device()) as adapter:
        client = BlockingEncapsulationClient.connect("127.0.0.1", adapter.port)
        io = io_connection(client, 21, 71, 0.010, output_size=4, input_size=4, timeout_multiplier=5,
                           target_io_port=adapter.io_endpoint.port)
        io._clock = lambda: time.monotonic() + skew[0]
        with io:
            io.wait_input(lambda i: True, timeout=5)
            skew[0] = 30.0
            with pytest.raises(IoTimeoutError, match="timed out"):
                _ = io.input
            assert io.timed_out
        assert io.closed and not client.is_open
