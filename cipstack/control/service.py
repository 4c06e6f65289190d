"""The command service: every operation on a running emulated device, once, for every surface.

The local control socket (``cipstack drive``), the HTTP API, scenarios, the pytest plugin and a
fleet's relay all call ``DeviceService``; none adds behaviour. ``OPERATIONS`` declares each
operation once (its handler here, its argument record with their JSON keys, its HTTP route, its
``cipstack drive`` words, its console formatter, its help), and the HTTP routes, ``/openapi.json``
and the ``cipstack drive`` subcommands are generated from it, so that every operation is on every
surface and no surface can drift.

Errors: an operation raises one of the kinds of ``cipstack.errors``; ``outcome`` is the one table
from an error to what each surface makes of it (an exit code, an HTTP status, the JSON error). The
messages name JSON keys (``"share"``), never command-line options: the command line checks its own
syntax before it asks.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
from collections.abc import Awaitable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ..devices.base import TripRefused
from ..devices.keypad import WriteRefused
from ..errors import BadRequest, CipstackError, NotFound, PeerUnreachable, StateRefused
from ..faults import FaultController, FaultRequest
from ..faults.model import JSON_SPELLING
from . import views
from .events import EventStream
from .operations import JSON_TYPES, KEYPAD, OPERATION_BY_NAME, OPERATIONS, TRIPS, Argument, Caller, Operation

if TYPE_CHECKING:
    from ..devices.base import DriveTrips
    from ..devices.keypad import Keypad
    from ..runtime import DeviceRuntime

#: How long an operation that opens or closes ports waits for them before it answers; a power-cycle
#: with a longer ``off`` answers while the power is still off.
SETTLE_S = 2.0

#: Events one ``events`` call returns at most (the oldest after ``since`` first).
MAX_EVENTS = 1000


# -- the outcome table ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Outcome:
    """What a surface makes of an error: its name on the control socket, the command line's exit code,
    the HTTP status."""

    name: str
    exit_code: int
    http_status: int


#: From an error's kind to its outcome, the first that matches (the command line's exit 2 is a usage
#: error: the request itself is malformed; 1 is a failure: the device has no such thing, its state
#: says no, or it cannot be reached).
OUTCOMES: tuple[tuple[type[CipstackError], Outcome], ...] = (
    (BadRequest, Outcome("bad-request", 2, 400)),
    (NotFound, Outcome("not-found", 1, 404)),
    (StateRefused, Outcome("refused", 1, 409)),
    (PeerUnreachable, Outcome("unreachable", 1, 503)),
    (CipstackError, Outcome("failed", 1, 500)),
)
OUTCOME_BY_NAME = {outcome.name: outcome for _, outcome in OUTCOMES}


def outcome(error: BaseException) -> Outcome | None:
    """The outcome of ``error``; None for an error the package did not raise on purpose (a defect)."""
    for kind, result in OUTCOMES:
        if isinstance(error, kind):
            return result
    return None


def error_of(name: str, message: str) -> CipstackError:
    """The error an outcome's name stands for, rebuilt on the client's side of a socket or an HTTP call."""
    kinds = {result.name: kind for kind, result in OUTCOMES}
    return kinds.get(name, CipstackError)(message)


def check_arguments(operation: Operation, arguments: dict[str, Any]) -> dict[str, Any]:
    """The arguments of a call, checked against the declaration: no unknown key, every required one."""
    stray = sorted(set(arguments) - {a.key for a in operation.arguments})
    if stray:
        valid = ", ".join(f'"{a.key}"' for a in operation.arguments) or "none"
        raise BadRequest(f"{operation.name}: unknown key {', '.join(repr(k) for k in stray)}; valid: {valid}")
    for argument in operation.arguments:
        value = arguments.get(argument.key)
        if value is None:
            if argument.required:
                raise BadRequest(f"{operation.name} needs \"{argument.key}\": {argument.help}")
            continue
        if isinstance(value, bool) or not isinstance(value, JSON_TYPES[argument.json_type]):
            raise BadRequest(f"{operation.name}: \"{argument.key}\" is a {argument.json_type.replace('|', ' or ')}, "
                             f"not {json.dumps(value)[:40]}")
    return arguments


#: The most digits a whole number given as text may have (an event number, a fault's id: far fewer).
MAX_WHOLE_DIGITS = 18
#: A whole number given as text (a query, a path, a command line): ASCII digits only. ``int()`` alone
#: takes what no client means (``+1``, ``1_0``, `` 1``, an Arabic-Indic one), and ``str.isdigit()`` what
#: ``int()`` refuses (a superscript two).
_WHOLE_NUMBER = re.compile(f"[0-9]{{1,{MAX_WHOLE_DIGITS}}}")


def is_whole_number(text: str) -> bool:
    return _WHOLE_NUMBER.fullmatch(text) is not None


def whole_number(key: str, text: str) -> int:
    """``text``, the value of ``key``, as a whole number; ``BadRequest`` naming the grammar when it is not
    1 to ``MAX_WHOLE_DIGITS`` ASCII digits."""
    if not is_whole_number(text):
        raise BadRequest(f"{key} is a whole number (1 to {MAX_WHOLE_DIGITS} digits 0-9), not {text[:40]!r}")
    return int(text)


class DeviceService:
    """The operations on one running device (each operation's ``handler`` calls one method), called with
    JSON values and answering JSON values."""

    def __init__(self, runtime: DeviceRuntime, faults: FaultController, events: EventStream,
                 name: str = "") -> None:
        self.runtime = runtime
        self.faults = faults
        self.events = events
        #: The device's product name, for ``/devices``.
        self.name = name
        #: How far a scenario running on the device is (``scenario.run`` keeps it), for ``status``.
        self.scenario: dict[str, Any] | None = None

    def describe(self) -> dict[str, Any]:
        """What ``GET /devices`` lists of the device: its EtherNet/IP port and product name."""
        return {"port": self.runtime.server.port, "product_name": self.name}

    def call(self, operation: str, arguments: dict[str, Any], origin: str = "python",
             peer: str | None = None) -> Any:
        """Run ``operation`` with ``arguments`` (JSON keys): its result, or for an operation that waits
        on the loop (a fault and its ports) an awaitable of it. ``origin`` and ``peer`` say who asks
        (what a parameter write's event records). Raises the kinds of ``cipstack.errors``."""
        declared = OPERATION_BY_NAME.get(operation)
        if declared is None:
            raise BadRequest(f"unknown operation {operation!r}; valid: {', '.join(OPERATION_BY_NAME)}")
        check_arguments(declared, arguments)
        record = declared.record(**arguments)
        self.refuse_absent(declared)
        return declared.handler(self, record, Caller(origin, peer))

    def offers(self, operation: Operation) -> bool:
        """Whether the device declares what ``operation`` needs (a drive's trips, a keypad)."""
        return operation.needs is None or operation.needs.declared(self.runtime.device) is not None

    def refuse_absent(self, operation: Operation) -> None:
        """The error of a device whose declaration lacks what ``operation`` needs, raised before anything
        runs (a trip of a device without a drive is a ``BadRequest``, as its message says)."""
        if not self.offers(operation):
            assert operation.needs is not None
            raise operation.needs.absent(self.runtime.device)

    async def call_async(self, operation: str, arguments: dict[str, Any], origin: str = "python",
                         peer: str | None = None) -> Any:
        """``call``, its result awaited when it is an awaitable."""
        result = self.call(operation, arguments, origin, peer)
        if isinstance(result, Awaitable):
            result = await result
        return result

    # -- status, trip ----------------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        self.runtime.tick()
        status = {**self.runtime.status(), "faults": len(self.faults.active)}
        if self.scenario is not None:
            status["scenario"] = dict(self.scenario)
        return status

    def check_trip(self, code: object) -> int | str:
        """``code`` as ``trip`` takes it, checked against the device's trip codes without tripping it
        (a scenario's steps are checked when it is read); ``BadRequest`` naming the valid ones."""
        if not isinstance(code, (int, str)) or isinstance(code, bool):
            raise BadRequest("\"code\" is a number or a name")
        if isinstance(code, str) and code.isascii():   # int() would read other digits as ASCII ones
            with contextlib.suppress(ValueError):
                code = int(code, 0)
        trips = self._trips()
        try:
            trips.check(code)
        except (KeyError, ValueError) as exc:
            reason = exc.args[0] if exc.args else exc
            raise BadRequest(f"{reason}; valid codes: {trips.codes()}") from None
        return code

    def _trips(self) -> DriveTrips:
        """The device's declared trips; the declaration's refusal where it has none."""
        trips = self.runtime.device.drive_trips()
        if trips is None:
            raise TRIPS.absent(self.runtime.device)
        return trips

    def trip(self, code: int | str) -> dict[str, Any]:
        code = self.check_trip(code)
        if not self.runtime.power.powered:
            raise StateRefused("the device is powered off (power-cycle): it cannot trip")
        now = self.runtime.tick()
        trips = self._trips()
        try:
            trip = trips.inject(code)
        except TripRefused as exc:
            raise StateRefused(str(exc)) from None
        except (KeyError, ValueError) as exc:
            reason = exc.args[0] if exc.args else exc
            raise BadRequest(f"{reason}; valid codes: {trips.codes()}") from None
        self.runtime.tick(now)
        fault = trip.fault_code
        return {"result": f"tripped: {trip.label}" + (f" (fault code 0x{fault:04X})" if fault is not None else ""),
                "trip": trip.label, "status": self.runtime.device.status_line()}

    def reset(self) -> dict[str, Any]:
        """A fault reset, now: the ACG's Drive Fault Reset, the MX2/RX Digital Operator's STOP/RESET key."""
        if not self.runtime.power.powered:
            raise StateRefused("the device is powered off (power-cycle): it cannot be reset")
        now = self.runtime.tick()
        trips = self._trips()
        try:
            cleared = trips.reset()
        except TripRefused as exc:
            raise StateRefused(str(exc)) from None
        self.runtime.tick(now)
        label = None if cleared is None else cleared.label
        return {"result": f"reset: {label} cleared" if label is not None else "reset: no trip to clear",
                "cleared": label, "status": self.runtime.device.status_line()}

    # -- faults -----------------------------------------------------------------------------------------
    async def fault(self, name: str, options: dict[str, Any] | None = None) -> dict[str, Any]:
        """Apply a fault (``options`` by their JSON keys); its record once its ports are closed or opened
        (at most ``SETTLE_S``: a long power-cycle answers while the power is off)."""
        if not isinstance(name, str):
            raise BadRequest("\"name\" names a fault: {\"name\": \"stop-producing\", \"options\": {...}}")
        if options is None:
            options = {}
        if not isinstance(options, dict):
            raise BadRequest("\"options\" is a JSON object")
        request = FaultRequest.build(name, options, JSON_SPELLING)
        fault = self.faults.apply(request)
        await self._settled()
        return fault.as_json(self.runtime.now())

    def faults_active(self) -> list[dict[str, Any]]:
        now = self.runtime.now()
        return [f.as_json(now) for f in self.faults.faults()]

    async def clear(self, fault: int | str | None = None) -> list[dict[str, Any]]:
        """Clear every active fault, or one by id, or those of one name; the faults cleared."""
        which = int(fault) if isinstance(fault, str) and is_whole_number(fault) else fault
        cleared = self.faults.clear(which)
        await self._settled()
        return [f.as_json() for f in cleared]

    async def _settled(self) -> None:
        """Wait for the ports a fault closes or opens, at most ``SETTLE_S``. A power-cycle whose power
        comes back within that time is waited for whole; a longer one answers as soon as its ports are
        closed, while the power is off (not when the wait runs out)."""
        loop = asyncio.get_running_loop()
        until = loop.time() + SETTLE_S
        with contextlib.suppress(asyncio.TimeoutError):
            await asyncio.wait_for(asyncio.shield(self.runtime.power.settled()), SETTLE_S)
            if not self.runtime.power.powered:
                back = max((f.until for f in self.faults.faults() if f.request.kind.lasts and f.until is not None),
                           default=None)
                if back is None or back > until:
                    return
            await asyncio.wait_for(asyncio.shield(self.faults.settle()), max(0.0, until - loop.time()))

    # -- power and link ---------------------------------------------------------------------------------
    async def power(self, action: str, off: str | float | None = None) -> Any:
        if action != "cycle":
            raise BadRequest(f"\"action\" {action!r}: the power takes \"cycle\"")
        return await self.fault("power-cycle", {"off": off} if off is not None else {})

    async def link(self, state: str) -> Any:
        if state not in ("unplug", "plug"):
            raise BadRequest(f"\"state\" {state!r}: unplug or plug")
        return await self.fault(state)

    # -- keypad parameters ------------------------------------------------------------------------------
    def _keypad(self) -> Keypad:
        keypad = self.runtime.device.keypad()
        if keypad is None:
            raise KEYPAD.absent(self.runtime.device)
        return keypad

    def parameter(self, code: str) -> dict[str, Any]:
        keypad = self._keypad()
        # A monitor (the output frequency, the output voltage) is read as of now, as ``parameters`` and
        # ``status`` read it: the simulation is moved to the present first, once an event loop runs the
        # device (before it serves, ``Adapter.keypad_parameter`` reads the device as it was built).
        try:
            now = self.runtime.now()
        except RuntimeError:
            now = None
        if now is not None:
            self.runtime.tick(now)
        return dict(keypad.get(code))

    def set_parameter(self, code: str, value: object, origin: str = "python", peer: str | None = None
                      ) -> dict[str, Any]:
        keypad = self._keypad()
        if isinstance(value, (dict, list, bool)) or value is None:
            raise BadRequest("\"value\" is in the keypad's unit (\"2.5\", 60, or an enumeration's name)")
        if not self.runtime.power.powered:
            raise WriteRefused(f"{code}: the device is powered off (power-cycle)")
        now = self.runtime.tick()
        register, raw = keypad.set(code, str(value), now)
        if self.events.watching:
            self.events.parameter_written(origin, **({"peer": peer} if peer is not None else {}),
                                          **keypad.write_fields(register, raw))
        self.runtime.tick(now)
        return dict(keypad.get(register.code))

    def parameters(self) -> dict[str, Any]:
        self.runtime.tick()
        return views.parameter_groups(self._keypad())

    # -- what a front panel shows ---------------------------------------------------------------------------
    def connections(self) -> dict[str, Any]:
        self.runtime.tick()
        return views.connections(self.runtime)

    @staticmethod
    def fault_table() -> list[dict[str, Any]]:
        return views.fault_table()

    def trips(self) -> list[dict[str, Any]]:
        trips = self.runtime.device.drive_trips()
        return [] if trips is None else [dict(choice) for choice in trips.choices()]

    # -- events -------------------------------------------------------------------------------------------
    def events_since(self, since: int | str = 0) -> list[dict[str, Any]]:
        if isinstance(since, str):
            number = whole_number("since", since)
        elif isinstance(since, int) and not isinstance(since, bool):
            number = since
        else:
            raise BadRequest("\"since\" is an event number")
        if number < 0:
            raise BadRequest("\"since\" is an event number (0 or more)")
        return [e.as_json() for e in self.events.since(number)[:MAX_EVENTS]]


__all__ = ["OPERATIONS", "OUTCOMES", "Argument", "DeviceService", "Operation", "Outcome", "check_arguments",
           "error_of", "is_whole_number", "outcome", "whole_number"]
