"""Saves of a running emulator: written off the event loop, coalesced, and refused (never crashed
on) when the state file cannot take them; state files a killed save or a hostile hand left behind.

The rule they keep (DESIGN, "Bounded by construction"): file I/O never runs on the event loop's
thread. A write that fails keeps the old file, logs one line naming the file and the reason, and
the client that asked is told: Modbus exception 0x04, CIP status 0x19 (store operation failure).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import subprocess
import sys
import threading
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.catalog import Catalog
from cipstack.cip.epath import request_path
from cipstack.cip.messages import MessageRouterRequest, MessageRouterResponse
from cipstack.cip.router import RequestContext
from cipstack.cip.status import CipError
from cipstack.devices import state
from cipstack.devices.acg.device import AcgDevice, build_acg_device
from cipstack.devices.acg.registers import ACG_REGISTERS, CLASS_64_INSTANCES
from cipstack.devices.omron.device import OmronDevice, build_omron_device
from cipstack.devices.omron.registers import modbus_path
from cipstack.devices.state import ParameterStore, StateFileError, StateWriter, load_state, save_state
from cipstack.modbus.tcp_server import ModbusTcpServer
from cipstack.scanner import Scanner
from tests.ports import free_port

ACC = ACG_REGISTERS.by_code("ACC").address
CM = CLASS_64_INSTANCES["CM"]
MX2 = "MX2-A2015-E"


def modbus_write(transaction: int, address: int, value: int) -> bytes:
    """Write Single Register (function 6) to unit 0xFF, as a scripted peer sends it."""
    return (transaction.to_bytes(2, "big") + bytes.fromhex("0000 0006 ff 06") + address.to_bytes(2, "big")
            + value.to_bytes(2, "big"))


# --- files left behind, files a hostile hand wrote ------------------------------------------------

def test_stale_temporaries_are_removed_at_start(tmp_path: Path) -> None:
    # 200 kill -9 during saves left 73 of these: each is a temporary a save never renamed.
    path = tmp_path / "acg.json"
    save_state(path, "acg", "ACG-ET2", {ACC: 70})
    stale = [tmp_path / f".acg.json.{suffix}.tmp" for suffix in ("k2j4_x", "9q8w7e", "a")]
    for leftover in stale:
        leftover.write_text('{"format": "cipstack.drive-')
    others = [tmp_path / ".other.json.k2j4_x.tmp", tmp_path / "acg.json.bak"]
    for other in others:
        other.write_text("kept")
    device = build_acg_device(state_path=path)
    assert device.drive.read(ACC) == 70
    assert not any(leftover.exists() for leftover in stale)
    assert all(other.read_text() == "kept" for other in others)     # another file's, or not a temporary


DEEP = b"[" * 100_000
HUGE = b'{"format": "cipstack.drive-state", "version": 1, "family": "acg", "parameters": {"0x1F01": ' + \
    b"9" * 5000 + b"}}"


@pytest.mark.parametrize(("content", "reason"), [(DEEP, "nested too deeply"), (HUGE, "corrupt")])
def test_hostile_state_file_is_one_line_naming_it(tmp_path: Path, content: bytes, reason: str) -> None:
    path = tmp_path / "acg.json"
    path.write_bytes(content)
    with pytest.raises(StateFileError) as raised:
        load_state(path, "acg")
    message = str(raised.value)
    assert message.startswith(f"{path}: ") and reason in message and "\n" not in message
    # The command line: one line naming the file, exit 2, no traceback; the file is left as it was.
    result = subprocess.run([sys.executable, "-m", "cipstack", "adapter", "--port", str(free_port()),
                             "--io-port", "0", "--state", str(path)],
                            capture_output=True, text=True, timeout=30, stdin=subprocess.DEVNULL)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and str(path) in lines[0], result.stderr
    assert "Traceback" not in result.stderr and path.read_bytes() == content


# --- off the event loop, coalesced ------------------------------------------------------------------

@dataclass
class Bench:
    device: AcgDevice
    adapter: Adapter
    modbus: ModbusTcpServer
    path: Path


@contextlib.asynccontextmanager
async def running(path: Path) -> AsyncIterator[Bench]:
    device = build_acg_device(state_path=path)
    settings = AdapterSettings(host="127.0.0.1", port=0, io_port=0, modbus_port=0)
    async with Adapter(settings, device=device) as adapter:
        assert adapter.modbus is not None
        yield Bench(device, adapter, adapter.modbus, path)


async def exchange(port: int, frames: list[bytes]) -> list[bytes]:
    """Send each frame in turn and read its reply (9 bytes: an exception; 12: a write's echo)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    replies = []
    try:
        for frame in frames:
            writer.write(frame)
            head = await asyncio.wait_for(reader.readexactly(8), 10)
            rest = await asyncio.wait_for(reader.readexactly(4 if head[7] < 0x80 else 1), 10)
            replies.append(head + rest)
    finally:
        writer.close()
    return replies


async def test_a_save_is_written_off_the_event_loop(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    threads: list[int] = []
    real_fsync = os.fsync
    monkeypatch.setattr(state.os, "fsync", lambda fd: (threads.append(threading.get_ident()), real_fsync(fd))[1])
    async with running(tmp_path / "acg.json") as bench:
        loop_thread = threading.get_ident()
        replies = await exchange(bench.modbus.port, [modbus_write(1, ACC, 123), modbus_write(2, 0x03E0, 0),
                                                     modbus_write(3, 0x03E0, 1)])
        # The reply to the save comes once the file holds it.
        assert replies[2] == modbus_write(3, 0x03E0, 1)
        assert load_state(bench.path, "acg")[ACC] == 123
        assert threads and loop_thread not in threads


def test_back_to_back_saves_coalesce(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # While one save is being written (its fsync held here), the next 50 replace each other:
    # the file is written twice in all, and ends with the latest values.
    release, entered = threading.Event(), threading.Event()
    real_fsync = os.fsync

    def slow_fsync(fd: int) -> None:
        entered.set()
        release.wait(10)
        real_fsync(fd)

    monkeypatch.setattr(state.os, "fsync", slow_fsync)
    path = tmp_path / "acg.json"
    writer = StateWriter(ParameterStore(path, "acg", "ACG-ET2"))
    futures = [writer.submit({ACC: 1})]
    assert entered.wait(10)
    futures += [writer.submit({ACC: value}) for value in range(2, 52)]
    release.set()
    assert writer.flush(10)
    writer.close()
    assert (writer.submitted, writer.written) == (51, 2)
    assert load_state(path, "acg") == {ACC: 51}
    assert all(f.done() and f.exception() is None for f in futures)


# --- a state file that takes no write ------------------------------------------------------------

def _mount(*args: str) -> bool:
    return subprocess.run(["mount", *args], capture_output=True).returncode == 0


@pytest.fixture
def small_filesystem(tmp_path: Path) -> Iterator[Path]:
    """A directory whose writes can be taken away: a 64 KiB tmpfs of our own when running as root
    (unmounted afterwards; root ignores permissions, so a read-only mount makes it read-only), else a
    plain directory (made read-only by its mode; filling a disk needs root)."""
    directory = tmp_path / "mnt"
    directory.mkdir()
    if os.geteuid() != 0:
        try:
            yield directory
        finally:
            directory.chmod(0o755)
        return
    if not _mount("-t", "tmpfs", "-o", "size=64k,mode=0755", "tmpfs", str(directory)):
        pytest.skip("mount is not allowed here")
    try:
        yield directory
    finally:
        subprocess.run(["umount", "-l", str(directory)], capture_output=True)


def make_read_only(directory: Path) -> str:
    """Take writes away from ``directory``; the reason a write then fails with."""
    if os.geteuid() == 0:
        assert _mount("-o", "remount,ro", str(directory))
        return "Read-only file system"
    directory.chmod(0o555)
    return "Permission denied"


def fill(directory: Path) -> None:
    fd = os.open(directory / "filler", os.O_WRONLY | os.O_CREAT)
    try:
        with contextlib.suppress(OSError):
            while True:
                os.write(fd, bytes(4096))
    finally:
        os.close(fd)


@pytest.mark.parametrize("damage", ["read-only directory", "full disk"])
async def test_a_save_the_file_cannot_take_is_refused(small_filesystem: Path, damage: str,
                                                      caplog: pytest.LogCaptureFixture) -> None:
    path = small_filesystem / "acg.json"
    save_state(path, "acg", "ACG-ET2", {ACC: 70})
    before = path.read_bytes()
    async with running(path) as bench:
        if damage == "read-only directory":
            why = make_read_only(small_filesystem)
        else:
            if os.geteuid() != 0:
                pytest.skip("filling a disk of our own needs root (mount)")
            fill(small_filesystem)
            why = "No space left on device"
        caplog.clear()
        with caplog.at_level(logging.DEBUG):
            replies = await exchange(bench.modbus.port, [
                modbus_write(1, ACC, 123), modbus_write(2, 0x03E0, 0), modbus_write(3, 0x03E0, 1),
                modbus_write(4, ACC, 124), modbus_write(5, 0x03E0, 0), modbus_write(6, 0x03E0, 1)])
            assert bench.device.flush_saves(10)
        # Modbus: exception 0x04 to the save (the reply waited for the write); the connection and the
        # drive go on; a second try, with the file known not to take writes, is refused at once.
        assert replies[2] == bytes.fromhex("0003 0000 0003 ff 86 04")
        assert replies[3] == modbus_write(4, ACC, 124)
        assert replies[5] == bytes.fromhex("0006 0000 0003 ff 86 04")
        # The log: one line per failed write, naming the file and why; no traceback anywhere.
        errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
        assert errors and all(m.startswith(f"{path}: parameters not saved ({why})") for m in errors), errors
        assert all("\n" not in m for m in errors)
        assert all(r.exc_info is None for r in caplog.records)
        # CIP: CM.94 Comm Update saves the CM group; the file is known not to take it: status 0x19.
        scanner = await Scanner.connect(f"127.0.0.1:{bench.adapter.port}", timeout=3,
                                        catalog=Catalog(bench.device.catalog_classes()))
        try:
            with pytest.raises(CipError) as refused:
                await scanner.set_attribute_single(0x64, CM, 94, 1)
            assert refused.value.general == 0x19
            assert await scanner.read(0x2A, 1, 102) == 124              # still serving
        finally:
            await scanner.close()
    assert path.read_bytes() == before                              # the old state kept


def test_an_omron_eeprom_save_the_file_cannot_take_is_refused(small_filesystem: Path) -> None:
    # The MX2's EEPROM save (0900h, section E-2-2) over class 0x64: the first is answered before the
    # write (the router does not wait), the next is refused with 0x19 and counts no save (Identity 9).
    path = small_filesystem / "mx2.json"
    device = build_omron_device(MX2, state_path=path)
    device.advance(0.0)
    assert put(device, 0x64, *modbus_path(0x0900), "01 00") == 0
    assert device.flush_saves(10)
    before = path.read_bytes()
    make_read_only(small_filesystem)
    assert put(device, 0x64, *modbus_path(0x0900), "01 00") == 0
    assert device.flush_saves(10) and device.saves is not None and device.saves.error is not None
    assert put(device, 0x64, *modbus_path(0x0900), "01 00") == 0x19
    assert request(device, 0x0E, 1, 1, 9).data == (2).to_bytes(2, "little")   # the refused one not counted
    device.close()
    assert path.read_bytes() == before


def request(device: OmronDevice, service: int, cls: int, instance: int, attribute: int, data: str = "",
            now: float = 1.0) -> MessageRouterResponse:
    device.advance(now)
    body = MessageRouterRequest(service, request_path(cls, instance, attribute), bytes.fromhex(data)).encode()
    return device.router.dispatch(body, RequestContext(device.router, now))


def put(device: OmronDevice, cls: int, instance: int, attribute: int, data: str) -> int:
    return request(device, 0x10, cls, instance, attribute, data).general_status


def test_an_omron_special_io_save_the_file_cannot_take_is_fault_04(small_filesystem: Path) -> None:
    # Special I/O (assembly 100/150, Tables B-13 to B-17): a write of 0900h the file cannot take answers
    # its function code with 80h and fault 04h "Slave device failure", the nearest Table B-17 has.
    device = build_omron_device(MX2, state_path=small_filesystem / "mx2.json")
    device.advance(0.0)
    make_read_only(small_filesystem)
    assert device.special_io(0x10, 0x0900, 1, 0, 1.0)[0] == 0x10                  # accepted before the write
    assert device.flush_saves(10) and device.saves is not None and device.saves.error is not None
    reply = device.special_io(0x10, 0x0900, 1, 0, 2.0)
    assert reply[0] == 0x90 and int.from_bytes(reply[4:6], "little") == 0x04
    device.close()
