"""The event stream of a running adapter: what happened, when, for assertions and for the HTTP API.

Events: class 1 connections opened, closed and timed out; run/idle changes of their O->T data; the
drive's state changes and trips (seen whenever the adapter moves the device to a new time);
parameter writes, one per write the device accepted from any route (``parameter write``: a CIP Set
service, a register of a Modbus TCP or Modbus-RTU request, a keypad parameter set over HTTP or from
Python; ``origin`` says which, with the peer or the station, and ``code``, ``address``, ``raw`` what
was written where the device knows the parameter); faults applied, cleared, expired, used up.
Each is an ``Event`` with its wall-clock time, its time on the loop's clock, a kind and fields.

Nothing is watched until the stream is started (``Adapter.events`` starts it on first use): it then
observes the device's runtime (``cipstack.runtime.RuntimeObserver``: class 1 events, the device's
clock, the one place each Modbus port writes a register) and the requests that reach the message
router (an observer in the request seam, behind any fault), so a device nobody observes pays
nothing. Each route is observed in one place and a write passes one of them, so a write is one
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
    from ..cip.router import RequestContext
    from ..eip.target.seams import Handle
    from ..faults import FaultController
    from ..runtime import DeviceRuntime

#: Events kept (the oldest go first).
DEFAULT_LIMIT = 10_000

#: Every kind of event the stream records (what a scenario's ``on`` may wait for).
EVENT_KINDS = ("connection opened", "connection closed", "connection timed out", "run", "idle", "drive state",
               "trip", "trip reset", "parameter write", "fault applied", "fault cleared", "fault expired",
               "fault used up", "fault replaced")

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


def _connection_fields(connection: Any) -> dict[str, Any]:
    return {"class": 1, "connection": f"0x{connection.ot_connection_id:08X}",
            "t_to_o": f"0x{connection.to_connection_id:08X}", "originator": connection.peer,
            "name": connection.name}


#: The field that names where a Modbus write came from, by port: a TCP peer, an RTU station.
_SOURCE_FIELD = {"modbus-tcp": "peer", "modbus-rtu": "station"}


class EventStream:
    def __init__(self, runtime: DeviceRuntime, faults: FaultController | None = None,
                 limit: int = DEFAULT_LIMIT) -> None:
        """``runtime``: the device watched; ``faults``: its fault controller, whose records become events."""
        self.runtime = runtime
        self.faults = faults
        self.events: deque[Event] = deque(maxlen=limit)
        self._numbers = itertools.count(1)
        self._waiters: list[tuple[Callable[[Event], bool], asyncio.Future[Event]]] = []
        self._listeners: list[Callable[[Event], None]] = []
        self._started = False
        self._drive: dict[str, Any] | None = None
        self._keypad = runtime.device.keypad()

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

    # -- watching -------------------------------------------------------------------------------------
    def start(self) -> None:
        """Observe the device (once)."""
        if self._started:
            return
        self._started = True
        self._drive = self._drive_state()
        self.runtime.watch(self)
        self.runtime.requests.add(self, observer=True)
        if self.faults is not None:
            self.faults.listeners.append(self._on_fault)

    def stop(self) -> None:
        """Stop observing (the events kept stay)."""
        if not self._started:
            return
        self._started = False
        self.runtime.unwatch(self)
        self.runtime.requests.remove(self)
        if self.faults is not None:
            self.faults.listeners.remove(self._on_fault)

    # -- what the runtime tells (``cipstack.runtime.RuntimeObserver``) -----------------------------------
    def ticked(self, now: float) -> None:
        self._look_at_drive()

    def io_opened(self, connection: Any) -> None:
        self.emit("connection opened", **_connection_fields(connection))

    def io_closed(self, connection: Any, timed_out: bool) -> None:
        self.emit("connection timed out" if timed_out else "connection closed", **_connection_fields(connection))

    def io_run_idle(self, connection: Any, run: bool) -> None:
        self.emit("run" if run else "idle", **_connection_fields(connection))

    def register_written(self, port: str, drive: Any, address: int, raw: int, source: object) -> None:
        """A register a Modbus port's request wrote: its source is the peer's ``host:port`` (TCP) or the
        station the frame addressed (RTU, 0 for a broadcast)."""
        found = drive.registers.word(address)
        register = found[0] if found is not None and found[1] == 0 else None
        keypad = self._keypad
        what = keypad.write_fields(register, raw, address) if keypad is not None else {"raw": raw}
        self.parameter_written(port, **{_SOURCE_FIELD.get(port, "source"): source}, **what)

    def request(self, raw: bytes, context: RequestContext, call_next: Handle) -> bytes:
        """An observer in the request seam: a Set service the router answered with success is a write."""
        reply = call_next(raw, context)
        if raw and raw[0] in _SET_SERVICES and len(reply) >= 4 and reply[2] == 0:
            self._cip_write(raw, getattr(context, "origin", ""))
        return reply

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
        fields = self.runtime.device.status_fields()
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
                self.emit("trip", trip=state["trip"], **_drive_fields(self.runtime))
            else:
                self.emit("trip reset", trip=before["trip"])
        if before is None or state["state"] != before["state"] or state["direction"] != before["direction"]:
            self.emit("drive state", state=state["state"], direction=state["direction"])


def _drive_fields(runtime: DeviceRuntime) -> dict[str, Any]:
    fields = runtime.device.status_fields() or {}
    return {k: fields[k] for k in ("fault_code",) if k in fields}
