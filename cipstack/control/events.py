"""The event stream of a running adapter: what happened, when, for assertions and for the HTTP API.

Events: class 1 connections opened, closed and timed out; run/idle changes of their O->T data; the
drive's state changes and trips (seen whenever the adapter moves the device to a new time);
parameter writes, one per write the device accepted from any route (``parameter write``: a CIP Set
service, a register of a Modbus TCP or Modbus-RTU request, a keypad parameter set over HTTP or from
Python; ``origin`` says which, with the peer or the station, and ``code``, ``address``, ``raw`` what
was written where the device knows the parameter); faults applied, cleared, expired, used up.
Each is an ``Event`` with its wall-clock time, its time on the loop's clock, a kind and fields.

Nothing is watched until the stream is started (``Adapter.events`` starts it on first use): the
taps are put where the adapter hands things to the device (its class 1 events, its clock, its
message router's entry, the one place each Modbus port writes a register), so an adapter nobody
observes pays nothing. Each route has its own tap and a write passes one of them, so a write is one
event (a CIP Set of class 0x64 is seen at the router, not again at the drive). Keypad parameters
given at start (``--param``) precede the stream and are no event. The stream keeps the last
``limit`` events; ``wait_for`` waits for one on the loop.
"""

from __future__ import annotations

import asyncio
import itertools
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..adapter import Adapter
    from ..devices.keypad import Keypad

#: Events kept (the oldest go first).
DEFAULT_LIMIT = 10_000

#: Services whose success writes a value (CIP Vol. 1, Appendix A): Set_Attributes_All,
#: Set_Attribute_List, Set_Attribute_Single, Set_Member.
_SET_SERVICES = frozenset({0x02, 0x04, 0x10, 0x19})


@dataclass(frozen=True)
class Event:
    number: int
    kind: str
    wall: float
    monotonic: float
    fields: dict[str, Any] = field(default_factory=dict)

    @property
    def time(self) -> str:
        return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(self.wall)) + f".{int(self.wall * 1000) % 1000:03d}Z"

    def as_json(self) -> dict[str, Any]:
        return {"number": self.number, "kind": self.kind, "time": self.time, "monotonic": round(self.monotonic, 6),
                **self.fields}


class _IoTap:
    """Stands in for the device as the class 1 target's ``events``: records, then tells the device."""

    def __init__(self, device: Any, stream: EventStream) -> None:
        self.device = device
        self.stream = stream

    @staticmethod
    def _fields(connection: Any) -> dict[str, Any]:
        return {"class": 1, "connection": f"0x{connection.ot_connection_id:08X}",
                "t_to_o": f"0x{connection.to_connection_id:08X}", "originator": connection.peer,
                "name": connection.name}

    def io_opened(self, connection: Any) -> None:
        self.stream.emit("connection opened", **self._fields(connection))
        self.device.io_opened(connection)

    def io_closed(self, connection: Any, timed_out: bool) -> None:
        self.stream.emit("connection timed out" if timed_out else "connection closed", **self._fields(connection))
        self.device.io_closed(connection, timed_out)

    def io_run_idle(self, connection: Any, run: bool) -> None:
        self.stream.emit("run" if run else "idle", **self._fields(connection))
        self.device.io_run_idle(connection, run)


class EventStream:
    def __init__(self, adapter: Adapter, limit: int = DEFAULT_LIMIT) -> None:
        self.adapter = adapter
        self.events: deque[Event] = deque(maxlen=limit)
        self._numbers = itertools.count(1)
        self._waiters: list[tuple[Callable[[Event], bool], asyncio.Future[Event]]] = []
        self._listeners: list[Callable[[Event], None]] = []
        self._started = False
        self._drive: dict[str, Any] | None = None
        self._undo: list[Callable[[], None]] = []
        self._keypad: Keypad | None = None

    # -- reading ---------------------------------------------------------------------------------------
    def since(self, number: int = 0) -> list[Event]:
        """The events after event ``number`` still kept, oldest first."""
        return [e for e in self.events if e.number > number]

    @property
    def watching(self) -> bool:
        """The taps are in place (``start``, until ``stop``)."""
        return self._started

    def kinds(self) -> list[str]:
        return [e.kind for e in self.events]

    def listen(self, listener: Callable[[Event], None]) -> None:
        """Call ``listener`` with each event as it happens (on the loop's thread)."""
        self._listeners.append(listener)

    async def wait_for(self, kind: str | Callable[[Event], bool], timeout: float = 10.0, after: int = 0) -> Event:
        """The first event after event ``after`` of ``kind`` (or for which ``kind(event)`` is true),
        waiting up to ``timeout`` seconds for it (``asyncio.TimeoutError``)."""
        match = kind if callable(kind) else (lambda event: event.kind == kind)
        for event in self.since(after):
            if match(event):
                return event
        future: asyncio.Future[Event] = asyncio.get_running_loop().create_future()
        waiter = (match, future)
        self._waiters.append(waiter)
        try:
            return await asyncio.wait_for(future, timeout)
        finally:
            if waiter in self._waiters:
                self._waiters.remove(waiter)

    # -- writing ---------------------------------------------------------------------------------------
    def emit(self, kind: str, **fields: Any) -> Event:
        try:
            now = asyncio.get_running_loop().time()
        except RuntimeError:
            now = time.monotonic()
        event = Event(next(self._numbers), kind, time.time(), now, fields)
        self.events.append(event)
        for match, future in list(self._waiters):
            if not future.done() and match(event):
                future.set_result(event)
        for listener in list(self._listeners):
            listener(event)
        return event

    # -- the taps --------------------------------------------------------------------------------------
    def start(self) -> None:
        """Put the taps in place (once)."""
        if self._started:
            return
        self._started = True
        adapter = self.adapter
        io = adapter.io
        if io is not None:
            device_events = io.events
            io.events = _IoTap(device_events, self)  # type: ignore[assignment]
            self._undo.append(lambda: setattr(io, "events", device_events))
        # The drive's state and trip, looked at whenever the adapter moves the device to a new time.
        self._drive = self._drive_state()
        target_tick, io_tick = adapter.target.tick, io.tick if io is not None else None

        def tick(now: float) -> None:
            adapter._tick(now)
            self._look_at_drive()

        adapter.target.tick = tick
        if io is not None:
            io.tick = tick
        self._undo.append(lambda: setattr(adapter.target, "tick", target_tick))
        if io is not None:
            self._undo.append(lambda: setattr(io, "tick", io_tick))
        # Parameter writes: at the device's message router, behind any fault in front of it; at the
        # register store of each Modbus port; keypad writes tell the stream themselves.
        self._keypad = adapter.device.keypad()
        router = adapter.device.router
        handle = type(router).handle.__get__(router)

        def handle_and_record(raw: bytes, context: Any) -> bytes:
            reply = handle(raw, context)
            if raw and raw[0] in _SET_SERVICES and len(reply) >= 4 and reply[2] == 0:
                self._cip_write(raw, getattr(context, "origin", ""))
            return reply

        router.handle = handle_and_record  # type: ignore[method-assign]
        self._undo.append(lambda: router.__dict__.pop("handle", None))
        if adapter.modbus is not None:
            self._tap_modbus(adapter.modbus.core, "modbus-tcp", "peer")
        if adapter.rtu is not None:
            self.tap_rtu(adapter.rtu)
        adapter.faults.listeners.append(self._on_fault)
        self._undo.append(lambda: adapter.faults.listeners.remove(self._on_fault))

    def stop(self) -> None:
        """Take the taps away (the events kept stay)."""
        for undo in reversed(self._undo):
            undo()
        self._undo.clear()
        self._started = False

    def tap_rtu(self, line: Any) -> None:
        """Watch the register writes of the drives on an RS-485 line (``RtuLine``), once it is open."""
        if self._started:
            for slave in line.slaves:
                self._tap_modbus(slave.core, "modbus-rtu", "station")

    def _tap_modbus(self, core: Any, origin: str, source_field: str) -> None:
        """Record each register a Modbus port's core writes (``ModbusCore.store``): its source is the
        peer's ``host:port`` (TCP) or the station the frame addressed (RTU, 0 for a broadcast)."""
        store = type(core).store.__get__(core)
        keypad = self._keypad

        def store_and_record(drive: Any, address: int, raw: int, now: float, source: object) -> None:
            store(drive, address, raw, now, source)
            found = drive.registers.word(address)
            register = found[0] if found is not None and found[1] == 0 else None
            what = keypad.write_fields(register, raw, address) if keypad is not None else {"raw": raw}
            self.parameter_written(origin, **{source_field: source}, **what)

        core.store = store_and_record
        self._undo.append(lambda: core.__dict__.pop("store", None))

    def _cip_write(self, request: bytes, peer: str) -> None:
        """A Set service the router answered with success: its service, path and data, and the
        parameter it wrote by code where the device's keypad knows the path (class 0x64 of the ACG,
        0x64/0x65 of the MX2/RX, an attribute that shows a register)."""
        size = 2 * request[1]
        fields: dict[str, Any] = {"peer": peer, "service": f"0x{request[0]:02X}",
                                  "path": request[2:2 + size].hex(), "data": request[2 + size:].hex()}
        if self._keypad is not None:
            fields.update(self._keypad.written_by(request))
        self.parameter_written("cip", **fields)

    def parameter_written(self, origin: str, **fields: Any) -> Event:
        """Record one accepted write: ``origin`` ("cip", "modbus-tcp", "modbus-rtu", "http", "python")
        and what the route knows of it (``peer`` or ``station``; ``code``, ``address``, ``raw``,
        ``value`` where the parameter is known)."""
        return self.emit("parameter write", origin=origin, **fields)

    def _on_fault(self, record: dict[str, Any]) -> None:
        self.emit(record["event"], id=record["id"], fault=record["fault"], options=record["options"])

    def _drive_state(self) -> dict[str, Any] | None:
        fields = self.adapter.device.status_fields()
        if fields is None:
            return None
        return {"state": fields.get("state"), "trip": fields.get("trip"), "direction": fields.get("direction")}

    def _look_at_drive(self) -> None:
        state = self._drive_state()
        before = self._drive
        if state is None or state == before:
            return
        self._drive = state
        if before is not None and state["trip"] != before["trip"]:
            if state["trip"] is not None:
                self.emit("trip", trip=state["trip"], **_drive_fields(self.adapter))
            else:
                self.emit("trip reset", trip=before["trip"])
        if before is None or state["state"] != before["state"] or state["direction"] != before["direction"]:
            self.emit("drive state", state=state["state"], direction=state["direction"])


def _drive_fields(adapter: Adapter) -> dict[str, Any]:
    fields = adapter.device.status_fields() or {}
    return {k: fields[k] for k in ("fault_code",) if k in fields}
