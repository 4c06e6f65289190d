"""What a front panel shows of a running device, as JSON, read from its runtime: every keypad
parameter group by group, every session and connection with its data decoded by field names, the
fault table and the trips a drive takes. Pure readers: they change nothing."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..devices.keypad import choices, record, shown_value
from ..devices.registers import RegisterError

if TYPE_CHECKING:
    from ..devices.keypad import Keypad
    from ..devices.registers import Register
    from ..eip.target.io_target import IoConnection
    from ..runtime import DeviceRuntime


def parameter_groups(keypad: Keypad) -> dict[str, Any]:
    """Every parameter of ``keypad`` with its value, range and access, group by group."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for register in keypad.codes.listed:
        groups.setdefault(register.group, []).append(_parameter(keypad, register))
    return {"keypad": keypad.codes.name,
            "groups": [{"group": name, "parameters": parameters} for name, parameters in groups.items()]}


def _parameter(keypad: Keypad, register: Register) -> dict[str, Any]:
    try:
        raw = keypad.read(register)
    except (RegisterError, KeyError, ValueError):
        raw = register.default
    entry = record(register, raw)
    entry.update(minimum=shown_value(register, register.raw_minimum),
                 maximum=shown_value(register, register.raw_maximum),
                 access=register.access.value, writable=register.access.writable)
    if register.enum:
        entry["choices"] = choices(register)
    return entry


def connections(runtime: DeviceRuntime) -> dict[str, Any]:
    """Sessions, class 3 and class 1 connections; class 1 with its counters and the data of both
    directions by field names (raw hex beside, and alone where the assembly has no field names)."""
    now = runtime.now()
    sessions = [{"session": handle, "peer": owner.peer}
                for handle, owner in sorted(runtime.target.sessions.items())]
    class3 = [{"id": f"0x{c.ot_connection_id:08X}", "originator": c.host, "requests": c.requests,
               "timeout_s": c.timeout_s, "serial": c.triad.connection_serial}
              for c in runtime.device.connection_table.connections.values()]
    return {"sessions": sessions, "class3": class3,
            "class1": [_class1(runtime, c, now) for c in runtime.class1_connections()]}


def _class1(runtime: DeviceRuntime, connection: IoConnection, now: float) -> dict[str, Any]:
    stats = connection.stats
    entry: dict[str, Any] = {
        "name": connection.name, "kind": connection.kind.value, "originator": connection.peer,
        "ot_id": f"0x{connection.ot_connection_id:08X}", "to_id": f"0x{connection.to_connection_id:08X}",
        "output": connection.consumed.instance_id if connection.consumed is not None else None,
        "input": connection.produced.instance_id,
        "ot_rpi_us": connection.ot_rpi_us, "to_rpi_us": connection.to_rpi_us,
        "run": connection.run, "multicast": connection.multicast,
        "received": stats.received, "lost": stats.lost, "stale": stats.stale, "duplicates": stats.duplicates,
        "sent": stats.sent, "late": stats.late,
        "output_data": _data(runtime, connection.consumed.instance_id) if connection.consumed is not None else None,
        "input_data": _data(runtime, connection.produced.instance_id),
    }
    return entry


def _data(runtime: DeviceRuntime, instance: int) -> dict[str, Any]:
    device = runtime.device
    try:
        data = device.assembly.data(instance)
    except Exception:  # an instance the device no longer serves (a remapped assembly)
        return {"hex": "", "fields": {}}
    schema = device.data_schema(instance)
    fields: dict[str, Any] = {}
    if schema is not None and schema.size == len(data):
        fields = {name: _json_value(value) for name, value in schema.decode(data).items() if not name.startswith("_")}
    return {"hex": data.hex(" "), "fields": fields}


def _json_value(value: Any) -> Any:
    """A decoded field as JSON has it: flags as 0/1 are bools already, words as numbers, bytes as hex."""
    if isinstance(value, (bytes, bytearray)):
        return bytes(value).hex(" ")
    return value if isinstance(value, (bool, int, float, str)) or value is None else str(value)


def fault_table() -> list[dict[str, Any]]:
    """Every fault a device can be given, with its options (the positional one first, ``for`` last
    where the fault lasts), as a form needs them."""
    from ..faults import FAULTS
    from ..faults.model import FOR

    table = []
    for kind in FAULTS.values():
        declared = [*((kind.positional,) if kind.positional is not None else ()), *kind.options,
                    *(() if kind.once else (FOR,))]
        # A group of ``requires`` with one option makes it required; a group of several asks for one
        # of them (``drop``: share or every).
        groups = {name: group for group in kind.requires for name in group}
        options = [{"name": o.name, "metavar": o.metavar, "help": o.help,
                    "required": o is kind.positional or len(groups.get(o.name, ())) == 1,
                    **({"one_of": list(groups[o.name])} if len(groups.get(o.name, ())) > 1 else {})}
                   for o in declared]
        table.append({"name": kind.name, "where": kind.where, "summary": kind.summary, "once": kind.once,
                      "lasts": kind.lasts, "options": options})
    return table


__all__ = ["connections", "fault_table", "parameter_groups"]
