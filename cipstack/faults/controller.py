"""The faults of one running adapter: applied, timed, cleared and logged.

``FaultController`` applies each fault from its declaration (``model.FAULTS``): the declared effect
is made and started, a filter in the seam of its layer (class 1 in or out, requests, replies) or a
change of the device's power and link (``cipstack.runtime.PowerLink``). It works on the device's
runtime (``cipstack.runtime.DeviceRuntime``), never on the adapter that composed it. A seam holds a
filter only while its fault is active: with none, the device runs exactly the code it runs without
this module. The command service (``cipstack.control.service``) is how every surface reaches it.

Every fault applied or cleared is logged with its time and kept in ``history``.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
import random
import time
from collections import deque
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..errors import NotFound
from ..runtime.power import settle_tasks
from .effect import Effect, FaultContext
from .errors import FaultError, FaultStateError, NoSuchConnection
from .model import CLASS1, FaultRequest, format_value

if TYPE_CHECKING:
    from ..runtime import DeviceRuntime

log = logging.getLogger(__name__)

#: Fault records kept in ``history`` (the oldest go first).
HISTORY_LIMIT = 1000


class NoActiveFault(NotFound):
    """``clear`` of a fault id or name that is not active."""


@dataclass
class Fault:
    """A fault applied: its id, what was asked, when, and until when (None: until cleared)."""

    id: int
    request: FaultRequest
    applied_at: float
    applied_wall: float
    until: float | None = None
    timer: asyncio.TimerHandle | None = field(default=None, repr=False)

    @property
    def name(self) -> str:
        return self.request.name

    def as_json(self, now: float | None = None) -> dict[str, Any]:
        record: dict[str, Any] = {"id": self.id, "name": self.name, "options": self.request.as_json(),
                                  "applied": _wall_text(self.applied_wall)}
        if self.until is not None:
            record["remaining_s"] = round(max(0.0, self.until - (now if now is not None else self.until)), 3)
        return record

    def __str__(self) -> str:
        return f"{self.id}: {self.request.describe()}"


def _wall_text(wall: float) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(wall)) + f".{int(wall * 1000) % 1000:03d}Z"


class FaultController:
    """The faults of one running device (``runtime``): each applied from its declaration
    (``model.FAULTS``) as an ``Effect`` in the seam of its layer, timed, cleared and logged."""

    def __init__(self, runtime: DeviceRuntime, rng: random.Random | None = None) -> None:
        self.runtime = runtime
        self.rng = rng or random.Random()
        self.active: dict[int, Fault] = {}
        self.history: deque[dict[str, Any]] = deque(maxlen=HISTORY_LIMIT)
        #: Called with each history record as it is made (the event stream listens here).
        self.listeners: list[Callable[[dict[str, Any]], None]] = []
        self._ids = itertools.count(1)
        self._effects: dict[int, Effect] = {}
        self._tasks: list[asyncio.Task[None]] = []

    # -- the API -------------------------------------------------------------------------------------
    def apply(self, name: str | FaultRequest, **options: object) -> Fault:
        """Apply a fault now (``options`` as the command line names them, ``_`` for ``-``); an action
        (``close-tcp``, ``drop-sessions``...) happens and is logged, and is not kept as active. Raises
        ``FaultError`` (unknown fault or option, bad value), ``NoSuchConnection`` (``connection`` is no
        open class 1 connection) or ``FaultStateError``. What needs the loop (closing and opening
        ports) is started here; ``await settle()`` waits for it."""
        request = name if isinstance(name, FaultRequest) else FaultRequest.build(name, options)
        kind = request.kind
        loop = asyncio.get_running_loop()
        now = loop.time()
        if kind.where == CLASS1:
            self._check_class1(request)
        if kind.ends is not None and not any(f.name == kind.ends for f in self.active.values()):
            raise FaultStateError(kind.refusal or f"no {kind.ends} is active")
        fault = Fault(next(self._ids), request, now, time.time())
        effect = kind.effect(FaultContext(self.runtime, fault.id, request.settings, self.rng,
                                          lambda: self._used_up(fault.id), self._start))
        effect.start()   # first: a fault its state refuses leaves everything as it was
        for ended in [f for f in self.active.values() if f.name in kind.replaces]:
            self._end(ended, "replaced" if ended.name == kind.name else "cleared")
        if not kind.lasting:
            self._record("applied", fault)
            return fault
        self.active[fault.id] = fault
        self._effects[fault.id] = effect
        duration = request.duration
        if duration is not None:
            fault.until = now + duration
            fault.timer = loop.call_at(fault.until, self._expire, fault.id)
        self._record("applied", fault)
        return fault

    def clear(self, which: int | str | None = None) -> list[Fault]:
        """Clear the faults still active: all (None), one by id, or all of one name; returns them.
        Raises ``FaultError`` when ``which`` names no active fault."""
        if which is None:
            chosen = list(self.active.values())
        elif isinstance(which, int) and not isinstance(which, bool):
            chosen = [self.active[which]] if which in self.active else []
        else:
            chosen = [f for f in self.active.values() if f.name == which]
        if which is not None and not chosen:
            active = ", ".join(str(f) for f in self.active.values()) or "none"
            raise NoActiveFault(f"no active fault {which!r} (active: {active})")
        for fault in chosen:
            self._end(fault, "cleared")
        return chosen

    def faults(self) -> list[Fault]:
        """The faults active now, oldest first."""
        return list(self.active.values())

    async def settle(self) -> None:
        """Wait until what the faults applied so far started on the loop is done (ports closed or
        opened, a power-cycle's power back)."""
        await settle_tasks(self._tasks)
        await self.runtime.power.settled()

    def shutdown(self) -> None:
        """The device is closing: no fault's timer fires and no port opens again after it (an unplug
        for a while, a power cycle still off); every filter leaves its seam, so the closing device is
        as it was."""
        self.runtime.power.shutdown()
        for task in self._tasks:
            task.cancel()
        self._tasks.clear()
        for fault in list(self.active.values()):
            if fault.timer is not None:
                fault.timer.cancel()
                fault.timer = None
            effect = self._effects.pop(fault.id, None)
            if effect is not None:
                effect.stop()
        self.active.clear()

    # -- bookkeeping -----------------------------------------------------------------------------------
    def _record(self, event: str, fault: Fault) -> None:
        wall = time.time()
        record = {"time": _wall_text(wall), "wall": wall, "monotonic": asyncio.get_running_loop().time(),
                  "event": "fault " + event, "id": fault.id, "fault": fault.name,
                  "options": fault.request.as_json()}
        self.history.append(record)
        log.info("fault %d %s %s at %s", fault.id, fault.request.describe(), event, record["time"])
        for listener in list(self.listeners):
            listener(record)

    def _expire(self, fault_id: int) -> None:
        fault = self.active.get(fault_id)
        if fault is not None:
            fault.timer = None
            self._end(fault, "expired")

    def _used_up(self, fault_id: int) -> None:
        fault = self.active.get(fault_id)
        if fault is not None:
            self._end(fault, "used up")

    def _end(self, fault: Fault, how: str) -> None:
        self.active.pop(fault.id, None)
        if fault.timer is not None:
            fault.timer.cancel()
            fault.timer = None
        effect = self._effects.pop(fault.id, None)
        if effect is not None:
            effect.stop()
        self._record(how, fault)

    def _start(self, work: Coroutine[Any, Any, None]) -> None:
        self._tasks.append(asyncio.get_running_loop().create_task(work))
        self._tasks[:] = [t for t in self._tasks if not t.done()]

    # -- class 1 -----------------------------------------------------------------------------------------
    def _check_class1(self, request: FaultRequest) -> None:
        if self.runtime.class1 is None:
            raise FaultError(f"{request.name}: this device has no class 1 I/O")
        wanted = request.settings.connection
        connections = self.runtime.class1_connections()
        if wanted is not None and not any(wanted in (c.ot_connection_id, c.to_connection_id) for c in connections):
            open_ids = ", ".join(f"0x{c.ot_connection_id:08X}/0x{c.to_connection_id:08X}"
                                 for c in connections) or "none"
            raise NoSuchConnection(f"no class 1 connection {format_value('connection', wanted)} "
                                   f"(open, O->T/T->O: {open_ids})")
