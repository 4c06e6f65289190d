"""The ACG drive's keypad (``cipstack.devices.keypad``): its codes and how it writes them.

A real ACG is made to run from the network on its keypad before any network client connects:
drv = 4 and Frq = 8 ("Field Bus", ACG-ET2 manual). ``--param`` does the same for the emulator, by the
keypad code and in the unit the keypad shows (``ACC=2.5`` is 2.5 s, raw 25 at scale 0.1). The
values are written as the drive's own write rules allow (range, not while running, the parameter
lock) and kept as keypad entries: a power cycle keeps them, where a value written over communication
and not saved is lost (ACG RS-485 manual, "Saving Parameters Defined by Communication").
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from ..keypad import Keypad, KeypadCodes
from ..registers import Register
from .drive import AcgDrive
from .registers import ACG_REGISTERS, KEYPAD_GROUPS, class64_register, register_for_code

#: The ACG's keypad codes: the operation group's (drv, Frq, ACC...) and GROUP.N (ACG RS-485 manual tables).
ACG_KEYPAD = KeypadCodes(
    "the ACG keypad", register_for_code, ("drv", "Frq", "ACC", "dr.20", "CM.23"),
    # The operation group first, as the keypad shows it at power-on, then the groups in their order.
    tuple(sorted((r for r in ACG_REGISTERS.values() if r.code and r.group in KEYPAD_GROUPS),
                 key=lambda r: (r.group != "operation", KEYPAD_GROUPS.index(r.group)))))

#: Class 0x64, the keypad parameters by group and code number (ACG-ET2 manual).
_KEYPAD_CLASS = 0x64


class AcgKeypad(Keypad):
    """The keypad of an ACG drive: its registers by keypad code, written as the drive's write rules
    allow (``AcgDrive.write``). ``drive``: the present drive (a device replaces it on a reset);
    ``objects``: the device's CIP objects by class, to name the parameter a CIP Set writes."""

    codes = ACG_KEYPAD

    def __init__(self, drive: Callable[[], AcgDrive], objects: dict[int, Any] | None = None) -> None:
        self._drive = drive
        self._objects = objects or {}

    def read(self, register: Register) -> int:
        return self._drive().read(register.address)

    def write(self, register: Register, raw: int, now: float) -> None:
        drive = self._drive()
        drive.write(register.address, raw, max(now, drive.time))

    def keep(self, written: list[Register], now: float) -> None:
        self._drive().keep_keypad_entries([register.address for register in written if register.address is not None])

    def register_at(self, class_id: int, instance: int, attribute: int) -> Register | None:
        if class_id == _KEYPAD_CLASS:
            return class64_register(instance, attribute)
        # Motor Data, Control Supervisor, AC/DC Drive: the register an attribute of instance 1 shows
        # (AC/DC Drive 102 is ACC, ACG-ET2 manual), as the objects declare it.
        obj = self._objects.get(class_id)
        register_of = getattr(obj, "register_of", None)
        return register_of(attribute) if register_of is not None and instance == 1 else None


def parse_assignment(text: str) -> tuple[Register, int]:
    """``CODE=VALUE`` -> (the register of the ACG keypad code, its raw value); ValueError names the problem."""
    return ACG_KEYPAD.parse(text)


def apply_parameters(drive: AcgDrive, assignments: list[str], now: float) -> list[str]:
    """Write each ``CODE=VALUE`` to a bare ``drive`` (no device around it) in order; one line per value
    set. The first one not taken raises ValueError naming the code and the reason."""
    return AcgKeypad(lambda: drive).assign(assignments, now)
