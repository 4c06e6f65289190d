"""The operations of the command service, each declared once (``cipstack.control.service``): its
handler (the service's method), its arguments as a typed record (a frozen dataclass whose fields are
the JSON keys, with where HTTP carries each and how the command line takes it), its HTTP route, its
console formatter and its help text. The HTTP routes, ``/openapi.json``, the ``cipstack drive``
subcommands, the control socket, scenarios and the pytest plugin are generated from, or call through,
this table alone: no surface asks an operation's name what it is. It imports nothing heavy, so that
the command line's parser can read it at no cost."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from . import console

if TYPE_CHECKING:
    from ..errors import CipstackError
    from .service import DeviceService


@dataclass(frozen=True)
class Argument:
    """An operation's argument: its JSON key, its JSON type, where HTTP carries it, and for the command
    line its metavar (positional when ``positional``)."""

    key: str
    json_type: str
    help: str
    where: str = "body"         # "path", "query" or "body"
    required: bool = False
    positional: bool = False
    metavar: str = ""
    #: The command line reads it as a number when it is one (decimal or 0x hex), else as text.
    number_or_name: bool = False
    #: The command line's help, where it says more than the JSON key's (``fault NAME``: or ``clear``).
    cli_help: str = ""
    #: The values it takes, for ``/openapi.json`` (called when the document is made).
    choices: Callable[[], list[str]] | None = None


def argument(json_type: str, help: str, *, where: str = "body", positional: bool = False, metavar: str = "",
             number_or_name: bool = False, cli_help: str = "", choices: Callable[[], list[str]] | None = None
             ) -> dict[str, Any]:
    """A field's metadata in an argument record: its declaration as ``Argument`` (the key is the field's
    name; a field without a default is required, an optional one defaults to None: not given)."""
    return {"argument": dict(json_type=json_type, help=help, where=where, positional=positional, metavar=metavar,
                             number_or_name=number_or_name, cli_help=cli_help, choices=choices)}


def arguments_of(record: type) -> tuple[Argument, ...]:
    """The arguments an argument record declares, in its fields' order."""
    return tuple(Argument(f.name, required=f.default is dataclasses.MISSING, **f.metadata["argument"])
                 for f in dataclasses.fields(record))


# -- the argument records ------------------------------------------------------------------------------
@dataclass(frozen=True)
class NoArguments:
    """An operation that takes no argument."""


_CODE_HELP = "keypad code: the ACG's (drv, Frq, ACC, CM.23, ...), an MX2/RX function code (F001, A004, P044, ...)"


def _fault_names() -> list[str]:
    from ..faults import FAULTS

    return list(FAULTS)


@dataclass(frozen=True, kw_only=True)
class TripArguments:
    code: int | str = field(metadata=argument(
        "string|integer", "fault code of the drive's manual (0x4200 on the ACG, 5 on the MX2/RX) or its name "
        "(OverHeat, E05)", positional=True, metavar="CODE", number_or_name=True))


@dataclass(frozen=True, kw_only=True)
class FaultArguments:
    name: str = field(metadata=argument(
        "string", "the fault", positional=True, metavar="NAME", cli_help="the fault (above), or clear [ID|NAME]",
        choices=_fault_names))
    options: dict[str, Any] | None = field(default=None, metadata=argument(
        "object", "the fault's options by name (share, every, by, jitter, connection, for, off, ...)"))


@dataclass(frozen=True, kw_only=True)
class ClearArguments:
    fault: int | str | None = field(default=None, metadata=argument(
        "string|integer", "a fault's id, or a fault name (all of that name)", where="path", positional=True,
        metavar="ID|NAME"))


@dataclass(frozen=True, kw_only=True)
class ParameterArguments:
    code: str = field(metadata=argument("string", _CODE_HELP, where="path", positional=True, metavar="CODE"))


@dataclass(frozen=True, kw_only=True)
class SetParameterArguments:
    code: str = field(metadata=argument("string", _CODE_HELP, where="path", positional=True, metavar="CODE"))
    value: str | int | float = field(metadata=argument(
        "string|number", "the value in the keypad's unit (\"2.5\", 60, or an enumeration's name)", positional=True,
        metavar="VALUE"))


@dataclass(frozen=True, kw_only=True)
class EventsArguments:
    since: int | str | None = field(default=None, metadata=argument(
        "integer", "an event number (0: every event kept)", where="query", metavar="N"))


@dataclass(frozen=True, kw_only=True)
class PowerArguments:
    action: str = field(metadata=argument("string", "cycle", positional=True, metavar="cycle",
                                          choices=lambda: ["cycle"]))
    off: str | float | None = field(default=None, metadata=argument(
        "string|number", "how long the power stays off (e.g. 2s; at most 3600s)", metavar="DURATION"))


@dataclass(frozen=True, kw_only=True)
class LinkArguments:
    state: str = field(metadata=argument("string", "unplug or plug", positional=True, metavar="unplug|plug",
                                         choices=lambda: ["unplug", "plug"]))


@dataclass(frozen=True)
class Caller:
    """Who asks for an operation: what the event of a parameter write records."""

    origin: str = "python"
    peer: str | None = None


#: An operation's handler: the service, the operation's argument record and who asks; its answer, or an
#: awaitable of it.
Handler = Callable[["DeviceService", Any, Caller], Any]


@dataclass(frozen=True)
class Capability:
    """What an operation needs the device to declare: a device whose declaration lacks it is refused the
    operation before the handler runs, with the error ``absent`` makes."""

    name: str
    #: The device's declaration of it (``Device.drive_trips()``, ``Device.keypad()``): None where absent.
    declared: Callable[[Any], Any]
    absent: Callable[[Any], CipstackError]


def _no_drive(device: Any) -> CipstackError:
    from ..devices.base import NoDrive

    return NoDrive(f"{device.identity_info.product_name}: this profile simulates no drive")


def _no_keypad(device: Any) -> CipstackError:
    from ..devices.keypad import NoKeypad
    from ..devices.profiles import keypad_families

    return NoKeypad(f"{device.identity_info.product_name}: this device has no keypad (keypad parameters are a "
                    f"drive's: {keypad_families()}); write its parameters over CIP")


#: A simulated drive's trips (``Device.drive_trips``).
TRIPS = Capability("trips", lambda device: device.drive_trips(), _no_drive)
#: A keypad's parameters by code (``Device.keypad``).
KEYPAD = Capability("keypad", lambda device: device.keypad(), _no_keypad)


@dataclass(frozen=True)
class StepKind:
    """An operation as a scenario's step takes it (``cipstack.control.scenario``): ``KEY = VALUE`` in a
    ``[[step]]`` table, the value being the operation's first argument (``true`` where it has none or
    that one is optional), its other arguments keys of the step by their JSON names."""

    key: str
    #: Checks the argument record when the file is read (the error of ``cipstack.faults`` for a fault's
    #: options) and says what the step does, for its line; None: its words are the generic ones.
    check: Callable[[Any], str] | None = None
    #: Checks what only the device can tell (a trip's code), before the device serves.
    on_device: Callable[[DeviceService, Any], object] | None = None


def _fault_step(arguments: FaultArguments) -> str:
    from ..faults import FaultRequest
    from ..faults.model import JSON_SPELLING

    return "fault " + FaultRequest.build(arguments.name, arguments.options or {}, JSON_SPELLING).describe()


def _clear_step(arguments: ClearArguments) -> str:
    from ..errors import BadRequest
    from ..faults.model import kind_of

    if arguments.fault is None:
        return "clear"
    if not isinstance(arguments.fault, str):
        # A fault's id is given when it is applied, after the file is read: a step clears by name.
        raise BadRequest(f"clear = {arguments.fault}: clear is true or a fault's name")
    kind_of(arguments.fault)      # a name no fault has is refused when the file is read
    return f"clear {arguments.fault}"


def _power_step(arguments: PowerArguments) -> str:
    from ..faults.model import parse_duration

    off = "" if arguments.off is None else f" --off {parse_duration(arguments.off):g}s"
    return f"power {arguments.action}{off}"


#: The Python types a JSON type names (a bool is no number here).
JSON_TYPES: dict[str, tuple[type, ...]] = {"string": (str,), "integer": (int,), "number": (int, float),
                                           "object": (dict,), "string|integer": (str, int),
                                           "string|number": (str, int, float)}


@dataclass(frozen=True)
class Operation:
    """One operation: its name (the control socket's ``command``, the ``cipstack drive`` subcommand, the
    OpenAPI ``operationId``), its help text, its HTTP route, its handler (called with the service, the
    argument record and the caller), its argument record, what it needs the device to declare and its
    console formatters."""

    name: str
    summary: str
    method: str
    path: str
    handler: Handler
    record: type = NoArguments
    #: What the device must declare for it (None: every device serves it).
    needs: Capability | None = None
    #: How a scenario's step takes it; None for what no step does (a read).
    step: StepKind | None = None
    #: The method of the pytest plugin's device that calls it (``cipstack.testing``): "" for the name's
    #: own words (``set-parameter``: ``set_parameter``), None for none.
    python: str | None = ""
    #: How its reply reads on a console, and what ``--json`` prints of it.
    text: Callable[[Any], str] = console.result_text
    json: Callable[[Any], Any] = console.as_given
    #: HTTP status of success (201 for what creates a fault).
    created: bool = False
    #: Also served without its path argument (``DELETE /faults`` clears every fault).
    optional_path: bool = False
    #: Said after the keys an HTTP body takes when it holds another.
    body_hint: str = ""
    #: The command line takes its last words as they come (a fault's options, checked by the fault
    #: model in the command line's own terms), and this word first names the operation given instead
    #: (``fault clear 3`` is ``clear 3``).
    free_words: bool = False
    instead: str = ""
    arguments: tuple[Argument, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "arguments", arguments_of(self.record))

    @property
    def python_name(self) -> str | None:
        """The plugin's method for it, or None."""
        return self.name.replace("-", "_") if self.python == "" else self.python

    def argument(self, key: str) -> Argument | None:
        return next((a for a in self.arguments if a.key == key), None)

    def given(self, record: Any) -> dict[str, Any]:
        """The JSON arguments of an argument record: the fields given (not None)."""
        return {f.name: value for f in dataclasses.fields(record) if (value := getattr(record, f.name)) is not None}


# -- the handlers: each operation bound to what serves it -------------------------------------------------
def _status(service: DeviceService, _: NoArguments, caller: Caller) -> Any:
    return service.status()


def _trip(service: DeviceService, arguments: TripArguments, caller: Caller) -> Any:
    return service.trip(arguments.code)


def _reset(service: DeviceService, _: NoArguments, caller: Caller) -> Any:
    return service.reset()


def _fault(service: DeviceService, arguments: FaultArguments, caller: Caller) -> Any:
    return service.fault(arguments.name, arguments.options)


def _faults(service: DeviceService, _: NoArguments, caller: Caller) -> Any:
    return service.faults_active()


def _clear(service: DeviceService, arguments: ClearArguments, caller: Caller) -> Any:
    return service.clear(arguments.fault)


def _parameter(service: DeviceService, arguments: ParameterArguments, caller: Caller) -> Any:
    return service.parameter(arguments.code)


def _set_parameter(service: DeviceService, arguments: SetParameterArguments, caller: Caller) -> Any:
    return service.set_parameter(arguments.code, arguments.value, caller.origin, caller.peer)


def _parameters(service: DeviceService, _: NoArguments, caller: Caller) -> Any:
    return service.parameters()


def _connections(service: DeviceService, _: NoArguments, caller: Caller) -> Any:
    return service.connections()


def _fault_table(service: DeviceService, _: NoArguments, caller: Caller) -> Any:
    return service.fault_table()


def _trips(service: DeviceService, _: NoArguments, caller: Caller) -> Any:
    return service.trips()


def _events(service: DeviceService, arguments: EventsArguments, caller: Caller) -> Any:
    return service.events_since(0 if arguments.since is None else arguments.since)


def _power(service: DeviceService, arguments: PowerArguments, caller: Caller) -> Any:
    return service.power(arguments.action, arguments.off)


def _link(service: DeviceService, arguments: LinkArguments, caller: Caller) -> Any:
    return service.link(arguments.state)


OPERATIONS: tuple[Operation, ...] = (
    Operation("status", "the drive's state, power and link, sessions and connections, active faults", "GET",
              "/status", _status, text=console.status_text, json=console.status_json),
    Operation("trip", "trip the drive with a fault code of its manual (decimal, 0x hex or its name)", "POST", "/trip",
              _trip, TripArguments, needs=TRIPS,
              step=StepKind("trip", on_device=lambda service, arguments: service.check_trip(arguments.code))),
    Operation("reset", "reset the drive's trip, as its manual's fault reset does", "POST", "/reset", _reset,
              needs=TRIPS, step=StepKind("reset")),
    Operation("fault", "apply a fault (cipstack.faults)", "POST", "/faults", _fault, FaultArguments,
              text=console.fault_text, created=True, body_hint=" (a fault's options go in \"options\")",
              free_words=True, instead="clear", step=StepKind("fault", _fault_step)),
    Operation("faults", "the faults active now", "GET", "/faults", _faults, text=console.faults_text),
    Operation("clear", "clear every active fault, or one by id or name", "DELETE", "/faults/{fault}", _clear,
              ClearArguments, text=console.cleared_text, optional_path=True, step=StepKind("clear", _clear_step),
              python="clear_faults"),
    Operation("parameter", "a keypad parameter: code, name, value in the keypad's unit, raw, unit, address",
              "GET", "/parameters/{code}", _parameter, ParameterArguments, needs=KEYPAD, text=console.parameter_text),
    Operation("set-parameter", "set a keypad parameter now, in the keypad's unit (not saved)", "PUT",
              "/parameters/{code}", _set_parameter, SetParameterArguments, needs=KEYPAD,
              text=console.parameter_text),
    Operation("parameters", "every keypad parameter, group by group: value, unit, range, access", "GET",
              "/parameters", _parameters, needs=KEYPAD, text=console.parameters_text),
    Operation("connections", "every session, class 3 and class 1 connection; class 1 with its counters and data "
              "by field names", "GET", "/connections", _connections, text=console.connections_text),
    Operation("fault-table", "every fault a device can be given, with its options", "GET", "/fault-table",
              _fault_table, text=console.fault_table_text),
    # Not refused without a drive: an empty list is how a device without trips shows none.
    Operation("trips", "the trips of the drive's manual that `trip` takes", "GET", "/trips", _trips,
              text=console.trips_text),
    # The plugin's device gives the events as records of their own (``events``, ``wait_for``), not as JSON.
    Operation("events", "the events after event number `since`, oldest first", "GET", "/events", _events,
              EventsArguments, text=console.events_text, python=None),
    Operation("power", "the power: `cycle` it (off for `off`, then on again)", "POST", "/power", _power,
              PowerArguments, text=console.fault_text, step=StepKind("power", _power_step)),
    Operation("link", "the Ethernet link: `unplug` or `plug` the cable", "POST", "/link", _link, LinkArguments,
              text=console.fault_text, step=StepKind("link")),
)
OPERATION_BY_NAME = {op.name: op for op in OPERATIONS}


__all__ = ["JSON_TYPES", "KEYPAD", "OPERATIONS", "OPERATION_BY_NAME", "TRIPS", "Argument", "Caller", "Capability",
           "Handler", "NoArguments", "Operation", "StepKind", "argument", "arguments_of"]
