"""O->T faults seen from outside: python-ethernetip commands the emulated ACG over class 1 (its own
RPI, 10 ms), pycomm3 reads what the drive does (AC/DC Drive SpeedRef and SpeedActual, attributes 8
and 7; Control Supervisor Running1, attribute 7), the faults applied with `cipstack drive fault`.

`ignore-output` and `idle` both leave the drive on the last command it consumed while the
originator's output changes, and the connection up: on the ACG an idle originator sends no new
command, so the drive keeps the last one and loses no command either (ACG-ET2 manual says nothing of the
run/idle header; cipstack/devices/acg/device.py). After `clear` the drive follows the output again.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import pytest

pytest.importorskip("pycomm3", reason="pycomm3, the peer these tests talk to, is not installed: pip install '.[test]'")

from pycomm3 import CIPDriver
from pycomm3.cip.data_types import INT, USINT

from cipstack.scanner import SyncScanner

from .conftest import PeerProcess
from .test_ethernetip import bits_to_int, class1, drive, select_instances, set_int
from .test_faults_peers import fault
from .test_pycomm3 import get_single, ok

pytestmark = pytest.mark.interop

__all__ = ["drive"]  # the fixture: the drive under network control, ACC and dEC 1.0 s

FIRST, SECOND = 600, 1200                        # speed references, rpm


def wait_until(read: Callable[[], int], wanted: int, timeout: float) -> list[int]:
    """What ``read`` returned, polled until it gives ``wanted`` (fails after ``timeout`` s)."""
    values: list[int] = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        values.append(read())
        if values[-1] == wanted:
            return values
        time.sleep(0.02)
    raise AssertionError(f"never {wanted}: {values[-20:]}")


@pytest.fixture
def reader(adapter: PeerProcess, drive: SyncScanner) -> Iterator[CIPDriver]:
    select_instances(drive, 0, 0)                # output 20 / input 70
    with CIPDriver(adapter.address) as drv:
        yield drv


@pytest.mark.parametrize("name", ["ignore-output", "idle"])
def test_the_drive_keeps_its_last_command_while_the_originators_output_changes(
        adapter: PeerProcess, reader: CIPDriver, name: str) -> None:
    def speed_reference() -> int:
        return ok(get_single(reader, 0x2A, 1, 8, INT))  # type: ignore[no-any-return]

    def speed_actual() -> int:
        return ok(get_single(reader, 0x2A, 1, 7, INT))  # type: ignore[no-any-return]

    with class1(adapter, 20, 70) as (_, inputs, outputs):
        outputs[0] = True                                         # Run Fwd
        set_int(outputs, 16, 16, FIRST)                           # Speed Reference, rpm
        wait_until(speed_actual, FIRST, 5)
        try:
            fault(adapter, name)
            set_int(outputs, 16, 16, SECOND)
            time.sleep(0.5)                                       # 50 of the originator's RPIs
            assert (speed_reference(), speed_actual()) == (FIRST, FIRST)
            assert ok(get_single(reader, 0x29, 1, 7, USINT)) == 1  # still Running1
            assert bits_to_int(inputs, 16, 16, signed=True) == FIRST  # its connection is up: input fresh
        finally:
            fault(adapter, "clear")
        wait_until(speed_reference, SECOND, 2)
        outputs[0] = False                                        # stop: the next test starts from rest
        wait_until(speed_actual, 0, 5)
