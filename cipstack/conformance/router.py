"""Group 2: the message router and its error statuses (CIP Vol. 1 Appendix B, general status codes,
as Wireshark's packet-cip.c and OpENer's cipmessagerouter.c give them; wire.md "What a conformance
tool expects")."""

from __future__ import annotations

import struct

from ..cip.epath import request_path
from .model import CheckSpec, Code, Outcome, Verdict
from .registry import Context, check, outcome
from .wire import Probe, Reply

STATUS = "CIP Vol. 1 Appendix B (general status codes); Wireshark packet-cip.c"
GET_SINGLE = 0x0E
MULTIPLE = 0x0A
#: A class code in the range CIP reserves (0xC8-0xEF): no conformant device implements it.
RESERVED_CLASS = 0xE0
#: A service code CIP reserves for future use among the common services (0x15-0x31 reserved).
RESERVED_SERVICE = 0x1F
IDENTITY_NAME = request_path(0x01, 1, 7)


def _general(spec: CheckSpec, probe: Probe, reply: Reply, what: str) -> Outcome:
    """Judge a general status by the codes the check declares."""
    return outcome(spec, spec.verdict_for(reply.status), f"{what}: {reply.describe()}", probe.exchanges)


def general(value: int, meaning: str, reference: str = STATUS) -> Code:
    return Code(value, meaning, reference)


NOT_FOUND = (general(0x05, "path destination unknown", f"{STATUS}; wire.md"),
             general(0x16, "object does not exist", STATUS))


@check("router.unknown_service", "a reserved service code to the Identity object",
       "general status 0x08 (service not supported)", f"{STATUS}; OpENer cipcommon.c NotifyClass",
       codes=[general(0x08, "service not supported")])
def unknown_service(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    reply = probe.request(RESERVED_SERVICE, request_path(0x01, 1))
    return _general(spec, probe, reply, f"service 0x{RESERVED_SERVICE:02X} to 1/1")


@check("router.unknown_class", "Get_Attribute_Single of a class in the reserved range (0xE0)",
       "general status 0x05 (path destination unknown) or 0x16 (object does not exist)",
       f"{STATUS}; wire.md (an unknown class answers 0x05)", codes=NOT_FOUND)
def unknown_class(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    reply = probe.request(GET_SINGLE, request_path(RESERVED_CLASS, 1, 1))
    return _general(spec, probe, reply, "class 0xE0")


@check("router.unknown_instance", "Get_Attribute_Single of Identity instance 0xFE",
       "general status 0x05 (path destination unknown) or 0x16 (object does not exist)", STATUS, codes=NOT_FOUND)
def unknown_instance(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    reply = probe.request(GET_SINGLE, request_path(0x01, 0xFE, 1))
    return _general(spec, probe, reply, "instance 1/0xFE")


@check("router.unknown_attribute", "Get_Attribute_Single of Identity attribute 0xFE",
       "general status 0x14 (attribute not supported)", f"{STATUS}; OpENer cipcommon.c GetAttributeSingle",
       codes=[general(0x14, "attribute not supported")])
def unknown_attribute(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    reply = probe.request(GET_SINGLE, request_path(0x01, 1, 0xFE))
    return _general(spec, probe, reply, "attribute 1/1/0xFE")


@check("router.too_much_data", "Get_Attribute_Single of Identity attribute 1 with 2 bytes after the path",
       "general status 0x15 (too much data): trailing bytes after a complete request",
       f"{STATUS}; wire.md (trailing bytes are too much data)", codes=[general(0x15, "too much data")])
def too_much_data(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    reply = probe.request(GET_SINGLE, request_path(0x01, 1, 1), b"\x00\x00")
    return _general(spec, probe, reply, "1/1/1 + 00 00")


@check("router.not_enough_data", "Forward_Open with its first 10 bytes only",
       "general status 0x13 (not enough data)", f"{STATUS}; CIP Vol. 1 §3-5.5.2 Forward_Open request",
       codes=[general(0x13, "not enough data")])
def not_enough_data(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    reply = probe.request(0x54, request_path(0x06, 1), bytes((0x0A, 0x0E)) + struct.pack("<II", 0, 0x1234))
    return _general(spec, probe, reply, "Forward_Open cut after 10 bytes")


@check("router.bad_path", "a request whose path holds a reserved segment type (0xE0)",
       "general status 0x04 (path segment error)", f"{STATUS}; CIP Vol. 1 Appendix C (segment types)",
       codes=[general(0x04, "path segment error", f"{STATUS}; CIP Vol. 1 Appendix C")])
def bad_path(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    reply = probe.request(GET_SINGLE, bytes((0xE0, 0x01, 0x24, 0x01)))
    return _general(spec, probe, reply, "path E0 01 24 01")


def _msp(requests: list[bytes]) -> bytes:
    """Multiple_Service_Packet data: count, offsets (from the count), the requests."""
    offsets, position = [], 2 + 2 * len(requests)
    for request in requests:
        offsets.append(position)
        position += len(request)
    return struct.pack(f"<H{len(requests)}H", len(requests), *offsets) + b"".join(requests)


def _msp_members(data: bytes) -> list[bytes] | None:
    try:
        (count,) = struct.unpack_from("<H", data)
        offsets = list(struct.unpack_from(f"<{count}H", data, 2))
    except struct.error:
        return None
    ends = [*offsets[1:], len(data)]
    if any(not 2 + 2 * count <= start <= end <= len(data) for start, end in zip(offsets, ends, strict=True)):
        return None
    return [data[start:end] for start, end in zip(offsets, ends, strict=True)]


def _hexes(statuses: list[int | None] | None) -> str:
    return "none" if statuses is None else "[" + ", ".join("?" if s is None else f"0x{s:02X}" for s in statuses) + "]"


def _member_status(member: bytes) -> int | None:
    return member[2] if len(member) >= 4 and member[0] & 0x80 else None


GOOD_MEMBERS = [bytes((GET_SINGLE, 3)) + request_path(0x01, 1, 1), bytes((GET_SINGLE, 3)) + IDENTITY_NAME]


@check("router.multiple_service.good", "Multiple_Service_Packet of two good Get_Attribute_Single requests",
       "general status 0; two replies, each with status 0",
       "CIP Vol. 1 Appendix A (Multiple_Service_Packet, 0x0A); Wireshark packet-cip.c (dissect_cip_multiple_service)")
def multiple_service_good(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    reply = probe.request(MULTIPLE, request_path(0x02, 1), _msp(GOOD_MEMBERS))
    if reply.status == 0x08:
        return outcome(spec, Verdict.NOT_APPLICABLE, "Multiple_Service_Packet not supported (0x08)", probe.exchanges)
    members = _msp_members(reply.data) if reply.status == 0 else None
    statuses = [_member_status(m) for m in members] if members is not None else None
    ok = statuses == [0, 0]
    return outcome(spec, ok, f"{reply.describe()}; member statuses {_hexes(statuses)}", probe.exchanges)


@check("router.multiple_service.bad_member", "Multiple_Service_Packet of a good request and one for attribute 0xFE",
       "general status 0x1E (embedded service error); the good member's status 0, the other's an error status "
       "(which one is router.unknown_attribute's concern)",
       "CIP Vol. 1 Appendix A (Multiple_Service_Packet) and Appendix B (0x1E)",
       codes=[general(0x1E, "embedded service error", "CIP Vol. 1 Appendix B")])
def multiple_service_bad(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    members_sent = [GOOD_MEMBERS[0], bytes((GET_SINGLE, 3)) + request_path(0x01, 1, 0xFE)]
    reply = probe.request(MULTIPLE, request_path(0x02, 1), _msp(members_sent))
    if reply.status == 0x08:
        return outcome(spec, Verdict.NOT_APPLICABLE, "Multiple_Service_Packet not supported (0x08)", probe.exchanges)
    members = _msp_members(reply.data) if reply.response is not None else None
    statuses = [_member_status(m) for m in members] if members is not None else None
    ok = (spec.verdict_for(reply.status) is Verdict.PASS and statuses is not None and len(statuses) == 2
          and statuses[0] == 0 and bool(statuses[1]))
    return outcome(spec, ok, f"{reply.describe()}; member statuses {_hexes(statuses)}", probe.exchanges)
