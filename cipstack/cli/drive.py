"""cipstack drive: a running emulator's control socket (trip, status)."""

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
