"""Class 1 I/O without sockets: datagrams, sequences, schedule, watchdog, every Forward_Open rule."""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cipstack.cip.epath import ElectronicKey, encode_path
from cipstack.cip.router import MessageRouter, RequestContext
from cipstack.cip.status import CipError
from cipstack.devices.profiles import identity_only_device as build_device
from cipstack.eip.io_core import (
    ConsumerState,
    IoDatagramError,
    ProductionGrid,
    ProductionSchedule,
    Reception,
    decode_io_datagram,
    encode_io_datagram,
    seq16_newer,
    seq32_newer,
)
from cipstack.eip.originator.io_originator import Class1Request, IoOriginator, OtFormat, class1_path, new_connection
from cipstack.eip.target.io_target import ConnectionKind, IoConnection, IoProfile, IoTarget
from cipstack.eip.wire.cm_messages import (
    ConnectionTriad,
    ConnectionType,
    ForwardCloseRequest,
    ForwardOpenRequest,
    NetworkParameters,
    TransportTrigger,
    TriggerType,
)
from cipstack.eip.wire.cpf import ItemType, SockAddr
from cipstack.objects.assembly import AssemblyPoint


# -- sequence arithmetic and the datagram ------------------------------------------------------------
def test_serial_number_arithmetic() -> None:
    assert seq16_newer(1, 0) and not seq16_newer(0, 1) and not seq16_newer(5, 5)
    assert seq16_newer(0x0000, 0xFFFF) and seq16_newer(0x0005, 0xFFF0)
    assert not seq16_newer(0x8000, 0x0000)  # half the space away: not newer
    assert seq32_newer(0, 0xFFFFFFFF) and not seq32_newer(0xFFFFFFFF, 0)


def test_datagram_bytes() -> None:
    raw = encode_io_datagram(0x11223344, 7, 0x0102, b"\xaa\xbb", run_idle=1)
    assert raw == bytes.fromhex("0200 0280 0800 44332211 07000000 b100 0800 0201 01000000 aabb")
    datagram = decode_io_datagram(raw)
    assert (datagram.connection_id, datagram.encap_sequence, datagram.cip_sequence) == (0x11223344, 7, 0x0102)
    assert datagram.payload == b"\x01\x00\x00\x00\xaa\xbb"


@given(st.integers(0, 0xFFFFFFFF), st.integers(0, 0xFFFFFFFF), st.integers(0, 0xFFFF), st.binary(max_size=500),
       st.none() | st.integers(0, 1))
def test_datagram_round_trip(cid: int, seq: int, cip: int, data: bytes, run_idle: int | None) -> None:
    datagram = decode_io_datagram(encode_io_datagram(cid, seq, cip, data, run_idle))
    header = b"" if run_idle is None else struct.pack("<I", run_idle)
    assert (datagram.connection_id, datagram.encap_sequence, datagram.cip_sequence, datagram.payload) == (
        cid, seq, cip, header + data)


@pytest.mark.parametrize("raw", [
    b"", b"\x02\x00" * 5, bytes.fromhex("0300 0280 0800 00000000 00000000 b100 0200 0000"),
    bytes.fromhex("0200 a100 0800 00000000 00000000 b100 0200 0000"),
    bytes.fromhex("0200 0280 0800 00000000 00000000 b100 0400 0000"),
    bytes.fromhex("0200 0280 0800 00000000 00000000 b200 0200 0000"),
])
def test_malformed_datagrams(raw: bytes) -> None:
    with pytest.raises(IoDatagramError):
        decode_io_datagram(raw)


# -- schedule -------------------------------------------------------------------------------------------
def test_schedule_on_time_late_and_skipped() -> None:
    schedule = ProductionSchedule(0.010, next_due=1.0)
    assert schedule.due(0.999) == (False, 0.0)
    assert schedule.due(1.0) == (True, 0.0)
    assert schedule.next_due == pytest.approx(1.010)
    due, lateness = schedule.due(1.0104)  # 0.4 ms late: within the 0.5 ms tolerance
    assert due and lateness == pytest.approx(0.0004) and schedule.stats.late == 0
    due, lateness = schedule.due(1.0209)  # 0.9 ms late: counted
    assert due and schedule.stats.late == 1
    # A stall of 35 ms: one packet goes out now, the three missed slots are skipped, not burst.
    due, lateness = schedule.due(1.065)
    assert due and lateness == pytest.approx(0.035)
    assert schedule.stats.skipped_slots == 3
    assert schedule.next_due == pytest.approx(1.070)
    assert schedule.due(1.066) == (False, 0.0)


def test_grid_the_first_production_sets_the_slots_and_later_ones_join_them() -> None:
    grid = ProductionGrid()
    assert grid.first_due(0.010, 5.0) == 5.0  # the first: at once
    assert grid.first_due(0.010, 5.0037) == pytest.approx(5.010)  # the next slot of its period
    assert grid.first_due(0.010, 5.020) == pytest.approx(5.020)  # on a slot: that slot
    assert grid.first_due(0.010, 4.0) == 5.0  # a time before the first slot waits for it
    assert grid.first_due(0.001, 5.0041) == pytest.approx(5.005)  # another period: whole periods from it
    assert grid.first_due(0.020, 5.0041) == pytest.approx(5.020)


# -- consumer ---------------------------------------------------------------------------------------------
def test_consumer_sequences_and_watchdog() -> None:
    consumer = ConsumerState.opened(timeout=0.08, now=0.0)
    assert consumer.deadline == 10.0  # at least 10 s before the first packet
    assert consumer.accept(100, 1, 1.0) is Reception.NEW
    assert consumer.deadline == pytest.approx(1.08)
    assert consumer.accept(101, 1, 1.01) is Reception.DUPLICATE  # same CIP count: no new data
    assert consumer.accept(101, 2, 1.02) is Reception.STALE  # encapsulation sequence not newer
    assert consumer.accept(99, 3, 1.03) is Reception.STALE
    assert consumer.accept(104, 2, 1.04) is Reception.NEW
    assert consumer.stats.lost == 2 and consumer.stats.duplicates == 1 and consumer.stats.stale == 2
    assert not consumer.expired(1.119) and consumer.expired(1.12)


def test_consumer_wraps_around() -> None:
    consumer = ConsumerState.opened(timeout=1.0, now=0.0)
    assert consumer.accept(0xFFFFFFFF, 0xFFFF, 0.1) is Reception.NEW
    assert consumer.accept(0, 0, 0.2) is Reception.NEW
    assert consumer.accept(1, 0, 0.3) is Reception.DUPLICATE
    assert consumer.stats.lost == 0


# -- target ---------------------------------------------------------------------------------------------------
@dataclass
class Recorder:
    events: list[tuple[str, object]] = field(default_factory=list)

    def io_opened(self, connection: IoConnection) -> None:
        self.events.append(("opened", connection.kind))

    def io_closed(self, connection: IoConnection, timed_out: bool) -> None:
        self.events.append(("closed", timed_out))

    def io_run_idle(self, connection: IoConnection, run: bool) -> None:
        self.events.append(("run" if run else "idle", connection.kind))


class Rig:
    def __init__(self, **profile: object) -> None:
        self.consumed_data: list[tuple[bytes, float]] = []
        self.outputs = {21: AssemblyPoint(21, 4, True, consume=lambda d, now: self.consumed_data.append((d, now))),
                        20: AssemblyPoint(20, 4, True)}
        self.inputs = {71: AssemblyPoint(71, 4, False, produce=lambda: b"\x11\x22\x33\x44"),
                       70: AssemblyPoint(70, 4, False)}
        self.profile = IoProfile(lambda: self.outputs, lambda: self.inputs, **profile)  # type: ignore[arg-type]
        self.events = Recorder()
        self.io = IoTarget(self.profile, self.events)
        self.device = build_device()
        self.router: MessageRouter = self.device.router
        self.serial = 0

    def context(self, now: float = 0.0, sockaddr: dict[int, SockAddr] | None = None) -> RequestContext:
        context = RequestContext(self.router, now, "127.0.0.1:50000")
        if sockaddr is not None:
            context.extras["sockaddr"] = sockaddr
        return context

    def request(self, path: bytes | None = None, *, ot_size: int = 10, to_size: int = 6, rpi: int = 10_000,
                to_type: ConnectionType = ConnectionType.POINT_TO_POINT,
                ot_type: ConnectionType = ConnectionType.POINT_TO_POINT, trigger: TriggerType = TriggerType.CYCLIC,
                triad: ConnectionTriad | None = None, multiplier: int = 0) -> ForwardOpenRequest:
        self.serial += 1
        return ForwardOpenRequest(
            0x0A, 0x0E, 0, 0xABCD0000 + self.serial, triad or ConnectionTriad(self.serial, 0xFFFE, 7), multiplier,
            rpi, NetworkParameters(ot_size, ot_type), rpi, NetworkParameters(to_size, to_type),
            TransportTrigger(1, trigger), class1_path(21, 71, 1) if path is None else path)

    def open(self, request: ForwardOpenRequest, now: float = 0.0, **kw: object):  # type: ignore[no-untyped-def]
        return self.io.forward_open(request, self.context(now, **kw))  # type: ignore[arg-type]


def failure(rig: Rig, request: ForwardOpenRequest) -> tuple[int, ...]:
    with pytest.raises(CipError) as exc:
        rig.open(request)
    assert exc.value.general == 0x01
    assert exc.value.data == struct.pack("<HHIBB", request.triad.connection_serial, 0xFFFE, 7, 0, 0)
    return exc.value.extended


@pytest.mark.parametrize(("kwargs", "extended"), [
    ({"trigger": TriggerType.CHANGE_OF_STATE}, (0x0103,)),
    ({"path": class1_path(22, 71, 1)}, (0x012A,)),
    ({"path": class1_path(21, 72, 1)}, (0x012B,)),
    ({"path": class1_path(21, 71, 9)}, (0x0129,)),
    ({"path": bytes.fromhex("20 05 24 01 2C 15 2C 47")}, (0x0117,)),
    ({"path": bytes.fromhex("20 04 24 01 2C 15")}, (0x012F,)),
    ({"path": bytes.fromhex("20 04 24 01 2C 15 2C 47 E0 00")}, (0x0315,)),
    ({"path": class1_path(21, 71, 1) + bytes.fromhex("80 01 00 00")}, (0x0118,)),
    ({"ot_size": 8}, (0x0127, 10)),
    ({"to_size": 4}, (0x0128, 6)),
    ({"ot_type": ConnectionType.MULTICAST}, (0x0108,)),
    ({"to_type": ConnectionType.NULL}, (0x0108,)),
    ({"rpi": 500}, (0x0112, 0x0202, 1000, 0, 1000, 0)),
    ({"rpi": 20_000_000}, (0x0112, 0x0303, 0x9680, 0x0098, 0x9680, 0x0098)),
    ({"path": encode_path([ElectronicKey(999, 2, 100, 1, 1)]) + class1_path(21, 71, 1)}, (0x0114,)),
    ({"path": encode_path([ElectronicKey(259, 7, 100, 1, 1)]) + class1_path(21, 71, 1)}, (0x0115,)),
    ({"path": encode_path([ElectronicKey(259, 2, 100, 3, 1)]) + class1_path(21, 71, 1)}, (0x0116,)),
])
def test_forward_open_refusals(kwargs: dict[str, object], extended: tuple[int, ...]) -> None:
    rig = Rig()
    assert failure(rig, rig.request(**kwargs)) == extended  # type: ignore[arg-type]
    assert not rig.io.connections


def test_pairs_restrict_exclusive_owners() -> None:
    rig = Rig(pairs=lambda: {(21, 71)})
    assert failure(rig, rig.request(class1_path(21, 70, 1), to_size=6)) == (0x012F,)
    assert rig.open(rig.request())


def test_exclusive_owner_open_consume_produce_close() -> None:
    rig = Rig()
    reply = rig.open(rig.request(), now=5.0, sockaddr={ItemType.SOCKADDR_T_O: SockAddr("0.0.0.0", 40000)})
    [connection] = rig.io.connections.values()
    assert reply.ot_connection_id == connection.ot_connection_id
    assert reply.to_connection_id == connection.to_connection_id == 0xABCD0001  # P2P T->O: the originator's id
    assert (reply.ot_api_us, reply.to_api_us) == (10_000, 10_000)
    assert connection.destination == ("127.0.0.1", 40000)  # the port of the Sockaddr Info item
    assert rig.events.events == [("opened", ConnectionKind.EXCLUSIVE_OWNER)]
    # Production starts at once and follows the RPI.
    [(datagram, _)] = rig.io.poll(5.0)
    decoded = decode_io_datagram(datagram)
    assert (decoded.connection_id, decoded.encap_sequence, decoded.cip_sequence, decoded.payload) == (
        0xABCD0001, 1, 1, b"\x11\x22\x33\x44")
    assert rig.io.poll(5.005) == []
    assert decode_io_datagram(rig.io.poll(5.010)[0][0]).encap_sequence == 2
    # Consumption: run header, new data only, from the originator's host only.
    cid = connection.ot_connection_id
    rig.io.receive(encode_io_datagram(cid, 1, 1, b"\x01\x02\x03\x04", 1), ("127.0.0.1", 2222), 5.02)
    rig.io.receive(encode_io_datagram(cid, 2, 1, b"\x09\x09\x09\x09", 1), ("127.0.0.1", 2222), 5.03)  # duplicate
    rig.io.receive(encode_io_datagram(cid, 3, 2, b"\x05\x06\x07\x08", 1), ("127.0.0.2", 2222), 5.04)  # wrong host
    rig.io.receive(encode_io_datagram(cid, 3, 2, b"\x05\x06", 1), ("127.0.0.1", 2222), 5.04)  # wrong size
    assert rig.consumed_data == [(b"\x01\x02\x03\x04", 5.02)]
    assert rig.io.dropped == 2
    rig.io.receive(encode_io_datagram(cid, 4, 3, b"\x05\x06\x07\x08", 0), ("127.0.0.1", 2222), 5.05)  # idle
    assert rig.consumed_data == [(b"\x01\x02\x03\x04", 5.02)]  # idle data is not applied
    assert rig.events.events[1:] == [("run", ConnectionKind.EXCLUSIVE_OWNER), ("idle", ConnectionKind.EXCLUSIVE_OWNER)]
    assert rig.io.forward_close(ForwardCloseRequest(0, 0, connection.triad), rig.context())
    assert rig.events.events[-1] == ("closed", False)
    assert not rig.io.forward_close(ForwardCloseRequest(0, 0, connection.triad), rig.context())


@pytest.mark.parametrize("sockaddr", [None, {ItemType.SOCKADDR_T_O: SockAddr("0.0.0.0", 0)}])
def test_t_to_o_without_a_port_goes_to_2222_whatever_the_consuming_port(
        sockaddr: dict[int, SockAddr] | None) -> None:
    """Consuming on 2223 (--io-port): T->O goes to the originator's 2222 when its Forward_Open names
    no port, and the reply names 2223 in an O->T Sockaddr Info item (issue 30, item 2)."""
    rig = Rig()
    rig.io.io_port = 2223
    context = rig.context(5.0, sockaddr)
    rig.io.forward_open(rig.request(), context)
    [connection] = rig.io.connections.values()
    assert connection.destination == ("127.0.0.1", 2222)
    [item] = context.extras["reply_items"]
    assert (item.type, item.data) == (ItemType.SOCKADDR_O_T, struct.pack(">hH4s8x", 2, 2223, bytes(4)))
    assert rig.io.poll(5.0)[0][1] == ("127.0.0.1", 2222)


def test_connections_of_one_rpi_are_produced_in_the_same_slots() -> None:
    """Opened 3.7 ms apart, two connections at 10 ms go out in one poll, every 10 ms, in the same
    order; one at 20 ms opened 4.1 ms in starts 20 ms in, with them, and every other slot after."""
    rig = Rig()

    def sent(now: float) -> list[int]:
        return [decode_io_datagram(d).connection_id for d, _ in rig.io.poll(now)]

    first = rig.open(rig.request(), now=5.0).to_connection_id
    assert sent(5.0) == [first]
    second = rig.open(rig.request(class1_path(None, 71, 1, heartbeat=198), ot_size=2), now=5.0037).to_connection_id
    other = rig.open(rig.request(class1_path(20, 70, 1), rpi=20_000), now=5.0041).to_connection_id
    assert sent(5.0041) == []
    assert rig.io.next_deadline() == pytest.approx(5.010)
    assert sent(5.010001) == [first, second]
    assert sorted(sent(5.020001)) == sorted([first, second, other])
    assert sent(5.030001) == [first, second]
    assert sorted(sent(5.040001)) == sorted([first, second, other])


def test_an_originator_produces_its_connections_of_one_rpi_in_the_same_slots() -> None:
    core = IoOriginator()
    request = Class1Request(None, 4, 10_000, 10_000, class1_path(None, 71, 1, heartbeat=198))
    core.add(new_connection(request, "127.0.0.1", 2222, 0x11, 0x21, 10_000, 10_000, now=1.0))
    assert [decode_io_datagram(d).connection_id for d, _ in core.poll(1.0)] == [0x11]
    core.add(new_connection(request, "127.0.0.1", 2222, 0x12, 0x22, 10_000, 10_000, now=1.0037))
    assert core.poll(1.0037) == []
    assert core.next_deadline() == pytest.approx(1.010)
    for slot in (1.010, 1.020):
        assert [decode_io_datagram(d).connection_id for d, _ in core.poll(slot + 1e-6)] == [0x11, 0x12]


def test_duplicate_ownership_and_limits() -> None:
    rig = Rig(max_connections=2)
    first = rig.request()
    rig.open(first)
    assert failure(rig, rig.request(triad=first.triad)) == (0x0100,)
    assert failure(rig, rig.request()) == (0x0106,)  # output 21 already owned
    rig.open(rig.request(class1_path(20, 70, 1)))
    assert failure(rig, rig.request(class1_path(None, 71, 1, heartbeat=198), ot_size=6)) == (0x0113,)


def test_watchdog_closes_and_reports_timeout() -> None:
    rig = Rig()
    rig.open(rig.request(multiplier=1), now=0.0)  # timeout 10 ms x 8 = 80 ms, 10 s before the first packet
    [connection] = rig.io.connections.values()
    assert rig.io.next_deadline() == 0.0  # first production
    rig.io.expire(9.99)
    assert rig.io.connections
    rig.io.receive(encode_io_datagram(connection.ot_connection_id, 1, 1, bytes(4), 1), ("127.0.0.1", 2222), 9.99)
    rig.io.expire(10.06)
    assert rig.io.connections
    rig.io.expire(10.07)
    assert not rig.io.connections
    assert rig.events.events[-1] == ("closed", True) and rig.io.timeouts == 1


def test_input_only_and_listen_only_with_multicast() -> None:
    rig = Rig()
    assert failure(rig, rig.request(class1_path(None, 71, 1, heartbeat=199), ot_size=6,
                                    to_type=ConnectionType.MULTICAST)) == (0x0119,)
    context = rig.context(1.0)
    owner_request = rig.request(class1_path(None, 71, 1, heartbeat=198), ot_size=2, to_type=ConnectionType.MULTICAST)
    owner_reply = rig.io.forward_open(owner_request, context)
    [item] = context.extras["reply_items"]
    assert item.type == ItemType.SOCKADDR_T_O
    group = SockAddr.decode(item.data)
    # 127.0.0.1/8: host id 1, so the CIP default block starts at 239.192.1.0.
    assert (group.host, group.port) == ("239.192.1.0", 2222)
    listener_reply = rig.open(rig.request(class1_path(None, 71, 1, heartbeat=199), ot_size=6,
                                          to_type=ConnectionType.MULTICAST), now=1.0)
    assert listener_reply.to_connection_id == owner_reply.to_connection_id  # the same multicast stream
    assert len(rig.io.poll(1.0)) == 1  # one production for both
    assert [c.kind for c in rig.io.connections.values()] == [ConnectionKind.INPUT_ONLY, ConnectionKind.LISTEN_ONLY]
    # Closing the owner closes the listener.
    rig.io.forward_close(ForwardCloseRequest(0, 0, owner_request.triad), rig.context())
    assert not rig.io.connections
    assert [e for e in rig.events.events if e[0] == "closed"] == [("closed", False), ("closed", False)]


def test_listen_only_needs_multicast() -> None:
    rig = Rig()
    assert failure(rig, rig.request(class1_path(None, 71, 1, heartbeat=199), ot_size=6)) == (0x0108,)


def test_identity_status_follows_io(tmp_path: object) -> None:
    device = build_device()
    device.update_io_status()
    assert device.identity.status == 0x0030  # no I/O connection
    rig = Rig()
    rig.io.events = device
    rig.open(rig.request())
    [connection] = rig.io.connections.values()
    assert device.identity.status == 0x0071  # owned, connection established (idle until data says run)
    rig.io.receive(encode_io_datagram(connection.ot_connection_id, 1, 1, bytes(4), 1), ("127.0.0.1", 2222), 0.1)
    assert device.identity.status == 0x0061  # owned, running
    rig.io.expire(100.0)
    assert device.identity.status == 0x0020  # I/O connection faulted (timed out)


def test_a_connection_past_511_bytes_is_opened_with_large_forward_open() -> None:
    """A Forward_Open's network parameters hold 9 bits of size: one byte more (sequence count, run/idle
    header and data, or T->O sequence count and data) needs the Large_Forward_Open."""
    def request(output: int | None, input_size: int) -> Class1Request:
        return Class1Request(output, input_size, 10_000, 10_000, b"",
                             ot_format=OtFormat.RUN_IDLE if output is not None else OtFormat.HEARTBEAT)

    assert request(505, 4).ot_size == 511 and not request(505, 4).large_forward_open
    assert request(506, 4).large_forward_open
    assert not request(None, 509).large_forward_open and request(None, 510).large_forward_open
    assert request(4, 4).ot_size == 10 and not request(4, 4).large_forward_open


def test_a_forward_open_over_dtls_opens_a_secured_point_to_point_connection() -> None:
    rig = Rig()
    session = ("127.0.0.1", 50000)
    context = rig.context(1.0)
    context.extras["io_path"] = session   # what a connection arriving in a DTLS session says
    rig.io.forward_open(rig.request(), context)
    [connection] = rig.io.connections.values()
    assert connection.secured and connection.destination == session
    [(_datagram, destination)] = rig.io.poll(1.0)
    assert destination == session   # T->O goes to the session, which the shell routes into DTLS
    ot = encode_io_datagram(connection.ot_connection_id, 1, 1, b"\x01\x00\x00\x00" + b"\x05\x06\x07\x08")
    rig.io.receive(ot, ("127.0.0.1", 2222), 1.001)   # the same datagram as plain UDP: dropped
    rig.io.receive(ot, ("127.0.0.1", 50001), 1.001, secured=True)   # another session's: dropped
    assert rig.io.dropped == 2 and rig.consumed_data == []
    rig.io.receive(ot, session, 1.002, secured=True)
    assert rig.consumed_data == [(b"\x05\x06\x07\x08", 1.002)]
    assert rig.io.close_path(session) == 1 and not rig.io.connections


def test_a_forward_open_over_dtls_for_multicast_is_refused() -> None:
    rig = Rig()
    context = rig.context(1.0)
    context.extras["io_path"] = ("127.0.0.1", 50000)
    with pytest.raises(CipError) as refused:
        rig.io.forward_open(rig.request(to_type=ConnectionType.MULTICAST), context)
    assert refused.value.extended == (0x0108,) and not rig.io.connections
