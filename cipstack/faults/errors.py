"""The errors of a fault request, each of the kind the command service maps to every surface's outcome."""

from __future__ import annotations

from ..errors import BadRequest, NotFound, StateRefused


class FaultError(BadRequest):
    """A fault request that names an unknown fault or option, or a bad value (one line)."""


class NoSuchConnection(NotFound):
    """A fault aimed at a class 1 connection that is not open (one line naming the open ones)."""


class FaultStateError(StateRefused, RuntimeError):
    """The device's state refuses the fault (plug when not unplugged, a second unplug, a power cycle
    while the power is off)."""


__all__ = ["FaultError", "FaultStateError", "NoSuchConnection"]
