"""`cipstack io` and T->O transport: --multicast from the command line; with --eds, the transport
the file allows and the target accepts (a listen-only point refused point-to-point with 0x0108 is
asked again by multicast), said on stderr; a listener without an owner is told an owner must
produce first; --eds with --output/--input takes the field names from the file; "none usable"
says why."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

from tests.library_support import adapter_process

FILES = Path(__file__).parent / "eds" / "files"


def run(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "cipstack", *args], capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


def io(address: str, io_port: int, *args: str, duration: str = "1s") -> list[str]:
    return [sys.executable, "-m", "cipstack", "io", address, "--target-io-port", str(io_port), "--rpi", "10ms",
            "--duration", duration, "--timeout-multiplier", "4", "--print", "summary", *args]


def received(stdout: str) -> int:
    return int(next(line for line in stdout.splitlines() if line.startswith("sent ")).split()[3])


def test_multicast_from_the_command_line() -> None:
    with adapter_process("--profile", "acg") as (address, io_port):
        result = subprocess.run(io(address, io_port, "--output", "21", "--input", "71", "--multicast"),
                                capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert "cipstack io: T->O multicast from 239.192.1." in result.stderr
    assert received(result.stdout) > 10


def _both_ways(tmp_path: Path) -> Path:
    """The drive file with its listen-only connections allowing T->O point-to-point and multicast
    (0x44640305, as some files write them)."""
    text = (FILES / "vendor_drive_own_data.eds").read_bytes().decode("latin-1")
    text = text.replace("0x01010002, 0x44240305", "0x01010002, 0x44640305")
    path = tmp_path / "both_ways.eds"
    path.write_bytes(text.encode("latin-1"))
    return path


def test_a_listen_only_point_refused_point_to_point_is_asked_again_by_multicast(tmp_path: Path) -> None:
    path = _both_ways(tmp_path)
    with adapter_process("--eds", str(path)) as (address, io_port):
        # The owner the file lets produce both ways: asked for multicast, so that there is something to listen to.
        owner = subprocess.Popen(io(address, io_port, "--eds", str(path), "--connection", "1", "--multicast",
                                    duration="30s"), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        owner_said: list[str] = []
        try:
            # The owner says where its T->O comes from once its connection is open (or ends at its duration).
            assert owner.stderr is not None
            for line in owner.stderr:
                owner_said.append(line)
                if "T->O multicast from" in line:
                    break
            listener = subprocess.run(io(address, io_port, "--eds", str(path), "--connection", "6"),
                                      capture_output=True, text=True, timeout=60)
        finally:
            owner.send_signal(signal.SIGINT)
            _, rest = owner.communicate(timeout=30)
            owner_err = "".join(owner_said) + rest
    assert listener.returncode == 0, listener.stderr
    lines = said(listener.stderr)
    assert lines[0] == ("cipstack io: the target refused point-to-point T->O (0x0108): multicast asked, which the "
                        "file allows")
    assert lines[1].startswith("cipstack io: T->O multicast from 239.192.1.") and len(lines) == 2
    assert received(listener.stdout) > 10
    assert owner.returncode == 130 and "T->O multicast from" in owner_err, owner_err


def test_a_listener_without_an_owner_is_told_an_owner_must_produce_first(tmp_path: Path) -> None:
    path = FILES / "vendor_drive_own_data.eds"
    with adapter_process("--eds", str(path)) as (address, io_port):
        result = subprocess.run(io(address, io_port, "--eds", str(path), "--connection", "6"),
                                capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert said(result.stderr) == [
        "cipstack io: error status service 0x54: a listen-only connection receives the multicast of a connection "
        "that already produces its input: an owner (exclusive owner or input only, opened with --multicast) must "
        "produce first: 0x01 (connection failure), extended 0x0119 (non listen only not opened)"]


def _without_connection_manager(tmp_path: Path) -> Path:
    """The sensor's file as a DeviceNet-like file: no [Connection Manager] (its assemblies stay),
    saved in Latin-1 as the specification's character set has it."""
    text = (FILES / "hand_utf8_distance_sensor.eds").read_text(encoding="utf-8")
    start, end = text.index("[Connection Manager]"), text.index("[Port]")
    path = tmp_path / "no_manager.eds"
    path.write_text(text[:start] + text[end:], encoding="latin-1")
    return path


def said(stderr: str) -> list[str]:
    """What the command says (its own lines; the log lines of the I/O endpoint left out)."""
    return [line for line in stderr.splitlines() if line.startswith("cipstack io:")]


def test_none_usable_says_why(tmp_path: Path) -> None:
    path = _without_connection_manager(tmp_path)
    result = run("io", "127.0.0.1:1", "--eds", str(path), "--connection", "1")
    assert result.returncode == 2
    assert said(result.stderr) == [
        f"cipstack io: {path}: no class 1 connection '1' in the EDS (known: none usable: the file has no "
        "[Connection Manager] (a DeviceNet or CompoNet file: its I/O is not described as EtherNet/IP connections); "
        "give --output N --input M to take only the field names from it)"]


def test_eds_with_output_and_input_takes_the_field_names_from_the_file(tmp_path: Path) -> None:
    """A connection the file does not list (it lists none): the device's assemblies by number, their
    field names from the file's assembly members."""
    path = _without_connection_manager(tmp_path)
    listed = run("io", "127.0.0.1:1", "--eds", str(path), "--heartbeat", "198", "--input", "100", "--list-fields")
    assert listed.returncode == 0, listed.stderr
    assert listed.stdout.splitlines() == [
        "output (O->T): no data (heartbeat)",
        "input (T->O): assembly 100 'Measurement', 8 bytes",
        "  distance                     byte 0 UDINT [µm]",
        "  temperature                  byte 4 INT [°C]",
        "  signal_quality               byte 6 UINT [%]"]
    with adapter_process("--eds", str(FILES / "hand_utf8_distance_sensor.eds")) as (address, io_port):
        result = subprocess.run(io(address, io_port, "--eds", str(path), "--heartbeat", "198", "--input", "100",
                                   "--ot-format", "heartbeat"), capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert "distance=0  temperature=20  signal_quality=0" in result.stdout


def test_an_assembly_without_field_names_is_shown_and_written_as_raw_hex() -> None:
    """A new user's first connection to a device emulated from a vendor's file: Connection3 of
    vendor_drive_own_data.eds names no member of its assemblies 100 and 150. What `--list-fields`
    lists, what each input line and `--json` show, and what `--set` takes are the raw bytes in hex."""
    path = FILES / "vendor_drive_own_data.eds"
    with adapter_process("--eds", str(path)) as (address, io_port):
        connection = ("--eds", str(path), "--connection", "3")
        listed = run("io", address, *connection, "--list-fields")
        assert listed.returncode == 0, listed.stderr
        assert listed.stdout.splitlines() == [
            "output (O->T): assembly 100 'Vendor Output', 8 bytes: no field names (write it with --set raw=HEX)",
            "input (T->O): assembly 150 'Vendor Input', 12 bytes: no field names (printed as raw=HEX)"]
        text = subprocess.run(io(address, io_port, *connection, "--print", "changes", "--set", "raw=0102030405060708",
                                 duration="0.5s"), capture_output=True, text=True, timeout=60)
        assert text.returncode == 0, text.stderr
        first = text.stdout.splitlines()[0].split()
        assert first[1:] == ["raw=" + "00" * 12], text.stdout
        written = run("get", address, "0x04/100/3")
        assert written.stdout.strip() == "Data = 01 02 03 04 05 06 07 08", written.stdout + written.stderr
        as_json = subprocess.run(io(address, io_port, *connection, "--print", "changes", "--json", duration="0.5s"),
                                 capture_output=True, text=True, timeout=60)
        assert as_json.returncode == 0, as_json.stderr
        assert json.loads(as_json.stdout.splitlines()[0])["input"] == {"raw": "00" * 12}
        wrong = subprocess.run(io(address, io_port, *connection, "--set", "speed=1", duration="0.5s"),
                               capture_output=True, text=True, timeout=60)
        short = subprocess.run(io(address, io_port, *connection, "--set", "raw=01", duration="0.5s"),
                               capture_output=True, text=True, timeout=60)
    assert wrong.returncode != 0 and wrong.stderr.strip() == (
        "cipstack io: --set speed=1: assembly 100 'Vendor Output' (8 bytes) declares no field names: "
        "give raw=HEX (8 bytes, e.g. raw=0000000000000000)")
    assert short.returncode != 0 and short.stderr.strip() == "cipstack io: --set raw=01: assembly is 8 bytes, got 1"
