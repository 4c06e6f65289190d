"""The originator against what C/C++ stacks in the field send (issue: "work with the stacks in the
field"): each case is a scripted target (tests/fakes.py) that answers with the bytes seen."""

from __future__ import annotations

import asyncio
import errno
import logging
import os
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from cipstack.cip.status import CipError
from cipstack.cli import main
from cipstack.devices.acg.eds_file import acg_et2_description
from cipstack.eds.generator import eds_text
from cipstack.eip.io_server import IoEndpoint
from cipstack.eip.originator.asyncio_client import MalformedReplyError, broadcast_addresses, discover
from cipstack.eip.originator.io_originator import ArrivalStatistics, Class1Request, OtFormat, class1_path
from cipstack.eip.wire.cpf import decode_items
from cipstack.eip.wire.encapsulation import EncapsulationError
from cipstack.scanner import UNDECODED, Scanner
from tests.fakes import (
    FORWARD_CLOSE,
    FORWARD_OPEN,
    GET_ATTRIBUTES_ALL,
    ClassOneProducer,
    MrRequest,
    ScriptedTarget,
    cpf,
    forward_open_fields,
    mr_reply,
    rr_body,
    sockaddr,
    to_port,
)

ROOT = Path(__file__).resolve().parent.parent

# Issue case 1: a Forward_Open reply (CPF items after the Null Address) with an O->T Sockaddr Info
# 0.0.0.0:2222 and a T->O Sockaddr Info 0.0.0.0:<the originator's port> on a point-to-point connection.
P2P_ECHO_ITEMS = bytes.fromhex(
    "b2001e00d40000001300c0b0ff864fe0b165fefff587a3221027000010270000000000801000000208ae000000000000"
    "0000000000000180100000000290d3000000000000000000000000")
P2P_OT_ID, P2P_TO_ID = 0xB0C00013, 0xE04F86FF

# Issue case 4: an error reply (0x01/0x0315) counting 2 CPF items and carrying a third.
TRAILING_FRAME = bytes.fromhex(
    "6f0034000100000000000000040000000000000000000000000000000000020000000000b2001000d400010115035c44feff"
    "19f4396400000180100000029de9000000000000000000000000")

# ListIdentity item of an ACG-ET2 (vendor 259, device type 2, product code 100), serial 0x00C0FFEE.
ACG_IDENTITY = (struct.pack("<H", 1) + sockaddr("127.0.0.1", 44818)
                + struct.pack("<HHHBBHI", 259, 2, 100, 1, 1, 0x0030, 0x00C0FFEE) + bytes([7]) + b"ACG-ET2" + b"\x03")


def p2p_echo_reply(request: MrRequest, producer: ClassOneProducer, period: float = 0.010) -> bytes:
    """The issue's reply, verbatim; the scripted target then produces to the port the request named."""
    fields = forward_open_fields(request)
    port = to_port(request)
    assert port is not None
    producer.produce(P2P_TO_ID, (request.peer[0], port), bytes(int(fields["to_size"]) - 2), period)
    return bytes(6) + struct.pack("<H", 4) + b"\x00\x00\x00\x00" + P2P_ECHO_ITEMS


def run_cli(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture
def producer() -> Any:
    made = ClassOneProducer()
    yield made
    made.close()


# -- 1: T->O Sockaddr Info 0.0.0.0 on a point-to-point connection ------------------------------------------
def test_p2p_sockaddr_echo_is_informational(producer: ClassOneProducer, capsys: pytest.CaptureFixture[str]) -> None:
    with ScriptedTarget(handler=lambda r: p2p_echo_reply(r, producer) if r.service == FORWARD_OPEN else None,
                        assembly_sizes={21: 4, 71: 4}) as target:
        code, out, err = run_cli(["io", target.address, "--output", "21", "--input", "71", "--duration", "0.6s",
                                  "--target-io-port", str(producer.port), "--set", "raw=01000000"], capsys)
        assert code == 0, err
        assert "Errno" not in err and "Traceback" not in err
        assert "received" in out
        received = int(out.split("received ")[1].split()[0])
        assert received > 20, out
        # O->T went point-to-point to the target, on the connection id its reply chose, with run/idle.
        assert producer.ot_payload_sizes(P2P_OT_ID) == {2 + 4 + 4}
        assert len(target.services(FORWARD_CLOSE)) == 1


# -- 2: every exit after a successful Forward_Open closes it ---------------------------------------------
def test_join_failure_after_open_sends_forward_close(producer: ClassOneProducer, monkeypatch: pytest.MonkeyPatch
                                                     ) -> None:
    def multicast_reply(request: MrRequest) -> bytes | None:
        if request.service != FORWARD_OPEN:
            return None
        reply = mr_reply(FORWARD_OPEN, data=struct.pack("<IIHHIIIBB", 0x11, 0x22, 1, 0xFFFE, 7, 10000, 10000, 0, 0))
        return rr_body(reply, (0x8001, sockaddr("239.192.1.1", 2222)))

    async def refuse(self: IoEndpoint, group: str, port: int) -> None:
        raise OSError(errno.EINVAL, "Invalid argument")

    monkeypatch.setattr(IoEndpoint, "join_multicast", refuse)

    async def scenario(address: str) -> None:
        async with await Scanner.connect(address) as scanner, scanner.io_connection(
                output=21, input=71, rpi=0.010, output_size=4, input_size=4, target_io_port=producer.port):
            pytest.fail("the connection must not open")

    with ScriptedTarget(handler=multicast_reply) as target:
        with pytest.raises(OSError, match="Invalid argument"):
            asyncio.run(scenario(target.address))
        assert len(target.services(FORWARD_CLOSE)) == 1
        opened = forward_open_fields(target.services(FORWARD_OPEN)[0])
        assert target.services(FORWARD_CLOSE)[0].data[2:10] == opened["triad"]


def test_error_in_the_body_sends_forward_close(producer: ClassOneProducer, capsys: pytest.CaptureFixture[str]) -> None:
    """``--set foo=1`` fails after the open: one line listing the fields, exit 2, and the connection closed."""
    with ScriptedTarget(handler=lambda r: p2p_echo_reply(r, producer) if r.service == FORWARD_OPEN else None,
                        identity=ACG_IDENTITY) as target:
        code, _, err = run_cli(["io", target.address, "--output", "21", "--input", "71", "--set", "foo=1",
                                "--target-io-port", str(producer.port)], capsys)
        assert code == 2
        assert err.count("\n") == 1 and "no field 'foo'" in err
        assert "run_forward" in err and "speed_reference" in err and "raw" in err
        assert len(target.services(FORWARD_CLOSE)) == 1


def test_ctrl_c_closes_prints_statistics_and_exits_130(producer: ClassOneProducer) -> None:
    with ScriptedTarget(handler=lambda r: p2p_echo_reply(r, producer) if r.service == FORWARD_OPEN else None,
                        assembly_sizes={21: 4, 71: 4}) as target:
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        proc = subprocess.Popen([sys.executable, "-m", "cipstack", "io", target.address, "--output", "21", "--input",
                                 "71", "--duration", "30s", "--target-io-port", str(producer.port)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        try:
            deadline = time.monotonic() + 20
            while not target.services(FORWARD_OPEN) or len(producer.received) < 5:
                assert time.monotonic() < deadline, "no class 1 traffic"
                assert proc.poll() is None, proc.communicate()
                time.sleep(0.05)
            proc.send_signal(signal.SIGINT)
            out, err = proc.communicate(timeout=20)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert proc.returncode == 130, err
        assert "Traceback" not in err and "aclose" not in err
        assert "sent " in out and "received " in out
        assert len(target.services(FORWARD_CLOSE)) == 1


# -- 3: heartbeat O->T format ----------------------------------------------------------------------------
def heartbeat_target(producer: ClassOneProducer, opens: list[dict[str, Any]]) -> Callable[[MrRequest], bytes | None]:
    """A target whose heartbeat point takes the sequence count alone: size 6 is refused with 0x0127, size 2."""
    def handle(request: MrRequest) -> bytes | None:
        if request.service != FORWARD_OPEN:
            return None
        fields = forward_open_fields(request)
        opens.append(fields)
        if fields["ot_size"] != 2:
            failure = fields["triad"] + b"\x00\x00"
            return rr_body(mr_reply(FORWARD_OPEN, 0x01, (0x0127, 2), failure))
        return p2p_echo_reply(request, producer)

    return handle


def test_heartbeat_retry_with_the_size_the_target_wants(producer: ClassOneProducer,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    opens: list[dict[str, Any]] = []
    with ScriptedTarget(handler=heartbeat_target(producer, opens), assembly_sizes={71: 4}) as target:
        code, out, err = run_cli(["io", target.address, "--heartbeat", "198", "--input", "71", "--duration", "0.5s",
                                  "--target-io-port", str(producer.port)], capsys)
        assert code == 0, err
        assert [o["ot_size"] for o in opens] == [6, 2]
        assert "0x0127" in err and "retrying with 2" in err
        assert producer.ot_payload_sizes(P2P_OT_ID) == {2}, (len(producer.received), out, err)  # the count alone
        assert len(target.services(FORWARD_CLOSE)) == 1


def test_heartbeat_format_from_the_eds_and_from_the_option(producer: ClassOneProducer,
                                                           capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    eds = tmp_path / "acg.eds"
    eds.write_text(eds_text(acg_et2_description()))
    opens: list[dict[str, Any]] = []
    with ScriptedTarget(handler=heartbeat_target(producer, opens), assembly_sizes={110: 4}) as target:
        code, _, err = run_cli(["io", target.address, "--eds", str(eds), "--connection", "17", "--duration", "0.3s",
                                "--target-io-port", str(producer.port)], capsys)
        assert code == 0, err
        code, _, err = run_cli(["io", target.address, "--heartbeat", "198", "--input", "110", "--ot-format",
                                "heartbeat", "--duration", "0.3s", "--target-io-port", str(producer.port)], capsys)
        assert code == 0, err
    # ConnectionN field 2 = 0x44640305 (O->T format 3): size 2 at the first attempt, no retry.
    assert [o["ot_size"] for o in opens] == [2, 2]
    assert "retrying" not in err


def test_size_correction_rules() -> None:
    heartbeat = Class1Request(None, 4, 10000, 10000, class1_path(None, 71, 1, 198))
    corrected = heartbeat.corrected((0x0127, 2))
    assert corrected is not None and corrected[0].ot_format is OtFormat.HEARTBEAT and corrected[0].ot_size == 2
    owner = Class1Request(4, 4, 10000, 10000, class1_path(21, 71, 1))
    assert owner.ot_size == 10 and owner.to_size == 6
    assert owner.corrected((0x0127, 6))[0].ot_format is OtFormat.MODELESS  # type: ignore[index]
    assert owner.corrected((0x0127, 14))[0].output_size == 8  # type: ignore[index]
    assert owner.corrected((0x0128, 10))[0].input_size == 8  # type: ignore[index]
    assert owner.corrected((0x0127,)) is None  # no size named: nothing to retry with
    assert owner.corrected((0x0127, 10)) is None  # the size sent: a retry would change nothing
    assert owner.corrected((0x0315, 2)) is None


# -- 4: bytes after the last CPF item; malformed replies ----------------------------------------------------
def test_trailing_item_keeps_the_cip_status(producer: ClassOneProducer, capsys: pytest.CaptureFixture[str],
                                            caplog: pytest.LogCaptureFixture) -> None:
    body = TRAILING_FRAME[24:]
    assert len(body) == struct.unpack_from("<H", TRAILING_FRAME, 2)[0]
    with ScriptedTarget(handler=lambda r: body if r.service == FORWARD_OPEN else None,
                        assembly_sizes={21: 4, 71: 4}) as target, \
            caplog.at_level(logging.DEBUG, logger="cipstack.eip.wire.cpf"):
        code, _, err = run_cli(["io", target.address, "--output", "21", "--input", "71",
                                "--target-io-port", str(producer.port)], capsys)
    assert code == 1
    assert err.count("\n") == 1 and "0x01" in err and "0x0315" in err, err
    assert any("after the 2 declared item" in r.getMessage() for r in caplog.records)


def test_cpf_strict_for_a_target_tolerant_for_a_reply() -> None:
    body = TRAILING_FRAME[24 + 6:]
    with pytest.raises(EncapsulationError):
        decode_items(body)
    items = decode_items(body, strict=False)
    assert [item.type for item in items] == [0x0000, 0x00B2]


MALFORMED = {
    "short message-router reply": rr_body(b"\xd4\x00"),
    "no Unconnected Data item": bytes(6) + cpf((0x0000, b"")),
    "item runs past the packet": bytes(6) + b"\x02\x00\x00\x00\x00\x00\xb2\x00\x40\x00\x8e\x00",
    "additional status past the end": rr_body(b"\x8e\x00\x00\x05\x01"),
}


@pytest.mark.parametrize("reply", list(MALFORMED.values()), ids=list(MALFORMED))
def test_a_malformed_reply_is_one_error_line(reply: bytes, capsys: pytest.CaptureFixture[str]) -> None:
    with ScriptedTarget(handler=lambda r: reply) as target:
        code, _, err = run_cli(["get", target.address, "1/1/7"], capsys)
    assert code == 1
    assert err.count("\n") == 1 and "malformed" in err and "Traceback" not in err, err


def test_a_malformed_forward_open_reply_is_malformed_reply_error(producer: ClassOneProducer) -> None:
    async def scenario(address: str) -> None:
        async with await Scanner.connect(address) as scanner, scanner.io_connection(
                output=21, input=71, output_size=4, input_size=4, target_io_port=producer.port):
            pass

    def handler(request: MrRequest) -> bytes | None:
        return rr_body(mr_reply(FORWARD_OPEN, data=b"\x01\x02\x03")) if request.service == FORWARD_OPEN else None
    with ScriptedTarget(handler=handler) as target, pytest.raises(MalformedReplyError, match="Forward_Open"):
        asyncio.run(scenario(target.address))


def test_a_garbled_list_identity_is_one_error_line(capsys: pytest.CaptureFixture[str]) -> None:
    with ScriptedTarget(identity=b"\x01\x00\x00\x02") as target:
        code, _, err = run_cli(["identity", target.address], capsys)
    assert code == 1 and err.count("\n") == 1 and "malformed ListIdentity" in err


# -- 5: configuration instance and data --------------------------------------------------------------------
def test_config_instance_and_data(producer: ClassOneProducer, capsys: pytest.CaptureFixture[str]) -> None:
    """A target whose configuration assembly is 151 refuses instance 1 with 0x0315."""
    def handle(request: MrRequest) -> bytes | None:
        if request.service != FORWARD_OPEN:
            return None
        path = bytes(forward_open_fields(request)["path"])  # type: ignore[arg-type]
        if path[:4] != b"\x20\x04\x24\x97":
            return rr_body(mr_reply(FORWARD_OPEN, 0x01, (0x0315,), forward_open_fields(request)["triad"] + b"\0\0"))
        return p2p_echo_reply(request, producer)

    with ScriptedTarget(handler=handle, assembly_sizes={21: 4, 71: 4}) as target:
        code, _, err = run_cli(["io", target.address, "--output", "21", "--input", "71", "--duration", "0.2s",
                                "--target-io-port", str(producer.port)], capsys)
        assert code == 1 and "0x0315" in err
        code, _, err = run_cli(["io", target.address, "--output", "21", "--input", "71", "--config", "151",
                                "--config-data", "0102030405", "--duration", "0.2s",
                                "--target-io-port", str(producer.port)], capsys)
        assert code == 0, err
        path = forward_open_fields(target.services(FORWARD_OPEN)[-1])["path"]
        assert path == bytes.fromhex("20042497 2c15 2c47 8003 010203040500".replace(" ", ""))


def test_timeout_multiplier_is_the_users(producer: ClassOneProducer, capsys: pytest.CaptureFixture[str]) -> None:
    """`--timeout-multiplier N` goes into the Forward_Open (byte 12 of its data): RPI x 4 x 2^N; 2 by
    default; outside 0..7 one line and exit 2."""
    def handle(request: MrRequest) -> bytes | None:
        return p2p_echo_reply(request, producer) if request.service == FORWARD_OPEN else None

    with ScriptedTarget(handler=handle, assembly_sizes={21: 4, 71: 4}) as target:
        for option, multiplier in (([], 2), (["--timeout-multiplier", "5"], 5)):
            code, _, err = run_cli(["io", target.address, "--output", "21", "--input", "71", "--duration", "0.2s",
                                    "--target-io-port", str(producer.port), *option], capsys)
            assert code == 0, err
            assert forward_open_fields(target.services(FORWARD_OPEN)[-1])["timeout_multiplier"] == multiplier
    code, _, err = run_cli(["io", "127.0.0.1:1", "--output", "21", "--input", "71", "--timeout-multiplier", "8"],
                           capsys)
    assert code == 2 and "--timeout-multiplier" in err


def test_config_data_must_be_hex(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["io", "127.0.0.1:1", "--output", "21", "--input", "71", "--config-data", "xyz"], capsys)
    assert code == 2 and "--config-data" in err


# -- 6: a producer slower than its API ---------------------------------------------------------------------
def test_a_slow_producer_shows_in_the_statistics(producer: ClassOneProducer, caplog: pytest.LogCaptureFixture
                                                 ) -> None:
    """The API granted is 1 ms; the target produces every 10 ms, numbering every packet (lost 0)."""
    def handle(request: MrRequest) -> bytes | None:
        if request.service != FORWARD_OPEN:
            return None
        port = to_port(request)
        assert port is not None
        producer.produce(0x22, (request.peer[0], port), bytes(4), 0.010)
        reply = struct.pack("<IIHHIIIBB", 0x11, 0x22, 1, 0xFFFE, 7, 1000, 1000, 0, 0)
        return rr_body(mr_reply(FORWARD_OPEN, data=reply))

    async def scenario(address: str) -> dict[str, Any]:
        async with await Scanner.connect(address) as scanner, scanner.io_connection(
                output=21, input=71, rpi=0.001, output_size=4, input_size=4, target_io_port=producer.port) as io:
            await asyncio.sleep(1.0)     # the subject: the statistics of a second of arrivals
            return io.statistics()

    with ScriptedTarget(handler=handle) as target, caplog.at_level(logging.WARNING):
        stats = asyncio.run(scenario(target.address))
    assert stats["lost"] == 0
    assert stats["api_rate_hz"] == 1000
    assert 40 < stats["received_rate_hz"] < 140, stats
    assert stats["interval_p50_ms"] > 5 and stats["interval_max_ms"] >= stats["interval_p99_ms"]
    assert stats["missed_slots"] > 0.8
    slow = [r for r in caplog.records if "slower than its API" in r.getMessage()]
    assert len(slow) == 1, [r.getMessage() for r in caplog.records]


def test_arrival_statistics_are_bounded_and_exact() -> None:
    arrivals = ArrivalStatistics(api=0.001, window=100)
    warnings = [arrivals.arrived(i * 0.010) for i in range(1000)]
    assert len(arrivals.intervals) == 100
    assert sum(w is not None for w in warnings) == 1
    figures = arrivals.as_dict()
    assert figures["interval_p50_ms"] == pytest.approx(10.0)
    assert figures["received_rate_hz"] == pytest.approx(100.0)
    assert figures["missed_slots"] == pytest.approx(1 - 1000 / 9991, abs=1e-4)


# -- 7: discovery --------------------------------------------------------------------------------------------
def list_identity_reply(context: bytes, serial: int) -> bytes:
    item = (struct.pack("<H", 1) + sockaddr("127.0.0.1", 44818)
            + struct.pack("<HHHBBHI", 259, 2, 100, 1, 1, 0x0030, serial) + bytes([7]) + b"ACG-ET2" + b"\x03")
    body = cpf((0x000C, item))
    return struct.pack("<HHII8sI", 0x63, len(body), 0, 0, context, 0) + body


class IdentityResponder:
    """Answers ListIdentity twice (0.5 ms and 0.3 s apart), as the device in the issue did."""

    def __init__(self, bind: str, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.bind((bind, port))
        self.sock.settimeout(0.1)
        self.reply_from = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.reply_from.bind(("127.0.0.1", 0))
        self.heard: list[str] = []
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)
        self.thread.start()

    def run(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self.sock.recvfrom(2048)
            except TimeoutError:
                continue
            except OSError:
                return
            self.heard.append(addr[0])
            reply = list_identity_reply(data[12:20], 0x00C0FFEE)
            self.reply_from.sendto(reply, addr)
            time.sleep(0.0005)
            self.reply_from.sendto(reply, addr)
            time.sleep(0.3)              # the subject: the late duplicate of the device
            self.reply_from.sendto(reply, addr)

    def close(self) -> None:
        self._stop.set()
        self.thread.join(5)  # before closing: a descriptor closed under a blocked thread gets reused
        self.sock.close()
        self.reply_from.close()


def test_loopback_broadcast_is_among_the_defaults() -> None:
    assert broadcast_addresses()[0] == "255.255.255.255"
    assert "127.255.255.255" in broadcast_addresses()


def test_discover_with_defaults_reaches_loopback_and_lists_a_device_once(capsys: pytest.CaptureFixture[str]) -> None:
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.bind(("127.0.0.1", 0))
    port = probe.getsockname()[1]
    probe.close()
    responder = IdentityResponder("127.255.255.255", port)  # hears only what is broadcast on loopback
    try:
        code, out, err = run_cli(["discover", "--port", str(port), "--timeout", "1s"], capsys)
        assert code == 0, err
        assert out.count("ACG-ET2") == 1, out
        assert "serial 0x00C0FFEE" in out
        assert responder.heard
        records = asyncio.run(discover(port=port, timeout=0.8))
        assert len(records) == 1
    finally:
        responder.close()


# -- 8: Get_Attributes_All of a class known in part ----------------------------------------------------------
def test_get_attributes_all_shows_the_undecoded_tail(capsys: pytest.CaptureFixture[str]) -> None:
    """Ethernet Link: 120 bytes, of which the catalog declares attributes 1-3 (14 bytes)."""
    reply_data = struct.pack("<II", 100, 0x0F) + bytes.fromhex("0002a5000001") + bytes(range(106))

    def handle(request: MrRequest) -> bytes | None:
        if request.service == GET_ATTRIBUTES_ALL and request.class_instance == (0xF6, 1):
            return rr_body(mr_reply(GET_ATTRIBUTES_ALL, data=reply_data))
        return None

    with ScriptedTarget(handler=handle) as target:
        code, out, err = run_cli(["get", target.address, "0xF6/1"], capsys)
        assert code == 0, err
        assert "100" in out and UNDECODED in out
        tail_line = next(line for line in out.splitlines() if line.startswith(UNDECODED))
        assert tail_line.endswith(bytes(range(106)).hex(" "))

        async def library(address: str) -> dict[str, Any] | None:
            async with await Scanner.connect(address) as scanner:
                return (await scanner.get_attributes_all(0xF6, 1))[1]

        values = asyncio.run(library(target.address))
        assert values is not None and values[UNDECODED] == bytes(range(106))


# -- issue 12: the first hour --------------------------------------------------------------------------------
def test_rpi_needs_a_unit(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["io", "127.0.0.1:1", "--output", "21", "--input", "71", "--rpi", "5"], capsys)
    assert code == 2 and "give a unit" in err and "5ms" in err
    code, _, err = run_cli(["io", "127.0.0.1:1", "--output", "21", "--input", "71", "--rpi", "20s"], capsys)
    assert code == 2 and "outside" in err


@pytest.mark.parametrize(("mode", "least", "most"), [("summary", 1, 1), ("every:0.2s", 3, 6), ("changes", 50, 200)])
def test_print_throttle(producer: ClassOneProducer, capsys: pytest.CaptureFixture[str], mode: str, least: int,
                        most: int) -> None:
    """Input changing every 10 ms: ``--print summary`` prints the last input only, ``every:0.2s`` a line per 0.2 s."""
    def handle(request: MrRequest) -> bytes | None:
        if request.service != FORWARD_OPEN:
            return None
        port = to_port(request)
        assert port is not None
        producer.produce(0x22, (request.peer[0], port), lambda n: struct.pack("<I", n), 0.010)
        return rr_body(mr_reply(FORWARD_OPEN, data=struct.pack("<IIHHIIIBB", 0x11, 0x22, 1, 0xFFFE, 7, 10000,
                                                                   10000, 0, 0)))

    with ScriptedTarget(handler=handle, assembly_sizes={21: 4, 71: 4}) as target:
        code, out, err = run_cli(["io", target.address, "--output", "21", "--input", "71", "--duration", "1s",
                                  "--print", mode, "--json", "--target-io-port", str(producer.port)], capsys)
    assert code == 0, (err, target.errors)
    lines = [line for line in out.splitlines() if '"input"' in line]
    assert least <= len(lines) <= most, out


def test_print_mode_is_checked(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = run_cli(["io", "127.0.0.1:1", "--output", "21", "--input", "71", "--print", "often"], capsys)
    assert code == 2 and "every:DURATION" in err


def test_outputs_that_never_show_in_the_input_are_reported(producer: ClassOneProducer,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """The I/O went to a port where nobody consumes it: the input never moves while outputs are set."""
    with ScriptedTarget(handler=lambda r: p2p_echo_reply(r, producer) if r.service == FORWARD_OPEN else None,
                        assembly_sizes={21: 4, 71: 4}) as target:
        code, out, err = run_cli(["io", target.address, "--output", "21", "--input", "71", "--duration", "0.5s",
                                  "--set", "raw=01000000", "--target-io-port", str(producer.port)], capsys)
    assert code == 0
    assert "input never changed while outputs were set" in err
    assert "input changes 0" in out


def test_forward_open_refusal_is_cip_error_with_extended_status(producer: ClassOneProducer) -> None:
    body = TRAILING_FRAME[24:]

    async def scenario(address: str) -> None:
        async with await Scanner.connect(address) as scanner, scanner.io_connection(
                output=21, input=71, output_size=4, input_size=4, target_io_port=producer.port):
            pass

    with ScriptedTarget(handler=lambda r: body if r.service == FORWARD_OPEN else None) as target, \
            pytest.raises(CipError) as refused:
        asyncio.run(scenario(target.address))
    assert refused.value.general == 0x01 and refused.value.extended[0] == 0x0315


@pytest.mark.parametrize(("service", "data", "what"), [
    (0x03, b"\x02\x00\x01\x00\x00\x00\x01", "Get_Attribute_List"),      # second entry cut short
    (0x0A, b"\x02\x00\x06\x00\x40\x00\x8e\x00\x00\x00", "Multiple_Service_Packet"),  # offset past the end
])
def test_a_malformed_list_reply_is_malformed_reply_error(service: int, data: bytes, what: str) -> None:
    with ScriptedTarget(handler=lambda r: rr_body(mr_reply(r.service, data=data)) if r.service == service
                        else None) as target:
        async def scenario() -> None:
            async with await Scanner.connect(target.address) as scanner:
                if service == 0x03:
                    await scanner.get_attribute_list(0x01, 1, [1, 2])
                else:
                    from cipstack.cip.epath import request_path
                    from cipstack.cip.messages import MessageRouterRequest
                    await scanner.multiple_service_packet([MessageRouterRequest(0x0E, request_path(1, 1, 1))] * 2)

        with pytest.raises(MalformedReplyError, match=what):
            asyncio.run(scenario())


def test_a_target_that_falls_silent_is_closed_too(producer: ClassOneProducer,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """The target stops producing after 30 packets: the watchdog ends the run (exit 1, one line) and
    the connection is still closed."""
    def handle(request: MrRequest) -> bytes | None:
        if request.service != FORWARD_OPEN:
            return None
        port = to_port(request)
        assert port is not None
        producer.produce(0x22, (request.peer[0], port), bytes(4), 0.010, count=30)
        return rr_body(mr_reply(FORWARD_OPEN, data=struct.pack("<IIHHIIIBB", 0x11, 0x22, 1, 0xFFFE, 7, 10000,
                                                                   10000, 0, 0)))

    with ScriptedTarget(handler=handle, assembly_sizes={21: 4, 71: 4}) as target:
        code, _, err = run_cli(["io", target.address, "--output", "21", "--input", "71", "--duration", "5s",
                                "--target-io-port", str(producer.port)], capsys)
        assert code == 1
        assert err.count("\n") == 1 and "timed out" in err, err
        assert len(target.services(FORWARD_CLOSE)) == 1


def test_ctrl_c_while_the_forward_open_is_on_the_wire(producer: ClassOneProducer) -> None:
    """The target answers the Forward_Open 1.5 s late; Ctrl-C comes before: what it opens is closed."""
    def slow(request: MrRequest) -> bytes | None:
        if request.service != FORWARD_OPEN:
            return None
        time.sleep(1.5)                  # the subject: a reply late enough for the Ctrl-C to come first
        return p2p_echo_reply(request, producer)

    with ScriptedTarget(handler=slow, assembly_sizes={21: 4, 71: 4}) as target:
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        proc = subprocess.Popen([sys.executable, "-m", "cipstack", "io", target.address, "--output", "21", "--input",
                                 "71", "--duration", "30s", "--target-io-port", str(producer.port)],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        try:
            deadline = time.monotonic() + 20
            while not target.services(FORWARD_OPEN):
                assert time.monotonic() < deadline and proc.poll() is None, proc.communicate()
                time.sleep(0.02)
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=20)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert proc.returncode == 130, err
        assert "Traceback" not in err
        assert len(target.services(FORWARD_CLOSE)) == 1


def test_t_o_data_of_another_size_is_counted_and_reported_once(producer: ClassOneProducer,
                                                               caplog: pytest.LogCaptureFixture) -> None:
    """The target produces 6 data bytes on a connection opened for 4: dropped, counted, one warning."""
    def handle(request: MrRequest) -> bytes | None:
        if request.service != FORWARD_OPEN:
            return None
        port = to_port(request)
        assert port is not None
        producer.produce(0x22, (request.peer[0], port), bytes(6), 0.010, count=40)
        return rr_body(mr_reply(FORWARD_OPEN, data=struct.pack("<IIHHIIIBB", 0x11, 0x22, 1, 0xFFFE, 7, 10000,
                                                                   10000, 0, 0)))

    async def scenario(address: str) -> dict[str, Any]:
        async with await Scanner.connect(address) as scanner, scanner.io_connection(
                output=21, input=71, output_size=4, input_size=4, target_io_port=producer.port) as io:
            await asyncio.sleep(0.6)     # the subject: the 40 datagrams (0.4 s) all come and are reported once
            return io.statistics()

    with ScriptedTarget(handler=handle) as target, caplog.at_level(logging.WARNING):
        stats = asyncio.run(scenario(target.address))
    assert stats["received"] == 0 and stats["wrong_size"] > 20, stats
    assert len([r for r in caplog.records if "sends 6 data bytes" in r.getMessage()]) == 1
