"""What an originator makes of a reply it cannot use: a non-zero encapsulation status, or bytes its
decoders refuse. Either is one line for the user, never a traceback."""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import TypeVar

from ...cip.status import CipError
from ...errors import ProtocolError
from ..wire.encapsulation import EncapsulationError, EncapsulationStatus

T = TypeVar("T")


class EncapsulationStatusError(ProtocolError):
    """A reply carried a non-zero encapsulation status."""

    def __init__(self, command: int, status: int) -> None:
        self.command = command
        self.status = status
        try:
            name = EncapsulationStatus(status).name.lower().replace("_", " ")
        except ValueError:
            name = "unknown"
        text = f"encapsulation command 0x{command:04X} failed with status 0x{status:04X} ({name})"
        if command == 0x0065 and status == 0x0002:
            # RegisterSession answered "insufficient memory": what targets answer when every session is taken.
            text += ": the target's session table is full (its session limit is reached)"
        super().__init__(text)


class MalformedReplyError(ProtocolError, ConnectionError):
    """A reply that cannot be decoded: one line for the user, never a traceback."""


def decode_reply(what: str, decode: Callable[[], T]) -> T:
    """Run a client-side decoder; any failure of it is a ``MalformedReplyError`` naming ``what``."""
    try:
        return decode()
    except (ValueError, struct.error, IndexError, CipError, EncapsulationError) as exc:
        raise MalformedReplyError(f"malformed {what}: {exc}") from None


__all__ = ["EncapsulationStatusError", "MalformedReplyError", "decode_reply"]
