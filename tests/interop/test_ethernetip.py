"""python-ethernetip (PyPI ``ethernetip``), a class 1 originator nobody here wrote, drives the ACG emulator.

It opens 20/70 and 21/71 connections, sets Run Forward and a speed reference in its output and
reads Running and Speed Actual ramping in its input (ACG-ET2 manual assembly tables), then closes cleanly.
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

pytest.importorskip("ethernetip", reason="python-ethernetip, the peer these tests talk to, is not installed: "
                                         "pip install '.[test]'")

import ethernetip
import ethernetip.ethernetip as enip_module

from cipstack.cip.types import UINT
from cipstack.devices.acg.registers import ACG_REGISTERS, CLASS_64_INSTANCES
from cipstack.devices.profiles import catalog_for
from cipstack.scanner import SyncScanner
from tests.ports import free_port

from .conftest import PeerProcess

pytestmark = pytest.mark.interop

CM = CLASS_64_INSTANCES["CM"]
DRV, FRQ = ACG_REGISTERS.by_code("drv").address, ACG_REGISTERS.by_code("Frq").address


def io_port(adapter: PeerProcess) -> int:
    found = re.search(r"class 1 I/O on UDP 127\.0\.0\.1:(\d+)", adapter.log_text())
    assert found, adapter.log_text()
    return int(found.group(1))


def bits_to_int(bits: list[bool], first: int, count: int, signed: bool = False) -> int:
    value = sum(1 << i for i in range(count) if bits[first + i])
    return value - (1 << count) if signed and value >= 1 << (count - 1) else value


def set_int(bits: list[bool], first: int, count: int, value: int) -> None:
    for i in range(count):
        bits[first + i] = bool((value >> i) & 1)


@pytest.fixture(scope="module")
def drive(adapter: PeerProcess) -> Iterator[SyncScanner]:
    """The emulated drive under network control: drv = 4 and Frq = 8 "Field Bus" (ACG-ET2 manual, keypad parameters
    related to the ACG-ET2), written through smart scaling (CM.51/CM.52 name them, assembly 122 carries them);
    ACC and dEC 1.0 s (AC/DC Drive attributes 102/103)."""
    with SyncScanner(adapter.address, catalog=catalog_for(259, 100)) as scanner:
        scanner.set_attribute_single(0x64, CM, 51, DRV, UINT)
        scanner.set_attribute_single(0x64, CM, 52, FRQ, UINT)
        scanner.set_attribute_single(0x04, 122, 3, UINT.encode(4) + UINT.encode(8))
        scanner.set_attribute_single(0x2A, 1, 102, 10, UINT)
        scanner.set_attribute_single(0x2A, 1, 103, 10, UINT)   # dEC 1.0 s (attribute 103)
        yield scanner


def select_instances(scanner: SyncScanner, output_setting: int, input_setting: int) -> None:
    """CM.24 / CM.23 select the output / input instance; they apply after CM.94 (Comm Update) = 1."""
    scanner.set_attribute_single(0x64, CM, 24, output_setting, UINT)
    scanner.set_attribute_single(0x64, CM, 23, input_setting, UINT)
    scanner.set_attribute_single(0x64, CM, 94, 1, UINT)




@contextmanager
def class1(adapter: PeerProcess, output: int, input_: int) -> Iterator[tuple[Any, list[bool], list[bool]]]:
    """python-ethernetip's class 1 connection to ``output``/``input_`` (4 bytes each, RPI 10 ms, timeout
    multiplier code 1), producing: its connection and its input and output bits. Closed by its
    Forward_Close after, which the adapter must accept."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(enip_module, "ENIP_TCP_PORT", int(adapter.address.rsplit(":", 1)[1]))
        patch.setattr(enip_module, "ENIP_UDP_PORT", io_port(adapter))
        enip = ethernetip.EtherNetIP("127.0.0.1")
        connection = enip.explicit_conn("127.0.0.1")
        connection.registerSession()
        inputs = enip.registerAssembly(ethernetip.EtherNetIP.ENIP_IO_TYPE_INPUT, 4, input_, connection)
        outputs = enip.registerAssembly(ethernetip.EtherNetIP.ENIP_IO_TYPE_OUTPUT, 4, output, connection)
        enip.startIO(free_port("0.0.0.0"))
        try:
            status = connection.sendFwdOpenReq(input_, output, 1, torpi=10, otrpi=10, multiplier=1, inputsz=4,
                                               outputsz=4, originator_udp_port=enip.originator_udp_port)
            assert status == 0, f"Forward_Open refused: extended status 0x{status or 0:04X}"
            connection.produce()
            yield connection, inputs, outputs
            connection.stopProduce()
            assert connection.sendFwdCloseReq(input_, output, 1) == 0
        finally:
            connection.stopProduce()
            enip.stopIO()


@pytest.mark.parametrize(("output", "input_", "setting", "extended"), [(20, 70, 0, False), (21, 71, 1, True)])
def test_python_ethernetip_runs_the_drive_over_class1(adapter: PeerProcess, drive: SyncScanner, output: int,
                                                     input_: int, setting: int, extended: bool) -> None:
    select_instances(drive, setting, setting)
    with class1(adapter, output, input_) as (_, inputs, outputs):
        outputs[0] = True                       # Run Fwd (byte 0, bit 0)
        if extended:
            outputs[5] = outputs[6] = True      # NetCtrl, NetRef (bits 5, 6: "not used" on the ACG, harmless)
        set_int(outputs, 16, 16, 1500)          # Speed Reference, rpm (bytes 2-3)
        speeds: list[int] = []
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            speed = bits_to_int(inputs, 16, 16, signed=True)
            if not speeds or speed != speeds[-1]:
                speeds.append(speed)
            # Speed Actual is the output frequency in whole rpm, rounded: it shows 1500 while the
            # output is still a fraction of a hertz short of the reference, before At Reference is set.
            if speed == 1500 and (not extended or inputs[7]):
                break
            time.sleep(0.005)
        assert inputs[2], "Running1 (Fwd) is not set in the input"
        assert not inputs[0], "Faulted"
        assert speeds[-1] == 1500, speeds
        assert any(0 < s < 1500 for s in speeds), f"no ramp seen: {speeds}"
        assert speeds == sorted(speeds)
        if extended:
            assert inputs[7] and inputs[4]      # At Reference, Ready
            assert bits_to_int(inputs, 8, 8) == 4  # Drive State: Enabled (Control Supervisor attribute 6)
        # The same state over explicit messaging.
        assert drive.read(0x29, 1, 7) == 1 and drive.read(0x2A, 1, 7) == 1500
        outputs[0] = False                      # stop before closing: the next test starts from rest
        deadline = time.monotonic() + 10
        while bits_to_int(inputs, 16, 16, signed=True) != 0 and time.monotonic() < deadline:
            time.sleep(0.01)
    # Closed cleanly at the target: no class 1 connection left, and no timeout (Pr.12 untouched).
    assert drive.read(0x29, 1, 10) == 0
    log = adapter.log_text()
    assert re.search(rf"class 1 exclusive owner {output}->{input_} \(0x[0-9A-F]+\) closed", log), log
