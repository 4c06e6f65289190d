"""How a declared unit and scale read to a person.

A declaration (an attribute, a register, an assembly field, an EDS parameter) gives the
engineering ``unit`` of the scaled value and the ``scale`` of one raw count: a frequency word of
0.01 Hz is ``unit="Hz", scale=0.01``. Everything that names a unit goes through these two
functions, so a raw word is never shown in the unit of its scaled value (3000 counts of 0.01 Hz
are 30.00 Hz, not 3000 Hz).
"""

from __future__ import annotations


def decimal_places(scale: float) -> int:
    """Decimal places a scaled value has: 0.01 -> 2, 0.1 -> 1, 1 -> 0, 5 -> 0, 1e-05 -> 5."""
    # From the shortest repr of the float, as Decimal(repr(scale)).normalize() reads it, without
    # importing decimal (a one-shot ``get`` prints one scaled value): digits after the point, less
    # the exponent; inf and nan have none.
    mantissa, _, exponent = repr(float(scale)).partition("e")
    fraction = mantissa.partition(".")[2].rstrip("0")
    return max(0, len(fraction) - int(exponent or 0))


def count_unit(unit: str, scale: float = 1.0) -> str:
    """The unit of one raw count, what a raw value is written in: ("Hz", 0.01) -> "0.01 Hz",
    ("rpm", 1) -> "rpm", ("A", 0.1) -> "0.1 A", ("", 0.5) -> "0.5", ("", 1) -> ""."""
    if scale == 1:
        return unit
    from decimal import Decimal  # here, not at the top: decoding a value needs only decimal_places

    step = f"{Decimal(repr(float(scale))).normalize():f}"
    return f"{step} {unit}".strip()


def scaled_text(raw: int, unit: str, scale: float = 1.0) -> str:
    """A raw value in its engineering unit, to the declaration's precision: (3000, "Hz", 0.01)
    -> "30.00 Hz", (900, "rpm", 1) -> "900 rpm"."""
    if scale == 1:
        return f"{raw} {unit}".strip()
    from decimal import Decimal

    value = Decimal(raw) * Decimal(repr(float(scale)))
    return f"{value:.{decimal_places(scale)}f} {unit}".strip()


__all__ = ["count_unit", "decimal_places", "scaled_text"]
