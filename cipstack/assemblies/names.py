"""The one rule that turns a human name into an assembly field name, and back.

A device declares its assembly fields in ``snake_case`` (``faulted``, ``speed_actual``,
``ctrl_from_net``); an EDS file names the same members in words a configuration tool shows
("Faulted", "Speed Actual", "SpeedActual", "Ctrl From Net"). ``field_name`` maps both spellings
to one name, so a script that sets ``run_forward`` or reads ``speed_actual`` works whether the
fields came from a profile or from the device's EDS file:

1. letters with accents lose them (``ß`` becomes ss), other non-ASCII characters are dropped;
2. CamelCase is split before a capitalised word that follows two lower-case letters or a digit
   (``SpeedActual`` -> speed actual, ``speedRef`` -> speed ref) or an acronym of two or more
   capitals (``RPMActual`` -> RPM actual, ``DCBusVoltage`` -> DC bus voltage). Short mixed-case
   codes stay whole (keypad codes ``bA.1``, ``dEC``, ``nOn``; units ``kWh``), and a letter
   followed by a digit is not split (``Running1`` stays running1);
3. every run of characters other than ASCII letters and digits becomes one ``_``, leading and
   trailing ones are dropped, and the result is lower case;
4. a name that starts with a digit (``1st Accel``) gets ``p_`` in front (``p_1st_accel``), so it
   is an identifier.

Within one assembly ``unique_field_names`` makes repeated names distinct: a name that occurs
again gets the position (1-based) of that occurrence appended, ``_N``. ``display_name`` is the
inverse for the names a device declares: ``ctrl_from_net`` -> "Ctrl From Net", which
``field_name`` maps back.
"""

from __future__ import annotations

import re
import unicodedata
from collections.abc import Iterable

#: Put before a name that would start with a digit.
DIGIT_PREFIX = "p_"

#: A capitalised word after two lower-case letters or a digit: "SpeedActual", "speedRef", "Mx2Drive".
_WORD_AFTER_LOWER = re.compile(r"(?:(?<=[a-z]{2})|(?<=[0-9]))(?=[A-Z][a-z])")
#: A capitalised word after an acronym of two or more capitals: "RPMActual", "DCBusVoltage".
_WORD_AFTER_ACRONYM = re.compile(r"(?<=[A-Z]{2})(?=[A-Z][a-z])")
_SEPARATORS = re.compile(r"[^0-9A-Za-z]+")


def field_name(text: str) -> str:
    """The field name of a human name (see the module docstring); "" when ``text`` has no
    letter or digit."""
    ascii_text = unicodedata.normalize("NFKD", text.replace("ß", "ss")).encode("ascii", "ignore").decode("ascii")
    split = _WORD_AFTER_ACRONYM.sub("_", _WORD_AFTER_LOWER.sub("_", ascii_text))
    name = _SEPARATORS.sub("_", split).strip("_").lower()
    if name[:1].isdigit():
        name = DIGIT_PREFIX + name
    return name


def unique_field_names(names: Iterable[str]) -> list[str]:
    """``names`` (already field names) with repeats made distinct: a name seen before gets
    ``_N``, N its 1-based position in ``names``; should that be taken too, ``_2``, ``_3`` ...
    follow. Names that occur once never change, so adding a member does not rename another."""
    given = list(names)
    taken = set(given)
    seen: set[str] = set()
    out: list[str] = []
    for position, name in enumerate(given, start=1):
        if name not in seen:
            seen.add(name)
            out.append(name)
            continue
        candidate, extra = f"{name}_{position}", 2
        while candidate in taken:
            candidate, extra = f"{name}_{position}_{extra}", extra + 1
        taken.add(candidate)
        out.append(candidate)
    return out


def display_name(name: str) -> str:
    """A declared field name in words, for a person: ``speed_actual`` -> "Speed Actual".
    ``field_name(display_name(n)) == n`` for every name already in field-name form."""
    return " ".join(part.capitalize() for part in name.split("_") if part)


__all__ = ["DIGIT_PREFIX", "display_name", "field_name", "unique_field_names"]
