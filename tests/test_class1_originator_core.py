"""The originator's class 1 core without sockets, on a fake clock (``now`` is whatever the test says):
Forward_Open parameters and the retry a target asks for, the production schedule, sequence counts,
run/idle, consumption, the watchdog and the one timeout rule both roles share."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from cipstack.cip.messages import MessageRouterResponse, Service
from cipstack.cip.status import CipError, GeneralStatus
from cipstack.eip import io_core
from cipstack.eip.io_core import connection_timeout, decode_io_datagram, encode_io_datagram, rpi_us_of
from cipstack.eip.originator.class1 import (
    Class1Opened,
    Class1Request,
    IoOriginator,
    OriginatorConnection,
    OtFormat,
    class1_path,
    close_plan,
    new_connection,
    open_plan,
    reply_addresses,
)
from cipstack.eip.originator.core import OriginatorCore
from cipstack.eip.wire.cm_messages import (
    ConnectionTriad,
    ConnectionType,
    ForwardCloseRequest,
    ForwardOpenReply,
    ForwardOpenRequest,
)
from cipstack.eip.wire.cpf import Item, ItemType, SockAddr

CORE = Path(__file__).resolve().parent.parent / "cipstack" / "eip" / "originator" / "class1.py"
PATH_21_71 = class1_path(21, 71, 1)


class Heard:
    """A listener that writes down what the core reports."""

    def __init__(self) -> None:
        self.inputs: list[bytes] = []
        self.timeouts = 0

    def input_changed(self, data: bytes) -> None:
        self.inputs.append(data)

    def timed_out(self) -> None:
        self.timeouts += 1


def opened(output_size: int | None = 4, input_size: int = 4, rpi_us: int = 10_000, now: float = 100.0,
           multiplier: int = 2, fmt: OtFormat = OtFormat.RUN_IDLE) -> tuple[IoOriginator, OriginatorConnection, Heard]:
    core, heard = IoOriginator(), Heard()
    request = Class1Request(output_size, input_size, rpi_us, rpi_us, PATH_21_71, timeout_multiplier=multiplier,
                            ot_format=fmt)
    connection = new_connection(request, "192.0.2.7", 2222, 0x1111, 0x2222, rpi_us, rpi_us, now, listener=heard)
    core.add(connection)
    return core, connection, heard


def t_o(sequence: int, data: bytes, cip_sequence: int | None = None, connection_id: int = 0x2222) -> bytes:
    return encode_io_datagram(connection_id, sequence, sequence if cip_sequence is None else cip_sequence, data)


# -- what the core is made of -------------------------------------------------------------------------
def test_the_core_imports_no_asyncio_socket_clock_or_target() -> None:
    imported = set()
    for node in ast.walk(ast.parse(CORE.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            imported |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            imported.add("." * node.level + (node.module or ""))
    assert not imported & {"asyncio", "socket", "time", "selectors", "threading"}, imported
    assert not [name for name in imported if "target" in name], imported
    script = ("import sys, cipstack.eip.originator.class1; "
              "print(sorted(m for m in sys.modules if m == 'asyncio' or m.startswith('cipstack.eip.target')))")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=True)
    assert done.stdout.strip() == "[]"


def test_both_roles_take_the_constants_and_the_timeout_rule_from_one_module() -> None:
    from cipstack.eip.originator import class1
    from cipstack.eip.target import io_target

    for name in ("EARLY_SHARE", "TO_OVERHEAD", "OT_OVERHEAD"):
        assert getattr(io_target, name) is getattr(io_core, name)
    assert class1.EARLY_SHARE is io_core.EARLY_SHARE and class1.TO_OVERHEAD is io_core.TO_OVERHEAD
    assert io_core.OT_OVERHEAD == 6 and io_core.TO_OVERHEAD == 2
    fo = ForwardOpenRequest.decode(Class1Request(4, 4, 2_000, 2_000, PATH_21_71, timeout_multiplier=3)
                                   .forward_open(2222)[0][6:], large=False)
    assert fo.timeout_s == connection_timeout(2_000, 3) == pytest.approx(0.064)   # 2 ms x 4 x 2^3
    assert connection_timeout(1_000, 9) == connection_timeout(1_000, 7) == pytest.approx(0.512)


@pytest.mark.parametrize(("seconds", "micro"), [(0.010, 10_000), (0.0029, 2_900), (0.001, 1_000), (0.0005, 500),
                                                (2.0, 2_000_000)])
def test_an_rpi_in_seconds_becomes_microseconds_once_rounded(seconds: float, micro: int) -> None:
    assert rpi_us_of(seconds) == micro


# -- Forward_Open parameters ---------------------------------------------------------------------------
def test_forward_open_parameters() -> None:
    request = Class1Request(4, 6, 10_000, 20_000, PATH_21_71, timeout_multiplier=1)
    raw, items, triad = request.forward_open(41_000)
    assert raw[0] == Service.FORWARD_OPEN and raw[2:6] == bytes.fromhex("2006 2401")
    fo = ForwardOpenRequest.decode(raw[6:], large=False)
    assert (fo.ot_rpi_us, fo.to_rpi_us, fo.timeout_multiplier) == (10_000, 20_000, 1)
    assert (fo.ot_parameters.size, fo.to_parameters.size) == (2 + 4 + 4, 2 + 6)   # O->T: count, run/idle, data
    assert fo.to_parameters.type is ConnectionType.POINT_TO_POINT
    assert fo.triad == triad and fo.connection_path == PATH_21_71
    assert items == [Item(ItemType.SOCKADDR_T_O, SockAddr("0.0.0.0", 41_000).encode())]


def test_forward_open_formats_multicast_and_large() -> None:
    heartbeat = Class1Request(None, 4, 10_000, 10_000, class1_path(None, 71, 1, heartbeat=198),
                              ot_format=OtFormat.HEARTBEAT, multicast=True)
    raw, items, _ = heartbeat.forward_open(2222)
    fo = ForwardOpenRequest.decode(raw[6:], large=False)
    assert fo.ot_parameters.size == 2 and fo.to_parameters.type is ConnectionType.MULTICAST
    assert items == []                                        # multicast: no Sockaddr Info asked
    assert Class1Request(4, 4, 1, 1, PATH_21_71, ot_format=OtFormat.MODELESS).ot_size == 6
    big = Class1Request(600, 4, 10_000, 10_000, PATH_21_71)
    raw, _, _ = big.forward_open(2222)
    assert raw[0] == Service.LARGE_FORWARD_OPEN
    assert ForwardOpenRequest.decode(raw[6:], large=True).ot_parameters.size == 606


def _reply(request_raw: bytes, ot_api_us: int = 10_000) -> bytes:
    fo = ForwardOpenRequest.decode(request_raw[6:], large=False)
    return MessageRouterResponse(Service.FORWARD_OPEN, 0, (), ForwardOpenReply(
        0xAAAA, fo.to_connection_id, fo.triad, ot_api_us, ot_api_us).encode()).encode()


def test_open_plan_retries_once_with_the_size_the_target_names() -> None:
    core = OriginatorCore()
    request = Class1Request(4, 4, 10_000, 10_000, PATH_21_71)
    plan = open_plan(core, request, 2222)
    first = next(plan)
    assert first.what == "SendRRData"
    second = plan.throw(CipError(GeneralStatus.CONNECTION_FAILURE, (0x0128, 10)))   # T->O: the target wants 10
    body = second.frame[24:]
    request_raw = body[16:16 + int.from_bytes(body[14:16], "little")]
    assert ForwardOpenRequest.decode(request_raw[6:], large=False).to_parameters.size == 10
    items = [Item(ItemType.SOCKADDR_O_T, SockAddr("192.0.2.7", 2300).encode())]
    with pytest.raises(StopIteration) as done:
        plan.send((_reply(request_raw), items))
    result = done.value.value
    assert isinstance(result, Class1Opened)
    assert result.request.input_size == 8 and result.reply.ot_connection_id == 0xAAAA and result.items == items
    assert result.notes == ["T->O size 6 refused (0x0128), the target wants 10: retrying with 10"]


def test_open_plan_raises_a_refusal_it_cannot_correct() -> None:
    plan = open_plan(OriginatorCore(), Class1Request(4, 4, 10_000, 10_000, PATH_21_71), 2222)
    next(plan)
    with pytest.raises(CipError) as refused:
        plan.throw(CipError(GeneralStatus.CONNECTION_FAILURE, (0x0100,)))    # connection in use
    assert refused.value.extended == (0x0100,)


def test_close_plan_names_the_triad() -> None:
    triad = ConnectionTriad(0x1234, 0xFFFE, 0x55667788)
    plan = close_plan(OriginatorCore(), triad, PATH_21_71)
    transaction = next(plan)
    body = transaction.frame[24:]
    request = body[16:16 + int.from_bytes(body[14:16], "little")]
    assert request[0] == Service.FORWARD_CLOSE
    assert ForwardCloseRequest.decode(request[6:]).triad == triad
    with pytest.raises(CipError):
        plan.send(MessageRouterResponse(Service.FORWARD_CLOSE, GeneralStatus.CONNECTION_FAILURE, (0x0107,)))


def test_reply_addresses() -> None:
    items = [Item(ItemType.SOCKADDR_T_O, SockAddr("0.0.0.0", 41_000).encode()),      # our port echoed: informational
             Item(ItemType.SOCKADDR_O_T, SockAddr("192.0.2.7", 2300).encode()),
             Item(ItemType.SOCKADDR_T_O, b"\x00\x01"),                                # does not decode: ignored
             Item(0x00A1, b"\x00" * 4)]                                                # another item: ignored
    assert reply_addresses(items) == (2300, None, 0)
    group = [Item(ItemType.SOCKADDR_T_O, SockAddr("239.192.1.32", 2222).encode())]
    assert reply_addresses(group) == (None, "239.192.1.32", 2222)


# -- production ----------------------------------------------------------------------------------------
def test_production_at_the_rpi_with_sequence_counts_and_run_idle() -> None:
    core, connection, _ = opened(rpi_us=10_000, now=100.0)
    connection.output[:] = b"\x01\x02\x03\x04"
    first = core.poll(100.0)
    assert [destination for _, destination in first] == [("192.0.2.7", 2222)]
    datagram = decode_io_datagram(first[0][0])
    assert (datagram.connection_id, datagram.encap_sequence, datagram.cip_sequence) == (0x1111, 1, 1)
    assert datagram.payload == b"\x01\x00\x00\x00\x01\x02\x03\x04"                   # run, then the data
    assert core.poll(100.005) == [] and core.next_deadline() == pytest.approx(100.010)
    connection.run = False
    second = decode_io_datagram(core.poll(100.010)[0][0])
    assert (second.encap_sequence, second.cip_sequence, second.payload[:4]) == (2, 2, b"\x00\x00\x00\x00")  # idle
    assert connection.stats.sent == 2


def test_a_production_may_leave_a_sixteenth_of_its_rpi_early_and_never_bursts() -> None:
    core, connection, _ = opened(rpi_us=16_000, now=0.0)
    core.poll(0.0)
    assert core.poll(0.016 - 0.0011) == []                        # more than RPI / 16 early: not yet
    assert len(core.poll(0.016 - 0.0009, horizon=0.001)) == 1     # within RPI / 16, in the horizon: sent
    assert len(core.poll(0.100)) == 1                             # slots missed: one packet, not a burst
    assert connection.stats.skipped_slots >= 4


def test_sequence_counts_wrap() -> None:
    core, connection, _ = opened(now=0.0)
    connection.encap_sequence, connection.cip_sequence = 0xFFFFFFFF, 0xFFFF
    datagram = decode_io_datagram(core.poll(0.0)[0][0])
    assert (datagram.encap_sequence, datagram.cip_sequence) == (0, 0)


@pytest.mark.parametrize(("fmt", "output", "payload"), [
    (OtFormat.MODELESS, 2, b"\x00\x00"), (OtFormat.HEARTBEAT, None, b""),
    (OtFormat.RUN_IDLE, None, b"\x01\x00\x00\x00")])
def test_the_o_to_t_format(fmt: OtFormat, output: int | None, payload: bytes) -> None:
    core, _, _ = opened(output_size=output, fmt=fmt, now=0.0)
    assert decode_io_datagram(core.poll(0.0)[0][0]).payload == payload


def test_a_closed_connection_produces_and_consumes_nothing() -> None:
    core, connection, heard = opened(now=0.0)
    core.remove(connection)
    assert connection.closed and core.poll(1.0) == [] and core.next_deadline() is None
    core.receive(t_o(1, b"abcd"), ("192.0.2.7", 2222), 0.1)
    assert heard.inputs == [] and core.dropped == 1


# -- consumption ---------------------------------------------------------------------------------------
def test_consumption_reports_changes_only() -> None:
    core, connection, heard = opened(now=0.0)
    source = ("192.0.2.7", 2222)
    core.receive(t_o(1, b"abcd"), source, 0.010)
    core.receive(t_o(2, b"abcd"), source, 0.020)                   # same data: no event
    core.receive(t_o(3, b"wxyz"), source, 0.030)
    core.receive(t_o(4, b"zzzz", cip_sequence=3), source, 0.040)   # same CIP count: a duplicate, not new data
    core.receive(t_o(2, b"oldd"), source, 0.050)                   # older than the newest: stale, dropped
    assert heard.inputs == [b"abcd", b"wxyz"] and connection.input == b"wxyz"
    stats = connection.stats
    assert (stats.received, stats.duplicates, stats.stale, stats.lost) == (4, 1, 1, 0)
    core.receive(t_o(9, b"nine"), source, 0.060)                   # 5 to 8 never came
    assert stats.lost == 4 and heard.inputs[-1] == b"nine"
    assert connection.arrivals.count == 5 and connection.arrivals.changes == 2


def test_wrong_sizes_unknown_ids_and_garbage_are_dropped_and_counted() -> None:
    core, connection, heard = opened(now=0.0)
    source = ("192.0.2.7", 2222)
    core.receive(t_o(1, b"abc"), source, 0.01)
    core.receive(t_o(2, b"abcd", connection_id=0x9999), source, 0.02)
    core.receive(b"\x02\x00garbage", source, 0.03)
    assert core.dropped == 3 and connection.arrivals.wrong_size == 1 and heard.inputs == []
    assert connection.stats.received == 0


# -- the watchdog --------------------------------------------------------------------------------------
def test_the_watchdog_allows_ten_seconds_for_the_first_packet_then_the_timeout() -> None:
    core, connection, heard = opened(rpi_us=10_000, multiplier=2, now=0.0)   # 10 ms x 4 x 4 = 160 ms
    assert connection.consumer.timeout == pytest.approx(0.160)
    assert core.expire(9.999) == [] and heard.timeouts == 0
    core.receive(t_o(1, b"abcd"), ("192.0.2.7", 2222), 5.0)
    assert core.expire(5.159) == [] and not connection.timed_out
    assert core.expire(5.160) == [connection] and connection.timed_out and heard.timeouts == 1
    assert core.expire(6.0) == [] and heard.timeouts == 1             # once


def test_packets_move_the_watchdog() -> None:
    core, connection, heard = opened(rpi_us=1_000, multiplier=0, now=0.0)     # 1 ms x 4 = 4 ms
    now = 0.0
    for sequence in range(1, 200):
        now = sequence * 0.001
        core.receive(t_o(sequence, b"abcd"), ("192.0.2.7", 2222), now)
        core.poll(now)
        assert core.expire(now + 0.0039) == []
    assert core.next_deadline() is not None and not connection.timed_out
    assert core.expire(now + 0.004) == [connection] and heard.timeouts == 1


def test_no_first_packet_times_out_after_ten_seconds() -> None:
    core, connection, heard = opened(rpi_us=10_000, now=0.0)
    assert core.expire(10.0) == [connection] and heard.timeouts == 1
