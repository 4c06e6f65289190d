"""Elementary types, EPATH and message-router codecs: round trips and the bytes of wire.md."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cipstack.cip import types as t
from cipstack.cip.epath import (
    DataSegment,
    ElectronicKey,
    LogicalSegment,
    LogicalType,
    PortSegment,
    decode_path,
    encode_path,
    parse_application_path,
    request_path,
)
from cipstack.cip.messages import MessageRouterRequest, MessageRouterResponse
from cipstack.cip.status import CipError, GeneralStatus

INTEGER_TYPES = [t.SINT, t.INT, t.DINT, t.LINT, t.USINT, t.UINT, t.UDINT, t.ULINT, t.BYTE, t.WORD, t.DWORD, t.LWORD]


@pytest.mark.parametrize("cip_type", INTEGER_TYPES, ids=lambda x: x.name)
@given(data=st.data())
def test_integer_round_trip(cip_type: t.IntegerType, data: st.DataObject) -> None:
    value = data.draw(st.integers(cip_type.minimum, cip_type.maximum))
    raw = cip_type.encode(value)
    assert len(raw) == cip_type.size
    assert cip_type.decode(raw) == value
    assert cip_type.encode(cip_type.decode(raw)) == raw
    # The construct codec agrees with the fast path.
    assert cip_type.construct.build(value) == raw
    assert cip_type.construct.parse(raw) == value


@pytest.mark.parametrize("cip_type", INTEGER_TYPES, ids=lambda x: x.name)
def test_integer_range_and_length_errors(cip_type: t.IntegerType) -> None:
    with pytest.raises(CipError) as exc:
        cip_type.encode(cip_type.maximum + 1)
    assert exc.value.general == GeneralStatus.INVALID_ATTRIBUTE_VALUE
    with pytest.raises(CipError) as exc:
        cip_type.decode(bytes(cip_type.size - 1))
    assert exc.value.general == GeneralStatus.NOT_ENOUGH_DATA
    with pytest.raises(CipError) as exc:
        cip_type.decode(bytes(cip_type.size + 1))
    assert exc.value.general == GeneralStatus.TOO_MUCH_DATA


def test_integer_bytes_are_little_endian() -> None:
    assert t.UINT.encode(0x1234) == b"\x34\x12"
    assert t.DINT.encode(-2) == b"\xfe\xff\xff\xff"
    assert t.UDINT.encode(0x10000064) == bytes.fromhex("64000010")
    assert t.INT.decode(b"\xdc\x05") == 1500


def test_bool() -> None:
    assert t.BOOL.encode(True) == b"\x01"
    assert t.BOOL.decode(b"\x05") == 1  # any non-zero byte reads as true
    with pytest.raises(CipError):
        t.BOOL.encode(2)
    assert t.BOOL.parse_text("true") == 1


@given(st.floats(allow_nan=False, width=32))
def test_real_round_trip(value: float) -> None:
    raw = t.REAL.encode(value)
    assert len(raw) == 4
    assert t.REAL.decode(raw) == value
    assert t.REAL.construct.parse(raw) == value


@given(st.floats(allow_nan=True))
def test_lreal_round_trip(value: float) -> None:
    raw = t.LREAL.encode(value)
    decoded = t.LREAL.decode(raw)
    assert (math.isnan(value) and math.isnan(decoded)) or decoded == value
    assert t.LREAL.encode(decoded) == raw


def test_real_overflow_refused() -> None:
    with pytest.raises(CipError) as exc:
        t.REAL.encode(1e300)
    assert exc.value.general == GeneralStatus.INVALID_ATTRIBUTE_VALUE


@given(st.text(alphabet=st.characters(max_codepoint=255), max_size=255))
def test_short_string_round_trip(text: str) -> None:
    raw = t.SHORT_STRING.encode(text)
    assert raw[0] == len(text)
    assert t.SHORT_STRING.decode(raw) == text
    assert t.SHORT_STRING.construct.build(text) == raw


@given(st.text(alphabet=st.characters(max_codepoint=255), max_size=600))
def test_string_round_trip(text: str) -> None:
    raw = t.STRING.encode(text)
    assert int.from_bytes(raw[:2], "little") == len(text)
    assert t.STRING.decode(raw) == text


def test_string_errors() -> None:
    assert t.SHORT_STRING.encode("CENT") == b"\x04CENT"
    with pytest.raises(CipError) as exc:
        t.SHORT_STRING.decode(b"\x05CENT")
    assert exc.value.general == GeneralStatus.NOT_ENOUGH_DATA
    with pytest.raises(CipError):
        t.SHORT_STRING.encode("x" * 256)
    with pytest.raises(CipError):
        t.SHORT_STRING.encode("\u20ac")


@pytest.mark.parametrize("cip_type", [t.SHORT_STRING, t.STRING])
def test_string_encoding_of_the_same_value_again(cip_type: t.StringType) -> None:
    """A string type keeps the last value it encoded: the same object gives the same bytes again, and
    what it keeps is never taken for another value (None, a mutable bytearray, a bad value)."""
    for _ in range(2):
        with pytest.raises(CipError):
            cip_type.encode(None)
    name = "ACG-ET2"
    first = cip_type.encode(name)
    assert cip_type.encode(name) is first and cip_type.decode(first) == name
    assert cip_type.decode(cip_type.encode("other")) == "other"
    buffer = bytearray(b"ab")
    with pytest.raises(CipError):
        cip_type.encode(buffer)  # not a string type's value: refused every time
    with pytest.raises(CipError):
        cip_type.encode("\u20ac")
    assert cip_type.decode(cip_type.encode(name)) == name


@given(st.integers(0, 255), st.integers(0, 255))
def test_struct_round_trip(major: int, minor: int) -> None:
    value = {"major": major, "minor": minor}
    raw = t.REVISION.encode(value)
    assert raw == bytes((major, minor))
    assert t.REVISION.decode(raw) == value
    parsed = t.REVISION.construct.parse(raw)
    assert (parsed.major, parsed.minor) == (major, minor)
    assert t.REVISION.construct.build(value) == raw


@given(st.lists(st.integers(0, 0xFFFF), max_size=20))
def test_array_round_trip(items: list[int]) -> None:
    greedy = t.ArrayType(t.UINT)
    assert greedy.decode(greedy.encode(items)) == items
    fixed = t.ArrayType(t.UINT, len(items))
    assert fixed.decode(fixed.encode(items)) == items


def test_type_lookup() -> None:
    assert t.type_by_name("uint") is t.UINT
    assert t.BY_CODE[0xDA] is t.SHORT_STRING
    with pytest.raises(ValueError):
        t.type_by_name("NOPE")


# -- EPATH -------------------------------------------------------------------------------------------
def test_epath_bytes_of_wire_md() -> None:
    assert request_path(0x01, 1, 7) == bytes.fromhex("20 01 24 01 30 07")
    assert request_path(0x0300, 1) == bytes.fromhex("21 00 00 03 24 01")
    assert encode_path([LogicalSegment(LogicalType.INSTANCE_ID, 0x1234)]) == bytes.fromhex("25 00 34 12")
    assert encode_path([LogicalSegment(LogicalType.ATTRIBUTE_ID, 0x100)]) == bytes.fromhex("31 00 00 01")
    assert encode_path([LogicalSegment(LogicalType.CONNECTION_POINT, 0x70)]) == bytes.fromhex("2C 70")
    assert encode_path([LogicalSegment(LogicalType.MEMBER_ID, 3)]) == bytes.fromhex("28 03")
    assert encode_path([LogicalSegment(LogicalType.INSTANCE_ID, 0x12345678)]) == bytes.fromhex("26 00 78 56 34 12")
    # Port 1 (backplane), slot 0; a long link address sets bit 4 and is padded to even length.
    assert encode_path([PortSegment(1, b"\x00")]) == bytes.fromhex("01 00")
    assert encode_path([PortSegment(2, b"10.0.0.1")]) == bytes.fromhex("12 08") + b"10.0.0.1"
    assert encode_path([PortSegment(2, b"1.2.3.4")]) == bytes.fromhex("12 07") + b"1.2.3.4" + b"\x00"
    assert encode_path([PortSegment(20, b"\x05")]) == bytes.fromhex("0F 14 00 05")
    key = ElectronicKey(259, 2, 100, 1, 1, compatibility=True)
    assert encode_path([key]) == bytes.fromhex("34 04 03 01 02 00 64 00 81 01")
    assert encode_path([DataSegment(b"\x01\x02\x03\x04")]) == bytes.fromhex("80 02 01 02 03 04")


def test_epath_packed_form() -> None:
    seg = [LogicalSegment(LogicalType.CLASS_ID, 0x1234)]
    assert encode_path(seg, padded=False) == bytes.fromhex("21 34 12")
    assert decode_path(bytes.fromhex("21 34 12"), padded=False) == [LogicalSegment(LogicalType.CLASS_ID, 0x1234, 16)]
    assert encode_path([PortSegment(2, b"1.2.3.4")], padded=False) == bytes.fromhex("12 07") + b"1.2.3.4"


logical = st.builds(LogicalSegment, st.sampled_from(list(LogicalType)), st.integers(0, 0xFF), st.just(8)) | st.builds(
    LogicalSegment, st.sampled_from(list(LogicalType)), st.integers(0, 0xFFFF), st.just(16)) | st.builds(
    LogicalSegment, st.sampled_from(list(LogicalType)), st.integers(0, 0xFFFFFFFF), st.just(32))
ports = st.builds(PortSegment, st.integers(1, 0xFFFF), st.binary(min_size=1, max_size=40))
keys = st.builds(ElectronicKey, st.integers(0, 0xFFFF), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF),
                 st.integers(0, 0x7F), st.integers(0, 0xFF), st.booleans())
datas = st.builds(DataSegment, st.binary(max_size=40).filter(lambda b: len(b) % 2 == 0))
segments = st.lists(logical | ports | keys | datas, max_size=8)


@given(segments, st.booleans())
def test_epath_round_trip(path: list, padded: bool) -> None:
    raw = encode_path(path, padded)
    if padded:
        assert len(raw) % 2 == 0
    assert decode_path(raw, padded) == path
    assert encode_path(decode_path(raw, padded), padded) == raw


@given(st.binary(max_size=30))
def test_epath_decode_never_crashes(raw: bytes) -> None:
    try:
        path = decode_path(raw)
    except CipError as exc:
        assert exc.general == GeneralStatus.PATH_SEGMENT_ERROR
    else:
        # Whatever decodes re-encodes to bytes that decode to the same segments.
        assert decode_path(encode_path(path)) == path


@pytest.mark.parametrize("raw", ["21 00 01", "25 00 01", "34 04 01 00", "12 08 31", "80 03 00 00", "E0", "26 00 01 00",
                                 "25 01 01 00"])
def test_epath_malformed_is_path_segment_error(raw: str) -> None:
    with pytest.raises(CipError) as exc:
        decode_path(bytes.fromhex(raw))
    assert exc.value.general == GeneralStatus.PATH_SEGMENT_ERROR


def test_application_path() -> None:
    assert parse_application_path(bytes.fromhex("20 01 24 01 30 07")).attribute == 7
    path = parse_application_path(bytes.fromhex("21 00 64 00 25 00 00 01 30 05"))
    assert (path.class_id, path.instance, path.attribute) == (0x64, 0x100, 5)
    assert parse_application_path(bytes.fromhex("20 02")).instance is None
    for bad in ("24 01 20 01", "20 01 20 01", "", "01 00 20 01"):
        with pytest.raises(CipError) as exc:
            parse_application_path(bytes.fromhex(bad))
        assert exc.value.general == GeneralStatus.PATH_SEGMENT_ERROR


# -- message router codecs -----------------------------------------------------------------------------
def test_request_bytes() -> None:
    request = MessageRouterRequest(0x0E, request_path(1, 1, 7))
    assert request.encode() == bytes.fromhex("0E 03 20 01 24 01 30 07")
    assert MessageRouterRequest.decode(request.encode()) == request


def test_response_bytes() -> None:
    ok = MessageRouterResponse(0x0E, 0, (), b"\x04CENT")
    assert ok.encode() == bytes.fromhex("8E 00 00 00 04") + b"CENT"
    failed = MessageRouterResponse(0x54, 0x01, (0x0113,))
    assert failed.encode() == bytes.fromhex("D4 00 01 01 13 01")
    assert MessageRouterResponse.decode(failed.encode()) == failed
    with pytest.raises(CipError) as exc:
        failed.raise_for_status()
    assert exc.value.extended == (0x0113,)
    assert "out of connections" in str(exc.value)


@given(st.integers(0, 0x7F), st.binary(max_size=20).filter(lambda b: len(b) % 2 == 0), st.binary(max_size=30))
def test_request_round_trip(service: int, path: bytes, data: bytes) -> None:
    request = MessageRouterRequest(service, path, data)
    assert MessageRouterRequest.decode(request.encode()) == request


@given(st.integers(0, 0x7F), st.integers(0, 255), st.lists(st.integers(0, 0xFFFF), max_size=4), st.binary(max_size=30))
def test_response_round_trip(service: int, status: int, ext: list[int], data: bytes) -> None:
    response = MessageRouterResponse(service, status, tuple(ext), data)
    assert MessageRouterResponse.decode(response.encode()) == response


def test_request_with_path_past_end() -> None:
    with pytest.raises(CipError) as exc:
        MessageRouterRequest.decode(bytes.fromhex("0E 04 20 01 24 01"))
    assert exc.value.general == GeneralStatus.PATH_SIZE_INVALID
