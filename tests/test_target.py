"""The encapsulation target without sockets: bytes and a fake clock in, bytes out."""

from __future__ import annotations

import random
import struct

import pytest

from cipstack.cip.epath import ElectronicKey, PortSegment, encode_path, request_path
from cipstack.cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from cipstack.cip.model import Binding
from cipstack.devices.base import Device, DeviceLimits
from cipstack.devices.profiles import identity_only_device as build_device
from cipstack.eip.target.core import EncapsulationConnection, EncapsulationTarget, TargetSettings
from cipstack.eip.wire.cm_messages import (
    ConnectionTriad,
    ConnectionType,
    ForwardCloseRequest,
    ForwardOpenReply,
    ForwardOpenRequest,
    NetworkParameters,
    TransportTrigger,
    TriggerType,
    UnconnectedSendRequest,
)
from cipstack.eip.wire.cpf import Item, ItemType, SockAddr, decode_items, encode_items
from cipstack.eip.wire.encapsulation import HEADER, HEADER_SIZE, Command, EncapsulationHeader
from cipstack.eip.wire.identity_items import decode_list_identity, decode_list_services

LOCAL = SockAddr("127.0.0.1", 44818)
CTX = b"ctx-0001"


def frame(command: int, data: bytes = b"", session: int = 0, options: int = 0, context: bytes = CTX) -> bytes:
    return HEADER.pack(command, len(data), session, 0, context, options) + data


def parse_frames(raw: bytes) -> list[tuple[EncapsulationHeader, bytes]]:
    out = []
    while raw:
        header = EncapsulationHeader.decode(raw)
        out.append((header, raw[HEADER_SIZE:HEADER_SIZE + header.length]))
        raw = raw[HEADER_SIZE + header.length:]
    return out


class Harness:
    def __init__(self, device: Device | None = None, **settings: object) -> None:
        self.device = device or build_device()
        self.settings = TargetSettings(**settings)  # type: ignore[arg-type]
        self.settings.inactivity_timeout = lambda: self.device.inactivity_timeout
        self.target = EncapsulationTarget(self.device.router, self.device.identity_record, self.settings,
                                          self.device.connection_table)
        self.now = 1000.0
        self.conn = self.new_connection()

    def new_connection(self) -> EncapsulationConnection:
        return self.target.connection("127.0.0.1:5000", LOCAL, self.now)

    def send(self, data: bytes, conn: EncapsulationConnection | None = None) -> list[tuple[EncapsulationHeader, bytes]]:
        conn = conn or self.conn
        conn.receive(data, self.now)
        return parse_frames(conn.data_to_send())

    def register(self, conn: EncapsulationConnection | None = None) -> int:
        [(header, body)] = self.send(frame(Command.REGISTER_SESSION, struct.pack("<HH", 1, 0)), conn)
        assert header.status == 0 and body == b"\x01\x00\x00\x00"
        return header.session

    def rr(self, request: bytes, session: int) -> MessageRouterResponse:
        data = struct.pack("<IH", 0, 5) + encode_items([Item(ItemType.NULL_ADDRESS), Item(ItemType.UNCONNECTED_DATA,
                                                                                           request)])
        [(header, body)] = self.send(frame(Command.SEND_RR_DATA, data, session))
        assert header.status == 0 and header.context == CTX
        items = decode_items(body, 6)
        assert [i.type for i in items] == [ItemType.NULL_ADDRESS, ItemType.UNCONNECTED_DATA]
        return MessageRouterResponse.decode(items[1].data)


def gas(class_id: int, instance: int, attribute: int) -> bytes:
    return MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(class_id, instance, attribute)).encode()


def forward_open(triad: ConnectionTriad, *, transport_class: int = 3, path: bytes | None = None, large: bool = False,
                 rpi_us: int = 100_000, multiplier: int = 0,
                 conn_type: ConnectionType = ConnectionType.POINT_TO_POINT) -> bytes:
    params = NetworkParameters(500, conn_type, variable=True)
    request = ForwardOpenRequest(0x0A, 0x0E, 0, 0x1111, triad, multiplier, rpi_us, params, rpi_us, params,
                                 TransportTrigger(transport_class, TriggerType.APPLICATION, True),
                                 request_path(2, 1) if path is None else path, large)
    service = Service.LARGE_FORWARD_OPEN if large else Service.FORWARD_OPEN
    return MessageRouterRequest(service, request_path(6, 1), request.encode()).encode()


TRIAD = ConnectionTriad(0x0042, 0xFFFE, 0xCAFEF00D)


# -- sessions -------------------------------------------------------------------------------------------
def test_register_session_and_get_attribute() -> None:
    h = Harness()
    session = h.register()
    reply = h.rr(gas(1, 1, 7), session)
    assert reply.data == b"\x04CENT"


def test_second_register_session_is_invalid_command() -> None:
    h = Harness()
    session = h.register()
    [(header, _)] = h.send(frame(Command.REGISTER_SESSION, struct.pack("<HH", 1, 0), session))
    assert header.status == 0x0001


@pytest.mark.parametrize("body", [struct.pack("<HH", 2, 0), struct.pack("<HH", 1, 1)])
def test_register_session_bad_version(body: bytes) -> None:
    h = Harness()
    [(header, data)] = h.send(frame(Command.REGISTER_SESSION, body))
    assert header.status == 0x0069
    assert header.session == 0
    assert data == struct.pack("<HH", 1, 0)  # the version we support


def test_register_session_wrong_length() -> None:
    h = Harness()
    [(header, _)] = h.send(frame(Command.REGISTER_SESSION, b"\x01\x00"))
    assert header.status == 0x0065


def test_session_limit() -> None:
    h = Harness(max_sessions=2, max_sessions_per_host=2)
    h.register()
    h.register(second := h.new_connection())
    third = h.new_connection()
    [(header, _)] = h.send(frame(Command.REGISTER_SESSION, struct.pack("<HH", 1, 0)), third)
    assert header.status == 0x0002
    # A closed connection frees its session slot.
    second.connection_lost()
    assert h.register(third)


def test_session_belongs_to_its_connection() -> None:
    h = Harness()
    session = h.register()
    other = h.new_connection()
    h.register(other)
    data = struct.pack("<IH", 0, 5) + encode_items([Item(0), Item(0xB2, gas(1, 1, 1))])
    [(header, _)] = h.send(frame(Command.SEND_RR_DATA, data, session), other)
    assert header.status == 0x0064


def test_send_rr_data_without_session() -> None:
    h = Harness()
    data = struct.pack("<IH", 0, 5) + encode_items([Item(0), Item(0xB2, gas(1, 1, 1))])
    [(header, _)] = h.send(frame(Command.SEND_RR_DATA, data, 0x1234))
    assert header.status == 0x0064


@pytest.mark.parametrize("cpf", [
    encode_items([Item(0xB2, gas(1, 1, 1))]),
    encode_items([Item(0xA1, b"\x00" * 4), Item(0xB2, gas(1, 1, 1))]),
    encode_items([Item(0), Item(0xB1, gas(1, 1, 1))]),
    encode_items([Item(0), Item(0xB2, b"")]),
    b"\x02\x00\x00\x00\x00\x00\xb2\x00\x40\x00",
    b"\x02",
])
def test_send_rr_data_bad_cpf(cpf: bytes) -> None:
    h = Harness()
    session = h.register()
    [(header, _)] = h.send(frame(Command.SEND_RR_DATA, struct.pack("<IH", 0, 5) + cpf, session))
    assert header.status == 0x0003
    assert h.rr(gas(1, 1, 1), session).data == struct.pack("<H", 259)  # still serving


def test_unknown_command_and_options_and_nop() -> None:
    h = Harness()
    [(header, _)] = h.send(frame(0x0099, b"abc"))
    assert (header.command, header.status) == (0x0099, 0x0001)
    assert h.send(frame(Command.LIST_IDENTITY, options=1)) == []  # discarded
    assert h.send(frame(Command.NOP, b"anything")) == []
    assert h.target.stats.dropped == 1


def test_unregister_session_closes_without_reply() -> None:
    h = Harness()
    session = h.register()
    assert h.send(frame(Command.UNREGISTER_SESSION, session=session)) == []
    assert h.conn.closing
    h.conn.connection_lost()
    assert session not in h.target.sessions


def test_oversized_frame_is_refused_and_connection_closed() -> None:
    h = Harness(max_frame_length=1000)
    replies = h.send(HEADER.pack(Command.SEND_RR_DATA, 65535, 0, 0, CTX, 0))
    assert [r[0].status for r in replies] == [0x0065]
    assert h.conn.closing
    assert h.conn.buffered_bytes == 0


def test_frames_split_and_coalesced() -> None:
    h = Harness()
    session = h.register()
    data = struct.pack("<IH", 0, 5) + encode_items([Item(0), Item(0xB2, gas(1, 1, 3))])
    one = frame(Command.SEND_RR_DATA, data, session)
    stream = one * 3
    replies = []
    for i in range(0, len(stream), 7):
        replies += h.send(stream[i:i + 7])
    assert len(replies) == 3
    assert all(MessageRouterResponse.decode(decode_items(b, 6)[1].data).data == b"\x64\x00" for _, b in replies)


def _gas_frame(session: int, class_id: int, instance: int, attribute: int, context: bytes = CTX) -> bytes:
    data = struct.pack("<IH", 0, 5) + encode_items([Item(0), Item(0xB2, gas(class_id, instance, attribute))])
    return frame(Command.SEND_RR_DATA, data, session, context=context)


def _reply_value(replies: list[tuple[EncapsulationHeader, bytes]]) -> bytes:
    [(header, body)] = replies
    assert header.status == 0
    reply = MessageRouterResponse.decode(decode_items(body, 6)[1].data)
    assert reply.general_status == 0
    return reply.data


def test_a_frame_sent_again_byte_for_byte_is_served_afresh() -> None:
    """A client polling one attribute sends the same frame again and again: each is counted, moves
    the device's clock, reads the attribute anew (its value changes between reads) and is answered
    with the frame's own session and context, as the first was."""
    h = Harness()
    counter = iter(range(100, 200))
    h.device.identity.bind(1, 5, Binding(lambda: next(counter)))
    ticks: list[float] = []
    h.target.tick = ticks.append
    session = h.register()
    polled = _gas_frame(session, 1, 1, 5)
    frames_before = h.target.stats.frames
    values = []
    for _ in range(4):
        h.now += 0.5
        replies = h.send(polled)
        assert replies[0][0].session == session and replies[0][0].context == CTX
        values.append(_reply_value(replies))
    assert values == [struct.pack("<H", v) for v in (100, 101, 102, 103)]
    assert ticks == [1000.5, 1001.0, 1001.5, 1002.0]
    assert h.target.stats.frames == frames_before + 4
    assert h.conn.last_activity == h.now
    # Another frame in between (another context), then the first again: each answered as its own.
    other = _gas_frame(session, 1, 1, 5, context=b"other-01")
    assert h.send(other)[0][0].context == b"other-01"
    assert h.send(polled)[0][0].context == CTX


def test_a_repeated_frame_is_not_served_after_the_session_ends_nor_when_it_completes_a_split_frame() -> None:
    h = Harness()
    session = h.register()
    polled = _gas_frame(session, 1, 1, 1)
    assert _reply_value(h.send(polled)) == struct.pack("<H", 259)  # the profile's vendor ID
    # The same bytes completing a frame cut short by the last read are that frame's rest: here the
    # data of a NOP, which has no reply.
    assert h.send(HEADER.pack(Command.NOP, len(polled), 0, 0, CTX, 0)) == []
    assert h.send(polled) == []
    assert h.conn.buffered_bytes == 0
    assert h.send(polled[:10]) == []
    [(header, _)] = h.send(polled[10:] + polled[:10])
    assert header.status == 0
    assert h.send(polled[10:])[0][0].status == 0
    # Two of them in one read are two frames.
    assert len(h.send(polled * 2)) == 2
    h.send(frame(Command.UNREGISTER_SESSION, session=session))
    assert h.conn.closing
    assert h.send(polled) == []


def test_a_repeated_frame_of_another_connection_or_an_old_session_is_refused() -> None:
    h = Harness()
    session = h.register()
    polled = _gas_frame(session, 1, 1, 1)
    h.send(polled)
    other = h.new_connection()
    h.register(other)
    [(header, _)] = h.send(polled, other)
    assert header.status == 0x0064  # that session is not this connection's
    [(header, _)] = h.send(polled, other)
    assert header.status == 0x0064


def test_a_repeated_request_whose_instance_has_gone_gets_the_router_s_answer() -> None:
    h = Harness()
    session = h.register()
    polled = _gas_frame(session, 1, 1, 1)
    h.send(polled)
    del h.device.identity.instances[1]
    [(header, body)] = h.send(polled)
    assert header.status == 0
    assert MessageRouterResponse.decode(decode_items(body, 6)[1].data).general_status == 0x05  # path unknown


# -- list commands --------------------------------------------------------------------------------------------
def test_list_identity_tcp_bytes() -> None:
    h = Harness()
    [(_, body)] = h.send(frame(Command.LIST_IDENTITY))
    expected_item = (b"\x01\x00" + bytes.fromhex("0002 AF12 7F000001 0000000000000000")
                     + struct.pack("<HHHBBHI", 259, 2, 100, 1, 1, 0, 0x10000064) + b"\x04CENT" + b"\x03")
    assert body == b"\x01\x00" + b"\x0c\x00" + struct.pack("<H", len(expected_item)) + expected_item
    [record] = decode_list_identity(body)
    assert (record.product_name, record.address) == ("CENT", LOCAL)


def test_list_services_bytes() -> None:
    h = Harness()
    [(_, body)] = h.send(frame(Command.LIST_SERVICES))
    assert body == bytes.fromhex("0100 0001 1400 0100 2000") + b"Communications\x00\x00"
    [service] = decode_list_services(body)
    assert service.cip_over_tcp and not service.class01_over_udp


def test_list_interfaces_empty() -> None:
    [(header, body)] = Harness().send(frame(Command.LIST_INTERFACES))
    assert header.status == 0 and body == b"\x00\x00"


# Above 2000 ms the target answers within 2 s: within any larger maximum, and no reply is held longer.
@pytest.mark.parametrize(("context_ms", "bound"), [(0, 2.0), (100, 0.5), (499, 0.5), (1000, 1.0), (1999, 1.999),
                                                   (4000, 2.0), (0xFFFF, 2.0)])
def test_udp_list_identity_delay(context_ms: int, bound: float) -> None:
    h = Harness(rng=random.Random(7))
    delays = []
    for _ in range(200):
        reply, delay = h.target.datagram(frame(Command.LIST_IDENTITY, context=struct.pack("<H", context_ms) + bytes(6)),
                                         LOCAL) or (b"", -1.0)
        assert decode_list_identity(reply[HEADER_SIZE:])[0].product_code == 100
        delays.append(delay)
    assert min(delays) >= 0 and max(delays) <= bound
    assert max(delays) > bound * 0.8  # really spread over the window


def test_udp_other_commands() -> None:
    h = Harness()
    reply, delay = h.target.datagram(frame(Command.LIST_SERVICES), LOCAL) or (b"", -1)
    assert delay == 0 and decode_list_services(reply[HEADER_SIZE:])
    reply, _ = h.target.datagram(frame(Command.REGISTER_SESSION, struct.pack("<HH", 1, 0)), LOCAL) or (b"", 0)
    assert EncapsulationHeader.decode(reply).status == 0x0001
    assert h.target.datagram(b"\x63\x00", LOCAL) is None
    assert h.target.datagram(frame(Command.LIST_IDENTITY) + b"x", LOCAL) is None


# -- inactivity timeout -----------------------------------------------------------------------------------------
def test_inactivity_timeout_follows_tcpip_attribute_13() -> None:
    h = Harness()
    h.register()
    assert h.conn.next_deadline() == h.now + 120
    h.device.tcpip.set(1, 13, 5)
    assert h.conn.next_deadline() == h.now + 5
    h.conn.on_timer(h.now + 4.9)
    assert not h.conn.closing
    h.conn.on_timer(h.now + 5.0)
    assert h.conn.closing
    h.device.tcpip.set(1, 13, 0)
    assert h.new_connection().next_deadline() is None


# -- Unconnected_Send ------------------------------------------------------------------------------------------------
def unconnected_send(message: bytes, route: bytes) -> bytes:
    return MessageRouterRequest(Service.UNCONNECTED_SEND, request_path(6, 1),
                                UnconnectedSendRequest(0x0A, 0x0E, message, route).encode()).encode()


def test_unconnected_send_to_this_device() -> None:
    h = Harness()
    session = h.register()
    for route in (encode_path([PortSegment(1, b"\x00")]), b""):
        reply = h.rr(unconnected_send(gas(1, 1, 7), route), session)
        assert reply.service == 0x0E and reply.data == b"\x04CENT"
    # An odd-length embedded request carries a pad byte.
    odd = MessageRouterRequest(0x0E, request_path(1, 1, 7), b"\x00").encode()
    assert len(odd) % 2 == 1
    assert h.rr(unconnected_send(odd, b"\x01\x00"), session).general_status == 0x15


def test_unconnected_send_routing_errors() -> None:
    h = Harness()
    session = h.register()
    slot3 = h.rr(unconnected_send(gas(1, 1, 7), b"\x01\x03"), session)
    assert (slot3.service, slot3.general_status, slot3.extended_status) == (0x52, 0x01, (0x0312,))
    port5 = h.rr(unconnected_send(gas(1, 1, 7), b"\x05\x01"), session)
    assert (port5.general_status, port5.extended_status, port5.data) == (0x01, (0x0311,), b"\x01\x00")
    bad = h.rr(MessageRouterRequest(0x52, request_path(6, 1), b"\x0a\x0e\x40\x00").encode(), session)
    assert bad.general_status == 0x13


# -- class 3 --------------------------------------------------------------------------------------------
def open_class3(h: Harness, session: int, **kwargs: object) -> ForwardOpenReply:
    reply = h.rr(forward_open(TRIAD, **kwargs), session)  # type: ignore[arg-type]
    assert reply.ok, reply
    return ForwardOpenReply.decode(reply.data)


def unit_data(h: Harness, session: int, connection_id: int, sequence: int, request: bytes
              ) -> tuple[int, int, MessageRouterResponse] | None:
    data = struct.pack("<IH", 0, 0) + encode_items([Item(0xA1, struct.pack("<I", connection_id)),
                                                    Item(0xB1, struct.pack("<H", sequence) + request)])
    replies = h.send(frame(Command.SEND_UNIT_DATA, data, session))
    if not replies:
        return None
    [(header, body)] = replies
    assert header.status == 0
    items = decode_items(body, 6)
    assert [i.type for i in items] == [0xA1, 0xB1]
    to_id = struct.unpack("<I", items[0].data)[0]
    seq = struct.unpack_from("<H", items[1].data)[0]
    return to_id, seq, MessageRouterResponse.decode(items[1].data[2:])


@pytest.mark.parametrize("large", [False, True])
def test_class3_connected_messaging(large: bool) -> None:
    h = Harness()
    session = h.register()
    opened = open_class3(h, session, large=large)
    assert opened.to_connection_id == 0x1111 and opened.triad == TRIAD
    assert opened.ot_api_us == 100_000
    result = unit_data(h, session, opened.ot_connection_id, 1, gas(1, 1, 7))
    assert result is not None
    to_id, seq, reply = result
    assert (to_id, seq, reply.data) == (0x1111, 1, b"\x04CENT")
    close = MessageRouterRequest(Service.FORWARD_CLOSE, request_path(6, 1),
                                 ForwardCloseRequest(0x0A, 0x0E, TRIAD, request_path(2, 1)).encode()).encode()
    closed = h.rr(close, session)
    assert closed.ok and closed.data[:8] == struct.pack("<HHI", 0x42, 0xFFFE, 0xCAFEF00D)
    assert unit_data(h, session, opened.ot_connection_id, 2, gas(1, 1, 7)) is None  # gone: dropped
    again = h.rr(close, session)
    assert (again.general_status, again.extended_status) == (0x01, (0x0107,))


def test_class3_duplicate_sequence_is_not_executed_twice() -> None:
    h = Harness()
    counter = iter(range(1, 100))
    h.device.identity.bind(1, 5, Binding(lambda: next(counter)))
    session = h.register()
    opened = open_class3(h, session)
    first = unit_data(h, session, opened.ot_connection_id, 7, gas(1, 1, 5))
    repeat = unit_data(h, session, opened.ot_connection_id, 7, gas(1, 1, 5))
    fresh = unit_data(h, session, opened.ot_connection_id, 8, gas(1, 1, 5))
    assert first and repeat and fresh
    assert first[2].data == repeat[2].data == b"\x01\x00"
    assert fresh[2].data == b"\x02\x00"


def test_class3_timeout_with_fake_clock() -> None:
    h = Harness()
    session = h.register()
    opened = open_class3(h, session, rpi_us=500_000, multiplier=1)  # timeout 0.5 s x 8 = 4 s
    conn_id = opened.ot_connection_id
    # Before the first packet at least 10 s.
    h.conn.on_timer(h.now + 9.9)
    assert conn_id in h.target.table.connections
    h.now += 9.0
    assert unit_data(h, session, conn_id, 1, gas(1, 1, 1)) is not None
    assert h.conn.next_deadline() == pytest.approx(h.now + 4.0)
    h.conn.on_timer(h.now + 3.9)
    assert conn_id in h.target.table.connections
    h.conn.on_timer(h.now + 4.0)
    assert conn_id not in h.target.table.connections
    assert h.target.table.timeouts == 1


def test_class3_connection_dies_with_its_tcp_connection() -> None:
    h = Harness()
    session = h.register()
    opened = open_class3(h, session)
    other = h.new_connection()
    other_session = h.register(other)
    data = struct.pack("<IH", 0, 0) + encode_items([Item(0xA1, struct.pack("<I", opened.ot_connection_id)),
                                                    Item(0xB1, b"\x01\x00" + gas(1, 1, 1))])
    assert h.send(frame(Command.SEND_UNIT_DATA, data, other_session), other) == []  # not its connection
    h.conn.connection_lost()
    assert not h.target.table.connections


@pytest.mark.parametrize(("kwargs", "extended"), [
    ({"transport_class": 1}, 0x0103),
    ({"transport_class": 2}, 0x0103),
    ({"path": request_path(1, 1)}, 0x0117),
    ({"path": b"\x01\x03" + request_path(2, 1)}, 0x0312),
    ({"path": b"\x02\x01" + request_path(2, 1)}, 0x0311),
    ({"path": b"\xe0\x00"}, 0x0315),
    ({"rpi_us": 0}, 0x0111),
    ({"conn_type": ConnectionType.MULTICAST}, 0x0108),
    # Both connection types null: a null Forward_Open, which this target does not support.
    ({"conn_type": ConnectionType.NULL}, 0x0132),
    ({"conn_type": ConnectionType.NULL, "transport_class": 1}, 0x0132),
    ({"path": encode_path([ElectronicKey(260, 0, 0, 0, 0)]) + request_path(2, 1)}, 0x0114),
    ({"path": encode_path([ElectronicKey(259, 0, 101, 0, 0)]) + request_path(2, 1)}, 0x0114),
    ({"path": encode_path([ElectronicKey(0, 3, 0, 0, 0)]) + request_path(2, 1)}, 0x0115),
    ({"path": encode_path([ElectronicKey(259, 2, 100, 2, 1)]) + request_path(2, 1)}, 0x0116),
    ({"path": encode_path([ElectronicKey(259, 2, 100, 1, 2, True)]) + request_path(2, 1)}, 0x0116),
    ({"path": encode_path([ElectronicKey(259, 2, 100, 1, 2)]) + request_path(2, 1)}, 0x0116),
])
def test_forward_open_errors(kwargs: dict[str, object], extended: int) -> None:
    h = Harness()
    session = h.register()
    reply = h.rr(forward_open(TRIAD, **kwargs), session)  # type: ignore[arg-type]
    assert (reply.service, reply.general_status, reply.extended_status) == (Service.FORWARD_OPEN, 0x01, (extended,))
    # The failure data names the connection: serial, vendor, originator serial, remaining path size, reserved.
    assert reply.data == struct.pack("<HHIBB", 0x42, 0xFFFE, 0xCAFEF00D, 0, 0)


@pytest.mark.parametrize("key", [ElectronicKey(259, 2, 100, 1, 1), ElectronicKey(259, 2, 100, 1, 0, True),
                                 ElectronicKey(259, 2, 100, 1, 1, True), ElectronicKey()])
def test_forward_open_matching_keys(key: ElectronicKey) -> None:
    h = Harness()
    session = h.register()
    assert open_class3(h, session, path=encode_path([key]) + request_path(2, 1))


def test_forward_open_duplicate_and_out_of_connections() -> None:
    h = Harness(device=build_device(limits=DeviceLimits(max_connections=2)))
    session = h.register()
    open_class3(h, session)
    duplicate = h.rr(forward_open(TRIAD), session)
    assert duplicate.extended_status == (0x0100,)
    assert h.rr(forward_open(ConnectionTriad(2, 1, 1)), session).ok
    full = h.rr(forward_open(ConnectionTriad(3, 1, 1)), session)
    assert (full.general_status, full.extended_status) == (0x01, (0x0113,))
    counters = h.rr(MessageRouterRequest(0x01, request_path(6, 1)).encode(), session).data
    open_requests, format_rejects, resource_rejects, other_rejects = struct.unpack_from("<HHHH", counters)
    assert (open_requests, format_rejects, resource_rejects, other_rejects) == (4, 0, 1, 1)


def test_forward_open_garbage_is_not_enough_data() -> None:
    h = Harness()
    session = h.register()
    reply = h.rr(MessageRouterRequest(0x54, request_path(6, 1), b"\x0a\x0e\x00").encode(), session)
    assert reply.general_status == 0x13


@pytest.mark.parametrize("large", [False, True])
def test_forward_open_codec_round_trip(large: bool) -> None:
    request = ForwardOpenRequest(0x0A, 0x0E, 1, 2, TRIAD, 3, 10_000,
                                 NetworkParameters(32, ConnectionType.MULTICAST, variable=False),
                                 20_000, NetworkParameters(6, ConnectionType.POINT_TO_POINT), TransportTrigger(1),
                                 bytes.fromhex("20 04 24 01 2C 70 2C 71"), large)
    assert ForwardOpenRequest.decode(request.encode(), large) == request
    raw = request.encode()
    # O->T parameters: multicast (bits 14-13 = 1), fixed, size 32 -> 0x2020 (0x20200000|32 in the large form).
    offset = 22 + 4  # after the 22-byte fixed head and the O->T RPI
    if large:
        assert struct.unpack_from("<I", raw, offset)[0] == 0x20000020
    else:
        assert struct.unpack_from("<H", raw, offset)[0] == 0x2020
