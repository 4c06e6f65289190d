"""pycomm3 and cpppo (independent clients) against the emulated ACG drive in its own process:
they read and write the 0x28/0x29/0x2A/0x64 attributes, see the drive ramp, and the save rule holds
across a restart of the emulator process on the same state file."""

from __future__ import annotations

import signal
import struct
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("pycomm3", reason="pycomm3, the peer these tests talk to, is not installed: pip install '.[test]'")

from pycomm3 import CIPDriver, Services
from pycomm3.cip.data_types import INT, SHORT_STRING, UINT, USINT
from pycomm3.cip.status_info import SERVICE_STATUS

from cipstack.devices.acg.registers import ACG_REGISTERS, CLASS_64_INSTANCES

from .conftest import HOST, IDENTITY, PeerProcess, cpppo_get_attribute, free_port, start_peer

pytestmark = pytest.mark.interop

CM, PR = CLASS_64_INSTANCES["CM"], CLASS_64_INSTANCES["Pr"]
DRV, FRQ = ACG_REGISTERS.by_code("drv").address, ACG_REGISTERS.by_code("Frq").address
SAVE_PARAMETERS = 0x03E0

EMULATOR = textwrap.dedent("""\
    import sys
    from pathlib import Path

    from cipstack.adapter import Adapter, AdapterSettings
    from cipstack.devices.acg.device import build_acg_device
    from cipstack.devices.profiles import DEFAULT_MAC
    from cipstack.eip.io_server import run_precise
    from cipstack.objects.tcpip import NetworkInterface

    port, state = int(sys.argv[1]), Path(sys.argv[2])
    device = build_acg_device(NetworkInterface(ip_address="127.0.0.1", mac=DEFAULT_MAC), state_path=state)
    run_precise(Adapter(AdapterSettings(host="127.0.0.1", port=port, io_port=0), device=device).serve_forever())
""")


def start_emulator(directory: Path, state: Path, name: str) -> PeerProcess:
    script = directory / "acg_emulator.py"
    script.write_text(EMULATOR)
    port = free_port()
    return start_peer(name, [sys.executable, str(script), str(port), str(state)], HOST, port,
                      directory / f"{name}.log")


def stop_cleanly(peer: PeerProcess) -> None:
    code = peer.stop(signal.SIGTERM)
    text = peer.log_text()
    assert code == 0, f"the emulator exited with {code}:\n{text}"
    assert "Traceback" not in text, text


@pytest.fixture(scope="module")
def emulator(tmp_path_factory: pytest.TempPathFactory) -> Iterator[PeerProcess]:
    directory = tmp_path_factory.mktemp("acg")
    peer = start_emulator(directory, directory / "state.json", "acg-emulator")
    try:
        yield peer
    finally:
        stop_cleanly(peer)


@pytest.fixture
def driver(emulator: PeerProcess) -> Iterator[CIPDriver]:
    drv = CIPDriver(emulator.address)
    drv.open()
    try:
        yield drv
    finally:
        drv.close()


def get(drv: CIPDriver, class_code: int, instance: int, attribute: int, data_type: Any) -> Any:
    tag = drv.generic_message(service=Services.get_attribute_single, class_code=class_code, instance=instance,
                              attribute=attribute, data_type=data_type, connected=False, route_path=False)
    assert tag.error is None, f"0x{class_code:02X}/{instance}/{attribute}: {tag.error}"
    return tag.value


def set_(drv: CIPDriver, class_code: int, instance: int, attribute: int, data: bytes) -> str | None:
    tag = drv.generic_message(service=Services.set_attribute_single, class_code=class_code, instance=instance,
                              attribute=attribute, request_data=data, connected=False, route_path=False)
    return tag.error


def write_registers(drv: CIPDriver, values: dict[int, int]) -> None:
    """Registers written over CIP: named in CM.51.. and set through smart-scaling output 12n."""
    for index, address in enumerate(values):
        assert set_(drv, 0x64, CM, 51 + index, struct.pack("<H", address)) is None
    data = b"".join(struct.pack("<H", v) for v in values.values())
    assert set_(drv, 0x04, 120 + len(values), 3, data) is None


def cpppo(address: str, *tags: str) -> tuple[int, list[tuple[str, str, Any]], str]:
    return cpppo_get_attribute(address, "-S", *tags)


def test_pycomm3_identity(emulator: PeerProcess, driver: CIPDriver) -> None:
    identity = CIPDriver.list_identity(emulator.address)
    assert identity is not None
    assert (identity["vendor"], identity["product_type"], identity["product_code"], identity["product_name"],
            identity["serial"], identity["status"], identity["state"]) == (
        "LS ELECTRIC", "AC Drive", 100, "CENT", f"{IDENTITY['serial_number']:08x}", b"\x30\x00", 3)
    assert get(driver, 1, 1, 7, SHORT_STRING) == "CENT"
    assert get(driver, 1, 1, 5, UINT) == 0x0030                       # no I/O connection (3)


def test_pycomm3_reads_and_writes_the_drive_objects(driver: CIPDriver) -> None:
    assert get(driver, 0x28, 1, 3, USINT) == 7
    assert set_(driver, 0x28, 1, 7, struct.pack("<H", 400)) is None
    assert get(driver, 0x28, 1, 7, UINT) == 400
    assert get(driver, 0x29, 1, 6, USINT) == 3                       # Ready
    assert get(driver, 0x2A, 1, 103, UINT) == 100                    # dEC 10.0 s
    assert get(driver, 0x64, CM, 23, UINT) == 1
    assert set_(driver, 0x64, PR, 13, struct.pack("<H", 30)) is None  # Pr.13 3.0 s
    assert get(driver, 0x64, PR, 13, UINT) == 30
    assert set_(driver, 0x29, 1, 6, b"\x04") == SERVICE_STATUS[0x0E]             # Drive State is Get only
    assert set_(driver, 0x64, PR, 12, struct.pack("<H", 9)) == SERVICE_STATUS[0x09]  # Pr.12 0-5


def test_pycomm3_sees_the_drive_ramp(driver: CIPDriver) -> None:
    write_registers(driver, {DRV: 4, FRQ: 8})                        # drv, Frq: Field Bus
    assert get(driver, 0x29, 1, 14, USINT) == 1
    assert set_(driver, 0x2A, 1, 102, struct.pack("<H", 20)) is None  # ACC 2.0 s to 60 Hz
    assert set_(driver, 0x2A, 1, 8, struct.pack("<h", 900)) is None   # 900 rpm
    assert set_(driver, 0x29, 1, 3, b"\x01") is None                  # Forward Run Cmd
    seen = []
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        seen.append(get(driver, 0x2A, 1, 7, INT))
        if seen[-1] == 900:
            break
        time.sleep(0.02)
    assert seen[-1] == 900 and any(0 < s < 900 for s in seen) and seen == sorted(seen), seen
    assert get(driver, 0x2A, 1, 3, USINT) == 1 and get(driver, 0x2A, 1, 100, UINT) == 3000
    # CM.24 "cannot be written while the drive is operating": device state conflict.
    assert set_(driver, 0x64, CM, 24, struct.pack("<H", 0)) == SERVICE_STATUS[0x10]
    assert set_(driver, 0x29, 1, 3, b"\x00") is None                  # stop: decelerate over dEC


def test_cpppo_reads_and_writes_the_drive_objects(emulator: PeerProcess) -> None:
    code, rows, output = cpppo(emulator.address, "@0x28/1/3", "@0x29/1/6", "@0x2A/1/103=(INT)55", "@0x2A/1/103",
                               f"@0x64/{CM}/24", f"@0x64/{PR}/14=(INT)250", f"@0x64/{PR}/14", "@0x29/1/9")
    assert code == 0, output
    assert rows == [
        ("G_A_S", "@0x0028/1/3", [7]),
        ("G_A_S", "@0x0029/1/6", [rows[1][2][0]]),
        ("S_A_S", "@0x002A/1/103", True),
        ("G_A_S", "@0x002A/1/103", [55, 0]),
        ("G_A_S", f"@0x0064/{CM}/24", [1, 0]),
        ("S_A_S", f"@0x0064/{PR}/14", True),
        ("G_A_S", f"@0x0064/{PR}/14", [250, 0]),
        ("G_A_S", "@0x0029/1/9", [1]),
    ], output
    code, rows, output = cpppo(emulator.address, "@0x29/1/7=(INT)1")   # read only: 0x0E
    assert code != 0 and rows == [("S_A_S", "@0x0029/1/7", None)], output
    code, rows, output = cpppo(emulator.address, "@0x28/1/1")          # not in the table: 0x14
    assert code != 0, output


def test_cpppo_sees_the_drive_ramp(emulator: PeerProcess) -> None:
    # drv/Frq named in CM.51 and written through output 121, then a slow ramp: 0 to 60 Hz in 20 s.
    code, _, output = cpppo(emulator.address, f"@0x64/{CM}/51=(INT){DRV}", "@4/121/3=(INT)4",
                            f"@0x64/{CM}/51=(INT){FRQ}", "@4/121/3=(INT)8", "@0x2A/1/102=(INT)200",
                            "@0x2A/1/8=(INT)1800", "@0x29/1/3=(SINT)0", "@0x29/1/3=(SINT)1")
    assert code == 0, output
    speeds = []
    for _ in range(3):
        code, rows, output = cpppo(emulator.address, "@0x2A/1/7", "@0x29/1/6")
        assert code == 0, output
        speeds.append(int.from_bytes(bytes(rows[0][2]), "little"))
        assert rows[1][2] == [4], output                                       # Enabled
        time.sleep(0.3)                 # the subject: the ramp goes on between the readings
    assert 0 < speeds[0] < speeds[1] < speeds[2] < 1800, speeds
    code, _, output = cpppo(emulator.address, "@0x29/1/3=(SINT)0", "@0x2A/1/102=(INT)50")
    assert code == 0, output


def test_save_rule_across_an_emulator_restart(tmp_path: Path) -> None:
    state = tmp_path / "state.json"
    first = start_emulator(tmp_path, state, "first")
    try:
        drv = CIPDriver(first.address)
        drv.open()
        try:
            assert set_(drv, 0x2A, 1, 103, struct.pack("<H", 55)) is None       # dEC 5.5 s
            assert set_(drv, 0x64, PR, 12, struct.pack("<H", 2)) is None        # Pr.12 Dec
            write_registers(drv, {SAVE_PARAMETERS: 0})
            write_registers(drv, {SAVE_PARAMETERS: 1})                          # 0x03E0 0 -> 1: save
            assert set_(drv, 0x2A, 1, 102, struct.pack("<H", 33)) is None       # ACC, never saved
        finally:
            drv.close()
    finally:
        stop_cleanly(first)
    assert state.exists()
    second = start_emulator(tmp_path, state, "second")
    try:
        drv = CIPDriver(second.address)
        drv.open()
        try:
            assert get(drv, 0x2A, 1, 103, UINT) == 55
            assert get(drv, 0x64, PR, 12, UINT) == 2
            assert get(drv, 0x2A, 1, 102, UINT) == 50                           # the factory 5.0 s
        finally:
            drv.close()
    finally:
        stop_cleanly(second)
