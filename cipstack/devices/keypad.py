"""A drive's keypad: its parameters by code, in the unit the keypad shows, for a test rig.

A drive's own keypad (the ACG's keypad, the MX2/RX Digital Operator) names each parameter by a code
(``drv``, ``ACC``, ``CM.23``; ``F001``, ``A004``, ``P044``) and shows its value in an engineering
unit (``ACC`` 2.5 s is raw 25 at scale 0.1). The emulator offers the same view to whoever drives it:
``cipstack adapter --param CODE=VALUE`` at start, the HTTP API's ``/parameters/CODE``, the pytest
plugin's ``params``. What is generic lives here: parsing ``CODE=VALUE`` in the keypad's unit (a number
on the keypad's step, or a name of the enumeration), the range check, and the JSON record of a
parameter. What a family adds is declared once, in its own package: which codes its keypad has
(``KeypadCodes``) and how its keypad reads and writes them (a ``Keypad``, which the device gives
with ``Device.keypad()``), with the write rules of its manual.

The values given at start (``--param``) are keypad entries: a drive keeps what is entered on its
keypad across a power loss, and loses only what was written over communication and not saved (ACG
RS-485 manual, "Saving Parameters Defined by Communication"; ACG-ET2 manual, CM.94; the CompoNet
manual's Table C-2 and section 3-3, where an operator setting is followed by a power OFF and ON). Each
family keeps them as its keypad does (``Keypad.keep``). Given with ``kept=False`` (``--param-unsaved``)
they are written as over communication instead, and a power-cycle loses them. A value set while the
device runs (the HTTP API, the pytest plugin's ``set_parameter``) is such a write too: not saved.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from typing import Any

from ..cip.epath import parse_application_path
from ..cip.status import CipError
from ..cip.values import Scaling
from ..errors import BadRequest, NotFound, StateRefused
from .registers import Register, RegisterError


class UnknownCode(NotFound, ValueError):
    """A code the keypad does not have; the message names valid examples. A ``ValueError`` too, as
    every assignment a keypad does not take is."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class BadValue(BadRequest):
    """A value the keypad does not take for a parameter (not a number, off its step, out of range)."""


class WriteRefused(StateRefused, ValueError):
    """A write the device refused (read-only, not while running, its mode...): the request was
    understood and the device said no. ``error`` is the device's refusal when it gave one."""

    def __init__(self, message: str, error: RegisterError | None = None) -> None:
        super().__init__(message)
        self.error = error


class NoKeypad(NotFound, ValueError):
    """A device without a keypad (an EDS-emulated device, a CompoNet gateway)."""


@dataclass(frozen=True)
class KeypadCodes:
    """The codes of one family's keypad, without a device: enough to check an assignment before a
    device is built (a fleet's spec file)."""

    #: What the keypad is called in messages: "the ACG keypad", "the MX2 Digital Operator".
    name: str
    #: The register of a code in any spelling the keypad accepts; ``KeyError`` for another.
    lookup: Callable[[str], Register]
    #: Codes an error message names as examples.
    examples: tuple[str, ...]
    #: Every parameter of the keypad with a code, group by group in the order its manual lists them
    #: (what a front panel shows).
    listed: tuple[Register, ...] = ()

    def register(self, code: str) -> Register:
        """The register of ``code``; ``UnknownCode`` naming valid examples for another."""
        try:
            register = self.lookup(code)
        except (KeyError, ValueError):
            register = None
        if register is None or not register.code:
            raise UnknownCode(f"{code.strip()!r} is not a code of {self.name} (e.g. {', '.join(self.examples)})")
        return register

    def parse(self, text: str, where: str = "--param") -> tuple[Register, int]:
        """``CODE=VALUE`` -> (the register of the code, its raw value); ``UnknownCode`` or ``BadValue``
        name the problem, prefixed with ``where`` and the assignment."""
        code, sep, value_text = text.partition("=")
        if not sep or not code.strip() or not value_text.strip():
            raise BadValue(f"{where} {text!r} is not CODE=VALUE (e.g. {self.examples[0]}=...)")
        try:
            register = self.register(code)
        except UnknownCode as exc:
            raise UnknownCode(f"{where} {text!r}: {exc}") from None
        try:
            return register, raw_value(register, value_text.strip())
        except BadValue as exc:
            raise BadValue(f"{where} {text!r}: {exc}") from None


def raw_value(register: Register, text: str) -> int:
    """The raw value of ``text`` in the keypad's unit: a number on the keypad's step (``scale``) within
    the parameter's range, or a name of its enumeration; ``BadValue`` says why not."""
    raw: int | None = None
    if register.enum:
        wanted = text.replace(" ", "").lower()
        raw = next((value for value, name in register.enum.items() if name.replace(" ", "").lower() == wanted), None)
    if raw is None:
        try:
            shown = Decimal(int(text, 0)) if text.lower().startswith("0x") else Decimal(text)
            steps = shown / Decimal(str(register.scale))
        except (InvalidOperation, ValueError):
            raise BadValue("not a number" + (f" nor one of {choices(register)}" if register.enum else "")) from None
        if not steps.is_finite() or steps != steps.to_integral_value():
            raise BadValue(f"finer than the keypad's step {register.scale:g}" if steps.is_finite() else "not a number")
        raw = int(steps)
    try:
        register.check(raw)
    except RegisterError:
        scaling = Scaling(register.unit, register.scale, enum=register.enum or None)
        raise BadValue(scaling.range_text(f"{register.code} ({register.name})", register.raw_minimum,
                                          register.raw_maximum)) from None
    return raw


def shown_value(register: Register, raw: int) -> str:
    """``raw`` as the keypad shows it: 25 at scale 0.1 is "2.5"."""
    return f"{Decimal(raw) * Decimal(str(register.scale)):f}" if register.scale != 1 else str(raw)


def choices(register: Register) -> str:
    return ", ".join(f"{raw} {name}" for raw, name in (register.enum or {}).items())


def record(register: Register, raw: int) -> dict[str, Any]:
    """A parameter as JSON: code, name, value in the keypad's unit (text, exact), raw value, unit, its
    communication address (None where it has none), the meaning of an enumerated value, and
    ``"simulated": false`` for a monitor the emulator does not simulate (it reads 0)."""
    address = register.address if register.address is not None and register.addressed else None
    result: dict[str, Any] = {"code": register.code, "name": register.name, "value": shown_value(register, raw),
                              "raw": raw, "unit": register.unit,
                              "address": f"0x{address:04X}" if address is not None else None}
    if register.enum and raw in register.enum:
        result["meaning"] = register.enum[raw]
    if not register.simulated:
        result["simulated"] = False
    return result


def describe(register: Register, raw: int) -> str:
    """One line for a log: ``ACC Acc Time = 2.5 s``, ``drv Cmd Source = 4 (Field Bus)``."""
    shown = shown_value(register, raw) + (f" {register.unit}" if register.unit else "")
    meaning = f" ({register.enum[raw]})" if register.enum and raw in register.enum else ""
    return f"{register.code} {register.name} = {shown}{meaning}"


class Keypad:
    """A device's keypad: ``codes`` and how the family reads and writes a parameter from it.
    A family overrides ``read`` and ``write`` (and, where it knows them, ``register_at`` and
    ``started``); everything else is the same for every family."""

    codes: KeypadCodes

    def read(self, register: Register) -> int:
        raise NotImplementedError

    def write(self, register: Register, raw: int, now: float) -> None:
        """Write as the keypad does, with the device's own rules; ``RegisterError`` when it refuses."""
        raise NotImplementedError

    def register_at(self, class_id: int, instance: int, attribute: int) -> Register | None:
        """The parameter a CIP Set of ``class_id``/``instance``/``attribute`` writes, where the family
        knows it (for the event stream); None elsewhere."""
        return None

    def keep(self, written: list[Register], now: float) -> None:
        """Keep the values of ``written``, just entered, as the keypad keeps its entries: a power-cycle
        brings them back (until a later save or write changes them). A family's keypad overrides it;
        the default keeps nothing."""

    def started(self, written: list[Register], now: float) -> None:
        """After the assignments given at start: what the device does with them before the network
        connects (nothing by default)."""

    # -- the same for every family -----------------------------------------------------------------
    def written_by(self, request: bytes) -> dict[str, Any]:
        """What a CIP Set request (service, path, data) that the device accepted wrote, for the event
        stream: ``code``, ``address``, ``raw`` and ``value`` of the parameter at its path (``register_at``),
        or nothing where it is not one."""
        size = 2 * request[1] if len(request) > 1 else 0
        try:
            target = parse_application_path(request[2:2 + size])
        except (CipError, ValueError):
            return {}
        if target.instance is None or target.attribute is None:
            return {}
        register = self.register_at(target.class_id, target.instance, target.attribute)
        raw = decode_raw(register, request[2 + size:]) if register is not None else None
        return self.write_fields(register, raw) if raw is not None else {}

    @staticmethod
    def write_fields(register: Register | None, raw: int, address: int | None = None) -> dict[str, Any]:
        """A write's fields for the event stream: the parameter's ``code`` (where it has one), its
        ``address`` (or the one written), the ``raw`` value and the ``value`` in the keypad's unit."""
        fields: dict[str, Any] = {}
        if register is not None:
            if register.code:
                fields["code"] = register.code
            if register.address is not None and register.addressed:
                address = register.address
        if address is not None:
            fields["address"] = f"0x{address:04X}"
        fields["raw"] = raw
        if register is not None:
            fields["value"] = shown_value(register, raw)
        return fields

    def get(self, code: str) -> dict[str, Any]:
        """The parameter ``code`` as JSON (``record``); ``UnknownCode`` for another code."""
        register = self.codes.register(code)
        return record(register, self.read(register))

    def set(self, code: str, value: str, now: float) -> tuple[Register, int]:
        """Write ``value`` (in the keypad's unit) to ``code``; ``UnknownCode``, ``BadValue`` or
        ``WriteRefused`` (with the device's reason) when not written. Returns what was written."""
        register = self.codes.register(code)
        try:
            raw = raw_value(register, value.strip())
        except BadValue as exc:
            raise BadValue(f"{register.code}={value.strip()}: {exc}") from None
        self._write(register, raw, now, f"{register.code}={value.strip()}")
        return register, raw

    def assign(self, assignments: Iterable[str], now: float, kept: bool = True) -> list[str]:
        """``--param CODE=VALUE`` at start, in order; one line per value set, for the log. The first one
        not taken raises (``UnknownCode``, ``BadValue``, ``WriteRefused``); nothing after it is written.
        ``kept``: keypad entries, which a power-cycle keeps (``keep``); False: written as over
        communication, not saved, so a power-cycle loses them."""
        applied, written = [], []
        for text in assignments:
            register, raw = self.codes.parse(text)
            self._write(register, raw, now, f"--param {text!r}")
            written.append(register)
            applied.append(describe(register, raw))
        if written:
            if kept:
                self.keep(written, now)
            self.started(written, now)
        return applied

    def _write(self, register: Register, raw: int, now: float, what: str) -> None:
        try:
            self.write(register, raw, now)
        except RegisterError as exc:
            raise WriteRefused(f"{what}: {exc}", exc) from None


def decode_raw(register: Register, data: bytes) -> int | None:
    """The raw value a CIP Set carries for ``register`` (little-endian, one or two words), or None when
    the data is not that size."""
    if len(data) not in (2, 4):
        return None
    return int.from_bytes(data, "little", signed=register.signed)
