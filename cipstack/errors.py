"""The root of every error cipstack raises on purpose, and the few kinds a caller tells apart.

``except CipstackError`` catches whatever the package raises by design (a bad packet, a refusal, an
unreachable peer, a file that is not an EDS). Each public error keeps the builtin base it had before
this root existed as a second base (``MalformedReplyError`` is still a ``ConnectionError``,
``UnknownAttributeError`` a ``TypeError``), so no caller's ``except`` breaks.

The kinds say what went wrong, not how a surface reports it: the command service
(``cipstack.control.service``) maps each to an exit code, an HTTP status and a JSON error in one
table. The device layer knows nothing of HTTP.
"""

from __future__ import annotations

import os
import re
from typing import TypeVar

_Unreachable = TypeVar("_Unreachable", bound="PeerUnreachable")


class CipstackError(Exception):
    """Every error the package raises on purpose derives from this one."""


class BadRequest(CipstackError, ValueError):
    """The request itself is wrong: an unknown name or option, a value out of range, malformed input."""


class NotFound(CipstackError, LookupError):
    """The request names a thing that is not there: a device, a parameter code, a connection, a fault."""

    def __str__(self) -> str:
        # LookupError would quote a single argument (KeyError does; keep every kind one plain line).
        return str(self.args[0]) if len(self.args) == 1 else super().__str__()


class UnknownKey(NotFound, KeyError):
    """A name or number looked up in a table that has no such entry (an assembly instance, a node, a
    keypad code). Still a ``KeyError`` for callers that catch one, but its message is one plain line."""


class UnknownField(NotFound, AttributeError):
    """A field or attribute asked for by name that is not there (an assembly field, a device's class 1
    I/O). Still an ``AttributeError``, so ``hasattr`` and ``getattr(obj, name, default)`` keep working."""


class ReadOnlyField(BadRequest, AttributeError):
    """A field that may be read and not set (input data, an immutable declaration). Still an
    ``AttributeError``, as setting a read-only property is in Python."""


class WrongType(BadRequest, TypeError):
    """An argument of the wrong type (a text where a number goes, a datetime where a date goes). Still
    a ``TypeError``."""


class StateRefused(CipstackError):
    """The request is understood and the device's present state refuses it (a trip while powered
    off, a write while running, a second unplug)."""


class WrongState(StateRefused, RuntimeError):
    """A call the object's present state does not allow (a blocking call from the loop it would wait
    on, a flexible format that is not active). Still a ``RuntimeError``."""


class TimedOut(CipstackError, TimeoutError):
    """A wait the caller bounded ran out before its condition held (the peer may well be answering)."""


class PeerUnreachable(CipstackError, ConnectionError):
    """A peer (a device, an emulator's control socket) cannot be reached, or stopped answering."""

    @classmethod
    def connecting(cls: type[_Unreachable], host: str, port: int, failure: BaseException) -> _Unreachable:
        """``cannot connect to HOST:PORT: REASON``, whichever socket API failed to connect: every command
        and the library say a refused connection in the same words."""
        return cls(f"cannot connect to {host}:{port}: {connect_failure(failure)}")


class NoReply(PeerUnreachable, TimeoutError):
    """A peer that was reached did not answer before the deadline: a ``TimeoutError`` too, so an
    ``except TimeoutError`` written for the reply that does not come still catches it."""


class NothingListens(PeerUnreachable, ConnectionRefusedError):
    """Nothing listens at the peer's port: a datagram answered by ICMP port unreachable (a
    ``ConnectionRefusedError`` too, as the socket reports it)."""


def connect_failure(failure: BaseException) -> str:
    """Why a connection could not be made, in the operating system's words for its error number.

    A blocking ``connect`` says ``[Errno 111] Connection refused`` where asyncio's ``create_connection``
    says ``[Errno 111] Connect call failed ('127.0.0.1', 1)`` for the same refusal, and joins several
    addresses' failures into ``Multiple exceptions: ...`` with no number: one number is one reason."""
    number = failure.errno if isinstance(failure, OSError) else None
    if number is None:
        numbers = set(re.findall(r"\[Errno (\d+)\]", str(failure)))
        number = int(numbers.pop()) if len(numbers) == 1 else None
    if number is not None and number > 0:
        return os.strerror(number)
    if isinstance(failure, OSError) and failure.strerror:   # a resolver's error (negative numbers)
        return failure.strerror
    return str(failure) or "timed out"


class SecurityError(CipstackError):
    """CIP Security refused or could not start: a credentials folder that is missing, unreadable or
    expired, a TLS handshake the peer or we refused (the message names the cause in one line)."""


class ProtocolError(CipstackError):
    """A peer answered with an error on the wire. ``general`` and ``extended`` carry the CIP status
    where there is one (None otherwise)."""

    general: int | None = None
    extended: tuple[int, ...] = ()


__all__ = ["BadRequest", "CipstackError", "NoReply", "NotFound", "PeerUnreachable", "ProtocolError", "ReadOnlyField",
           "SecurityError", "StateRefused", "TimedOut", "UnknownField", "UnknownKey", "WrongState", "WrongType"]
