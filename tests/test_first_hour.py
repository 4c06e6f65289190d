"""What a new user meets in the first hour: making the ACG run from the network, ports that are the
adapter's own, class 1 refusals and silences that say why, and the command's messages and shapes."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import socket
import struct
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.catalog import Catalog
from cipstack.cip.status import CipError
from cipstack.cli import build_parser, json_key
from cipstack.devices.acg.device import AcgDevice
from cipstack.devices.acg.drive import AcgDrive
from cipstack.devices.acg.keypad import apply_parameters, parse_assignment
from cipstack.devices.acg.registers import ACG_REGISTERS
from cipstack.devices.profiles import catalog_for
from cipstack.devices.registers import RegisterError
from cipstack.scanner import ReplyDecodeError, Scanner
from tests.ports import free_port
from tests.test_cli import one_line_error, run, start_adapter, stop
from tests.waiting import wait_until

ACG_CATALOG = catalog_for(259, 100)


# -- 12.2: keypad parameters at start ----------------------------------------------------------------------
def test_param_takes_keypad_codes_in_the_keypad_unit() -> None:
    assert parse_assignment("drv=4") == (ACG_REGISTERS.by_code("drv"), 4)
    assert parse_assignment("Frq=Field Bus") == (ACG_REGISTERS.by_code("Frq"), 8)
    assert parse_assignment("ACC=2.5") == (ACG_REGISTERS.by_code("ACC"), 25)      # 0.1 s steps
    assert parse_assignment("cm-24=3") == (ACG_REGISTERS.by_code("CM.24"), 3)
    for text, words in (("drv=9", "takes 0..4"), ("ACC=2.55", "step 0.1"), ("foo=1", "not a code of the ACG keypad"),
                        ("drv", "CODE=VALUE"), ("drv=x", "not a number")):
        with pytest.raises(ValueError, match=words):
            parse_assignment(text)


def test_param_write_rules_hold() -> None:
    drive = AcgDrive()
    assert apply_parameters(drive, ["drv=4", "Frq=8"], drive.time) == [
        "drv Cmd Source = 4 (Field Bus)", "Frq Freq Ref Src = 8 (Field Bus)"]
    with pytest.raises(ValueError, match=r"CM\.6.*read-only"):
        apply_parameters(drive, ["CM.6=3"], drive.time)


async def _acg_adapter(*params: str) -> Adapter:
    adapter = Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0))
    assert isinstance(adapter.device, AcgDevice)
    apply_parameters(adapter.device.drive, list(params), adapter.device.drive.time)
    await adapter.start()
    return adapter


@pytest.mark.parametrize("params, runs", [(("drv=4", "Frq=8", "ACC=0.5"), True), (("ACC=0.5",), False)])
async def test_drv_and_frq_make_the_drive_run_over_class_1(params: tuple[str, ...], runs: bool) -> None:
    adapter = await _acg_adapter(*params)
    try:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=ACG_CATALOG) as scanner, \
                scanner.io_connection(output=21, input=71, rpi=0.010, timeout_multiplier=5,
                                      target_io_port=adapter.io.io_port) as io:
            io.output.speed_reference = 900
            io.output.run_forward = True
            if runs:
                image = await io.wait_input(lambda i: i.at_reference, 10)
                assert image.speed_actual == 900 and image.ctrl_from_net and image.ref_from_net
            else:
                # Factory drv = 1: the terminals command the drive, the network's run bit does nothing, in
                # 50 packets that reached it (0.5 s of them), however long they took to come.
                assert adapter.io is not None
                [consuming] = adapter.io.connections.values()
                await wait_until(lambda: consuming.stats.received >= 50, 10, "50 O->T packets")
                assert not io.input.running_forward and io.input.speed_actual == 0 and not io.input.ctrl_from_net
    finally:
        await adapter.close()


async def test_refused_pair_names_the_cm24_cm23_selection(caplog: pytest.LogCaptureFixture) -> None:
    adapter = await _acg_adapter()
    try:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=ACG_CATALOG) as scanner:
            with caplog.at_level(logging.INFO, logger="cipstack.eip.target.io_target"), \
                    pytest.raises(CipError) as refused:
                async with scanner.io_connection(output=100, input=110, rpi=0.010, target_io_port=adapter.io.io_port):
                    pass
        assert refused.value.extended[:1] == (0x012A,)
        line = next(r.getMessage() for r in caplog.records if "refused" in r.getMessage())
        assert "no output assembly 100" in line
        assert "output 21 / input 71, the pair CM.24 = 1 / CM.23 = 1 select" in line
        assert "--param CM.24=N --param CM.23=N --param CM.94=1" in line
    finally:
        await adapter.close()


async def test_cm24_cm23_at_start_select_another_pair() -> None:
    adapter = await _acg_adapter("CM.24=3", "CM.23=3", "CM.94=1")
    try:
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=ACG_CATALOG) as scanner, \
                scanner.io_connection(output=101, input=111, rpi=0.010, target_io_port=adapter.io.io_port) as io:
            await io.wait_input(lambda i: i.ready, 5)
    finally:
        await adapter.close()


# -- 12.3: the adapter's ports are its own; silence is reported ----------------------------------------------
async def test_silent_consumer_is_logged(caplog: pytest.LogCaptureFixture) -> None:
    """The issue's case: the originator sends its O->T data to another port than the adapter's."""
    adapter = await _acg_adapter()
    elsewhere = free_port()
    try:
        with caplog.at_level(logging.INFO, logger="cipstack.eip.target.io_target"):
            async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=ACG_CATALOG) as scanner:
                async with scanner.io_connection(output=21, input=71, rpi=0.010, target_io_port=elsewhere):
                    # Said half a second (SILENT_MINIMUM_S) after the open; within the second the test gave it.
                    await wait_until(lambda: any("no O->T data" in r.getMessage() for r in caplog.records), 1.0,
                                     "the warning of no O->T data")
                silent = [r for r in caplog.records if "no O->T data" in r.getMessage()]
                assert len(silent) == 1 and silent[0].levelno == logging.WARNING
                assert f"consumes on UDP port {adapter.io.io_port}" in silent[0].getMessage()
                caplog.clear()
                async with scanner.io_connection(output=21, input=71, rpi=0.010, target_io_port=adapter.io.io_port):
                    await asyncio.sleep(1.0)   # the subject: no warning past the moment it would come (0.5 s)
                assert not [r for r in caplog.records if "no O->T data" in r.getMessage()]
    finally:
        await adapter.close()


def test_a_second_adapter_on_the_same_io_port_fails(tmp_path: Path) -> None:
    io_port = free_port()
    _, first = start_adapter("--io-port", str(io_port), "--control", str(tmp_path / "a.sock"))
    try:
        second = run("adapter", "--port", str(free_port()), "--io-port", str(io_port),
                     "--control", str(tmp_path / "b.sock"))
        assert second.returncode == 2
        assert one_line_error(second) == (f"cipstack adapter: cannot listen on UDP 127.0.0.1:{io_port} "
                                          "(class 1 I/O, --io-port): Address already in use")
        control = run("adapter", "--port", str(free_port()), "--io-port", "0", "--control", str(tmp_path / "a.sock"))
        assert control.returncode == 2
        assert one_line_error(control) == ("cipstack adapter: cannot listen on control socket (--control): another "
                                           f"emulator already uses {tmp_path / 'a.sock'}; give another --control path")
    finally:
        stop(first)


@pytest.mark.parametrize("kind", ["udp", "modbus"])
def test_a_taken_port_is_one_line_and_exit_2(kind: str) -> None:
    port = free_port()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM if kind == "udp" else socket.SOCK_STREAM) as busy:
        busy.bind(("127.0.0.1", port))
        if kind == "udp":
            result = run("adapter", "--port", str(port), "--io-port", "0")
            expected = f"UDP 127.0.0.1:{port} (EtherNet/IP, --port)"
        else:
            busy.listen()
            result = run("adapter", "--port", str(free_port()), "--io-port", "0", "--modbus-port", str(port))
            expected = f"TCP 127.0.0.1:{port} (Modbus TCP, --modbus-port)"
    assert result.returncode == 2
    assert one_line_error(result) == f"cipstack adapter: cannot listen on {expected}: Address already in use"


# -- 12.6: messages and shapes ---------------------------------------------------------------------------------
def test_trips_in_words_and_valid_codes_listed(tmp_path: Path) -> None:
    control = tmp_path / "mx2.sock"
    _, process = start_adapter("--model", "MX2-A2015-E", "--quiet", "--control", str(control))
    try:
        tripped = run("drive", "trip", "5", "--control", str(control))
        assert tripped.returncode == 0, tripped.stderr
        assert tripped.stdout.splitlines()[0] == "tripped: E05 Overload protection"
        # A second fault while tripped is refused and the first one kept (issue 14 item 9).
        second = run("drive", "trip", "E12", "--control", str(control), "--json")
        assert second.returncode == 1 and "already tripped" in one_line_error(second)
        unknown = run("drive", "trip", "12345", "--control", str(control))
        assert unknown.returncode == 2
        assert "valid codes: 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 20" in one_line_error(unknown)
        status = json.loads(run("drive", "status", "--control", str(control), "--json").stdout)
        assert status["model"] == "MX2-A2015-E" and status["state"] == "faulted" and status["trip"] == "E05"
        assert status["class1_connections"] == 0 and "ok" not in status
    finally:
        stop(process)
    absent = run("drive", "status", "--control", str(control))
    assert absent.returncode == 1 and "no emulator listens" in one_line_error(absent)


def test_acg_status_json_by_field(tmp_path: Path) -> None:
    control = tmp_path / "acg.sock"
    _, process = start_adapter("--quiet", "--control", str(control), "--param", "drv=4")
    try:
        by_name = run("drive", "trip", "OverHeat", "--control", str(control), "--json")
        assert json.loads(by_name.stdout)["trip"] == "OverHeat", by_name.stderr
        status = json.loads(run("drive", "status", "--control", str(control), "--json").stdout)
        assert status == {"state": "FAULT_STOP", "direction": None, "output_frequency_hz": 0.0, "reference_hz": 0.0,
                          "output_current_a": 0.0, "not_simulated": ["output_current_a"], "io_connections": 0,
                          "trip": "OverHeat", "fault_code": 0x4200,
                          "lost_command": False, "comm_update_pending": False, "power": "on", "link": "plugged",
                          "sessions": 0, "class3_connections": 0, "class1_connections": 0, "faults": 0,
                          "productions": {"sent": 0, "late": 0, "missed": 0}}
    finally:
        stop(process)


def test_model_without_profile() -> None:
    address, process = start_adapter("--model", "RX-A4055-E", "--quiet")
    try:
        assert json.loads(run("identity", address, "--json").stdout)["vendor_id"] == 47
    finally:
        stop(process)
    unknown = run("adapter", "--model", "MX2-A2015", "--port", str(free_port()))
    assert unknown.returncode == 2 and "did you mean MX2-A2015-E" in one_line_error(unknown)
    acg = run("adapter", "--profile", "acg", "--model", "MX2-A2015-E", "--port", str(free_port()))
    assert acg.returncode == 2 and "acg profile has one model" in one_line_error(acg)


def test_type_mismatch_is_local(tmp_path: Path) -> None:
    address, process = start_adapter("--quiet", "--control", str(tmp_path / "c.sock"))
    try:
        result = run("get", address, "1/1/7", "--type", "UINT")
        assert result.returncode == 2
        assert one_line_error(result) == ("cipstack get: 0x01/1/7 answered 5 bytes (04 43 45 4e 54), which do not "
                                          "decode as UINT: UINT is 2 bytes, got 5")
    finally:
        stop(process)


async def test_declared_decoding_tolerates_a_device_that_differs() -> None:
    """Decoding by declaration is tolerant: raw bytes stand; an explicit type is a local error."""
    adapter = await _acg_adapter()
    try:
        wrong = Catalog(resolvers={0x01: lambda instance, attribute: ACG_CATALOG.attribute(0x01, 1, 1)})
        async with await Scanner.connect(f"127.0.0.1:{adapter.port}", catalog=wrong) as scanner:
            assert await scanner.read(0x01, 1, 7) == b"\x04CENT"
            with pytest.raises(ReplyDecodeError):
                await scanner.read(0x01, 1, 7, ACG_CATALOG.attribute(0x01, 1, 1).type)   # type: ignore[union-attr]
    finally:
        await adapter.close()


@contextlib.contextmanager
def refusing_target(status: int) -> Iterator[int]:
    """A scripted target that answers every RegisterSession with ``status`` (a full session table: 0x0002)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    stopping = threading.Event()

    def serve() -> None:
        server.settimeout(0.2)
        while not stopping.is_set():
            try:
                peer, _ = server.accept()
            except OSError:
                continue
            with peer:
                header = peer.recv(28)
                if len(header) >= 24:
                    command, _, _, _, context, _ = struct.unpack("<HHII8sI", header[:24])
                    peer.sendall(struct.pack("<HHII8sI", command, 4, 0, status, context, 0) + b"\x01\x00\x00\x00")

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield server.getsockname()[1]
    finally:
        stopping.set()
        thread.join(2)
        server.close()


def test_full_session_table_names_the_limit(tmp_path: Path) -> None:
    with refusing_target(0x0002) as port:
        result = run("get", f"127.0.0.1:{port}", "1/1/7", "--type", "SHORT_STRING")
    assert result.returncode == 1
    assert one_line_error(result).endswith("status 0x0002 (insufficient memory): the target's session table is "
                                           "full (its session limit is reached)")
    address, process = start_adapter("--quiet", "--max-sessions", "1", "--control", str(tmp_path / "s.sock"))
    try:
        from cipstack.scanner import SyncScanner

        with SyncScanner(address):
            refused = run("get", address, "1/1/7")
        assert refused.returncode == 1 and "session table is full" in one_line_error(refused)
    finally:
        stderr = stop(process)
    assert "RegisterSession refused (0x0002): all 1 sessions in use (the session limit, --max-sessions)" in stderr


def test_failed_save_is_logged(caplog: pytest.LogCaptureFixture) -> None:
    drive = AcgDrive()
    apply_parameters(drive, ["drv=4", "Frq=8"], 0.0)
    drive.write(0x0380, 3000, 0.0)
    drive.set_run_command(True, False, 0.0)
    with caplog.at_level(logging.WARNING, logger="cipstack.devices.acg.drive"), pytest.raises(RegisterError):
        drive.write(0x03E0, 1, 1.0)
    assert [r.getMessage() for r in caplog.records] == [
        "parameter save refused (0x03E0 = 1 while the drive runs): nothing saved"]


def test_options_the_docs_name() -> None:
    """The command line's page (docs/command-line/index.md) says which commands take --json and
    which --timeout: each does."""
    parser = build_parser()
    printing = ["discover", "identity h", "get h 1/1", "set h 1/1/1 1 --type UINT", "io h", "models",
                "drive trip 1", "drive status", "eds check f", "eds show f"]
    talking = ["discover", "identity h", "get h 1/1", "set h 1/1/1 1 --type UINT", "io h", "drive trip 1",
               "drive status", "eds check f"]
    for command in printing:
        assert parser.parse_args([*command.split(), "--json"]).json
    for command in talking:
        assert parser.parse_args([*command.split(), "--timeout", "1.5"]).timeout == 1.5
    readme = " ".join((Path(__file__).resolve().parents[1] / "docs" / "command-line" / "index.md").read_text().split())
    assert "`discover`, `identity`, `get`, `set`, `io`, `models`, `drive`, `eds check` and `eds show`" in readme
    assert "`identity`, `get`, `set`, `io`, `drive` and `eds check`" in readme
    overview = subprocess.run([sys.executable, "-m", "cipstack", "--help"], capture_output=True, text=True).stdout
    assert "EDS files: generate, check, show, fetch" in " ".join(overview.split())
    adapter_help = " ".join(run("adapter", "--help").stdout.split())
    assert "--port PORT EtherNet/IP port, TCP and UDP (default 44818)" in adapter_help
    assert "refused with 0x0002 (default 32)" in adapter_help


def test_json_keys() -> None:
    assert json_key("Serial Number") == "serial_number"
    assert json_key("Maximum ID Number Class Attributes") == "maximum_id_number_class_attributes"


# -- 12.8: instance 0 by what the device declares -------------------------------------------------------------
def test_omron_register_instance_zero(tmp_path: Path) -> None:
    address, process = start_adapter("--model", "MX2-A2015-E", "--quiet", "--control", str(tmp_path / "o.sock"))
    try:
        f001 = run("get", address, "0x64/0/1", "--json")
        assert f001.returncode == 0, f001.stderr
        record = json.loads(f001.stdout)
        assert record["type"] == "UDINT" and len(bytes.fromhex(record["data"])) == 4
        assert record["name"].startswith("F001 ")
        typed = run("get", address, "0x64/0/1", "--type", "UDINT")
        assert typed.returncode == 0 and typed.stdout.startswith("F001 ") and "Revision" not in typed.stdout
        # Other classes keep the standard class attributes at instance 0.
        assert run("get", address, "0x29/0/1").stdout.startswith("Revision = ")
    finally:
        stop(process)


def test_gateway_status_json_and_trip_refusal(tmp_path: Path) -> None:
    control = tmp_path / "gateway.sock"
    port = free_port()
    gateway = subprocess.Popen([sys.executable, "-m", "cipstack", "componet", "--nodes", "mx2:MX2-A2015-E@3",
                                "--port", str(port), "--io-port", "0", "--quiet", "--control", str(control)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for _ in range(300):
            status = run("drive", "status", "--control", str(control), "--json")
            if status.returncode == 0:
                break
        record = json.loads(status.stdout)
        assert record["status"].startswith("CompoNet gateway") and record["sessions"] == 0
        trip = run("drive", "trip", "5", "--control", str(control))
        assert trip.returncode == 2 and "simulates no drive" in one_line_error(trip)
    finally:
        stop(gateway)


@pytest.mark.parametrize("data_at", [None, 0.1])
def test_silence_is_said_once_after_8_rpis(caplog: pytest.LogCaptureFixture, data_at: float | None) -> None:
    """Sans I/O: 8 RPIs of 10 ms is under the 0.5 s floor, so the warning comes at 0.5 s, once, and
    only when no O->T datagram came; the watchdog still waits its 10 s before closing."""
    from cipstack.eip.io_core import encode_io_datagram
    from tests.test_io_core import Rig

    rig = Rig()
    with caplog.at_level(logging.WARNING, logger="cipstack.eip.target.io_target"):
        rig.open(rig.request(rpi=10_000), now=0.0)
        [connection] = rig.io.connections.values()
        if data_at is not None:
            rig.io.receive(encode_io_datagram(connection.ot_connection_id, 1, 1, bytes(4), 1), ("127.0.0.1", 2222),
                           data_at)
        assert connection.silence_check == 0.5
        rig.io.poll(0.0)   # production due at once: the next deadline is then the earliest of RPI and silence
        assert rig.io.next_deadline() == 0.01
        rig.io.expire(0.49)
        assert not caplog.records
        rig.io.expire(0.5)
        rig.io.expire(0.9)
    said = [r.getMessage() for r in caplog.records]
    if data_at is None:
        assert len(said) == 1 and said[0].startswith(f"class 1 {connection.name}: no O->T data from 127.0.0.1 "
                                                     "after 8 RPIs (0.500 s)")
        assert rig.io.connections and connection.silence_check is None   # open until its first 10 s are up
    else:
        assert said == []   # data came (then stopped: the watchdog closed it at RPI x 4, no silence to tell)


@contextlib.contextmanager
def omron_register_target(reply_data: bytes, layout: str = "00000000 0000 0200 0000 0000 b200") -> Iterator[int]:
    """A scripted MX2 (vendor 47, the product code of MX2-A2015-E) that answers every explicit request
    with status 0 and ``reply_data``: the issue's 4-byte reply of 0x64/0/1 (F001). ``layout``: the bytes of
    the SendRRData reply before the unconnected item's length (interface, timeout, item count, items)."""
    from cipstack.devices.omron.models import model
    from cipstack.eip.wire.cpf import SockAddr
    from cipstack.eip.wire.identity_items import IdentityRecord, encode_list_identity

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen()
    port = server.getsockname()[1]
    identity = encode_list_identity(IdentityRecord(47, 2, model("MX2-A2015-E").product_code, (1, 1), 0, 1, "MX2"),
                                    SockAddr("127.0.0.1", port))
    stopping = threading.Event()

    def frame(command: int, session: int, context: bytes, body: bytes) -> bytes:
        return struct.pack("<HHII8sI", command, len(body), session, 0, context, 0) + body

    def serve_one(peer: socket.socket) -> None:
        data = b""
        while not stopping.is_set():
            chunk = peer.recv(4096)
            if not chunk:
                return
            data += chunk
            while len(data) >= 24:
                command, length, _, _, context, _ = struct.unpack("<HHII8sI", data[:24])
                if len(data) < 24 + length:
                    break
                body, data = data[24:24 + length], data[24 + length:]
                if command == 0x63:            # ListIdentity
                    peer.sendall(frame(command, 0, context, identity))
                elif command == 0x65:          # RegisterSession
                    peer.sendall(frame(command, 0x11223344, context, body))
                elif command == 0x6F:          # SendRRData: reply service = request service | 0x80, status 0
                    service = body[16]         # after interface, timeout, count, null item, item header
                    response = bytes((service | 0x80, 0, 0, 0)) + reply_data
                    items = (bytes.fromhex(layout) + struct.pack("<H", len(response))
                             + response)
                    peer.sendall(frame(command, 0x11223344, context, items))
                else:                          # UnRegisterSession
                    return

    def serve() -> None:
        server.settimeout(0.2)
        while not stopping.is_set():
            try:
                peer, _ = server.accept()
            except OSError:
                continue
            with peer:
                peer.settimeout(5)
                with contextlib.suppress(OSError):
                    serve_one(peer)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield port
    finally:
        stopping.set()
        thread.join(2)
        server.close()


def test_instance_zero_register_reply_from_its_wire_bytes() -> None:
    """The issue's bytes: F001 = 1000 (0x000003E8) answered at 0x64/0/1 in 4 bytes."""
    with omron_register_target(bytes.fromhex("e8030000")) as port:
        declared = run("get", f"127.0.0.1:{port}", "0x64/0/1", "--json")
        typed = run("get", f"127.0.0.1:{port}", "0x64/0/1", "--type", "UDINT")
        wrong = run("get", f"127.0.0.1:{port}", "0x64/0/1", "--type", "UINT")
    assert declared.returncode == 0, declared.stderr
    record = json.loads(declared.stdout)
    assert (record["value"], record["type"], record["data"]) == (1000, "UDINT", "e8030000")
    assert record["name"].startswith("F001 ")
    # F001 is declared in 0.01 Hz (its register): the engineering value, its unit, then the raw value.
    assert typed.returncode == 0 and typed.stdout.startswith("F001 ")
    assert typed.stdout.rstrip().endswith("= 10.00 Hz (1000)")
    assert wrong.returncode == 2 and "0x15" not in one_line_error(wrong)
    assert "4 bytes (e8 03 00 00), which do not decode as UINT" in one_line_error(wrong)


def test_a_malformed_reply_is_one_line() -> None:
    """A SendRRData reply whose item count is wrong (timeout 2, no items, then bytes): one line, exit 1."""
    with omron_register_target(bytes.fromhex("e8030000"), layout="00000000 0200 0000 0000 b200") as port:
        result = run("get", f"127.0.0.1:{port}", "0x64/0/1")
    assert result.returncode == 1
    assert one_line_error(result) == "cipstack get: malformed SendRRData reply: no Unconnected Data item"
