"""A fault's options as a typed record, made once when the request is checked (``FaultRequest.build``):
the effects and the seams read attributes, never a mapping by key on each datagram or request.

Each attribute is one option of the fault table (``model.FAULTS``), None where the request does not
give it; the effect of each fault says what its absence means (``drop`` needs ``share`` or
``every``, ``delay`` defaults ``by`` to 10 ms). An option declares its attribute where its name is
not one (``Option.attribute``): ``for`` is ``duration``, ``class`` is ``class_id``, and
``refuse-forward-open``'s ``status`` (the Connection Manager's extended status) is
``extended_status``, apart from ``error-status``'s general/extended pair."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass


@dataclass(frozen=True)
class FaultOptions:
    """The checked options of one fault request (values as ``Option.parse`` made them)."""

    # Which class 1 connections (or DTLS sessions) it acts on.
    connection: int | None = None
    originator: str | None = None
    # How many packets, records or requests.
    share: float | None = None
    every: int | None = None
    count: int | None = None
    # How long: a delay, its jitter, the fault itself, a power-cycle's off time (seconds).
    by: float | None = None
    jitter: float | None = None
    duration: float | None = None
    off: float | None = None
    # What it changes or matches.
    size: int | None = None
    status: tuple[int, tuple[int, ...]] | None = None
    extended_status: int | None = None
    service: int | None = None
    class_id: int | None = None
    instance: int | None = None
    attribute: int | None = None
    suite: str | None = None
    direction: str | None = None


#: Every attribute of the record (a test holds them equal to the options the fault table declares).
ATTRIBUTES = tuple(f.name for f in dataclasses.fields(FaultOptions))


__all__ = ["ATTRIBUTES", "FaultOptions"]
