"""The object model and message router: every service and every failure status of wire.md."""

from __future__ import annotations

import struct

import pytest

from cipstack.cip.epath import request_path
from cipstack.cip.messages import MessageRouterRequest, MessageRouterResponse, Service
from cipstack.cip.model import Access, AttributeSpec, Binding, CipObject, ClassSpec
from cipstack.cip.router import MessageRouter, RequestContext
from cipstack.cip.status import CipError, GeneralStatus
from cipstack.cip.types import INT, REAL, SHORT_STRING, UINT
from cipstack.devices.profiles import identity_only_device as build_device

SPEED_SPEC = ClassSpec(
    0x70, "Test Drive", revision=3,
    instance_attributes=(
        AttributeSpec(1, "Name", SHORT_STRING, default="drive"),
        AttributeSpec(2, "Speed Reference", INT, Access.GET_SET, default=0, minimum=-1800, maximum=1800, unit="rpm"),
        AttributeSpec(3, "Mode", UINT, Access.GET_SET, default=1, enum={1: "speed", 2: "torque"}),
        AttributeSpec(4, "Gain", REAL, Access.GET_SET, default=1.5),
        AttributeSpec(5, "Live Counter", UINT, in_get_all=False),
    ),
)


@pytest.fixture
def router() -> MessageRouter:
    router = build_device().router
    obj = CipObject(SPEED_SPEC)
    counter = iter(range(100, 1000))
    obj.add_instance(1, live_counter=Binding(lambda: next(counter)))
    obj.add_instance(2, name="second")
    router.register(obj)
    return router


def ask(router: MessageRouter, service: int, path: bytes, data: bytes = b"") -> MessageRouterResponse:
    raw = router.handle(MessageRouterRequest(service, path, data).encode(), RequestContext(router))
    return MessageRouterResponse.decode(raw)


def test_get_attribute_single(router: MessageRouter) -> None:
    reply = ask(router, Service.GET_ATTRIBUTE_SINGLE, request_path(1, 1, 7))
    assert reply.encode() == bytes.fromhex("8E 00 00 00 04") + b"CENT"
    assert ask(router, 0x0E, request_path(0x70, 1, 2)).data == b"\x00\x00"
    # A bound attribute reads live.
    assert ask(router, 0x0E, request_path(0x70, 1, 5)).data == struct.pack("<H", 100)
    assert ask(router, 0x0E, request_path(0x70, 1, 5)).data == struct.pack("<H", 101)


@pytest.mark.parametrize(("service", "path", "data", "status"), [
    (0x0E, request_path(0x99, 1, 1), b"", GeneralStatus.PATH_DESTINATION_UNKNOWN),
    (0x0E, request_path(0x70, 9, 1), b"", GeneralStatus.PATH_DESTINATION_UNKNOWN),
    (0x0E, request_path(0x70, 1, 99), b"", GeneralStatus.ATTRIBUTE_NOT_SUPPORTED),
    (0x0E, request_path(0x70, 0, 99), b"", GeneralStatus.ATTRIBUTE_NOT_SUPPORTED),
    (0x0E, request_path(0x70, 1, 1), b"\x00", GeneralStatus.TOO_MUCH_DATA),
    (0x4C, request_path(0x70, 1, 1), b"", GeneralStatus.SERVICE_NOT_SUPPORTED),
    (0x10, request_path(0x70, 1, 1), b"\x01x", GeneralStatus.ATTRIBUTE_NOT_SETTABLE),
    (0x10, request_path(0x70, 1, 2), b"\x01", GeneralStatus.NOT_ENOUGH_DATA),
    (0x10, request_path(0x70, 1, 2), b"\x01\x00\x00", GeneralStatus.TOO_MUCH_DATA),
    (0x10, request_path(0x70, 1, 2), struct.pack("<h", 1801), GeneralStatus.INVALID_ATTRIBUTE_VALUE),
    (0x10, request_path(0x70, 1, 3), struct.pack("<H", 3), GeneralStatus.INVALID_ATTRIBUTE_VALUE),
    (0x10, request_path(0x70, 1, 99), b"\x00\x00", GeneralStatus.ATTRIBUTE_NOT_SUPPORTED),
    (0x10, request_path(0x70, 1), b"\x00\x00", GeneralStatus.PATH_SEGMENT_ERROR),
    (0x0E, bytes.fromhex("24 01 20 70"), b"", GeneralStatus.PATH_SEGMENT_ERROR),
    (0x10, request_path(0x01, 1, 1), b"\x00\x00", GeneralStatus.SERVICE_NOT_SUPPORTED),
    (0x05, request_path(0x01, 1), b"\x07", GeneralStatus.INVALID_PARAMETER_VALUE),
])
def test_failures(router: MessageRouter, service: int, path: bytes, data: bytes, status: int) -> None:
    reply = ask(router, service, path, data)
    assert reply.general_status == status
    assert reply.service == service


def test_set_attribute_single_then_get(router: MessageRouter) -> None:
    assert ask(router, 0x10, request_path(0x70, 1, 2), struct.pack("<h", -1500)).ok
    assert ask(router, 0x0E, request_path(0x70, 1, 2)).data == struct.pack("<h", -1500)
    # Instance 2 is untouched.
    assert ask(router, 0x0E, request_path(0x70, 2, 2)).data == b"\x00\x00"


def test_class_attributes_derive_from_declaration(router: MessageRouter) -> None:
    def class_attr(attribute: int) -> int:
        return struct.unpack("<H", ask(router, 0x0E, request_path(0x70, 0, attribute)).data)[0]

    assert class_attr(1) == 3  # revision
    assert class_attr(2) == 2  # max instance
    assert class_attr(3) == 2  # number of instances
    assert class_attr(6) == 7  # max class attribute id
    assert class_attr(7) == 5  # max instance attribute id


def test_get_attributes_all(router: MessageRouter) -> None:
    reply = ask(router, 0x01, request_path(0x70, 2))
    # Attributes 1-4 in id order; 5 is declared outside Get_Attributes_All.
    assert reply.data == b"\x06second" + b"\x00\x00" + b"\x01\x00" + struct.pack("<f", 1.5)
    identity = ask(router, 0x01, request_path(0x01, 1)).data
    assert identity == (struct.pack("<HHHBBHI", 259, 2, 100, 1, 1, 0, 0x10000064) + b"\x04CENT")


def test_get_attribute_list(router: MessageRouter) -> None:
    reply = ask(router, 0x03, request_path(0x70, 1), struct.pack("<HHH", 2, 2, 3))
    assert reply.ok
    assert reply.data == struct.pack("<HHHhHHH", 2, 2, 0, 0, 3, 0, 1)
    partial = ask(router, 0x03, request_path(0x70, 1), struct.pack("<HHH", 2, 2, 42))
    assert partial.general_status == GeneralStatus.ATTRIBUTE_LIST_ERROR
    assert partial.data == struct.pack("<HHHhHH", 2, 2, 0, 0, 42, GeneralStatus.ATTRIBUTE_NOT_SUPPORTED)
    assert ask(router, 0x03, request_path(0x70, 1), struct.pack("<HH", 2, 2)).general_status == 0x13
    assert ask(router, 0x03, request_path(0x70, 1), struct.pack("<HHHH", 2, 2, 3, 4)).general_status == 0x15


def test_set_attribute_list(router: MessageRouter) -> None:
    data = struct.pack("<HHhHH", 2, 2, 900, 3, 2)
    reply = ask(router, 0x04, request_path(0x70, 1), data)
    assert reply.ok
    assert reply.data == struct.pack("<HHHHH", 2, 2, 0, 3, 0)
    assert ask(router, 0x0E, request_path(0x70, 1, 2)).data == struct.pack("<h", 900)
    # One value out of range, one read-only: per-attribute statuses and 0x0A overall; the good one still applies.
    data = struct.pack("<HHhHH", 3, 2, 5000, 3, 1) + struct.pack("<H", 1) + b"\x01x"
    reply = ask(router, 0x04, request_path(0x70, 1), data)
    assert reply.general_status == GeneralStatus.ATTRIBUTE_LIST_ERROR
    assert reply.data == struct.pack("<HHHHHHH", 3, 2, 0x09, 3, 0, 1, 0x0E)
    assert ask(router, 0x0E, request_path(0x70, 1, 2)).data == struct.pack("<h", 900)


def test_multiple_service_packet(router: MessageRouter) -> None:
    inner = [MessageRouterRequest(0x0E, request_path(1, 1, 1)).encode(),
             MessageRouterRequest(0x0E, request_path(1, 1, 99)).encode()]
    table = struct.pack("<HHH", 2, 6, 6 + len(inner[0]))
    reply = ask(router, 0x0A, request_path(2, 1), table + b"".join(inner))
    assert reply.general_status == GeneralStatus.EMBEDDED_SERVICE_ERROR
    count, first, second = struct.unpack_from("<HHH", reply.data)
    assert count == 2
    assert MessageRouterResponse.decode(reply.data[first:second]).data == struct.pack("<H", 259)
    assert MessageRouterResponse.decode(reply.data[second:]).general_status == 0x14
    ok = ask(router, 0x0A, request_path(2, 1), struct.pack("<HH", 1, 4) + inner[0])
    assert ok.ok
    bad_offsets = ask(router, 0x0A, request_path(2, 1), struct.pack("<HH", 1, 200) + inner[0])
    assert bad_offsets.general_status == GeneralStatus.INVALID_PARAMETER


def test_message_router_object_list(router: MessageRouter) -> None:
    data = ask(router, 0x0E, request_path(2, 1, 1)).data
    count = struct.unpack_from("<H", data)[0]
    classes = list(struct.unpack_from(f"<{count}H", data, 2))
    assert classes == [0x01, 0x02, 0x04, 0x06, 0x70, 0xF5, 0xF6]


def test_identity_reset_types(router: MessageRouter) -> None:
    device = build_device()
    assert ask(device.router, 0x05, request_path(1, 1), b"\x01").ok
    assert device.pending_reset == 1
    assert ask(device.router, 0x05, request_path(1, 1)).ok
    assert device.pending_reset == 0


def test_object_exception_becomes_status_not_crash(router: MessageRouter) -> None:
    obj = router[0x70]

    def broken() -> int:
        raise RuntimeError("boom")

    obj.bind(2, 5, Binding(broken))
    assert ask(router, 0x0E, request_path(0x70, 2, 5)).general_status == GeneralStatus.VENDOR_SPECIFIC


def test_tcpip_inactivity_timeout_range() -> None:
    device = build_device()
    assert ask(device.router, 0x10, request_path(0xF5, 1, 13), struct.pack("<H", 3601)).general_status == 0x09
    assert ask(device.router, 0x10, request_path(0xF5, 1, 13), struct.pack("<H", 30)).ok
    assert device.inactivity_timeout == 30


@pytest.mark.parametrize("profile", ["acg", "mx2"])
def test_get_attribute_single_served_directly_answers_as_dispatch_does(profile: str) -> None:
    """``handle`` serves ``0E 03 20 cc 24 ii 30 aa`` without the request and reply objects when it can:
    for every class, instance and attribute of a device (and ones it lacks) the reply is the one the
    full dispatch gives, errors included."""
    from cipstack.devices.profiles import build_device as build_profile_device

    device = build_profile_device(profile)
    router = device.router
    context = RequestContext(router, 1.0, "127.0.0.1:1", None)
    compared = 0
    for _pass in range(2):  # the second pass through the readers the first one made
        for class_id in [*sorted(router.objects), 0x99]:
            obj = router.objects.get(class_id)
            instances = [0, *sorted(obj.instances)[:3], 0xFE] if obj is not None else [0, 1]
            for instance in instances:
                for attribute in range(0, 24):
                    raw = bytes((0x0E, 0x03, 0x20, class_id, 0x24, instance, 0x30, attribute))
                    assert router.handle(raw, context) == router.dispatch(raw, context).encode(), raw.hex()
                    compared += 1
    assert compared > 1000
    # Other 8-byte Get_Attribute_Single requests (other segments, path sizes, a member) go to dispatch.
    for raw in (bytes.fromhex("0e032001240128 07".replace(" ", "")), bytes.fromhex("0e03200124013007"),
                bytes.fromhex("0e02200124013007"), bytes.fromhex("0e03210001002407"),
                bytes.fromhex("0e03200130072401"), bytes.fromhex("0e0320012c013007")):
        for _pass in range(2):
            assert router.handle(raw, context) == router.dispatch(raw, context).encode(), raw.hex()
    # A request with data is no plain Get_Attribute_Single: 0x15 (too much data), as dispatch says.
    raw = bytes((0x0E, 0x03, 0x20, 0x01, 0x24, 0x01, 0x30, 0x07, 0x00))
    assert router.handle(raw, context)[2] == GeneralStatus.TOO_MUCH_DATA


def test_a_kept_attribute_reader_reads_what_is_there_now(router: MessageRouter) -> None:
    """``handle`` keeps a reader per Get_Attribute_Single request: it reads the value of the moment,
    of the instance that exists now, and a failure is answered as dispatch answers it."""
    obj = router[0x70]
    assert ask(router, 0x0E, request_path(0x70, 2, 2)).data == b"\x00\x00"
    assert ask(router, 0x10, request_path(0x70, 2, 2), struct.pack("<h", -5)).ok
    assert ask(router, 0x0E, request_path(0x70, 2, 2)).data == struct.pack("<h", -5)
    # The instance goes: 0x05, as for an instance that never was; another instance 2: its value.
    del obj.instances[2]
    assert ask(router, 0x0E, request_path(0x70, 2, 2)).general_status == GeneralStatus.PATH_DESTINATION_UNKNOWN
    obj.add_instance(2, speed_reference=7)
    assert ask(router, 0x0E, request_path(0x70, 2, 2)).data == struct.pack("<h", 7)
    # A read that fails is answered as dispatch answers it; once the value reads again, it is served.
    assert ask(router, 0x0E, request_path(0x70, 1, 5)).data == struct.pack("<H", 100)
    failing = True

    def flaky() -> int:
        if failing:
            raise RuntimeError("not now")
        return 42

    obj.bind(1, 5, Binding(flaky))
    assert ask(router, 0x0E, request_path(0x70, 1, 5)).general_status == GeneralStatus.VENDOR_SPECIFIC
    failing = False
    assert ask(router, 0x0E, request_path(0x70, 1, 5)).data == struct.pack("<H", 42)
    # A value out of its type's range is refused at every read (0x09, as dispatch says), not once.
    obj.bind(1, 5, Binding(lambda: 70000))
    for _ in range(2):
        assert ask(router, 0x0E, request_path(0x70, 1, 5)).general_status == GeneralStatus.INVALID_ATTRIBUTE_VALUE


def test_attribute_readers_are_bounded() -> None:
    from cipstack.cip.router import MAX_ATTRIBUTE_READERS

    router = MessageRouter()
    spec = ClassSpec(0x70, "Many", instance_attributes=tuple(
        AttributeSpec(attribute, f"A{attribute}", UINT, default=attribute) for attribute in range(1, 256)))
    obj = CipObject(spec)
    for instance in range(1, 256):
        obj.add_instance(instance)
    router.register(obj)
    context = RequestContext(router)
    for instance in range(1, 256):
        for attribute in range(1, 256):
            raw = bytes((0x0E, 0x03, 0x20, 0x70, 0x24, instance, 0x30, attribute))
            assert router.handle(raw, context) == b"\x8e\x00\x00\x00" + struct.pack("<H", attribute)
    assert len(router._readers) == MAX_ATTRIBUTE_READERS  # internals: the router's own cache, seen nowhere else


def test_a_failing_read_is_read_once(router: MessageRouter, caplog: pytest.LogCaptureFixture) -> None:
    """A read may have an effect (a counter, a latch that clears): a Get_Attribute_Single reads its
    attribute once, whether the read succeeds, fails with a CIP status or fails with a bug, and the
    failure is counted and answered as dispatch answers it."""
    obj = router[0x70]
    reads: list[str] = []

    def read(outcome: str) -> int:
        reads.append(outcome)
        if outcome == "bug":
            raise RuntimeError("boom")
        if outcome == "state":
            raise CipError(GeneralStatus.OBJECT_STATE_CONFLICT)
        return 9

    for outcome, status in (("ok", 0), ("state", GeneralStatus.OBJECT_STATE_CONFLICT),
                            ("bug", GeneralStatus.VENDOR_SPECIFIC), ("ok", 0)):
        obj.bind(1, 5, Binding(lambda o=outcome: read(o)))
        before = dict(router.status_counts)
        for _ in range(2):  # the first through a new reader, the second through the kept one
            reads.clear()
            assert ask(router, 0x0E, request_path(0x70, 1, 5)).general_status == status
            assert reads == [outcome]
        assert router.status_counts[status] == before.get(status, 0) + 2
        assert router.reply_counts[0x0E << 8 | status] >= 2
    assert "internal error serving service 0x0E" in caplog.text
