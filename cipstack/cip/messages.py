"""Service codes and the message-router request/response codecs."""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple

from ..errors import BadRequest
from .status import CipError, GeneralStatus, describe_status


class Service(IntEnum):
    GET_ATTRIBUTES_ALL = 0x01
    SET_ATTRIBUTES_ALL = 0x02
    GET_ATTRIBUTE_LIST = 0x03
    SET_ATTRIBUTE_LIST = 0x04
    RESET = 0x05
    START = 0x06
    STOP = 0x07
    CREATE = 0x08
    DELETE = 0x09
    MULTIPLE_SERVICE_PACKET = 0x0A
    APPLY_ATTRIBUTES = 0x0D
    GET_ATTRIBUTE_SINGLE = 0x0E
    SET_ATTRIBUTE_SINGLE = 0x10
    FIND_NEXT_OBJECT_INSTANCE = 0x11
    RESTORE = 0x15
    SAVE = 0x16
    NO_OPERATION = 0x17
    GET_MEMBER = 0x18
    SET_MEMBER = 0x19
    FORWARD_CLOSE = 0x4E
    UNCONNECTED_SEND = 0x52
    FORWARD_OPEN = 0x54
    GET_CONNECTION_OWNER = 0x5A
    LARGE_FORWARD_OPEN = 0x5B


REPLY_BIT = 0x80


class MessageRouterRequest(NamedTuple):
    """A message-router request: service code, request path (padded EPATH), request data."""

    service: int
    path: bytes
    data: bytes = b""

    def encode(self) -> bytes:
        if len(self.path) % 2:
            raise BadRequest("request path must be a whole number of words")
        return bytes((self.service, len(self.path) // 2)) + self.path + self.data

    @classmethod
    def decode(cls, raw: bytes) -> MessageRouterRequest:
        """Split a request; a request too short for its path size answers 0x04/0x13 upstream."""
        if len(raw) < 2:
            raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message="request shorter than its header")
        service = raw[0]
        if service & REPLY_BIT:
            raise CipError(GeneralStatus.SERVICE_NOT_SUPPORTED, message="a reply is not a request")
        end = 2 + 2 * raw[1]
        if end > len(raw):
            raise CipError(GeneralStatus.PATH_SIZE_INVALID, message="path size runs past the request")
        return cls(service, bytes(raw[2:end]), bytes(raw[end:]))


class MessageRouterResponse(NamedTuple):
    """A message-router reply: the service it answers (reply bit clear), general and extended
    status, reply data."""

    service: int
    general_status: int = 0
    extended_status: tuple[int, ...] = ()
    data: bytes = b""

    @property
    def ok(self) -> bool:
        return self.general_status == GeneralStatus.SUCCESS

    def encode(self) -> bytes:
        head = bytes((self.service | REPLY_BIT, 0, self.general_status, len(self.extended_status)))
        ext = b"".join(w.to_bytes(2, "little") for w in self.extended_status)
        return head + ext + self.data

    @classmethod
    def decode(cls, raw: bytes) -> MessageRouterResponse:
        if len(raw) < 4:
            raise BadRequest("reply shorter than the 4-byte message-router reply header")
        if not raw[0] & REPLY_BIT:
            raise BadRequest(f"service 0x{raw[0]:02X} is not a reply")
        ext_words = raw[3]
        end = 4 + 2 * ext_words
        if end > len(raw):
            raise BadRequest("additional status runs past the reply")
        ext = tuple(int.from_bytes(raw[i:i + 2], "little") for i in range(4, end, 2))
        return cls(raw[0] & 0x7F, raw[2], ext, bytes(raw[end:]))

    @classmethod
    def from_error(cls, service: int, error: CipError) -> MessageRouterResponse:
        return cls(service, error.general, error.extended, error.data)

    def raise_for_status(self) -> MessageRouterResponse:
        """Raise ``CipError`` unless the reply is a success (0x06 partial transfer is data)."""
        if self.general_status not in (GeneralStatus.SUCCESS, GeneralStatus.PARTIAL_TRANSFER):
            raise CipError(self.general_status, self.extended_status,
                           message=f"service 0x{self.service:02X}", data=self.data)
        return self

    def __str__(self) -> str:
        return f"service 0x{self.service:02X} reply {describe_status(self.general_status, self.extended_status)}"
