"""What a fault does while it is active: an ``Effect`` made from its declaration (``model.FAULTS``)
with a ``FaultContext``, started when the fault is applied and stopped when it ends."""

from __future__ import annotations

import random
from collections.abc import Callable, Coroutine
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from .options import FaultOptions

if TYPE_CHECKING:
    from ..runtime import DeviceRuntime


class Effect(Protocol):
    def start(self) -> None:
        """Act, or put a filter in its seam; raise ``FaultStateError`` when the device's state refuses."""

    def stop(self) -> None:
        """Undo what ``start`` put in place (the fault was cleared, expired or used up)."""


@dataclass
class FaultContext:
    """What an effect works with: the device's runtime, the fault's checked options as a typed record
    (read once, when the effect is made), a random source, and how it reports back to the controller."""

    runtime: DeviceRuntime
    fault_id: int
    options: FaultOptions
    rng: random.Random
    #: The fault ends itself (``--count`` spent): the controller clears it.
    used_up: Callable[[], None]
    #: Hand work to the loop (closing or opening ports); the controller's ``settle`` waits for it.
    start_work: Callable[[Coroutine[Any, Any, None]], None]


#: How a fault's effect is made from its context (a filter class, an action class).
EffectFactory = Callable[[FaultContext], Effect]


class Action:
    """An effect that happens once when applied and leaves nothing to undo."""

    def __init__(self, context: FaultContext) -> None:
        self.context = context

    def stop(self) -> None:
        pass


__all__ = ["Action", "Effect", "EffectFactory", "FaultContext"]
