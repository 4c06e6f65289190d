"""cipstack drive: a running emulator's control socket (trip, status, faults)."""

from __future__ import annotations

import argparse
import json
from typing import Any

from ..cip.types import parse_int
from .common import (
    EXIT_OK,
    UsageError,
    _emit,
)


# -- emulator control ---------------------------------------------------------------------------------------
def _control(args: argparse.Namespace, request: dict[str, Any]) -> dict[str, Any]:
    from ..control import ControlError, ControlRefused, control_request, default_control_path

    path = args.control or default_control_path(args.port, args.host)
    try:
        reply = control_request(path, request, args.timeout)
    except ControlRefused as exc:
        raise UsageError(str(exc)) from None    # the emulator named what is wrong with the argument
    except ControlError as exc:
        raise ConnectionError(str(exc)) from None   # no emulator there, no answer, or its state says no: exit 1
    reply.pop("ok", None)
    return reply


def _trip_code(text: str) -> int | str:
    try:
        return parse_int(text)
    except ValueError:
        return text.strip()


def cmd_drive_trip(args: argparse.Namespace) -> int:
    reply = _control(args, {"command": "trip", "code": args.code})
    _emit(args, reply, f"{reply['result']}" + (f"\n{reply['status']}" if reply.get("status") else ""))
    return EXIT_OK


def cmd_drive_status(args: argparse.Namespace) -> int:
    reply = _control(args, {"command": "status"})
    if args.json:
        # Fields, not the console line: the drive's state, then the emulator's sessions and connections.
        # A device without one drive (the CompoNet gateway) has its status lines instead.
        fields = reply.get("drive") or {"status": reply.get("status")}
        record = {**fields, "sessions": reply["sessions"],
                  "class3_connections": reply["class3_connections"], "class1_connections": reply["class1_connections"]}
        if "rtu" in reply:
            record["rtu"] = reply["rtu"]
        print(json.dumps(record), flush=True)
        return EXIT_OK
    rtu = reply.get("rtu")
    line = "" if not rtu else ("  rtu " + " ".join(f"{k} {v}" for k, v in rtu.items() if k != "device"))
    print(f"{reply['status'] or '(no drive)'}  sessions {reply['sessions']}  class 3 "
          f"{reply['class3_connections']}  class 1 {reply['class1_connections']}{line}", flush=True)
    return EXIT_OK


# -- faults (cipstack.faults) -------------------------------------------------------------------------------
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
    from ..faults import FaultError, parse_arguments

    rest = _common_options(args)
    if args.name == "clear":
        if len(rest) > 1:
            raise UsageError(f"clear takes one fault (its id or name), not {' '.join(rest)}")
        which: int | str | None = None
        if rest:
            try:
                which = parse_int(rest[0])
            except ValueError:
                which = rest[0]
        reply = _control(args, {"command": "clear", "which": which})
        _emit(args, reply, reply["result"])
        return EXIT_OK
    try:
        request = parse_arguments(args.name, rest)
    except FaultError as exc:
        raise UsageError(str(exc)) from None
    reply = _control(args, {"command": "fault", "name": request.name, "options": request.as_json()})
    _emit(args, reply, reply["result"])
    return EXIT_OK


def cmd_drive_faults(args: argparse.Namespace) -> int:
    from ..faults.model import format_value

    reply = _control(args, {"command": "faults"})
    faults = reply["faults"]
    if args.json:
        print(json.dumps(faults), flush=True)
        return EXIT_OK
    for fault in faults:
        options = " ".join(f"--{k} {format_value(k, v)}" for k, v in fault["options"].items())
        left = f"  ({fault['remaining_s']:g} s left)" if "remaining_s" in fault else ""
        print(f"{fault['id']}: {fault['name']}{' ' + options if options else ''}  since {fault['applied']}{left}",
              flush=True)
    if not faults:
        print("no fault active", flush=True)
    return EXIT_OK
