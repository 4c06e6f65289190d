"""Why a request was answered 0x15 (too much data), for the target's log: a strict device refuses
bytes a service does not take, and a client author sees only "Too much data". The most common
cause in the field is a client that appends the route path of an Unconnected_Send (its size in
words, a reserved byte, port segments) to a request it sends to the device itself: pycomm3's
``CIPDriver.generic_message`` does so unless ``route_path=False``."""

from __future__ import annotations

from ...cip.epath import PortSegment, decode_path, parse_application_path
from ...cip.messages import MessageRouterRequest, Service
from ...cip.status import CipError, GeneralStatus

#: Services whose request carries no data after its path: whatever follows is trailing.
_NO_DATA = frozenset({Service.GET_ATTRIBUTE_SINGLE, Service.GET_ATTRIBUTES_ALL})
#: The longest route path looked for at a request's end, in 16-bit words (a few hops).
_MAX_ROUTE_WORDS = 8


#: 0x15 as a plain int: compared on every explicit reply, where an enum member's lookup costs more.
_TOO_MUCH_DATA = int(GeneralStatus.TOO_MUCH_DATA)


def is_too_much_data(reply: bytes) -> bool:
    """The encoded message-router reply answers 0x15 (the general status is its third byte)."""
    return len(reply) > 2 and reply[2] == _TOO_MUCH_DATA


def route_path_at_end(request: bytes) -> tuple[list[PortSegment], bytes] | None:
    """The route path (size in words, reserved byte 0, padded port segments) that ``request`` ends
    with: its port segments and its bytes; or None. An empty one (``00 00``) is what pycomm3 appends
    for a device addressed by its IP address alone."""
    for words in range(0, _MAX_ROUTE_WORDS + 1):
        size = 2 + 2 * words
        if len(request) < size + 2:   # a request keeps at least its service and path size
            return None
        tail = request[-size:]
        if tail[0] != words or tail[1] != 0:
            continue
        try:
            segments = decode_path(tail[2:])
        except CipError:
            continue
        ports = [s for s in segments if isinstance(s, PortSegment)]
        if len(ports) == len(segments):
            return ports, bytes(tail)
    return None


def _hop(segment: PortSegment) -> str:
    link = segment.link
    shown = str(link[0]) if len(link) == 1 else link.decode("ascii", "replace")
    return f"port {segment.port}, link {shown}"


def too_much_data_hint(request: bytes) -> str:
    """One line on a request answered 0x15: the service and path, the bytes it carries beyond what the
    service takes where that is known, and the likely cause when they read as a route path."""
    try:
        decoded = MessageRouterRequest.decode(request)
        path = parse_application_path(decoded.path)
    except CipError:
        return f"a request of {len(request)} bytes answered 0x15 (too much data)"
    try:
        name = Service(decoded.service).name.title()
    except ValueError:
        name = f"service 0x{decoded.service:02X}"
    where = "".join(f"/{v}" for v in (path.instance, path.attribute) if v is not None)
    what = f"{name} 0x{path.class_id:02X}{where} answered 0x15 (too much data)"
    route = route_path_at_end(request)
    if route is not None:
        extra = route[1]
    elif decoded.service in _NO_DATA:
        extra = decoded.data
    else:
        return f"{what}: the request carries more data than the service takes"
    count = f"{len(extra)} byte" + ("s" if len(extra) != 1 else "")
    line = f"{what}: the request carries {count} after it ({extra.hex(' ')})"
    if route is not None:
        hops = "; ".join(_hop(s) for s in route[0]) or "empty"
        line += (f", which read as a route path ({hops}): a client that "
                 "appends the route path of an Unconnected_Send to a request sent to the device itself "
                 "(pycomm3's generic_message does, unless route_path=False)")
    return line
