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
from typing import Any

from . import console


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


#: The Python types a JSON type names (a bool is no number here).
JSON_TYPES: dict[str, tuple[type, ...]] = {"string": (str,), "integer": (int,), "number": (int, float),
                                           "object": (dict,), "string|integer": (str, int),
                                           "string|number": (str, int, float)}


@dataclass(frozen=True)
class Operation:
    """One operation: its name (the control socket's ``command``, the ``cipstack drive`` subcommand, the
    OpenAPI ``operationId``), its help text, its HTTP route, its handler (the name of the
    ``DeviceService`` method that serves it, called with the record's fields), its argument record and
    its console formatters."""

    name: str
    summary: str
    method: str
    path: str
    handler: str
    record: type = NoArguments
    #: How its reply reads on a console, and what ``--json`` prints of it.
    text: Callable[[Any], str] = console.result_text
    json: Callable[[Any], Any] = console.as_given
    #: HTTP status of success (201 for what creates a fault).
    created: bool = False
    #: Also served without its path argument (``DELETE /faults`` clears every fault).
    optional_path: bool = False
    #: The handler is told who asks (``origin``, ``peer``): what the event it records says.
    tells_origin: bool = False
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

    def argument(self, key: str) -> Argument | None:
        return next((a for a in self.arguments if a.key == key), None)

    def given(self, record: Any) -> dict[str, Any]:
        """The handler's keyword arguments from an argument record: the fields given (not None)."""
        return {f.name: value for f in dataclasses.fields(record) if (value := getattr(record, f.name)) is not None}


OPERATIONS: tuple[Operation, ...] = (
    Operation("status", "the drive's state, power and link, sessions and connections, active faults", "GET",
              "/status", "status", text=console.status_text, json=console.status_json),
    Operation("trip", "trip the drive with a fault code of its manual (decimal, 0x hex or its name)", "POST", "/trip",
              "trip", TripArguments),
    Operation("reset", "reset the drive's trip, as its manual's fault reset does", "POST", "/reset", "reset"),
    Operation("fault", "apply a fault (cipstack.faults)", "POST", "/faults", "fault", FaultArguments,
              text=console.fault_text, created=True, body_hint=" (a fault's options go in \"options\")",
              free_words=True, instead="clear"),
    Operation("faults", "the faults active now", "GET", "/faults", "faults_active", text=console.faults_text),
    Operation("clear", "clear every active fault, or one by id or name", "DELETE", "/faults/{fault}", "clear",
              ClearArguments, text=console.cleared_text, optional_path=True),
    Operation("parameter", "a keypad parameter: code, name, value in the keypad's unit, raw, unit, address",
              "GET", "/parameters/{code}", "parameter", ParameterArguments, text=console.parameter_text),
    Operation("set-parameter", "set a keypad parameter now, in the keypad's unit (not saved)", "PUT",
              "/parameters/{code}", "set_parameter", SetParameterArguments, text=console.parameter_text,
              tells_origin=True),
    Operation("parameters", "every keypad parameter, group by group: value, unit, range, access", "GET",
              "/parameters", "parameters", text=console.parameters_text),
    Operation("connections", "every session, class 3 and class 1 connection; class 1 with its counters and data "
              "by field names", "GET", "/connections", "connections", text=console.connections_text),
    Operation("fault-table", "every fault a device can be given, with its options", "GET", "/fault-table",
              "fault_table", text=console.fault_table_text),
    Operation("trips", "the trips of the drive's manual that `trip` takes", "GET", "/trips", "trips",
              text=console.trips_text),
    Operation("events", "the events after event number `since`, oldest first", "GET", "/events", "events_since",
              EventsArguments, text=console.events_text),
    Operation("power", "the power: `cycle` it (off for `off`, then on again)", "POST", "/power", "power",
              PowerArguments, text=console.fault_text),
    Operation("link", "the Ethernet link: `unplug` or `plug` the cable", "POST", "/link", "link", LinkArguments,
              text=console.fault_text),
)
OPERATION_BY_NAME = {op.name: op for op in OPERATIONS}


__all__ = ["JSON_TYPES", "OPERATIONS", "OPERATION_BY_NAME", "Argument", "NoArguments", "Operation", "argument",
           "arguments_of"]
