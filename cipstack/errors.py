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


class CipstackError(Exception):
    """Every error the package raises on purpose derives from this one."""


class BadRequest(CipstackError, ValueError):
    """The request itself is wrong: an unknown name or option, a value out of range, malformed input."""


class NotFound(CipstackError, LookupError):
    """The request names a thing that is not there: a device, a parameter code, a connection, a fault."""

    def __str__(self) -> str:
        # LookupError would quote a single argument (KeyError does; keep every kind one plain line).
        return str(self.args[0]) if len(self.args) == 1 else super().__str__()


class StateRefused(CipstackError):
    """The request is understood and the device's present state refuses it (a trip while powered
    off, a write while running, a second unplug)."""


class PeerUnreachable(CipstackError, ConnectionError):
    """A peer (a device, an emulator's control socket) cannot be reached, or stopped answering."""


class ProtocolError(CipstackError):
    """A peer answered with an error on the wire. ``general`` and ``extended`` carry the CIP status
    where there is one (None otherwise)."""

    general: int | None = None
    extended: tuple[int, ...] = ()


__all__ = ["BadRequest", "CipstackError", "NotFound", "PeerUnreachable", "ProtocolError", "StateRefused"]
