"""Group ``profile``: the AC/DC drive profile (Identity device type 2, AC drive, or 0x13, DC drive):
its required I/O assemblies and their sizes, and the Control Supervisor (0x29) and AC/DC Drive (0x2A)
attributes the profile requires, with their types, access and ranges. The attribute and assembly
tables are those the drive manuals agree on (ACG-ET2 manual, the instance tables of Appendix B;
CompoNet manual, Tables B-1..B-8 and D-3..D-7). A device of another type: not applicable.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ..cip.epath import request_path
from .discovery import DRIVE_DEVICE_TYPES, assembly_size
from .model import CheckSpec, Outcome, Verdict
from .registry import Context, check, outcome
from .wire import Probe

PROFILE = "CIP Vol. 1 §6 (AC/DC drive profile, device type 0x02 / 0x13)"
CONTROL_SUPERVISOR, AC_DC_DRIVE = 0x29, 0x2A
#: Required assemblies and their data sizes; the speed + torque forms, where present, are 6 bytes.
REQUIRED_ASSEMBLIES = {20: 4, 21: 4, 70: 4, 71: 4}
OPTIONAL_ASSEMBLIES = {22: 6, 23: 6, 72: 6, 73: 6}


@dataclass(frozen=True)
class Required:
    """A required attribute: its name, the sizes its type takes (drives disagree on some: a USINT or a
    UINT), and the values it may have (None: any)."""

    name: str
    sizes: tuple[int, ...]
    allowed: Callable[[int], bool] | None = None


def boolean(value: int) -> bool:
    return value in (0, 1)


#: Control Supervisor instance 1 (the ACG-ET2 manual's Control Supervisor table; CompoNet manual Table D-4).
SUPERVISOR = {
    3: Required("Run1", (1,), boolean), 4: Required("Run2", (1,), boolean),
    6: Required("State", (1, 2), lambda v: 0 <= v <= 7), 7: Required("Running1", (1,), boolean),
    8: Required("Running2", (1,), boolean), 9: Required("Ready", (1, 2), boolean),
    10: Required("Faulted", (1,), boolean), 12: Required("FaultRst", (1,), boolean),
    13: Required("FaultCode", (2,)), 15: Required("CtrlFromNet", (1,), boolean),
}
#: AC/DC Drive instance 1 (ACG-ET2 manual's AC/DC Drive table; CompoNet manual Table D-7).
DRIVE = {
    3: Required("AtReference", (1,), boolean), 7: Required("SpeedActual", (2,)), 8: Required("SpeedRef", (2,)),
    29: Required("RefFromNet", (1,), boolean),
}
#: A Get-only attribute of each: with --allow-writes, a Set of its own value must be refused with 0x0E.
READ_ONLY = {CONTROL_SUPERVISOR: 6, AC_DC_DRIVE: 7}


def faulted(probe: Probe) -> bool | None:
    """Control Supervisor attribute 10 Faulted; None where it cannot be read."""
    reply = probe.request(0x0E, request_path(CONTROL_SUPERVISOR, 1, 10))
    return bool(reply.data[0]) if reply.status == 0 and reply.data else None


def clear_fault_of_the_run(ctx: Context, probe: Probe) -> tuple[str, bool]:
    """A drive found not faulted that is faulted now was faulted by the run (a class 1 connection
    timed out on a drive whose network-loss action is a trip: the MX2's and RX's P045 default,
    CompoNet manual Table 12). With --allow-writes or --allow-motion: FaultRst (0x29/1/12) 0 -> 1 -> 0
    by explicit messaging, as the drive was found; without, nothing is written and it is only said.
    What was found or done in words ("" when nothing) and whether the drive is clear."""
    if ctx.drive_faulted_at_start is not False or not faulted(probe):
        return "", True
    code = probe.request(0x0E, request_path(CONTROL_SUPERVISOR, 1, 13))
    what = f"FaultCode {code.data.hex(' ') if code.status == 0 else 'unreadable'}"
    if not (ctx.allow_writes or ctx.allow_motion):
        return (f"the drive was faulted during the run ({what}), not at its start (a class 1 timeout trips a drive "
                "whose network-loss action is a trip); not cleared, as nothing is written without --allow-writes: "
                "clear it with FaultRst 0 then 1 (0x29/1/12) or on the drive"), False
    for value in (b"\0", b"\1", b"\0"):  # a 0 -> 1 edge (ACG-ET2 manual, Drive Fault Reset), then 0 as found
        probe.request(0x10, request_path(CONTROL_SUPERVISOR, 1, 12), value)
    clear = faulted(probe) is False
    return (f"the drive was faulted during the run ({what}), not at its start: FaultRst 0->1 "
            + ("cleared it" if clear else "did not clear it; clear it on the drive (its STOP/RESET key)")), clear


def not_a_drive(ctx: Context, spec: CheckSpec) -> Outcome | None:
    device_type = (ctx.identity or {}).get("device_type")
    if device_type in DRIVE_DEVICE_TYPES:
        return None
    return outcome(spec, Verdict.NOT_APPLICABLE, f"device type {device_type}: not an AC or DC drive")


@check("profile.assemblies", "the profile's I/O assemblies and their sizes",
       "assemblies 20, 21 (outputs) and 70, 71 (inputs) exist with 4 data bytes (Assembly attribute 4, else the "
       "length of attribute 3); 22, 23, 72, 73, where present, with 6",
       f"{PROFILE}; ACG-ET2 manual, input and output instances; CompoNet manual, Tables B-1 to B-8")
def assemblies(ctx: Context, spec: CheckSpec) -> Outcome:
    skipped = not_a_drive(ctx, spec)
    if skipped is not None:
        return skipped
    probe = ctx.probe()
    problems, seen = [], []
    for table, required in ((REQUIRED_ASSEMBLIES, True), (OPTIONAL_ASSEMBLIES, False)):
        for instance, size in table.items():
            found = assembly_size(probe, instance)
            if found is None:
                if required:
                    problems.append(f"assembly {instance} missing")
                continue
            seen.append(f"{instance}: {found}")
            if found != size:
                problems.append(f"assembly {instance} has {found} bytes, the profile's has {size}")
    return outcome(spec, not problems, "; ".join(problems) or "sizes " + ", ".join(seen), probe.exchanges)


def _attributes(ctx: Context, spec: CheckSpec, class_id: int, table: dict[int, Required]) -> Outcome:
    skipped = not_a_drive(ctx, spec)
    if skipped is not None:
        return skipped
    probe = ctx.probe()
    problems = []
    for attribute, required in table.items():
        reply = probe.request(0x0E, request_path(class_id, 1, attribute))
        where = f"{class_id:#04x}/1/{attribute} {required.name}"
        if reply.status != 0:
            problems.append(f"{where}: {reply.describe()}")
            continue
        if len(reply.data) not in required.sizes:
            problems.append(f"{where}: {len(reply.data)} bytes, its type has {' or '.join(map(str, required.sizes))}")
            continue
        value = int.from_bytes(reply.data, "little", signed=len(reply.data) == 2 and attribute in (7, 8))
        if required.allowed is not None and not required.allowed(value):
            problems.append(f"{where}: value {value} out of its range")
    problems += _read_only_refused(ctx, probe, class_id)
    return outcome(spec, not problems, "; ".join(problems) or f"{len(table)} attributes read, types and ranges as "
                   "the profile's" + (", a read-only one refused a Set (0x0E)" if ctx.allow_writes else ""),
                   probe.exchanges)


def _read_only_refused(ctx: Context, probe: Probe, class_id: int) -> list[str]:
    """With --allow-writes: a Set of a Get-only attribute, with the value it has, is refused with 0x0E."""
    if not ctx.allow_writes:
        return []
    path = request_path(class_id, 1, READ_ONLY[class_id])
    current = probe.request(0x0E, path)
    if current.status != 0:
        return []
    reply = probe.request(0x10, path, current.data)
    if reply.status == 0:
        from .registry import restore_later

        restore_later(ctx, path, current.data, f"{class_id:#04x}/1/{READ_ONLY[class_id]}")
    return [] if reply.status == 0x0E else [f"Set of read-only {class_id:#04x}/1/{READ_ONLY[class_id]}: "
                                            f"{reply.describe()} (0x0E expected)"]


@check("profile.control_supervisor", "Control Supervisor (0x29) instance 1: the attributes the profile requires",
       "Run1 (3), Run2 (4), State (6, 0-7), Running1 (7), Running2 (8), Ready (9), Faulted (10), FaultRst (12), "
       "FaultCode (13, UINT) and CtrlFromNet (15) readable, BOOLs 1 byte and 0 or 1 (State and Ready 1 or 2 bytes, "
       "as drives differ); with --allow-writes, a Set of State refused with 0x0E",
       f"{PROFILE}; ACG-ET2 manual, Control Supervisor object; CompoNet manual, Table D-4")
def control_supervisor(ctx: Context, spec: CheckSpec) -> Outcome:
    return _attributes(ctx, spec, CONTROL_SUPERVISOR, SUPERVISOR)


@check("profile.ac_dc_drive", "AC/DC Drive (0x2A) instance 1: the attributes the profile requires",
       "AtReference (3), SpeedActual (7, INT), SpeedRef (8, INT) and RefFromNet (29) readable with their types' "
       "sizes, BOOLs 0 or 1; with --allow-writes, a Set of SpeedActual refused with 0x0E",
       f"{PROFILE}; ACG-ET2 manual, AC/DC Drive object; CompoNet manual, Table D-7")
def ac_dc_drive(ctx: Context, spec: CheckSpec) -> Outcome:
    return _attributes(ctx, spec, AC_DC_DRIVE, DRIVE)

