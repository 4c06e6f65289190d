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
from ..control.operations import OPERATION_BY_NAME, OPERATIONS, Operation
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


def cmd_drive_operation(args: argparse.Namespace) -> int:
    """Any operation: its arguments from the command line, by their JSON keys, to the control socket."""
    operation: Operation = args.operation
    request: dict[str, Any] = {"command": operation.name}
    for argument in operation.arguments:
        value = getattr(args, argument.key, None)
        if value is not None:
            request[argument.key] = value
    _print(args, operation, _control(args, request))
    return EXIT_OK


def _print(args: argparse.Namespace, operation: Operation, reply: dict[str, Any]) -> None:
    """The answer: with ``--json`` as the service gave it (or the fields its declaration picks), else as
    its declaration's console line."""
    payload = reply["result"] if set(reply) == {"result"} else reply
    if args.json:
        print(json.dumps(operation.json(payload)), flush=True)
    else:
        print(operation.text(payload), flush=True)


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
    sent; ``fault clear [ID|NAME]`` is the operation its declaration names ``instead``."""
    from ..faults import FaultError, parse_arguments

    operation: Operation = args.operation
    rest = _common_options(args)
    if operation.instead and args.name == operation.instead:
        instead = OPERATION_BY_NAME[operation.instead]
        # Its one argument, positional, is the word after it.
        key = instead.arguments[0].key
        if len(rest) > 1:
            raise UsageError(f"{instead.name} takes one fault (its id or name), not {' '.join(rest)}")
        _print(args, instead, _control(args, {"command": instead.name, **({key: rest[0]} if rest else {})}))
        return EXIT_OK
    try:
        request = parse_arguments(args.name, rest)
    except FaultError as exc:
        raise UsageError(str(exc)) from None
    _print(args, operation, _control(args, {"command": operation.name, "name": request.name,
                                            "options": request.as_json()}))
    return EXIT_OK


def add_drive_commands(drive: Any, add_common: Callable[[argparse.ArgumentParser], None]) -> None:
    """One subcommand per operation of the command service, its arguments from the declaration
    (a positional for each argument marked so, ``--KEY`` for the others); ``add_common`` adds where the
    emulator is (``--host``, ``--port``, ``--control``, ``--timeout``, ``--json``)."""
    for operation in OPERATIONS:
        q = drive.add_parser(operation.name)
        if operation.free_words:
            first = operation.arguments[0]
            q.add_argument(first.key, metavar=first.metavar, help=first.cli_help or first.help)
            q.add_argument("arguments", nargs=argparse.REMAINDER, metavar="OPTION",
                           help="the fault's options (docs/faults.md), e.g. --share 0.1 --for 2s")
            q.set_defaults(func=cmd_drive_fault, operation=operation)
        else:
            for argument in operation.arguments:
                kind = _trip_code if argument.number_or_name else str
                if argument.positional:
                    q.add_argument(argument.key, metavar=argument.metavar or argument.key.upper(), type=kind,
                                   nargs=None if argument.required else "?", help=argument.help)
                else:
                    q.add_argument(f"--{argument.key}", metavar=argument.metavar or "VALUE", type=kind,
                                   help=argument.help)
            q.set_defaults(func=cmd_drive_operation, operation=operation)
        add_common(q)


__all__ = ["add_drive_commands", "cmd_drive_fault", "cmd_drive_operation"]
