"""A value read from a device with its declaration: the raw value, the engineering value, the unit.

One rule turns the number on the wire into the number a person reads, wherever a declaration
gives a scale (an attribute's ``AttributeSpec``, an EDS ``ParamN``, an assembly field):

    engineering = (raw + offset) x scale

with ``scale`` = multiplier x base / divider of an EDS ``ParamN`` (fields 13-16, the EDS
specification) and ``offset`` its field 16; the text shows ``decimals`` places (field 21; else as many as
the scale has: 0.1 -> 1, 0.01 -> 2). The ACG's acceleration time, 0.1 s per step (ACG-ET2 manual, AC/DC
Drive object attribute 102; ACG RS-485 manual ACC), reads ``Value(raw=50)`` and prints ``5.0 s``.

Writing goes the other way (``Scaling.to_raw``): an engineering value that is not a whole number of
steps is refused rather than rounded, because a drive parameter set to a value nobody asked for is
worse than an error.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, NamedTuple

from ..errors import BadRequest, WrongType
from .types import CipType
from .units import decimal_places


def places_of(scale: float) -> int:
    """The decimal places a value of step ``scale`` shows: 0.1 -> 1, 0.01 -> 2, 0.5 -> 1, 10 -> 0
    (``units.decimal_places``, what every other text of a scaled value uses)."""
    if scale <= 0 or not math.isfinite(scale):
        return 0
    return decimal_places(scale)


class Scaling(NamedTuple):
    """How a raw value becomes an engineering value, and its unit (the declaration's)."""

    unit: str = ""
    #: Engineering per raw step (EDS: multiplier x base / divider).
    scale: float = 1.0
    #: Added to the raw value before scaling (EDS field 16).
    offset: float = 0.0
    #: Decimal places the engineering value shows (None: those of ``scale``).
    decimals: int | None = None
    #: Raw value -> meaning, for an enumerated attribute.
    enum: Mapping[int, str] | None = None

    @property
    def scaled(self) -> bool:
        """True when the engineering value differs from the raw value."""
        return self.scale != 1.0 or self.offset != 0.0

    @property
    def places(self) -> int:
        return self.decimals if self.decimals is not None else places_of(self.scale)

    def engineering(self, raw: Any) -> Any:
        """The engineering value of ``raw`` (``raw`` itself when unscaled or not a number)."""
        if not self.scaled or isinstance(raw, bool) or not isinstance(raw, (int, float)):
            return raw
        return round((raw + self.offset) * self.scale, self.places + 6)

    def to_raw(self, engineering: float) -> int:
        """The raw integer whose engineering value is ``engineering``; ``ValueError`` when it falls
        between two steps (5.05 s with a step of 0.1 s)."""
        if isinstance(engineering, bool) or not isinstance(engineering, (int, float)):
            raise WrongType(f"an engineering value is a number, not {type(engineering).__name__}")
        steps = engineering / self.scale - self.offset
        raw = round(steps)
        if abs(steps - raw) > 1e-6 * max(1.0, abs(steps)):
            step = f"{self.scale:g} {self.unit}".strip()
            raise BadRequest(f"{engineering:g} {self.unit} is not a whole number of steps of {step}".replace("  ", " "))
        return int(raw)

    def text(self, raw: Any) -> str:
        """``raw`` as a person reads it: ``5.0 s``, ``900 rpm``, ``3 (Ready)``, ``'CENT'`` stays ``CENT``."""
        if isinstance(raw, (bytes, bytearray)):
            return bytes(raw).hex(" ")
        if isinstance(raw, (dict, list)):
            import json  # a structure's text only: a one-shot that prints a number does without

            return json.dumps(raw)
        if self.enum is not None and isinstance(raw, int) and raw in self.enum:
            return f"{raw} ({self.enum[raw]})"
        number = self.number(raw)
        return f"{number} {self.unit}" if self.unit else number

    def number(self, raw: Any) -> str:
        """The engineering value of ``raw`` as a number alone (no unit): ``5.0`` for raw 50 at 0.1 s."""
        value = self.engineering(raw)
        return f"{value:.{self.places}f}" if self.scaled and isinstance(value, (int, float)) else str(value)

    def range_text(self, label: str, minimum: Any, maximum: Any) -> str:
        """What a parameter takes, in its own unit: ``ACC (Acc Time) takes 0.0..6000.0 s`` for the raw bounds
        0..60000 at 0.1 s, with the choices of an enumeration. The one wording of a value out of a
        declared range, wherever it is checked (the keypad, a write by code, ``cipstack set``)."""
        unit = f" {self.unit}" if self.unit else ""
        choices = f" ({', '.join(f'{raw} {name}' for raw, name in self.enum.items())})" if self.enum else ""
        return f"{label} takes {self.number(minimum)}..{self.number(maximum)}{unit}{choices}"


_UNSCALED = Scaling()


class Value:
    """A value read from a device: ``raw`` as on the wire, ``value`` in engineering units, ``unit``.

    ``str(v)`` is what a person reads (``5.0 s``); ``v.raw`` is 50. A ``Value`` compares equal to
    another with the same raw value and declaration, and to a plain Python value equal to its raw
    value (``v == 50``): the wire value, never the engineering one (compare ``v.value`` for that).
    ``type`` is None when nothing declares the attribute: ``raw`` is then the reply's bytes.
    """

    # A plain class with slots, not a frozen dataclass: one is made per read, and a frozen
    # dataclass's __init__ costs a few microseconds more on that path. Treat it as immutable.
    __slots__ = ("name", "raw", "scaling", "type")

    def __init__(self, raw: Any, name: str = "", type: CipType | None = None, scaling: Scaling = _UNSCALED) -> None:
        #: The value as the wire carries it (``bytes`` when nothing declares the attribute).
        self.raw = raw
        #: The attribute's declared name ("Acceleration Time"), empty when unknown.
        self.name = name
        #: The CIP type the reply was decoded as, None when undeclared.
        self.type = type
        #: Unit, scale, offset, decimal places and enumeration of the declaration.
        self.scaling = scaling

    @property
    def value(self) -> Any:
        """The engineering value: ``(raw + offset) x scale`` (the raw value when unscaled)."""
        return self.scaling.engineering(self.raw)

    @property
    def unit(self) -> str:
        return self.scaling.unit

    @property
    def scaled(self) -> bool:
        """True when ``value`` differs from ``raw`` by a scale or an offset."""
        return self.scaling.scaled and isinstance(self.raw, (int, float)) and not isinstance(self.raw, bool)

    @property
    def meaning(self) -> str | None:
        """The enumeration's text for the raw value, when the declaration has one."""
        enum = self.scaling.enum
        return enum.get(self.raw) if enum is not None and isinstance(self.raw, int) else None

    @property
    def known(self) -> bool:
        """True when a declaration (or a type given) decoded the value."""
        return self.type is not None

    def __str__(self) -> str:
        return self.scaling.text(self.raw)

    def __repr__(self) -> str:
        name = f"{self.name!r}, " if self.name else ""
        return f"Value({name}raw={self.raw!r}, {str(self)!r})"

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Value):
            return self.raw == other.raw and self.scaling == other.scaling
        return bool(self.raw == other)

    def __hash__(self) -> int:
        try:
            return hash(self.raw)
        except TypeError:
            return id(self)

    def __bool__(self) -> bool:
        return bool(self.raw)

    def __int__(self) -> int:
        """The raw value, as ``==`` compares it: a count read is used as a count."""
        return int(self.raw)

    def __float__(self) -> float:
        return float(self.raw)

    def json(self) -> dict[str, Any]:
        """A JSON record: ``value`` (raw, as the type writes it), and ``engineering``, ``unit``,
        ``meaning`` when the declaration gives them."""
        raw = self.raw
        if self.type is not None:
            raw = self.type.to_json(raw)
        elif isinstance(raw, (bytes, bytearray)):
            raw = bytes(raw).hex()
        out: dict[str, Any] = {"value": raw}
        if self.scaled:
            out["engineering"] = self.value
        if self.unit:
            out["unit"] = self.unit
        if self.meaning is not None:
            out["meaning"] = self.meaning
        return out


__all__ = ["Scaling", "Value", "places_of"]
