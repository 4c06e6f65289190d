"""The operations of the command service, declared once (``cipstack.control.service``): their
arguments with their JSON keys and types, their HTTP route, their ``cipstack drive`` words. The HTTP
routes, ``/openapi.json`` and the ``cipstack drive`` subcommands are generated from this table; it
imports nothing, so that the command line's parser can read it at no cost."""

from __future__ import annotations

from dataclasses import dataclass


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


#: The Python types a JSON type names (a bool is no number here).
JSON_TYPES: dict[str, tuple[type, ...]] = {"string": (str,), "integer": (int,), "number": (int, float),
                                           "object": (dict,), "string|integer": (str, int),
                                           "string|number": (str, int, float)}


@dataclass(frozen=True)
class Operation:
    name: str
    summary: str
    method: str
    path: str
    arguments: tuple[Argument, ...] = ()
    #: HTTP status of success (201 for what creates a fault).
    created: bool = False
    #: Also served without its path argument (``DELETE /faults`` clears every fault).
    optional_path: bool = False

    def argument(self, key: str) -> Argument | None:
        return next((a for a in self.arguments if a.key == key), None)


_CODE = Argument("code", "string", "keypad code: the ACG's (drv, Frq, ACC, CM.23, ...), an MX2/RX function code "
                 "(F001, A004, P044, ...)", where="path", required=True, positional=True, metavar="CODE")

OPERATIONS: tuple[Operation, ...] = (
    Operation("status", "the drive's state, power and link, sessions and connections, active faults", "GET", "/status"),
    Operation("trip", "trip the drive with a fault code of its manual (decimal, 0x hex or its name)", "POST", "/trip",
              (Argument("code", "string|integer", "fault code of the drive's manual (0x4200 on the ACG, 5 on the "
                        "MX2/RX) or its name (OverHeat, E05)", required=True, positional=True, metavar="CODE"),)),
    Operation("reset", "reset the drive's trip, as its manual's fault reset does", "POST", "/reset"),
    Operation("fault", "apply a fault (cipstack.faults)", "POST", "/faults",
              (Argument("name", "string", "the fault", required=True, positional=True, metavar="NAME"),
               Argument("options", "object", "the fault's options by name (share, every, by, jitter, connection, "
                        "for, off, ...)")), created=True),
    Operation("faults", "the faults active now", "GET", "/faults"),
    Operation("clear", "clear every active fault, or one by id or name", "DELETE", "/faults/{fault}",
              (Argument("fault", "string|integer", "a fault's id, or a fault name (all of that name)", where="path",
                        positional=True, metavar="ID|NAME"),), optional_path=True),
    Operation("parameter", "a keypad parameter: code, name, value in the keypad's unit, raw, unit, address",
              "GET", "/parameters/{code}", (_CODE,)),
    Operation("set-parameter", "set a keypad parameter now, in the keypad's unit (not saved)", "PUT",
              "/parameters/{code}",
              (_CODE, Argument("value", "string|number", "the value in the keypad's unit (\"2.5\", 60, or an "
                               "enumeration's name)", required=True, positional=True, metavar="VALUE"))),
    Operation("parameters", "every keypad parameter, group by group: value, unit, range, access", "GET",
              "/parameters"),
    Operation("connections", "every session, class 3 and class 1 connection; class 1 with its counters and data "
              "by field names", "GET", "/connections"),
    Operation("fault-table", "every fault a device can be given, with its options", "GET", "/fault-table"),
    Operation("trips", "the trips of the drive's manual that `trip` takes", "GET", "/trips"),
    Operation("events", "the events after event number `since`, oldest first", "GET", "/events",
              (Argument("since", "integer", "an event number (0: every event kept)", where="query",
                        metavar="N"),)),
    Operation("power", "the power: `cycle` it (off for `off`, then on again)", "POST", "/power",
              (Argument("action", "string", "cycle", required=True, positional=True, metavar="cycle"),
               Argument("off", "string|number", "how long the power stays off (e.g. 2s; at most 3600s)",
                        metavar="DURATION"))),
    Operation("link", "the Ethernet link: `unplug` or `plug` the cable", "POST", "/link",
              (Argument("state", "string", "unplug or plug", required=True, positional=True,
                        metavar="unplug|plug"),)),
)
OPERATION_BY_NAME = {op.name: op for op in OPERATIONS}



__all__ = ["JSON_TYPES", "OPERATIONS", "OPERATION_BY_NAME", "Argument", "Operation"]
