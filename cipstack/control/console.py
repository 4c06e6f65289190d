"""How each operation's reply reads on a console (``cipstack drive`` without ``--json``), and the
fields ``--json`` prints where they are not the reply itself. Each operation's declaration
(``cipstack.control.operations``) names its formatter here; this module imports nothing of ours at
import time, so that the command line's parser reads the declarations at no cost."""

from __future__ import annotations

import json
from typing import Any

#: The share of a device's production slots skipped above which ``drive status`` says so.
OVERLOAD_SHARE = 0.01


def status_text(reply: dict[str, Any]) -> str:
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


def status_json(reply: dict[str, Any]) -> dict[str, Any]:
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


def fault_words(fault: dict[str, Any]) -> str:
    """``1: drop --share 0.1``: a fault's record as the command line gives a fault."""
    from ..faults.model import format_value

    options = " ".join(f"--{k} {format_value(k, v)}" for k, v in fault["options"].items())
    return f"{fault['id']}: {fault['name']}" + (" " + options if options else "")


def faults_text(reply: Any) -> str:
    lines = []
    for fault in reply:
        left = f"  ({fault['remaining_s']:g} s left)" if "remaining_s" in fault else ""
        lines.append(f"{fault_words(fault)}  since {fault['applied']}{left}")
    return "\n".join(lines) or "no fault active"


def fault_text(reply: dict[str, Any]) -> str:
    return f"fault {fault_words(reply)}"


def cleared_text(reply: list[dict[str, Any]]) -> str:
    return f"cleared {len(reply)} fault(s)"


def parameter_text(reply: dict[str, Any]) -> str:
    unit = f" {reply['unit']}" if reply.get("unit") else ""
    return f"{reply.get('code')} ({reply.get('name')}) = {reply.get('value')}{unit}  raw {reply.get('raw')}"


def events_text(reply: Any) -> str:
    lines = []
    for event in reply:
        rest = " ".join(f"{k}={v}" for k, v in event.items() if k not in ("number", "kind", "time", "monotonic"))
        lines.append(f"{event['number']:>6}  {event['time']}  {event['kind']}{'  ' + rest if rest else ''}")
    return "\n".join(lines) or "no event"


def parameters_text(reply: dict[str, Any]) -> str:
    lines = [str(reply["keypad"])]
    for group in reply["groups"]:
        lines.append(f"[{group['group']}]")
        for p in group["parameters"]:
            unit = f" {p['unit']}" if p.get("unit") else ""
            access = "" if p["writable"] else "  read-only"
            lines.append(f"  {p['code']:<7} {p['name']:<28} {p['value']}{unit}  ({p['minimum']}..{p['maximum']})"
                         f"{access}")
    return "\n".join(lines)


def connections_text(reply: dict[str, Any]) -> str:
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


def fault_table_text(reply: list[dict[str, Any]]) -> str:
    return "\n".join(f"{f['name']:<22} {f['where']:<9} {f['summary']}"
                     + "".join(f"\n  {o['name']} {o['metavar']}: {o['help']}" for o in f["options"]) for f in reply)


def trips_text(reply: list[dict[str, Any]]) -> str:
    return "\n".join(f"{t['code']!s:<20} fault code 0x{t['fault_code']:04X}  {t['label']}" for t in reply) \
        or "this device simulates no drive"


def result_text(reply: Any) -> str:
    if isinstance(reply, dict) and "result" in reply:
        text = str(reply["result"])
        return text + (f"\n{reply['status']}" if isinstance(reply.get("status"), str) else "")
    return json.dumps(reply)


def as_given(reply: Any) -> Any:
    """``--json`` of an operation whose fields are the reply itself."""
    return reply


__all__ = ["OVERLOAD_SHARE", "as_given", "cleared_text", "connections_text", "events_text", "fault_table_text",
           "fault_text", "fault_words", "faults_text", "parameter_text", "parameters_text", "result_text",
           "status_json", "status_text", "trips_text"]
