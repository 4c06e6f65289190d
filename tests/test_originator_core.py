"""The originator's sans-I/O core: transactions in, frames out; bytes and a fake clock in, replies out.
No socket anywhere: the peer is a scripted frame, or the target's own sans-I/O connection."""

from __future__ import annotations

import random
import struct
from typing import Any

import pytest

from cipstack.cip.epath import PortSegment, request_path
from cipstack.cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from cipstack.cip.status import CipError
from cipstack.devices.profiles import identity_only_device
from cipstack.eip.originator.core import (
    FrameBuffer,
    NoReplyError,
    OriginatorCore,
    Transaction,
    decode_multiple_service,
    encode_multiple_service,
    run_plan,
)
from cipstack.eip.originator.replies import EncapsulationStatusError, MalformedReplyError
from cipstack.eip.target.core import EncapsulationTarget, TargetSettings
from cipstack.eip.wire.cm_messages import ForwardCloseRequest, ForwardOpenRequest, UnconnectedSendRequest
from cipstack.eip.wire.cpf import Item, ItemType, SockAddr, decode_items, encode_items
from cipstack.eip.wire.encapsulation import HEADER, HEADER_SIZE, Command, EncapsulationHeader
from cipstack.scanner import ExplicitMessaging

GET_NAME = MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 7)).encode()


def reply_frame(command: int, body: bytes, context: bytes, session: int = 7, status: int = 0) -> bytes:
    return HEADER.pack(command, len(body), session, status, context, 0) + body


def rr_reply(mr_reply: bytes) -> bytes:
    return struct.pack("<IH", 0, 0) + encode_items((Item(ItemType.NULL_ADDRESS), Item(ItemType.UNCONNECTED_DATA,
                                                                                        mr_reply)))


def context_of(frame: bytes) -> bytes:
    return EncapsulationHeader.decode(frame).context


def test_register_session_frame_and_reply() -> None:
    core = OriginatorCore()
    transaction = core.register_session()
    frame = core.start(transaction, now=0.0)
    # RegisterSession: command 0x65, length 4, session 0, status 0, context 1, options 0; version 1, options 0.
    assert frame == bytes.fromhex("6500 0400 00000000 00000000 0100000000000000 00000000 0100 0000".replace(" ", ""))
    [(done, header, body)] = core.receive_data(reply_frame(Command.REGISTER_SESSION, b"\x01\x00\x00\x00",
                                                           context_of(frame), session=0x1234))
    assert done is transaction
    assert done.result(header, body) == 0x1234
    assert core.session == 0x1234 and core.pending == 0


def test_send_rr_data_frame_states_the_bytes() -> None:
    core = OriginatorCore()
    core.session = 0x11223344
    frame = core.start(core.send_rr_data(GET_NAME), now=0.0)
    assert frame == bytes.fromhex(
        "6f00 1800 44332211 00000000 0100000000000000 00000000"   # header: SendRRData, 24 bytes
        "00000000 0000 0200 0000 0000 b200 0800"                  # handle, timeout, Null Address, Unconnected Data
        "0e 03 20 01 24 01 30 07".replace(" ", ""))              # Get_Attribute_Single 1/1/7


def test_a_reply_split_anywhere_completes_once() -> None:
    core = OriginatorCore()
    transaction = core.request(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 7))
    frame = core.start(transaction, 0.0)
    reply = reply_frame(Command.SEND_RR_DATA, rr_reply(b"\x8e\x00\x00\x00\x03abc"), context_of(frame))
    completions = []
    for index in range(len(reply)):
        completions += core.receive_data(reply[index:index + 1])
    [(done, header, body)] = completions
    assert done.result(header, body) == MessageRouterResponse(0x0E, 0, (), b"\x03abc")


def test_replies_out_of_order_match_their_requests_by_context() -> None:
    core = OriginatorCore()
    first = core.request(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 1))
    second = core.request(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 7))
    frames = [core.start(first, 0.0), core.start(second, 0.0)]
    assert context_of(frames[0]) != context_of(frames[1])
    both = (reply_frame(Command.SEND_RR_DATA, rr_reply(b"\x8e\x00\x00\x00\x07"), context_of(frames[1]))
            + reply_frame(Command.SEND_RR_DATA, rr_reply(b"\x8e\x00\x00\x00\x01"), context_of(frames[0])))
    results = {done: done.result(header, body).data for done, header, body in core.receive_data(both)}
    assert results == {second: b"\x07", first: b"\x01"}


def test_deadlines_follow_the_clock_given_and_a_late_reply_is_dropped() -> None:
    core = OriginatorCore(timeout=2.0)
    transaction = core.list_identity()
    frame = core.start(transaction, now=100.0)
    quick = core.command(Command.LIST_SERVICES, timeout=0.5)
    core.start(quick, now=100.0)
    assert core.next_deadline() == 100.5
    assert core.expired(100.4) == []
    assert core.expired(100.5) == [quick]
    assert core.next_deadline() == 102.0
    assert core.expired(102.0) == [transaction]
    assert core.next_deadline() is None and core.pending == 0
    assert core.receive_data(reply_frame(Command.LIST_IDENTITY, b"\x00\x00", context_of(frame))) == []


def test_a_reply_to_another_command_with_the_same_context_is_not_taken() -> None:
    core = OriginatorCore()
    frame = core.start(core.list_identity(), 0.0)
    assert core.receive_data(reply_frame(Command.LIST_SERVICES, b"\x00\x00", context_of(frame))) == []
    assert core.pending == 1


def test_status_and_malformed_replies_raise_their_errors() -> None:
    core = OriginatorCore()
    frame = core.start(core.send_rr_data(GET_NAME), 0.0)
    [(done, header, body)] = core.receive_data(reply_frame(Command.SEND_RR_DATA, b"", context_of(frame),
                                                           status=0x64))
    with pytest.raises(EncapsulationStatusError, match="0x0064"):
        done.result(header, body)
    frame = core.start(core.request(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 7)), 0.0)
    [(done, header, body)] = core.receive_data(reply_frame(Command.SEND_RR_DATA, b"\x00\x00\x00\x00\x00\x00\x01\x00"
                                                           b"\x00\x00\x00\x00", context_of(frame)))
    with pytest.raises(MalformedReplyError, match="no Unconnected Data item"):
        done.result(header, body)


def test_unconnected_send_wraps_a_routed_request() -> None:
    core = OriginatorCore()
    frame = core.start(core.request(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 7),
                                    route=[PortSegment(1, b"\x00")]), 0.0)
    data = decode_items(frame[HEADER_SIZE:], 6)[1].data
    outer = MessageRouterRequest.decode(data)
    assert (outer.service, outer.path) == (Service.UNCONNECTED_SEND, request_path(6, 1))
    inner = UnconnectedSendRequest.decode(outer.data)
    assert (inner.message, inner.route_path) == (GET_NAME, b"\x01\x00")


def test_multiple_service_packet_round_trip() -> None:
    requests = [MessageRouterRequest(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, a)) for a in (1, 7)]
    encoded = encode_multiple_service(requests)
    assert encoded[:6] == b"\x02\x00\x06\x00\x0e\x00"
    replies = [MessageRouterResponse(0x0E, 0, (), b"\x01\x00"), MessageRouterResponse(0x0E, 0x14)]
    body = b"\x02\x00\x06\x00\x0c\x00" + b"".join(r.encode() for r in replies)
    assert decode_multiple_service(body) == replies
    with pytest.raises(MalformedReplyError, match="Multiple_Service_Packet"):
        decode_multiple_service(b"\x05\x00")


def test_frame_buffer_splits_a_stream() -> None:
    buffer = FrameBuffer()
    one = reply_frame(Command.NOP, b"abc", bytes(8))
    two = reply_frame(Command.NOP, b"", bytes(8))
    assert buffer.feed(one[:10]) == []
    assert buffer.feed(one[10:] + two + two[:3]) == [one, two]
    assert len(buffer) == 3


class TargetPeer:
    """The target's sans-I/O connection as the other end: frames in, frames out, the same fake clock."""

    def __init__(self) -> None:
        device = identity_only_device()
        settings = TargetSettings()
        settings.inactivity_timeout = lambda: device.inactivity_timeout  # type: ignore[method-assign]
        self.target = EncapsulationTarget(device.router, device.identity_record, settings, device.connection_table)
        self.now = 10.0
        self.connection = self.target.connection("127.0.0.1:5000", SockAddr("127.0.0.1", 44818), self.now)
        self.core = OriginatorCore(rng=random.Random(7))
        self.sent: list[bytes] = []

    def perform(self, transaction: Transaction[Any]) -> Any:
        frame = self.core.start(transaction, self.now)
        self.sent.append(frame)
        self.connection.receive(frame, self.now)
        for done, header, body in self.core.receive_data(self.connection.data_to_send()):
            if done is transaction:
                return transaction.result(header, body)
        self.now += transaction.timeout or self.core.timeout
        assert self.core.expired(self.now) == [transaction]
        raise NoReplyError(transaction.what)


def test_class_3_against_the_target_core() -> None:
    peer = TargetPeer()
    core = peer.core
    peer.perform(core.register_session())
    opened = peer.perform(core.forward_open(rpi_us=1_000_000, connection_size=500, large=True))
    assert core.connection is opened
    request = ForwardOpenRequest.decode(MessageRouterRequest.decode(
        decode_items(peer.sent[-1][HEADER_SIZE:], 6)[1].data).data, large=True)
    assert request.triad == opened.triad and request.ot_rpi_us == 1_000_000
    for expected_sequence in (1, 2):
        reply = peer.perform(core.request(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 1)))
        assert reply.data == b"\x03\x01"   # vendor id 259, over the class 3 connection
        items = decode_items(peer.sent[-1][HEADER_SIZE:], 6)
        assert items[0].type == ItemType.CONNECTED_ADDRESS
        assert struct.unpack_from("<H", items[1].data)[0] == expected_sequence
    closing = core.forward_close()
    assert closing is not None and core.connection is None
    peer.perform(closing)
    sent = ForwardCloseRequest.decode(MessageRouterRequest.decode(decode_items(peer.sent[-1][HEADER_SIZE:], 6)[1]
                                                                  .data).data)
    assert sent.triad == opened.triad
    assert core.forward_close() is None


def test_a_connected_reply_with_another_sequence_count_is_dropped() -> None:
    peer = TargetPeer()
    core = peer.core
    peer.perform(core.register_session())
    peer.perform(core.forward_open())
    transaction = core.request(Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 1))
    frame = core.start(transaction, peer.now)
    peer.connection.receive(frame, peer.now)
    reply = bytearray(peer.connection.data_to_send())
    struct.pack_into("<H", reply, HEADER_SIZE + 6 + 2 + 8 + 4, 999)   # the sequence count of the reply
    assert core.receive_data(bytes(reply)) == []
    assert core.pending == 1


def test_plans_run_the_scanner_logic_without_io() -> None:
    """The scanner's plans (identify, read, write) over the core, the target core answering."""
    peer = TargetPeer()
    peer.perform(peer.core.register_session())
    explicit = ExplicitMessaging(peer.core)
    record = run_plan(explicit.identify(), peer.perform)
    assert record is not None and record.vendor_id == 259 and record.address is not None   # ListIdentity's
    assert run_plan(explicit.read(1, 1, 1), peer.perform).raw == 259
    with pytest.raises(CipError) as refused:
        run_plan(explicit.write(1, 1, 1, 5, False, None), peer.perform)   # Vendor ID is read-only
    assert refused.value.general in (0x0E, 0x08)


def test_a_plan_sees_a_timeout_thrown_in_and_falls_back() -> None:
    """A ListIdentity nobody answers: the identify plan reads the Identity object instead."""
    peer = TargetPeer()
    peer.perform(peer.core.register_session())

    def perform(transaction: Transaction[Any]) -> Any:
        if transaction.command == Command.LIST_IDENTITY:
            peer.now += 5.0
            assert peer.core.expired(peer.now) == []   # never started: nothing to expire
            raise NoReplyError("no reply to ListIdentity")
        return peer.perform(transaction)

    record = run_plan(ExplicitMessaging(peer.core).identify(), perform)
    # From the Identity object: no address, no serial number (attributes 1-4 and 7 only).
    assert record is not None and (record.vendor_id, record.product_name, record.address) == (259, "CENT", None)
