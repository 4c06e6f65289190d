"""Drive parameters by the codes their manual prints, for a scanner author who thinks in them: the
ACG keypad's ``ACC``, ``dEC``, ``CM.24``, ``Pr.12``; an Omron function code ``A004``; an EDS file's
``ParamN`` or that parameter's name. Where each is and how its value converts come from the
catalog's declarations (``Catalog.parameters``: the profile's, or every linked ``ParamN`` of an
EDS file), the same list the parameter recipes use.

A value given by code is in the parameter's own unit, as the keypad, ``--param`` and the HTTP API
take it: ``2.5`` for an acceleration time of 2.5 s, turned into raw steps by the declaration; a
value between two steps is refused. ``Scanner.parameter``/``set_parameter`` and ``cipstack get|set
HOST CODE`` call what is here, over the scanner's own read and write."""

from __future__ import annotations

from typing import Any

from .catalog import Catalog, Parameter
from .cip.types import IntegerType
from .cip.values import Value
from .errors import BadRequest, NotFound


class UnknownParameterError(NotFound, KeyError):
    """A code the device's declarations do not name; the message lists the nearest ones."""

    def __init__(self, code: str, catalog: Catalog, near: list[str]) -> None:
        self.code = code
        self.near = near
        hint = f": did you mean {', '.join(near)}?" if near else ":"
        listed = ("`cipstack params dump HOST` lists them" if catalog.parameters
                  else "give an EDS file (eds=, --eds) that declares them")
        # NotFound's __str__ comes before KeyError's: the message plain, not its repr.
        super().__init__(f"no parameter {code!r} in {catalog.source}{hint} {listed}")


class ParameterValueError(BadRequest):
    """A value a parameter cannot take as given (not a number, between two steps, not a choice)."""


def _key(text: str) -> str:
    """A code as a person may type it: case and ``-``/``.``/blanks between group and number ignored
    (``cm-24``, ``CM 24`` and ``CM.24`` are one code)."""
    return "".join(c for c in text.lower() if c.isalnum())


def find_parameter(catalog: Catalog, code: str) -> Parameter:
    """The parameter ``code`` names: its code exactly, else its code or its name (an EDS
    ``ParamN``'s name, ``"Accel Time"``) without regard to case and separators. A name two
    parameters share is refused with their codes."""
    exact = catalog.parameter(code)
    if exact is not None:
        return exact
    parameters = catalog.parameters
    wanted = _key(code)
    by_code = [p for p in parameters if _key(p.code) == wanted]
    if len(by_code) == 1:
        return by_code[0]
    by_name = [p for p in parameters if _key(p.spec.name) == wanted]
    if len(by_name) == 1:
        return by_name[0]
    if len(by_code) + len(by_name) > 1:
        raise UnknownParameterError(code, catalog, [p.code for p in by_code + by_name])
    import difflib  # only to suggest codes near one that is not there

    names = {p.code: p for p in parameters}
    near = difflib.get_close_matches(code, list(names), n=5, cutoff=0.6)
    if not near:   # by name, then their codes
        spelled = {p.spec.name: p.code for p in parameters}
        near = [spelled[n] for n in difflib.get_close_matches(code, list(spelled), n=5, cutoff=0.6)]
    raise UnknownParameterError(code, catalog, near)


def raw_of(parameter: Parameter, value: Any) -> Any:
    """The raw value of ``value`` given in the parameter's unit: a number (or its text) scaled by the
    declaration, a choice of an enumeration by its text (``"Field Bus"``), a ``Value`` as it was read.
    A value outside the declared range (else the type's) is refused here, before anything is sent:
    ``ACC (Acceleration Time) takes 0.0..6000.0 s``."""
    raw = _raw_of(parameter, value)
    out_of_range = parameter.spec.out_of_range(raw, f"{parameter.code} ({parameter.spec.name})")
    if out_of_range is not None:
        raise ParameterValueError(out_of_range)
    return raw


def _raw_of(parameter: Parameter, value: Any) -> Any:
    spec = parameter.spec
    if isinstance(value, Value):
        return value.raw
    where = f"{parameter.code} ({spec.name})"
    if isinstance(value, str):
        text = value.strip()
        for raw, meaning in (spec.enum or {}).items():
            if meaning.lower() == text.lower():
                return raw
        try:
            value = float(text)
        except ValueError:
            if isinstance(spec.type, IntegerType):
                choices = f"; its choices: {', '.join(spec.enum.values())}" if spec.enum else ""
                raise ParameterValueError(f"{where}: {value!r} is not a number{choices}") from None
            return spec.type.parse_text(text)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterValueError(f"{where} takes a number in {spec.unit or 'its unit'}, not {value!r}")
    scaling = spec.scaling
    if not isinstance(spec.type, IntegerType):   # a REAL: no steps to round to
        return value / scaling.scale - scaling.offset
    try:
        return scaling.to_raw(value)
    except ValueError as exc:
        raise ParameterValueError(f"{where}: {exc}") from None
