"""Class 1 from synchronous code (issue 26, item 4): ``SyncScanner.io_connection`` runs the connection on
a private event loop in a background thread; fields by name, ``wait_input``, statistics, and a
Forward_Close on every way out of the ``with`` block. A blocking ``discover``."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from cipstack.devices.acg.device import build_acg_device
from cipstack.devices.acg.eds_file import acg_et2_description
from cipstack.eds.generator import eds_text
from cipstack.scanner import SyncScanner, discover_blocking
from tests.library_support import threaded_adapter

NETWORK_CONTROL = ("drv=4", "Frq=8")   # ACG-ET2 manual: "4: Field Bus" command source, "8: Field Bus" reference


def test_sync_class1_runs_the_drive_by_field_names() -> None:
    """21/71 (ACG-ET2 manual, Extended Speed Control): run forward at 900 rpm (30 Hz on the 4-pole motor),
    wait for At Reference, stop; the ramp follows ACC (0 to 60 Hz in 1.0 s here)."""
    with threaded_adapter(build_acg_device(), params=NETWORK_CONTROL) as adapter, \
            SyncScanner(f"127.0.0.1:{adapter.port}") as scanner:
        scanner.write(0x2A, 1, 102, 1.0, scaled=True)                     # ACC and dEC 1.0 s (0 <-> 60 Hz)
        scanner.write(0x2A, 1, 103, 1.0, scaled=True)
        with scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=5,
                                   target_io_port=adapter.io_endpoint.port) as io:
            io.update(run_forward=True, speed_reference=900)
            started = time.monotonic()
            image = io.wait_input(lambda i: i.at_reference, timeout=5)
            ramp = time.monotonic() - started
            assert image.speed_actual == 900 and io.input.running_forward
            assert 0.3 < ramp < 3.0, ramp                                  # 30 Hz of a 60 Hz-per-second ramp
            io.update(run_forward=False)
            io.wait_input(lambda i: i.speed_actual == 0, timeout=5)
            stats = io.statistics()
        assert stats["received"] > 10 and stats["lost"] == 0
        assert io.closed
        assert str(scanner.read(0x2A, 1, 100)) == "0.00 Hz"


def test_every_exit_sends_forward_close() -> None:
    """An exception in the block, close() twice, and closing the scanner with a connection still open:
    the target forgets the connection each time (a new exclusive owner of 21/71 is accepted at once)."""
    with threaded_adapter(build_acg_device(), params=NETWORK_CONTROL) as adapter, \
            SyncScanner(f"127.0.0.1:{adapter.port}") as scanner:
        port = adapter.io_endpoint.port
        with pytest.raises(RuntimeError, match="boom"), \
                scanner.io_connection(output=21, input=71, rpi=0.010, target_io_port=port):
            raise RuntimeError("boom")
        again = scanner.io_connection(output=21, input=71, rpi=0.010, target_io_port=port)  # 0x0100 if still open
        again.close()
        again.close()
        last = scanner.io_connection(output=21, input=71, rpi=0.010, target_io_port=port)
        scanner.close()                                          # closes `last` first
        assert last.closed
        before = threading.active_count()
    assert threading.active_count() <= before        # the loop thread ended with the scanner


def test_wait_input_times_out_with_builtin_timeout_error() -> None:
    with threaded_adapter(build_acg_device()) as adapter, SyncScanner(f"127.0.0.1:{adapter.port}") as scanner, \
            scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=5,
                                  target_io_port=adapter.io_endpoint.port) as io:
        with pytest.raises(TimeoutError, match=r"within 0\.2 s"):
            io.wait_input(lambda i: i.faulted, timeout=0.2)
        assert not io.timed_out


def test_sync_class1_from_the_eds(tmp_path: Path) -> None:
    """``io_connection_from_eds`` with the file's path: the fields are named after its parameters."""
    eds = tmp_path / "ACG-ET2.eds"
    eds.write_text(eds_text(acg_et2_description()), encoding="latin-1")
    with threaded_adapter(build_acg_device(), params=NETWORK_CONTROL) as adapter, \
            SyncScanner(f"127.0.0.1:{adapter.port}") as scanner, \
            scanner.io_connection_from_eds(eds, 1, target_io_port=adapter.io_endpoint.port) as io:
        assert "run_forward" in io.output.field_names and "speed_actual" in io.input.field_names
        io.update(run_forward=1, speed_reference=300)
        assert io.wait_input(lambda i: i.speed_actual == 300, timeout=10).running_forward


def test_blocking_discover() -> None:
    with threaded_adapter(build_acg_device()) as adapter:
        found = discover_blocking("127.0.0.1", adapter.port, timeout=1.0)
        assert [(r.vendor_id, r.product_code) for r in found] == [(259, 100)]
        assert SyncScanner.discover("127.0.0.1", adapter.port, timeout=0.5)[0].product_name == "CENT"
