"""The File object (class 0x37): an emulator serves its EDS file at instance 0xC8, generated from the
same declarations as ``cipstack eds generate`` (or the file it was emulated from), and ``cipstack eds
fetch`` reads it over the wire with Initiate_Upload and Upload_Transfer."""

from __future__ import annotations

import gzip
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from cipstack.devices.profiles import PROFILES
from cipstack.objects.file import (
    FIRST,
    FIRST_AND_LAST,
    INITIATE_UPLOAD,
    LAST,
    MIDDLE,
    UPLOAD_TRANSFER,
    FileTransferError,
    checksum,
    read_file,
    stringi,
)
from cipstack.scanner import SyncScanner
from tests.cli_errors import one_line_error
from tests.interop.conftest import python_module
from tests.ports import free_port

from .conftest import AdapterStarter

FAKE_EDS = Path(__file__).with_name("fake_device.eds")


def fetch(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", "eds", "fetch", *args], capture_output=True, text=True,
                          timeout=60, check=False)


@pytest.mark.parametrize("profile", [["--profile", "acg"], ["--profile", "mx2", "--model", "MX2-A2015-E"]],
                         ids=["acg", "mx2"])
def test_the_emulator_serves_the_eds_file_it_generates(profile: list[str], adapter_with: AdapterStarter,
                                                       tmp_path: Path) -> None:
    peer = adapter_with(*profile)
    out = tmp_path / "fetched.eds"
    result = fetch(f"{peer.host}:{peer.port}", "-o", str(out))
    assert result.returncode == 0, result.stderr
    subprocess.run(python_module("cipstack", "eds", "generate", *profile, "-o", str(tmp_path / "gen")), check=True,
                   capture_output=True, timeout=60)
    (generated,) = (tmp_path / "gen").glob("*.eds")
    assert out.read_bytes() == generated.read_bytes()
    assert result.stdout.strip() == f"{out}: {len(generated.read_bytes())} bytes"


def generated_eds(tmp_path: Path, *profile: str) -> bytes:
    """What ``cipstack eds generate`` writes for ``profile``."""
    out = tmp_path / "generated"
    subprocess.run(python_module("cipstack", "eds", "generate", *profile, "-o", str(out)), check=True,
                   capture_output=True, timeout=60)
    (generated,) = out.glob("*.eds")
    return generated.read_bytes()


def test_a_fleet_device_serves_its_eds_file(tmp_path: Path) -> None:
    from tests.test_fleet import addresses, running

    hosts = addresses(21, 2)
    port = free_port(*hosts)
    with running(tmp_path, "--addresses", f"{hosts[0]}-{hosts[1]}", "--device", "acg", "--device",
                 "mx2:MX2-A2015-E", "--port", str(port), "--io-port", str(free_port(*hosts)), "--factory"):
        for host, name in zip(hosts, ("acg", "mx2"), strict=True):
            out = tmp_path / f"{name}.eds"
            result = fetch(f"{host}:{port}", "-o", str(out))
            assert result.returncode == 0, result.stderr
    assert (tmp_path / "acg.eds").read_bytes() == generated_eds(tmp_path / "acg", "--profile", "acg")
    assert (tmp_path / "mx2.eds").read_bytes() == generated_eds(tmp_path / "mx2", "--profile", "mx2", "--model",
                                                                "MX2-A2015-E")


def test_the_pytest_plugins_device_serves_its_eds_file(tmp_path: Path) -> None:
    from cipstack.testing.device import DeviceOptions, EmulatedDevice

    with EmulatedDevice(DeviceOptions(profile="rx", state_path=tmp_path / "state.json")) as device:
        out = tmp_path / "rx.eds"
        result = fetch(device.address, "-o", str(out))
        assert result.returncode == 0, result.stderr
    model = PROFILES["rx"].default_model
    assert model is not None and model.removeprefix("RX-") in device.adapter.device.identity_info.product_name
    assert out.read_bytes() == generated_eds(tmp_path, "--profile", "rx", "--model", model)


def test_an_eds_emulated_device_serves_its_file_byte_for_byte(adapter_with: AdapterStarter, tmp_path: Path) -> None:
    peer = adapter_with("--eds", str(FAKE_EDS))
    out = tmp_path / "fetched.eds"
    assert fetch(f"{peer.host}:{peer.port}", "-o", str(out)).returncode == 0
    assert out.read_bytes() == FAKE_EDS.read_bytes()


def test_the_instance_attributes_and_the_wire_bytes(adapter_with: AdapterStarter) -> None:
    peer = adapter_with("--eds", str(FAKE_EDS))
    data = FAKE_EDS.read_bytes()
    with SyncScanner(f"{peer.host}:{peer.port}", identify=False) as scanner:
        def get(attribute: int) -> bytes:
            return bytes(scanner.request(0x0E, 0x37, 0xC8, attribute).data)

        assert get(1) == b"\x02"  # File Loaded
        assert get(2) == stringi("EDS and Icon Files") == b"\x01eng\xda\x04\x00\x12EDS and Icon Files"
        assert get(4) == stringi("EDS.txt")
        assert get(6) == struct.pack("<I", len(data)) and get(7) == struct.pack("<H", checksum(data))
        assert (get(8), get(10), get(11)) == (b"\xff", b"\x01", b"\x00")  # no invocation, read-only, binary
        initiated = bytes(scanner.request(INITIATE_UPLOAD, 0x37, 0xC8, data=b"\x40").data)
        assert initiated == struct.pack("<IB", len(data), 64)
        first = bytes(scanner.request(UPLOAD_TRANSFER, 0x37, 0xC8, data=b"\x00").data)
        assert first[:2] == bytes((0, FIRST)) and first[2:] == data[:64]
        again = bytes(scanner.request(UPLOAD_TRANSFER, 0x37, 0xC8, data=b"\x00").data)
        assert again == first  # a repeat of the last number: the same packet
        skipped = scanner.request(UPLOAD_TRANSFER, 0x37, 0xC8, data=b"\x05", check=False)
        assert skipped.general_status == 0x20  # out of sequence
        assert get(1) == b"\x05"  # Upload In Progress
    assert (sum(data) + checksum(data)) & 0xFFFF == 0


def test_fetch_from_a_device_without_a_file_object_is_one_line(tmp_path: Path) -> None:
    from .fake_target import FakeTarget

    with FakeTarget() as target:
        result = fetch(target.address, "-o", str(tmp_path / "x.eds"))
    assert result.returncode == 1
    assert one_line_error(result).startswith(f"cipstack eds fetch: {target.address} serves no EDS file")
    assert not (tmp_path / "x.eds").exists()


class Script:
    """A File object scripted packet by packet: what ``read_file`` does with each reply."""

    def __init__(self, data: bytes, transfer: int = 4, *, echo_wrong: bool = False, bad_checksum: bool = False,
                 extra_last: bool = False) -> None:
        self.data, self.transfer = data, transfer
        self.echo_wrong, self.bad_checksum, self.extra_last = echo_wrong, bad_checksum, extra_last
        self.requests: list[tuple[int, bytes]] = []

    def __call__(self, service: int, data: bytes) -> tuple[int, bytes]:
        self.requests.append((service, data))
        if service == INITIATE_UPLOAD:
            return 0, struct.pack("<IB", len(self.data), self.transfer)
        number = data[0]
        chunk = self.data[number * self.transfer:(number + 1) * self.transfer]
        end = (number + 1) * self.transfer
        last = end > len(self.data) or (end == len(self.data) and not self.extra_last)
        kind = (FIRST_AND_LAST if number == 0 else LAST) if last else (FIRST if number == 0 else MIDDLE)
        tail = struct.pack("<H", checksum(self.data) ^ (1 if self.bad_checksum else 0)) if last else b""
        return 0, bytes(((number + 1) & 0xFF if self.echo_wrong else number, kind)) + chunk + tail


def test_read_file_takes_both_ways_of_ending_and_checks_what_it_reads() -> None:
    data = b"[File]\r\nDescText = \"x\";\r\n"
    assert read_file(Script(data)) == data
    exact = data[:24]
    assert read_file(Script(exact, extra_last=True)) == exact   # one more Last packet with the checksum only
    assert read_file(Script(exact)) == exact                     # the last full packet marked Last
    assert read_file(Script(gzip.compress(data))) == data        # encoding 1, as a gzip container
    with pytest.raises(FileTransferError, match="checksum"):
        read_file(Script(data, bad_checksum=True))
    with pytest.raises(FileTransferError, match="does not echo"):
        read_file(Script(data, echo_wrong=True))
    with pytest.raises(FileTransferError, match="0x08"):
        read_file(lambda service, data: (0x08, b""))
