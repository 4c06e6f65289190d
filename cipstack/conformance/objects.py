"""Group 3: the objects every EtherNet/IP adapter has: Identity, Message Router, Connection Manager,
TCP/IP Interface, Ethernet Link (CIP Vol. 1 chapter 5, Vol. 2 chapter 5; Wireshark packet-cip.c
and packet-enip.c decode each attribute with the type used here)."""

from __future__ import annotations

import contextlib
import struct
import time
from collections.abc import Callable

from ..cip.epath import request_path
from .model import CheckSpec, Outcome, Verdict
from .registry import Context, check, outcome, restore_later
from .wire import Probe, TargetUnreachable

GET_SINGLE, GET_ALL, SET_SINGLE, RESET = 0x0E, 0x01, 0x10, 0x05

#: Checks the size (and shape) of an attribute value; returns a problem or None.
Shape = Callable[[bytes], "str | None"]


def fixed(size: int, type_name: str) -> Shape:
    return lambda data: None if len(data) == size else f"{len(data)} bytes, {type_name} is {size}"


def short_string(data: bytes) -> str | None:
    if not data or len(data) != 1 + data[0]:
        return f"{len(data)} bytes, a SHORT_STRING of length {data[0] if data else '?'} is {1 + data[0] if data else 1}"
    return None


def string_at(data: bytes, offset: int) -> str | None:
    """A STRING (UINT length, characters) at ``offset``, padded to an even length (Vol. 2 §5-3)."""
    if len(data) < offset + 2:
        return f"{len(data)} bytes, cut short before the STRING length"
    (length,) = struct.unpack_from("<H", data, offset)
    end = offset + 2 + length
    if len(data) not in (end, end + (length & 1)):
        return f"{len(data)} bytes, a STRING of length {length} at offset {offset} makes {end}"
    return None


def padded_epath(data: bytes) -> str | None:
    if len(data) < 2:
        return f"{len(data)} bytes, a path size UINT is 2"
    (words,) = struct.unpack_from("<H", data)
    return None if len(data) == 2 + 2 * words else f"{len(data)} bytes, path size {words} words makes {2 + 2 * words}"


IDENTITY: dict[int, tuple[str, Shape]] = {
    1: ("vendor ID", fixed(2, "UINT")), 2: ("device type", fixed(2, "UINT")), 3: ("product code", fixed(2, "UINT")),
    4: ("revision", fixed(2, "USINT major + USINT minor")), 5: ("status", fixed(2, "WORD")),
    6: ("serial number", fixed(4, "UDINT")), 7: ("product name", short_string),
}
TCP_IP: dict[int, tuple[str, Shape]] = {
    1: ("status", fixed(4, "DWORD")), 2: ("configuration capability", fixed(4, "DWORD")),
    3: ("configuration control", fixed(4, "DWORD")), 4: ("physical link object", padded_epath),
    5: ("interface configuration", lambda d: string_at(d, 20)), 6: ("host name", lambda d: string_at(d, 0)),
    13: ("encapsulation inactivity timeout", fixed(2, "UINT")),
}
ETHERNET_LINK: dict[int, tuple[str, Shape]] = {
    1: ("interface speed", fixed(4, "UDINT")), 2: ("interface flags", fixed(4, "DWORD")),
    3: ("physical address", fixed(6, "6 x USINT")),
}


def read_attributes(probe: Probe, class_id: int, attributes: dict[int, tuple[str, Shape]], shapes: bool = True
                    ) -> tuple[dict[int, bytes], list[str]]:
    """Each attribute's value, and what is wrong: an error status, or (with ``shapes``) a size its
    type does not have. Checks that compare values read them without ``shapes``: a wrong size is
    ``objects.identity.attributes``'s finding, not theirs."""
    values, problems = {}, []
    for attribute, (name, shape) in attributes.items():
        reply = probe.request(GET_SINGLE, request_path(class_id, 1, attribute))
        if reply.status != 0:
            problems.append(f"{attribute} {name}: {reply.describe()}")
            _judged(probe)
            continue
        values[attribute] = reply.data
        problem = shape(reply.data) if shapes else None
        if problem:
            problems.append(f"{attribute} {name}: {problem}")
            _judged(probe)
    return values, problems


def _judged(probe: Probe) -> None:
    """Mark the last exchange as the one a finding is about (reports show those first)."""
    if probe.exchanges:
        probe.exchanges[-1].judged = True


def number(data: bytes) -> int:
    return int.from_bytes(data, "little")


def _attributes_check(ctx: Context, spec: CheckSpec, class_id: int,
                      attributes: dict[int, tuple[str, Shape]]) -> Outcome:
    probe = ctx.probe()
    _, problems = read_attributes(probe, class_id, attributes)
    return outcome(spec, not problems, "; ".join(problems) or f"attributes {', '.join(map(str, attributes))} as "
                   "specified", probe.exchanges)


@check("objects.identity.attributes", "Identity (0x01) instance 1, attributes 1-7",
       "each readable with Get_Attribute_Single, with its type's size: UINT, UINT, UINT, 2 x USINT, WORD, UDINT, "
       "SHORT_STRING", "CIP Vol. 1 §5-2.2 (Identity instance attributes); Wireshark packet-cip.c")
def identity_attributes(ctx: Context, spec: CheckSpec) -> Outcome:
    return _attributes_check(ctx, spec, 0x01, IDENTITY)


@check("objects.identity.status", "Identity attribute 5 (status)",
       "reserved bits 1 and 3 are 0", "CIP Vol. 1 §5-2.2.1.5 (Identity status word); Wireshark packet-cip.c "
       "(cip_id_status)")
def identity_status(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    reply = probe.request(GET_SINGLE, request_path(0x01, 1, 5))
    if reply.status != 0 or len(reply.data) != 2:
        return outcome(spec, False, reply.describe(), probe.exchanges)
    (status,) = struct.unpack("<H", reply.data)
    return outcome(spec, not status & 0x000A, f"status 0x{status:04X}", probe.exchanges)


@check("objects.identity.list_identity", "Identity attributes against ListIdentity",
       "vendor, device type, product code, revision, serial number and product name read from the Identity object "
       "equal what ListIdentity reports", "CIP Vol. 2 §2-4.3 (the ListIdentity item carries Identity attributes)")
def identity_matches_list_identity(ctx: Context, spec: CheckSpec) -> Outcome:
    if ctx.identity is None:
        return outcome(spec, Verdict.NOT_APPLICABLE, "ListIdentity gave no identity to compare with")
    probe = ctx.probe()
    values, problems = read_attributes(probe, 0x01, IDENTITY, shapes=False)
    if problems:
        return outcome(spec, False, "; ".join(problems), probe.exchanges)
    read = {
        "vendor_id": number(values[1]), "device_type": number(values[2]), "product_code": number(values[3]),
        "revision": {"major": values[4][:1] and values[4][0], "minor": values[4][1:2] and values[4][1]},
        "serial_number": number(values[6]), "product_name": values[7][1:].decode("latin-1"),
    }
    differ = [f"{key}: attribute {value!r}, ListIdentity {ctx.identity.get(key)!r}" for key, value in read.items()
              if ctx.identity.get(key) != value]
    return outcome(spec, not differ, "; ".join(differ) or "the same identity", probe.exchanges)


@check("objects.identity.get_attributes_all", "Get_Attributes_All of Identity instance 1",
       "attributes 1-7 in order, as Get_Attribute_Single reads them (more may follow); 0x08 if not supported",
       "CIP Vol. 1 §5-2.3 (Identity services); Wireshark packet-cip.c (dissect_cip_get_attribute_all_rsp)")
def identity_get_all(ctx: Context, spec: CheckSpec) -> Outcome:
    probe = ctx.probe()
    reply = probe.request(GET_ALL, request_path(0x01, 1))
    if reply.status == 0x08:
        return outcome(spec, Verdict.NOT_APPLICABLE, "Get_Attributes_All not supported (0x08)", probe.exchanges)
    if reply.status != 0:
        return outcome(spec, False, reply.describe(), probe.exchanges)
    values, problems = read_attributes(probe, 0x01, IDENTITY, shapes=False)
    if problems:
        return outcome(spec, False, "; ".join(problems), probe.exchanges)
    expected = b"".join(values[a] for a in range(1, 8))
    got = reply.data[:len(expected)]
    # The status word (attribute 5) may change between the two reads.
    status_at = sum(len(values[a]) for a in range(1, 5))
    status_end = status_at + len(values[5])
    same = got[:status_at] == expected[:status_at] and got[status_end:] == expected[status_end:]
    return outcome(spec, same, f"{len(reply.data)} bytes; attributes 1-7 {'match' if same else 'differ: ' + got.hex()}",
                   probe.exchanges)


@check("objects.identity.reset", "Identity Reset type 0 (only with --allow-reset)",
       "status 0, then the device accepts a connection and a session again within 30 s",
       "CIP Vol. 1 §5-2.3.1 (Reset service, type 0: as a power cycle)")
def identity_reset(ctx: Context, spec: CheckSpec) -> Outcome:
    if not ctx.allow_reset:
        return outcome(spec, Verdict.NOT_RUN, "needs --allow-reset")
    probe = ctx.probe()
    reply = probe.request(RESET, request_path(0x01, 1), b"\x00")
    if reply.status != 0:
        return outcome(spec, False, reply.describe(), probe.exchanges)
    deadline = time.monotonic() + 30.0
    time.sleep(0.5)
    # A device that resets is away for a while on purpose: not silent (the runner asks after the check).
    with ctx.liveness.hold() if ctx.liveness is not None else contextlib.nullcontext():
        while time.monotonic() < deadline:
            try:
                ctx.probe()
                return outcome(spec, True, "reset accepted; the device came back", probe.exchanges)
            except TargetUnreachable:
                time.sleep(0.5)
    return outcome(spec, False, "reset accepted, but the device did not come back in 30 s", probe.exchanges)


def _object_present(ctx: Context, spec: CheckSpec, class_id: int) -> Outcome:
    probe = ctx.probe()
    reply = probe.request(GET_SINGLE, request_path(class_id, 1, 1))
    ok = reply.status is not None and reply.status not in (0x05, 0x16)
    return outcome(spec, ok, f"Get_Attribute_Single {class_id}/1/1: {reply.describe()}", probe.exchanges)


@check("objects.message_router", "Message Router (0x02) instance 1 exists",
       "Get_Attribute_Single 2/1/1 answers anything but 0x05/0x16 (the instance exists)",
       "CIP Vol. 1 §5-3 (Message Router object, required)")
def message_router(ctx: Context, spec: CheckSpec) -> Outcome:
    return _object_present(ctx, spec, 0x02)


@check("objects.connection_manager", "Connection Manager (0x06) instance 1 exists",
       "Get_Attribute_Single 6/1/1 answers anything but 0x05/0x16 (the instance exists)",
       "CIP Vol. 1 §3-5 (Connection Manager object, required)")
def connection_manager(ctx: Context, spec: CheckSpec) -> Outcome:
    return _object_present(ctx, spec, 0x06)


@check("objects.tcp_ip.attributes", "TCP/IP Interface (0xF5) instance 1, attributes 1-6 and 13",
       "each readable, with its type's size: DWORD x3, padded EPATH with its size, 4 x UDINT + STRING, STRING, UINT",
       "CIP Vol. 2 §5-3 (TCP/IP Interface object); Wireshark packet-enip.c (dissect_tcpip_*)")
def tcp_ip(ctx: Context, spec: CheckSpec) -> Outcome:
    return _attributes_check(ctx, spec, 0xF5, TCP_IP)


@check("objects.ethernet_link.attributes", "Ethernet Link (0xF6) instance 1, attributes 1-3",
       "each readable: UDINT speed, DWORD flags, 6-byte MAC address",
       "CIP Vol. 2 §5-4 (Ethernet Link object); Wireshark packet-enip.c")
def ethernet_link(ctx: Context, spec: CheckSpec) -> Outcome:
    return _attributes_check(ctx, spec, 0xF6, ETHERNET_LINK)


@check("objects.identity.set_read_only", "Set_Attribute_Single of Identity attribute 1 (only with --allow-writes)",
       "general status 0x0E (attribute not settable); 0x08 when Identity has no Set_Attribute_Single makes the "
       "check not applicable; the value it sends is the one the device reports",
       "CIP Vol. 1 Appendix B (0x0E); §5-2.2 (vendor ID is Get only)")
def set_read_only(ctx: Context, spec: CheckSpec) -> Outcome:
    if not ctx.allow_writes:
        return outcome(spec, Verdict.NOT_RUN, "needs --allow-writes")
    probe = ctx.probe()
    current = probe.request(GET_SINGLE, request_path(0x01, 1, 1))
    if current.status != 0:
        return outcome(spec, False, f"vendor ID not readable: {current.describe()}", probe.exchanges)
    reply = probe.request(SET_SINGLE, request_path(0x01, 1, 1), current.data)
    if reply.status == 0:
        # Taken (the check fails): it wrote the value it read, and the end of the run writes it back all the same.
        restore_later(ctx, request_path(0x01, 1, 1), current.data, "Identity vendor ID (1/1/1)")
    if reply.status == 0x08:
        # An Identity object with no settable attribute need not implement the service at all.
        return outcome(spec, Verdict.NOT_APPLICABLE, "Identity implements no Set_Attribute_Single (0x08)",
                       probe.exchanges)
    return outcome(spec, reply.status == 0x0E, f"set 1/1/1: {reply.describe()}", probe.exchanges)
