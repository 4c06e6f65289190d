"""Modbus-RTU: what the fleet spec accepts for a shared RS-485 line, a save the state file does not
take (exception 06 over the line), a baud-rate change over the line, and a profile without the port."""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
import time
import tty
from pathlib import Path

import pytest

from cipstack.devices.acg.device import build_acg_device
from cipstack.devices.acg.drive import AcgDrive
from cipstack.devices.acg.modbus_rtu import RtuSlave, with_crc
from cipstack.devices.acg.registers import ACG_REGISTERS
from cipstack.fleet.spec import FleetDevice, SpecError, assign, assign_stations, make_group, parse_addresses
from cipstack.modbus.rtu_line import PtyPort, RtuLine
from tests.ports import free_port
from tests.test_state_saves import make_read_only, small_filesystem  # noqa: F401 (a fixture)


def addr(code: str) -> int:
    return ACG_REGISTERS.by_code(code).address


def write(station: int, address: int, value: int) -> bytes:
    return with_crc(bytes((station, 6)) + (address - 1).to_bytes(2, "big") + value.to_bytes(2, "big"))


# -- the fleet spec -----------------------------------------------------------------------------------
def devices(*groups: tuple[str, int, int | None]) -> list[FleetDevice]:
    made = [make_group(profile, None, count, None, (), f"group {n}", station)
            for n, (profile, count, station) in enumerate(groups)]
    return assign(made, parse_addresses("127.0.0.10-127.0.0.60"), None)


def test_stations_from_1_in_address_order_and_a_groups_own_first_id() -> None:
    placed = assign_stations(devices(("acg", 2, None), ("mx2", 1, None), ("acg", 2, 7)), workers=1)
    assert [(d.profile, d.station, d.params) for d in placed] == [
        ("acg", 1, ("CM.1=1",)), ("acg", 2, ("CM.1=2",)), ("mx2", None, ()), ("acg", 7, ("CM.1=7",)),
        ("acg", 8, ("CM.1=8",))]


@pytest.mark.parametrize(("groups", "workers", "message"), [
    ((("acg", 17, None),), 1, "--rtu: 17 ACG drives, but an RS-485 line takes at most 16"),
    ((("mx2", 2, None),), 1, "--rtu: the fleet has no device with an RS-485 port (the ACG's RS-485 port: profile acg)"),
    ((("acg", 2, None),), 2, "--rtu: one RS-485 line is served by one process: --workers 1"),
    ((("acg", 2, 5), ("acg", 1, 6)), 1, "--rtu: station 6 is given to 127.0.0.11 and 127.0.0.12"),
])
def test_a_line_the_spec_cannot_make_is_one_line(groups: tuple[tuple[str, int, int | None], ...], workers: int,
                                                 message: str) -> None:
    with pytest.raises(SpecError) as raised:
        assign_stations(devices(*groups), workers)
    assert str(raised.value).startswith(message)


@pytest.mark.parametrize(("profile", "station", "params", "message"), [
    ("acg", 251, (), "station 251 is not a station ID (1..250, CM.1)"),
    ("mx2", 3, (), "a station ID is the ACG's RS-485 port (profile acg)"),
    ("acg", None, ("CM.1=4",), "CM.1 (the station ID) is given by the fleet's RTU line: use station = N"),
])
def test_a_group_the_line_cannot_take(profile: str, station: int | None, params: tuple[str, ...],
                                      message: str) -> None:
    with pytest.raises(SpecError) as raised:
        make_group(profile, None, 1, None, params, "group", station)
    assert str(raised.value) == f"group: {message}"


def test_a_station_without_a_line_is_refused_by_the_command(tmp_path: Path) -> None:
    spec = tmp_path / "fleet.toml"
    spec.write_text('addresses = "127.0.0.10-127.0.0.20"\n[[device]]\nprofile = "acg"\nstation = 3\n')
    result = subprocess.run([sys.executable, "-m", "cipstack", "fleet", "--spec", str(spec)], capture_output=True,
                            text=True, timeout=30)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        f"cipstack fleet: {spec}: a station ID puts a drive on the fleet's RS-485 line: give --rtu (rtu = \"pty\")"]


def test_a_profile_without_the_port_is_one_line(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "cipstack", "adapter", "--profile", "mx2", "--port",
                             str(free_port()), "--io-port", "0", "--rtu", "pty", "--state", str(tmp_path / "s.json")],
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [
        "cipstack adapter: profile 'mx2' has no RS-485 Modbus-RTU port (one has: profile acg)"]


# -- over the line ---------------------------------------------------------------------------------------
async def _reply(fd: int, size: int, within: float = 2.0) -> bytes:
    end = time.monotonic() + within
    data = b""
    while len(data) < size and time.monotonic() < end:
        try:
            data += os.read(fd, 256)
        except BlockingIOError:
            await asyncio.sleep(0.002)
    return data


async def test_a_save_the_state_file_does_not_take_is_exception_06(small_filesystem: Path) -> None:  # noqa: F811
    """The reply to 0x03E0 = 1 waits for the state file; a save it did not take is 06 Slave Device
    Busy, the chapter's code for a drive that could not carry the request out; the drive goes on."""
    device = build_acg_device(state_path=small_filesystem / "acg.json", now=0.0)
    line = RtuLine(PtyPort())
    line.add(RtuSlave(lambda: device.drive, line.port.paced), device.saves)
    try:
        async with line:
            fd = os.open(line.name, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            tty.setraw(fd)
            try:
                os.write(fd, write(1, 0x03E0, 1))
                assert await _reply(fd, 8) == write(1, 0x03E0, 1)            # saved
                assert device.flush_saves(10)
                os.write(fd, write(1, 0x03E0, 0))
                assert await _reply(fd, 8) == write(1, 0x03E0, 0)
                make_read_only(small_filesystem)
                os.write(fd, write(1, 0x03E0, 1))
                assert await _reply(fd, 5) == with_crc(bytes.fromhex("01 86 06"))
                os.write(fd, write(1, addr("ACC"), 30))
                assert await _reply(fd, 8) == write(1, addr("ACC"), 30)
            finally:
                os.close(fd)
    finally:
        device.close()


def test_a_baud_rate_written_over_the_line_takes_effect_from_the_next_frame() -> None:
    """CM.3 = 7 (115,200 bps) written at 9,600 bps: the reply is timed at 9,600, the next request at
    115,200 (a character of 87 us, the frame-end silence 1.75 ms)."""
    slave = RtuSlave(AcgDrive(now=0.0), paced=True)
    slow, fast = 10 / 9600, 10 / 115200
    assert slave.feed(write(1, addr("CM.3"), 7), 0.0) == []
    (reply,) = slave.poll(11.5 * slow)
    assert reply.due == pytest.approx(11.5 * slow + 0.005 + 8 * slow)
    assert slave.feed(write(1, addr("ACC"), 30), 1.0) == []
    (reply,) = slave.poll(1.0 + 8 * fast + 0.00175)
    assert reply.due == pytest.approx(1.0 + 8 * fast + 0.00175 + 0.005 + 8 * fast)
