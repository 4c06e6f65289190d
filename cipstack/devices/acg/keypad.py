"""Keypad parameters set when the emulator starts (``cipstack adapter --param CODE=VALUE``).

A real ACG is made to run from the network on its keypad before any network client connects:
drv = 4 and Frq = 8 ("Field Bus", seed 000). ``--param`` does the same for the emulator, by the
keypad code and in the unit the keypad shows (``ACC=2.5`` is 2.5 s, raw 25 at scale 0.1). The
values are written as the drive's own write rules allow (range, not while running) and are not
saved: like any value written but not saved, they last until the emulator stops.
"""

from __future__ import annotations

from decimal import Decimal, InvalidOperation

from ..registers import Register, RegisterError
from .drive import AcgDrive
from .registers import register_for_code


def parse_assignment(text: str) -> tuple[Register, int]:
    """``CODE=VALUE`` -> (the register of the keypad code, its raw value); ValueError names the problem."""
    code, sep, value_text = text.partition("=")
    if not sep or not code.strip() or not value_text.strip():
        raise ValueError(f"--param {text!r} is not CODE=VALUE (e.g. drv=4)")
    try:
        register = register_for_code(code)
    except KeyError as exc:
        raise ValueError(f"--param {text!r}: {exc.args[0]}") from None
    value = _raw_value(register, value_text.strip())
    low, high = register.raw_minimum, register.raw_maximum
    try:
        register.check(value)
    except RegisterError:
        raise ValueError(f"--param {text!r}: {register.code} ({register.name}) takes {_shown(register, low)}.."
                         f"{_shown(register, high)}{' ' + register.unit if register.unit else ''}"
                         + (f" ({_choices(register)})" if register.enum else "")) from None
    return register, value


def _raw_value(register: Register, text: str) -> int:
    """The raw register value of ``text`` in the keypad's unit: a number, or a name of the enumeration."""
    if register.enum:
        for raw, name in register.enum.items():
            if name.replace(" ", "").lower() == text.replace(" ", "").lower():
                return raw
    try:
        shown = Decimal(int(text, 0)) if text.lower().startswith("0x") else Decimal(text)
        raw = shown / Decimal(str(register.scale))
    except (InvalidOperation, ValueError):
        raise ValueError(f"--param {register.code}={text}: not a number"
                         + (f" nor one of {_choices(register)}" if register.enum else "")) from None
    if raw != raw.to_integral_value():
        raise ValueError(f"--param {register.code}={text}: finer than the keypad's step {register.scale:g}")
    return int(raw)


def _shown(register: Register, raw: int) -> str:
    return f"{Decimal(raw) * Decimal(str(register.scale)):f}" if register.scale != 1 else str(raw)


def _choices(register: Register) -> str:
    return ", ".join(f"{raw} {name}" for raw, name in (register.enum or {}).items())


def apply_parameters(drive: AcgDrive, assignments: list[str], now: float) -> list[str]:
    """Write each ``CODE=VALUE`` to ``drive`` in order; returns one line per value set, for the log.
    A value the drive refuses raises ValueError naming the code and the reason; nothing after it is written."""
    applied = []
    for text in assignments:
        register, value = parse_assignment(text)
        try:
            drive.write(register.address, value, now)
        except RegisterError as exc:
            raise ValueError(f"--param {text!r}: {exc}") from None
        shown = _shown(register, value) + (f" {register.unit}" if register.unit else "")
        name = f" ({register.enum[value]})" if register.enum and value in register.enum else ""
        applied.append(f"{register.code} {register.name} = {shown}{name}")
    return applied
