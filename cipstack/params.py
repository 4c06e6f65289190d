"""Drive parameter recipes: dump a drive's parameters to a TOML file, load them into another, diff.

The parameters are those the scanner's catalog declares (``Catalog.parameters``: a device profile's,
or every ``ParamN`` with a link path of an EDS file), each with its code, name, raw value, engineering
value and unit. Loading writes only the settable parameters whose value differs, in the catalog's
order (the ones that bound the others first), refuses while the drive runs unless forced, and saves
where the device has a save command, as its catalog declares it (``Catalog.save``: on the ACG, memory
control register 0x03E0 "Save parameters" reached over CIP through CM.51 and output assembly 121).

The file::

    # cipstack parameter recipe
    [device]
    vendor_id = 259
    ...

    [[parameter]]
    code = "ACC"
    name = "Acc Time"
    path = "0x64/1/3"      # class/instance/attribute
    raw = 50
    value = 5.0
    unit = "s"

``raw`` is what is written back; ``value`` and ``unit`` are for the reader.
"""

from __future__ import annotations

import json
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .catalog import Parameter
from .cip.status import CipError
from .cip.values import Value
from .errors import BadRequest, NotFound, StateRefused

if TYPE_CHECKING:
    from .scanner import Scanner

class DriveRunningError(StateRefused, RuntimeError):
    """A recipe load refused because the drive runs (give ``force=True`` to load anyway)."""


@dataclass(frozen=True)
class ParamValue:
    """One parameter as read from a device or a recipe."""

    code: str
    name: str
    path: tuple[int, int, int]
    raw: Any
    value: Any = None
    unit: str = ""
    settable: bool = True

    @property
    def path_text(self) -> str:
        return f"0x{self.path[0]:02X}/{self.path[1]}/{self.path[2]}"

    def text(self) -> str:
        """``5.0 s (50)``, or the raw value alone when unscaled."""
        shown = f"{self.value} {self.unit}".strip() if self.value is not None else str(self.raw)
        return shown if self.value == self.raw or self.value is None else f"{shown} ({self.raw})"


@dataclass
class LoadReport:
    """What ``load_params`` did: written, unchanged, refused (with the device's reason), saved."""

    written: list[ParamValue] = field(default_factory=list)
    unchanged: int = 0
    refused: list[tuple[ParamValue, str]] = field(default_factory=list)
    skipped: list[tuple[ParamValue, str]] = field(default_factory=list)
    saved: bool = False


@dataclass(frozen=True)
class Difference:
    """A parameter whose device value is not the recipe's (``device`` None: the device has no such parameter)."""

    recipe: ParamValue
    device: ParamValue | None

    def text(self) -> str:
        here = "not on the device" if self.device is None else self.device.text()
        name = f"{self.recipe.code or self.recipe.path_text} {self.recipe.name}"
        return f"{name}: device {here}, file {self.recipe.text()}"


def _value_of(parameter: Parameter, reading: Value) -> ParamValue:
    value = reading.value if reading.known else None
    if isinstance(value, float):
        value = round(value, 9)
    return ParamValue(parameter.code, parameter.spec.name, parameter.path, reading.raw, value, parameter.spec.unit,
                      parameter.settable)


def _declared(parameter: Parameter | None, item: ParamValue) -> ParamValue:
    """A recipe's entry with its value and unit as the declaration reads its raw value (the file's
    ``value`` is for its reader and may be stale)."""
    if parameter is None:
        return item
    return _value_of(parameter, Value(item.raw, parameter.spec.name, parameter.spec.type, parameter.spec.scaling))


def _parameters(scanner: Scanner) -> tuple[Parameter, ...]:
    parameters = scanner.catalog.parameters
    if not parameters:
        raise NotFound(f"no parameters are declared in {scanner.catalog.source}: give an EDS file (eds=)")
    return parameters


async def dump_params(scanner: Scanner) -> list[ParamValue]:
    """Every declared parameter's present value (``scanner.catalog.parameters``), in the catalog's order.
    A parameter the device refuses to read is left out (logged by the scanner at DEBUG)."""
    out = []
    for parameter in _parameters(scanner):
        try:
            reading = await scanner.read(*parameter.path)
        except CipError:
            continue
        out.append(_value_of(parameter, reading))
    return out


async def drive_running(scanner: Scanner) -> bool:
    """Whether the drive runs: Control Supervisor (0x29) attribute 7 or 8 (Running1/Running2, the
    ACG's Running Forward/Reverse); a device without them is taken as stopped."""
    for attribute in (7, 8):
        try:
            if (await scanner.read(0x29, 1, attribute)).raw:
                return True
        except CipError:
            continue
    return False


async def load_params(scanner: Scanner, recipe: Sequence[ParamValue], *, force: bool = False,
                      save: bool = True) -> LoadReport:
    """Write a recipe's settable parameters whose value differs, in the catalog's order, then save
    (where the device has a save command and ``save``). Refuses with ``DriveRunningError`` while the
    drive runs, unless ``force``. A value the device refuses is reported, and the rest is written."""
    if not force and await drive_running(scanner):
        raise DriveRunningError("the drive is running: stop it first, or force the load")
    report = LoadReport()
    declared = {p.path: p for p in _parameters(scanner)}
    wanted = {item.path: _declared(declared.get(item.path), item) for item in recipe}
    known = set(declared)
    for item in recipe:
        if item.path not in known:
            report.skipped.append((item, f"not a parameter of {scanner.catalog.source}"))
    for parameter in _parameters(scanner):
        value = wanted.get(parameter.path)
        if value is None:
            continue
        if not parameter.settable:
            report.skipped.append((value, "read only"))
            continue
        try:
            present = await scanner.read(*parameter.path)
            if present.raw == value.raw:
                report.unchanged += 1
                continue
            await scanner.write(*parameter.path, value.raw)
        except CipError as exc:
            report.refused.append((value, str(exc)))
            continue
        report.written.append(value)
    if save and report.written:
        report.saved = await save_params(scanner, wanted)
    return report


async def save_params(scanner: Scanner, recipe: dict[tuple[int, int, int], ParamValue] | None = None) -> bool:
    """Make the written parameters survive a power cycle where the device has a save command (its
    catalog's ``SaveProcedure``); returns whether it has one. The pointer then gets back its value: the
    recipe's, else the one before (so a saved set keeps the save command in it)."""
    save = scanner.catalog.save
    if save is None:
        return False
    before = (await scanner.read(*save.pointer)).raw
    await scanner.write(*save.pointer, save.target)
    try:
        for edge in save.edges:
            await scanner.set_attribute_single(*save.trigger, edge.to_bytes(save.width, "little"))
    finally:
        restored = recipe.get(save.pointer) if recipe else None
        await scanner.write(*save.pointer, restored.raw if restored is not None else before)
    return True


async def diff_params(scanner: Scanner, recipe: Sequence[ParamValue]) -> list[Difference]:
    """The recipe's parameters whose raw value on the device differs, in the recipe's order."""
    out = []
    declared = {p.path: p for p in scanner.catalog.parameters}
    for entry in recipe:
        parameter = declared.get(entry.path)
        item = _declared(parameter, entry)
        try:
            reading = await scanner.read(*item.path)
        except CipError:
            out.append(Difference(item, None))
            continue
        present = (_value_of(parameter, reading) if parameter is not None
                   else ParamValue(item.code, item.name, item.path, reading.raw))
        if present.raw != item.raw:
            out.append(Difference(item, present))
    return out


# -- the file -------------------------------------------------------------------------------------------------
def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, (bytes, bytearray)):
        return json.dumps(bytes(value).hex())
    return json.dumps(str(value), ensure_ascii=False)  # a JSON string is a TOML basic string


def recipe_text(values: Sequence[ParamValue], device: dict[str, Any] | None = None) -> str:
    """The TOML text of a recipe (see the module's docstring)."""
    lines = ["# cipstack parameter recipe: `cipstack params load HOST FILE` writes the raw values back", ""]
    if device:
        lines.append("[device]")
        lines += [f"{key} = {_toml_value(value)}" for key, value in device.items() if value is not None]
        lines.append("")
    for item in values:
        lines.append("[[parameter]]")
        if item.code:
            lines.append(f"code = {_toml_value(item.code)}")
        lines += [f"name = {_toml_value(item.name)}", f"path = {_toml_value(item.path_text)}",
                  f"raw = {_toml_value(item.raw)}"]
        if item.value is not None and item.value != item.raw:
            lines.append(f"value = {_toml_value(item.value)}")
        if item.unit:
            lines.append(f"unit = {_toml_value(item.unit)}")
        lines.append("")
    return "\n".join(lines)


def write_recipe(path: str | os.PathLike[str], values: Sequence[ParamValue], device: dict[str, Any] | None = None
                 ) -> None:
    """Write a recipe file (TOML)."""
    Path(path).write_text(recipe_text(values, device), encoding="utf-8")


def _load_toml(text: str) -> dict[str, Any]:
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover - Python 3.10
        import tomli as tomllib
    return tomllib.loads(text)


def parse_recipe(text: str) -> list[ParamValue]:
    """The parameters of a recipe's TOML text; ``ValueError`` naming the entry that is not one."""
    try:
        data = _load_toml(text)
    except Exception as exc:  # tomllib.TOMLDecodeError and its 3.10 twin
        raise BadRequest(f"not a TOML recipe: {exc}") from None
    out = []
    for index, entry in enumerate(data.get("parameter", []), 1):
        try:
            parts = str(entry["path"]).split("/")
            path = (int(parts[0], 0), int(parts[1], 0), int(parts[2], 0))
            raw = entry["raw"]
        except (KeyError, ValueError, IndexError, TypeError):
            raise BadRequest(f"parameter {index}: needs path = \"CLASS/INSTANCE/ATTRIBUTE\" and raw") from None
        out.append(ParamValue(str(entry.get("code", "")), str(entry.get("name", "")), path, raw,
                              entry.get("value"), str(entry.get("unit", ""))))
    return out


def read_recipe(path: str | os.PathLike[str]) -> list[ParamValue]:
    """The parameters of a recipe file."""
    return parse_recipe(Path(path).read_text(encoding="utf-8"))


def device_record(scanner: Scanner) -> dict[str, Any]:
    """The ``[device]`` table of a recipe: what the device said it is and where the declarations came from."""
    identity = scanner.identity
    record: dict[str, Any] = {"declarations": scanner.catalog.source}
    if identity is not None:
        record = {"vendor_id": identity.vendor_id, "product_code": identity.product_code,
                  "product_name": identity.product_name,
                  "revision": f"{identity.revision[0]}.{identity.revision[1]}", **record}
    return record


__all__ = ["Difference", "DriveRunningError", "LoadReport", "ParamValue", "device_record", "diff_params",
           "drive_running", "dump_params", "load_params", "parse_recipe", "read_recipe", "recipe_text",
           "save_params", "write_recipe"]
