"""Class 1 from blocking code without an event loop (issue 54): ``SyncScanner.io_connection`` is a shell
over the sans-I/O originator core on a plain UDP socket, served by the calling thread, or by a thread
of its own only when the caller asks for a callback."""

from __future__ import annotations

import json
import logging
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from cipstack.devices.acg.device import build_acg_device
from cipstack.eip.io_core import rpi_us_of
from cipstack.eip.originator.blocking import BlockingEncapsulationClient
from cipstack.eip.originator.blocking_io import SyncIoConnection
from cipstack.eip.originator.class1 import Class1Request, IoTimeoutError
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


#: The same, the fields named by the profile the device identifies as: its catalog is the compact data's,
#: and building it imports no asyncio, nothing of the target, and no device module beyond the generated one.
IDENTIFIED = """
import json, sys
from cipstack.scanner import SyncScanner

address, io_port = sys.argv[1], int(sys.argv[2])
with SyncScanner(address) as scanner, \\
        scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=5, target_io_port=io_port) as io:
    io.update(speed_reference=300, run_forward=False)
    image = io.wait_input(lambda i: True, timeout=10)
loaded = [name for name in sys.modules if name == "asyncio" or name.startswith("cipstack.eip.target")
          or (name.startswith("cipstack.devices.") and not name.startswith("cipstack.devices.declared"))]
print(json.dumps({"loaded": loaded, "fields": sorted(image.fields())}))
"""


def test_class1_fields_named_by_the_identified_profile_load_no_device_model() -> None:
    with adapter_process() as (address, io_port):
        done = subprocess.run([sys.executable, "-c", IDENTIFIED, address, str(io_port)], capture_output=True,
                              text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert report["loaded"] == []
    assert {"speed_actual", "running_forward", "at_reference"} <= set(report["fields"])


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
        # The shell takes its clock at construction: this one can be moved past the watchdog.
        io = SyncIoConnection(client, Class1Request.asked(21, 71, rpi_us_of(0.010), output_size=4, input_size=4,
                                                          timeout_multiplier=5),
                              target_io_port=adapter.io_endpoint.port, clock=lambda: time.monotonic() + skew[0])
        with io:
            io.wait_input(lambda i: True, timeout=5)
            skew[0] = 30.0
            with pytest.raises(IoTimeoutError, match="timed out"):
                _ = io.input
            assert io.timed_out
        assert io.closed and not client.is_open


MULTICAST = """
import json, sys
sys.path[:0] = [{root!r}]
from cipstack.devices.acg.device import build_acg_device
from cipstack.scanner import SyncScanner
from tests.library_support import threaded_adapter

with threaded_adapter(build_acg_device()) as adapter, \\
        SyncScanner(f"127.0.0.1:{{adapter.port}}") as first, SyncScanner(f"127.0.0.1:{{adapter.port}}") as second:
    port = adapter.io_endpoint.port
    # One thread serves each connection in turn: a long timeout lets the other wait meanwhile.
    with first.io_connection(output=21, input=71, rpi=0.005, multicast=True, timeout_multiplier=7,
                             target_io_port=port) as owner, \\
            second.io_connection(input=71, heartbeat=199, rpi=0.005, multicast=True, timeout_multiplier=7,
                                 target_io_port=port) as listener:
        owner.wait_input(lambda i: True, 3)
        listener.wait_input(lambda i: True, 3)
        owner.sleep(0.05)
        listener.sleep(0.05)
        report = {{"groups": [owner.multicast_group, listener.multicast_group],
                  "shared": owner.connection.to_connection_id == listener.connection.to_connection_id,
                  "owner_received": owner.stats.received, "listener_received": listener.stats.received}}
print(json.dumps(report))
"""


@pytest.mark.skipif(os.geteuid() != 0 or not shutil.which("unshare") or not shutil.which("ip"),
                    reason="needs root, unshare and ip for a private network namespace")
def test_multicast_owner_and_listener_without_asyncio_in_the_scanner(tmp_path: Path) -> None:
    """The blocking shell joins the group the Forward_Open reply names, as the asyncio one does."""
    script = tmp_path / "multicast.py"
    script.write_text(MULTICAST.format(root=str(Path(__file__).resolve().parent.parent)))
    result = subprocess.run(["unshare", "-n", "sh", "-c", f"ip link set lo up && exec {sys.executable} {script}"],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report["groups"] == ["239.192.1.0", "239.192.1.0"] and report["shared"] is True
    assert report["owner_received"] > 0 and report["listener_received"] > 0


def test_a_lost_session_still_gets_its_forward_close(caplog: pytest.LogCaptureFixture) -> None:
    """The connection's TCP session dies under it (the target closed it): closing sends the
    Forward_Close on a new session, and the target forgets the connection at once."""
    with threaded_adapter(build_acg_device()) as adapter, SyncScanner(f"127.0.0.1:{adapter.port}") as scanner:
        io = scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=7,
                                   target_io_port=adapter.io_endpoint.port)
        io.wait_input(lambda i: True, timeout=5)
        assert len(adapter.io.connections) == 1
        sock = io._client._sock   # internals: the connection's own session, which nothing public reaches
        assert sock is not None
        sock.shutdown(socket.SHUT_RDWR)                        # the session is gone; the socket object stays
        with caplog.at_level(logging.INFO, logger="cipstack.eip.originator.blocking_io"):
            io.close()
        assert adapter.io.connections == {}
        assert any("a new one sends the Forward_Close" in r.getMessage() for r in caplog.records), caplog.text
