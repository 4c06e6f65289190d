"""The faults of one running adapter: applied, timed, cleared and logged.

``FaultController`` is the one in-process API the command line (over the control socket), the
HTTP API, scenarios and the pytest plugin all use. It puts each fault where the DESIGN says faults
sit, between the wire and the device: class 1 faults in a layer the class 1 endpoint reads and
sends through (``io.IoFaultLayer``), request faults in a layer in front of the message router
(``explicit.RouterFaultLayer``), reply delays on the TCP shells, and the device-wide ones where the
adapter's ports are opened and closed. A layer is in place only while one of its faults is active:
with none, the adapter runs exactly the code it runs without this module.

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

from .explicit import ReplyDelay, RouterFaultLayer
from .io import DEFAULT_DELAY, IoFaultLayer, send_later_on
from .model import CLASS1, FaultError, FaultRequest, NoSuchConnection, format_value

if TYPE_CHECKING:
    from ..adapter import Adapter

log = logging.getLogger(__name__)

#: Fault records kept in ``history`` (the oldest go first).
HISTORY_LIMIT = 1000


class FaultStateError(RuntimeError):
    """The device's state refuses the request (plug when not unplugged, a second unplug)."""


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
    def __init__(self, adapter: Adapter, rng: random.Random | None = None) -> None:
        self.adapter = adapter
        self.rng = rng or random.Random()
        self.active: dict[int, Fault] = {}
        self.history: deque[dict[str, Any]] = deque(maxlen=HISTORY_LIMIT)
        #: Called with each history record as it is made (the event stream listens here).
        self.listeners: list[Callable[[dict[str, Any]], None]] = []
        self._ids = itertools.count(1)
        self._io_layer: IoFaultLayer | None = None
        self._router_layer: RouterFaultLayer | None = None
        self._reply_delay: tuple[int, ReplyDelay] | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self.unplugged = False
        #: True from a power-cycle's loss of power until its ports open again: a device without power
        #: takes no trip, no keypad write and no second power cycle.
        self.powered_off = False

    # -- the API -------------------------------------------------------------------------------------
    def apply(self, name: str | FaultRequest, **options: object) -> Fault:
        """Apply a fault now (``options`` as the command line names them, ``_`` for ``-``); an action
        (``close-tcp``, ``power-cycle``...) happens and is logged, and is not kept as active. Raises
        ``FaultError`` (unknown fault or option, bad value), ``NoSuchConnection`` (``connection`` is no
        open class 1 connection) or ``FaultStateError``. What needs the loop (closing and opening
        ports) is started here; ``await settle()`` waits for it."""
        request = name if isinstance(name, FaultRequest) else FaultRequest.build(name, options)
        kind = request.kind
        loop = asyncio.get_running_loop()
        now = loop.time()
        if kind.where == CLASS1:
            self._check_class1(request)
        fault = Fault(next(self._ids), request, now, time.time())
        getattr(self, "_apply_" + request.name.replace("-", "_"))(fault)
        if kind.once:
            self._record("applied", fault)
            return fault
        self.active[fault.id] = fault
        if request.duration is not None:
            fault.until = now + request.duration
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
            raise FaultError(f"no active fault {which!r} (active: {active})")
        for fault in chosen:
            self._end(fault, "cleared")
        return chosen

    def faults(self) -> list[Fault]:
        """The faults active now, oldest first."""
        return list(self.active.values())

    async def settle(self) -> None:
        """Wait until what the faults applied so far started on the loop (ports closed or opened) is done."""
        while self._tasks:
            tasks, self._tasks = self._tasks, []
            for task in tasks:
                await task

    def shutdown(self) -> None:
        """The adapter is closing: no fault's timer fires and no port opens again after it (an unplug
        for a while, a power cycle still off); the layers go, so the closing adapter is as it was."""
        for task in self._tasks:
            task.cancel()
        self._tasks.clear()
        for fault in list(self.active.values()):
            if fault.timer is not None:
                fault.timer.cancel()
                fault.timer = None
        self.active.clear()
        if self._io_layer is not None:
            self._io_layer.uninstall(self.adapter.io_endpoint)
            self._io_layer = None
        if self._router_layer is not None:
            self.adapter.target.router = self._router_layer.router
            self._router_layer = None
        if self._reply_delay is not None:
            self._reply_delay[1].uninstall()
            self._reply_delay = None
        self.unplugged = False

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
            self._end(fault, "used up", removed_from_layer=True)

    def _end(self, fault: Fault, how: str, removed_from_layer: bool = False) -> None:
        self.active.pop(fault.id, None)
        if fault.timer is not None:
            fault.timer.cancel()
            fault.timer = None
        kind = fault.request.kind
        if kind.where == CLASS1 or fault.name == "unplug":
            layer = self._io_layer
            if layer is not None:
                layer.remove(fault.id)
                if not layer.faults:
                    layer.uninstall(self.adapter.io_endpoint)
                    self._io_layer = None
        if fault.name in ("error-status", "refuse-forward-open"):
            router_layer = self._router_layer
            if router_layer is not None:
                if not removed_from_layer:
                    router_layer.remove(fault.id)
                if not router_layer.faults:
                    self.adapter.target.router = router_layer.router
                    self._router_layer = None
        if fault.name == "delay-replies" and self._reply_delay is not None and self._reply_delay[0] == fault.id:
            self._reply_delay[1].uninstall()
            self._reply_delay = None
        if fault.name == "unplug":
            self.unplugged = False
            self._start(self._open_ports())
        self._record(how, fault)

    def _start(self, work: Coroutine[Any, Any, None]) -> None:
        self._tasks.append(asyncio.get_running_loop().create_task(work))

    # -- class 1 -----------------------------------------------------------------------------------------
    def _check_class1(self, request: FaultRequest) -> None:
        io = self.adapter.io
        if io is None or self.adapter.io_endpoint is None:
            raise FaultError(f"{request.name}: this device has no class 1 I/O")
        wanted = request.options.get("connection")
        if wanted is not None and not any(wanted in (c.ot_connection_id, c.to_connection_id)
                                          for c in io.connections.values()):
            open_ids = ", ".join(f"0x{c.ot_connection_id:08X}/0x{c.to_connection_id:08X}"
                                 for c in io.connections.values()) or "none"
            raise NoSuchConnection(f"no class 1 connection {format_value('connection', wanted)} "
                                   f"(open, O->T/T->O: {open_ids})")

    def _io(self) -> IoFaultLayer:
        if self._io_layer is None:
            adapter = self.adapter
            assert adapter.io is not None and adapter.io_endpoint is not None
            layer = IoFaultLayer(adapter.io, send_later_on(asyncio.get_running_loop(), adapter.io_endpoint), self.rng)
            layer.install(adapter.io_endpoint)
            self._io_layer = layer
        return self._io_layer

    def _apply_class1(self, fault: Fault) -> None:
        self._io().add(fault.id, fault.request)

    _apply_stop_producing = _apply_drop = _apply_duplicate = _apply_reorder = _apply_delay = _apply_class1
    _apply_freeze_sequence = _apply_wrong_size = _apply_ignore_output = _apply_idle = _apply_class1

    # -- explicit ---------------------------------------------------------------------------------------
    def _router(self) -> RouterFaultLayer:
        if self._router_layer is None:
            target = self.adapter.target
            self._router_layer = RouterFaultLayer(target.router, self._used_up)
            target.router = self._router_layer  # type: ignore[assignment]
        return self._router_layer

    def _apply_error_status(self, fault: Fault) -> None:
        self._router().add(fault.id, fault.request)

    _apply_refuse_forward_open = _apply_error_status

    def _apply_delay_replies(self, fault: Fault) -> None:
        if self._reply_delay is not None:
            self._end(self.active[self._reply_delay[0]], "replaced")
        options = fault.request.options
        delay = ReplyDelay(self.adapter.server, asyncio.get_running_loop(), options.get("by", DEFAULT_DELAY),
                           options.get("jitter", 0.0), self.rng)
        delay.install()
        self._reply_delay = (fault.id, delay)

    def _apply_close_tcp(self, fault: Fault) -> None:
        for served in list(self.adapter.server.connections):
            served.close()

    def _apply_drop_sessions(self, fault: Fault) -> None:
        self.adapter.target.drop_sessions()

    # -- the whole device -------------------------------------------------------------------------------
    def _apply_unplug(self, fault: Fault) -> None:
        if self.unplugged:
            raise FaultStateError("the device is unplugged already")
        self.unplugged = True
        if self.adapter.io_endpoint is not None and self.adapter.io is not None:
            self._io().add(fault.id, fault.request)
        self._start(self._close_ports())

    def _apply_plug(self, fault: Fault) -> None:
        unplugs = [f for f in self.active.values() if f.name == "unplug"]
        if not unplugs:
            raise FaultStateError("the device is not unplugged")
        for unplug in unplugs:
            self._end(unplug, "cleared")

    def _apply_power_cycle(self, fault: Fault) -> None:
        if self.powered_off:
            raise FaultStateError("the device is powered off already (a power-cycle is under way)")
        self.powered_off = True
        self._start(self._power_cycle(fault.request.options.get("off", 0.0)))

    async def _close_ports(self) -> None:
        adapter = self.adapter
        await adapter.server.close()
        if adapter.modbus is not None:
            # Opened again on the port it had, also when it was chosen by the system (--modbus-port 0).
            adapter.modbus._requested_port = adapter.modbus.port
            await adapter.modbus.close()

    async def _open_ports(self) -> None:
        adapter = self.adapter
        if adapter.modbus is not None:
            await adapter.modbus.start()
        await adapter.server.start()

    async def _power_cycle(self, off: float) -> None:
        """A power loss: every port closes and every connection with it (no Forward_Close, no FIN
        from a device without power would come, but the peer's socket is gone either way); the
        whole device restarts from what it keeps over a power loss (``Device.power_cycle``: each
        family says what that is, from its manual); after ``off`` seconds its ports open again,
        unless it is unplugged."""
        adapter = self.adapter
        loop = asyncio.get_running_loop()
        was_plugged = not self.unplugged
        try:
            if was_plugged:
                await self._close_ports()
            if adapter.io is not None:
                adapter.io.close_all()
            adapter.device.power_cycle(loop.time())
            adapter.target.tick(loop.time())   # through the event stream's tap, if any: the new state is seen
            # A save the device had handed to its memory before the power went is written (or failed).
            await loop.run_in_executor(None, adapter.device.flush_saves, 10.0)
            if off:
                await asyncio.sleep(off)
        finally:
            self.powered_off = False
        if was_plugged and not self.unplugged:
            await self._open_ports()
