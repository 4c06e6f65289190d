"""CompoNet explicit messages as a CompoNet master sends them (appendix E).

The master carries an explicit request to a slave in the frame of the FINS "Explicit Message
Send" command of the CS/CJ CompoNet Master Units (section 4-6, command 2802): command code,
destination node address, service code, class ID, instance ID, then the attribute ID and the
data. The response repeats the command code, gives an end code and the number of bytes that
follow, the source node address, the response service code and the data. Header fields are
big-endian (FINS); the data is CIP-encoded, little-endian ("Please note the swapping of the data
following CIP data type encoding", sections 4-6-2 and E-2-2)::

    request:  28 02 | node (2) | service | class (2) | instance (2) | [attribute] | data
    response: 28 02 | end code (2) | byte count (2) | node (2) | service | data
    error:    28 02 | end code (2) | byte count (2) | node (2) | 94 | general status | additional status

The node address of a word mixed slave such as the option board is 10@@h, @@ the node address
0-3Fh (section E-1). Services 0Eh/10h/05h answer 8Eh/90h/85h (Table E-1); an error answers 94h
with the two-byte code of Table E-5 (general status, then the additional code, FFh for none).
Get/Set_Attribute_Single carry the attribute ID; other services (Reset) carry none.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from ..cip.epath import request_path
from ..cip.messages import REPLY_BIT, MessageRouterRequest, Service
from ..cip.router import MessageRouter, RequestContext
from ..errors import ProtocolError

#: FINS command code of Explicit Message Send through a CompoNet master (section 4-6).
COMMAND_CODE = 0x2802
#: Node address prefix of a word mixed slave unit: 10@@h (section E-1).
WORD_MIXED = 0x1000
MAX_NODE = 0x3F
#: Response service code of an explicit message error (Table E-5 format).
ERROR_SERVICE = 0x94
#: Additional code meaning "no additional information".
NO_ADDITIONAL = 0xFF
#: Services whose request carries an attribute ID.
ATTRIBUTE_SERVICES = frozenset({Service.GET_ATTRIBUTE_SINGLE, Service.SET_ATTRIBUTE_SINGLE})
#: End code of a normal completion.
NORMAL_END = 0x0000

_REQUEST = struct.Struct(">HHBHH")
_RESPONSE = struct.Struct(">HHHHB")


class FrameError(ProtocolError, ValueError):
    """A byte string that is not an explicit-message frame of this format."""


def word_mixed_address(node: int) -> int:
    """10@@h for node ``@@`` (0-63)."""
    if not 0 <= node <= MAX_NODE:
        raise FrameError(f"node address {node} outside 0-63")
    return WORD_MIXED | node


def node_of(address: int) -> int:
    if address & 0xFF00 != WORD_MIXED or address & 0xFF > MAX_NODE:
        raise FrameError(f"{address:04X}h is not the node address of a word mixed slave (10@@h)")
    return address & 0xFF


@dataclass(frozen=True)
class ExplicitRequest:
    node: int
    service: int
    class_id: int
    instance: int
    attribute: int | None = None
    data: bytes = b""

    def encode(self) -> bytes:
        if (self.attribute is not None) != (self.service in ATTRIBUTE_SERVICES):
            raise FrameError(f"service {self.service:02X}h " + (
                "needs an attribute ID" if self.service in ATTRIBUTE_SERVICES else "takes no attribute ID"))
        head = _REQUEST.pack(COMMAND_CODE, word_mixed_address(self.node), self.service, self.class_id, self.instance)
        attribute = bytes([self.attribute]) if self.attribute is not None else b""
        return head + attribute + self.data

    @classmethod
    def decode(cls, raw: bytes) -> ExplicitRequest:
        if len(raw) < _REQUEST.size:
            raise FrameError("explicit request shorter than its header")
        command, address, service, class_id, instance = _REQUEST.unpack_from(raw)
        if command != COMMAND_CODE:
            raise FrameError(f"command {command:04X}h is not Explicit Message Send")
        offset = _REQUEST.size
        attribute = None
        if service in ATTRIBUTE_SERVICES:
            if len(raw) <= offset:
                raise FrameError("attribute ID missing")
            attribute = raw[offset]
            offset += 1
        return cls(node_of(address), service, class_id, instance, attribute, bytes(raw[offset:]))

    def message_router_request(self) -> MessageRouterRequest:
        """The CIP request the slave's message router serves."""
        return MessageRouterRequest(self.service, request_path(self.class_id, self.instance, self.attribute),
                                    self.data)


@dataclass(frozen=True)
class ExplicitResponse:
    node: int
    #: Response service code: request service | 80h, or 94h for an error.
    service: int
    data: bytes = b""
    end_code: int = NORMAL_END

    @property
    def is_error(self) -> bool:
        return self.service == ERROR_SERVICE

    @property
    def error_code(self) -> tuple[int, int]:
        """(general status, additional code) of an error response (Table E-5)."""
        if not self.is_error or len(self.data) != 2:
            raise FrameError("not an error response")
        return self.data[0], self.data[1]

    @classmethod
    def error(cls, node: int, general: int, additional: int = NO_ADDITIONAL) -> ExplicitResponse:
        return cls(node, ERROR_SERVICE, bytes((general, additional)))

    def encode(self) -> bytes:
        count = 3 + len(self.data)   # source node address, service code, data
        return _RESPONSE.pack(COMMAND_CODE, self.end_code, count, word_mixed_address(self.node), self.service) \
            + self.data

    @classmethod
    def decode(cls, raw: bytes) -> ExplicitResponse:
        if len(raw) < _RESPONSE.size:
            raise FrameError("explicit response shorter than its header")
        command, end_code, count, address, service = _RESPONSE.unpack_from(raw)
        if command != COMMAND_CODE:
            raise FrameError(f"command {command:04X}h is not Explicit Message Send")
        if count != len(raw) - 6:
            raise FrameError(f"byte count {count} does not match the {len(raw) - 6} bytes received")
        response = cls(node_of(address), service, bytes(raw[_RESPONSE.size:]), end_code)
        if response.is_error:
            response.error_code  # noqa: B018 - checks the two-byte error code
        elif not service & REPLY_BIT:
            raise FrameError(f"response service {service:02X}h lacks the reply bit")
        return response


def serve_explicit(router: MessageRouter, request: ExplicitRequest, context: RequestContext) -> ExplicitResponse:
    """The slave side: hand the request to the slave's message router and frame its answer."""
    reply = router.dispatch(request.message_router_request().encode(), context)
    if reply.ok:
        return ExplicitResponse(request.node, request.service | REPLY_BIT, reply.data)
    additional = reply.extended_status[0] & 0xFF if reply.extended_status else NO_ADDITIONAL
    return ExplicitResponse.error(request.node, reply.general_status, additional)


__all__ = [
    "COMMAND_CODE", "ERROR_SERVICE", "NO_ADDITIONAL", "WORD_MIXED", "ExplicitRequest", "ExplicitResponse",
    "FrameError", "node_of", "serve_explicit", "word_mixed_address",
]
