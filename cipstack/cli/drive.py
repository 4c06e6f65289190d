"""cipstack drive: a running emulator's command service over its control socket. One subcommand per
operation of the service (``cipstack.control.operations.OPERATIONS``), generated from it: status,
trip, fault / faults / clear, parameter / set-parameter, parameters, connections, fault-table, trips,
events, power, link."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from typing import Any

from ..cip.types import parse_int
from ..control.operations import OPERATIONS, Operation
from ..errors import PeerUnreachable
from .common import EXIT_OK, UsageError


# -- the control socket -----------------------------------------------------------------------------------
def _control(args: argparse.Namespace, request: dict[str, Any]) -> dict[str, Any]:
    from ..control import ControlError, ControlRefused, control_request, default_control_path

    path = args.control or default_control_path(args.port, args.host)
    try:
        reply = control_request(path, request, args.timeout)
    except ControlRefused as exc:
        raise UsageError(str(exc)) from None    # the emulator named what is wrong with the argument: exit 2
    except ControlError as exc:
        # Nothing of that name there, its state says no, no emulator there, no answer: exit 1
        # (``cipstack.control.service.OUTCOMES``).
        raise PeerUnreachable(str(exc)) from None
    reply.pop("ok", None)
    return reply


def _trip_code(text: str) -> int | str:
    try:
        return parse_int(text)
    except ValueError:
        return text.strip()


# -- what each operation prints without --json --------------------------------------------------------------
#: The share of a device's production slots skipped above which ``drive status`` says so.
OVERLOAD_SHARE = 0.01


def _status_text(reply: dict[str, Any]) -> str:
    rtu = reply.get("rtu")
    line = "" if not rtu else ("  rtu " + " ".join(f"{k} {v}" for k, v in rtu.items() if k != "device"))
    power = "" if reply.get("power", "on") == "on" else "  POWER OFF"
    link = "" if reply.get("link", "plugged") == "plugged" else "  UNPLUGGED"
    scenario = reply.get("scenario")
    if scenario:
        line += (f"  scenario {scenario['file']} {scenario['state']} {scenario['fired']}/{scenario['steps']}"
                 + (f" next {scenario['next']}" if scenario["next"] else ""))
    productions = reply.get("productions") or {}
    # Said where an operator looks first when an overloaded process skipped more than 1 % of the
    # device's production slots, as a fleet judges its workers; a device on time keeps its short line
    # (a production past its half-millisecond tolerance alone is a busy machine, not overload).
    sent, missed = productions.get("sent", 0), productions.get("missed", 0)
    late = (f" (productions late {productions.get('late', 0)}, missed {missed} of {sent + missed})"
            if missed > OVERLOAD_SHARE * (sent + missed) else "")
    return (f"{reply['status'] or '(no drive)'}{power}{link}  sessions {reply['sessions']}  class 3 "
            f"{reply['class3_connections']}  class 1 {reply['class1_connections']}{late}{line}")


def _status_json(reply: dict[str, Any]) -> dict[str, Any]:
    """Fields, not the console line: the drive's state, power and link, then the emulator's sessions and
    connections. A device without one drive (the CompoNet gateway) has its status line instead."""
    fields = reply.get("drive") or {"status": reply.get("status")}
    record = {**fields, "power": reply.get("power"), "link": reply.get("link"), "sessions": reply["sessions"],
              "class3_connections": reply["class3_connections"], "class1_connections": reply["class1_connections"],
              "faults": reply.get("faults", 0)}
    for extra in ("productions", "rtu", "scenario"):
        if extra in reply:
            record[extra] = reply[extra]
    return record


def _fault_words(fault: dict[str, Any]) -> str:
    """``1: drop --share 0.1``: a fault's record as the command line gives a fault."""
    from ..faults.model import format_value

    options = " ".join(f"--{k} {format_value(k, v)}" for k, v in fault["options"].items())
    return f"{fault['id']}: {fault['name']}" + (" " + options if options else "")


def _faults_text(reply: Any) -> str:
    lines = []
    for fault in reply:
        left = f"  ({fault['remaining_s']:g} s left)" if "remaining_s" in fault else ""
        lines.append(f"{_fault_words(fault)}  since {fault['applied']}{left}")
    return "\n".join(lines) or "no fault active"


def _fault_text(reply: dict[str, Any]) -> str:
    return f"fault {_fault_words(reply)}"


def _cleared_text(reply: list[dict[str, Any]]) -> str:
    return f"cleared {len(reply)} fault(s)"


def _parameter_text(reply: dict[str, Any]) -> str:
    unit = f" {reply['unit']}" if reply.get("unit") else ""
    return f"{reply.get('code')} ({reply.get('name')}) = {reply.get('value')}{unit}  raw {reply.get('raw')}"


def _events_text(reply: Any) -> str:
    lines = []
    for event in reply:
        rest = " ".join(f"{k}={v}" for k, v in event.items() if k not in ("number", "kind", "time", "monotonic"))
        lines.append(f"{event['number']:>6}  {event['time']}  {event['kind']}{'  ' + rest if rest else ''}")
    return "\n".join(lines) or "no event"


def _parameters_text(reply: dict[str, Any]) -> str:
    lines = [str(reply["keypad"])]
    for group in reply["groups"]:
        lines.append(f"[{group['group']}]")
        for p in group["parameters"]:
            unit = f" {p['unit']}" if p.get("unit") else ""
            access = "" if p["writable"] else "  read-only"
            lines.append(f"  {p['code']:<7} {p['name']:<28} {p['value']}{unit}  ({p['minimum']}..{p['maximum']})"
                         f"{access}")
    return "\n".join(lines)


def _connections_text(reply: dict[str, Any]) -> str:
    lines = [f"sessions {len(reply['sessions'])}" + "".join(f"  {s['peer']}" for s in reply["sessions"])]
    lines += [f"class 3 {c['id']} from {c['originator']}  requests {c['requests']}" for c in reply["class3"]]
    for c in reply["class1"]:
        run = "-" if c["run"] is None else "run" if c["run"] else "idle"
        lines.append(f"class 1 {c['name']} from {c['originator']}  rpi {c['ot_rpi_us']}/{c['to_rpi_us']} us  "
                     f"received {c['received']} lost {c['lost']} sent {c['sent']} late {c['late']}  {run}")
        for direction, data in (("O->T", c["output_data"]), ("T->O", c["input_data"])):
            if data is not None:
                fields = " ".join(f"{k}={int(v) if isinstance(v, bool) else v}" for k, v in data["fields"].items())
                lines.append(f"  {direction} {fields or data['hex'] or '(no data)'}")
    return "\n".join(lines)


def _fault_table_text(reply: list[dict[str, Any]]) -> str:
    return "\n".join(f"{f['name']:<22} {f['where']:<9} {f['summary']}"
                     + "".join(f"\n  {o['name']} {o['metavar']}: {o['help']}" for o in f["options"]) for f in reply)


def _trips_text(reply: list[dict[str, Any]]) -> str:
    return "\n".join(f"{t['code']!s:<20} fault code 0x{t['fault_code']:04X}  {t['label']}" for t in reply) \
        or "this device simulates no drive"


def _result_text(reply: Any) -> str:
    if isinstance(reply, dict) and "result" in reply:
        text = str(reply["result"])
        return text + (f"\n{reply['status']}" if isinstance(reply.get("status"), str) else "")
    return json.dumps(reply)


#: How each operation's reply reads on a console (``--json`` prints the reply itself).
_TEXT: dict[str, Callable[[Any], str]] = {"status": _status_text, "faults": _faults_text, "fault": _fault_text,
                                          "power": _fault_text, "link": _fault_text, "clear": _cleared_text,
                                          "parameter": _parameter_text, "set-parameter": _parameter_text,
                                          "events": _events_text, "parameters": _parameters_text,
                                          "connections": _connections_text, "fault-table": _fault_table_text,
                                          "trips": _trips_text}
_JSON: dict[str, Callable[[Any], Any]] = {"status": _status_json}


def cmd_drive_operation(args: argparse.Namespace) -> int:
    """Any operation: its arguments from the command line, by their JSON keys, to the control socket."""
    operation: Operation = args.operation
    request: dict[str, Any] = {"command": operation.name}
    for argument in operation.arguments:
        value = getattr(args, argument.key, None)
        if value is not None:
            request[argument.key] = value
    _print(args, operation.name, _control(args, request))
    return EXIT_OK


def _print(args: argparse.Namespace, operation: str, reply: dict[str, Any]) -> None:
    """The answer: with ``--json`` as the service gave it, else as a console line."""
    payload = reply["result"] if set(reply) == {"result"} else reply
    if args.json:
        print(json.dumps(_JSON.get(operation, lambda r: r)(payload)), flush=True)
    else:
        print(_TEXT.get(operation, _result_text)(payload), flush=True)


# -- faults: the fault's options as the command line gives them ----------------------------------------------
def _common_options(args: argparse.Namespace) -> list[str]:
    """Take ``--host``, ``--port``, ``--control``, ``--timeout`` and ``--json`` from the words after the
    fault's name (they may come anywhere on the line); the rest are the fault's own."""
    from pathlib import Path

    from .common import parse_duration

    common = argparse.ArgumentParser(add_help=False, allow_abbrev=False)
    common.add_argument("--host")
    common.add_argument("--port")
    common.add_argument("--control", type=Path)
    common.add_argument("--timeout")
    common.add_argument("--json", action="store_true")
    found, rest = common.parse_known_args(args.arguments)
    if found.host is not None:
        args.host = found.host
    if found.port is not None:
        try:
            args.port = parse_int(found.port)
        except ValueError:
            raise UsageError(f"--port: {found.port!r} is not a number") from None
    if found.control is not None:
        args.control = found.control
    if found.timeout is not None:
        args.timeout = parse_duration(found.timeout)
    args.json = args.json or found.json
    return list(rest)


def cmd_drive_fault(args: argparse.Namespace) -> int:
    """``fault NAME [OPTION...]``, checked here in the command line's own terms (``--share``) before it is
    sent; ``fault clear [ID|NAME]`` is the ``clear`` operation."""
    from ..faults import FaultError, parse_arguments

    rest = _common_options(args)
    if args.name == "clear":
        if len(rest) > 1:
            raise UsageError(f"clear takes one fault (its id or name), not {' '.join(rest)}")
        _print(args, "clear", _control(args, {"command": "clear", **({"fault": rest[0]} if rest else {})}))
        return EXIT_OK
    try:
        request = parse_arguments(args.name, rest)
    except FaultError as exc:
        raise UsageError(str(exc)) from None
    _print(args, "fault", _control(args, {"command": "fault", "name": request.name, "options": request.as_json()}))
    return EXIT_OK


def add_drive_commands(drive: Any, add_common: Callable[[argparse.ArgumentParser], None]) -> None:
    """One subcommand per operation of the command service, its arguments from the declaration
    (a positional for each argument marked so, ``--KEY`` for the others); ``add_common`` adds where the
    emulator is (``--host``, ``--port``, ``--control``, ``--timeout``, ``--json``)."""
    for operation in OPERATIONS:
        q = drive.add_parser(operation.name)
        if operation.name == "fault":
            q.add_argument("name", metavar="NAME", help="the fault (above), or clear [ID|NAME]")
            q.add_argument("arguments", nargs=argparse.REMAINDER, metavar="OPTION",
                           help="the fault's options (docs/faults.md), e.g. --share 0.1 --for 2s")
            q.set_defaults(func=cmd_drive_fault)
        else:
            for argument in operation.arguments:
                kind = _trip_code if argument.key == "code" and operation.name == "trip" else str
                if argument.positional:
                    q.add_argument(argument.key, metavar=argument.metavar or argument.key.upper(), type=kind,
                                   nargs=None if argument.required else "?", help=argument.help)
                else:
                    q.add_argument(f"--{argument.key}", metavar=argument.metavar or "VALUE", type=kind,
                                   help=argument.help)
            q.set_defaults(func=cmd_drive_operation, operation=operation)
        add_common(q)


__all__ = ["add_drive_commands", "cmd_drive_fault", "cmd_drive_operation"]
