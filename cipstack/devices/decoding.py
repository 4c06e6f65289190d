"""The declarations a scanner decodes replies by, per profile, loaded as compact data.

``catalog_for`` (``devices.profiles``) builds a profile's whole catalog from its device model: the
classes, the assemblies, the parameters a recipe holds. A one-shot read (``cipstack get HOST
0x2A/1/102``) needs only the attributes' declarations, and importing the device model would cost
it most of its time. ``decoding_catalog`` gives those from the modules of ``devices/declared/``,
generated from the same declarations by ``python -m cipstack.devices.decoding`` (and held equal to
them by ``tests/test_decoding_data.py``): the same attributes, names, types, units and scales, and
the same ``source``; no assemblies and no parameters.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from ..catalog import Catalog
from ..cip import types
from ..cip.model import Access, AttributeSpec, ClassSpec
from ..cip.types import CipType, RemainingBytes, type_by_name

#: One attribute's declaration as data: id, name, type, access, unit, scale, offset, decimals,
#: enumeration, in Get_Attributes_All.
Row = tuple[int, str, str, str, str, float, float, "int | None", "dict[int, str] | None", bool]

#: What the generated modules are made from, and where they go.
DECLARED = Path(__file__).resolve().parent / "declared"
_BYTES = "bytes:"


def _type(name: str) -> CipType:
    """The type a row names: an elementary type, another type ``cip.types`` defines (REVISION), or
    ``bytes:NAME``, the remaining bytes under that name."""
    if name.startswith(_BYTES):
        return RemainingBytes(name[len(_BYTES):])
    defined = getattr(types, name, None)
    return defined if isinstance(defined, CipType) else type_by_name(name)


def _spec(row: Row) -> AttributeSpec:
    attribute, name, type_name, access, unit, scale, offset, decimals, enum, in_get_all = row
    return AttributeSpec(attribute, name, _type(type_name), Access(access), enum=enum, unit=unit, scale=scale,
                         in_get_all=in_get_all, offset=offset, decimals=decimals)


def _no_profile(vendor_id: int, product_code: int) -> str:
    return f"the standard objects only: no profile for vendor {vendor_id} product code {product_code} " \
           "(give eds= or catalog=)"


def decoding_catalog(vendor_id: int, product_code: int) -> Catalog:
    """The attribute declarations of the profile of (vendor id, product code), without its device
    model: ``catalog_for``'s, for decoding replies (no assemblies, no parameters)."""
    from .declared import DESCRIPTIONS, PROFILES

    name = PROFILES.get((vendor_id, product_code))
    if name is None:
        return Catalog(source=_no_profile(vendor_id, product_code))
    description = DESCRIPTIONS[name]
    data: Any = importlib.import_module(f"{__package__}.declared.{name}")
    classes = [ClassSpec(class_id, class_name, instance_attributes=tuple(_spec(row) for row in rows))
               for class_id, (class_name, rows) in data.CLASSES.items()]
    resolvers = {class_id: _resolver(rows) for class_id, rows in data.RESOLVED.items()}
    return Catalog(classes, resolvers=resolvers, profile=data.PROFILE,
                   source=f"profile {name} (vendor {vendor_id} product code {product_code}: {description})")


def _resolver(rows: dict[tuple[int, int], Row]) -> Callable[[int, int], AttributeSpec | None]:
    built: dict[tuple[int, int], AttributeSpec] = {}

    def resolve(instance: int, attribute: int) -> AttributeSpec | None:
        spec = built.get((instance, attribute))
        if spec is None:
            row = rows.get((instance, attribute))
            if row is None:
                return None
            spec = built[instance, attribute] = _spec(row)
        return spec

    return resolve


# -- generation ----------------------------------------------------------------------------------------
def row_of(spec: AttributeSpec) -> Row:
    """The data of one declaration (what decoding a reply and writing a value use of it)."""
    if isinstance(spec.type, RemainingBytes):
        type_name = _BYTES + spec.type.name
    else:
        type_name = spec.type.name
        try:
            named = _type(type_name)
        except ValueError:
            named = None
        if named is not spec.type:
            raise ValueError(f"{spec.name}: type {spec.type.name} cannot be named in the compact data")
    return (spec.id, spec.name, type_name, spec.access.value, spec.unit, float(spec.scale), float(spec.offset),
            spec.decimals, {int(k): str(v) for k, v in spec.enum.items()} if spec.enum is not None else None,
            spec.in_get_all)


def _resolved_rows(resolve: Callable[[int, int], AttributeSpec | None]) -> Iterator[tuple[tuple[int, int], Row]]:
    # A resolver answers for instance and attribute numbers of one byte each (the class 0x64/0x65 maps).
    for instance in range(256):
        for attribute in range(256):
            spec = resolve(instance, attribute)
            if spec is not None:
                yield (instance, attribute), row_of(spec)


def generate() -> dict[str, str]:
    """The modules of ``devices/declared/``, by file name, generated from the profiles' declarations."""
    from ..catalog import STANDARD_CLASSES
    from .profiles import PROFILES

    header = '"""Generated by ``python -m cipstack.devices.decoding`` from the device declarations: do not edit.\n\n'
    files: dict[str, str] = {}
    identities: dict[tuple[int, int], str] = {}
    descriptions: dict[str, str] = {}
    for name, profile in PROFILES.items():
        if profile.catalog is None:
            continue
        for product_code in sorted(profile.product_codes):
            identities[profile.vendor_id, product_code] = name
        descriptions[name] = profile.description
        catalog = profile.catalog()
        classes = {class_id: (spec.name, [row_of(a) for a in spec.instance_attributes])
                   for class_id, spec in sorted(catalog.classes.items())
                   if STANDARD_CLASSES.get(class_id) is not spec and class_id not in catalog.resolvers}
        resolved = {class_id: dict(_resolved_rows(resolve)) for class_id, resolve in sorted(catalog.resolvers.items())}
        files[f"{name}.py"] = (
            f'{header}The attribute declarations of profile {name} that replies decode by."""\n\n'
            f"PROFILE = {catalog.profile!r}\n\n"
            f"#: class id -> (class name, instance attributes), where they are not the standard objects'.\n"
            f"CLASSES = {_pretty(classes)}\n\n"
            f"#: class id -> {{(instance, attribute): declaration}}, the classes declared per instance.\n"
            f"RESOLVED = {_pretty(resolved)}\n")
    files["__init__.py"] = (
        f'{header}Which profile a device is, by its identity, and what the profile is."""\n\n'
        f"#: (vendor id, product code) -> profile.\nPROFILES = {_pretty(identities)}\n\n"
        f"#: profile -> what it emulates.\nDESCRIPTIONS = {_pretty(descriptions)}\n")
    return files


def _pretty(value: Any) -> str:
    """A dict literal with one entry a line (a diff of the generated file then shows what changed)."""
    if not isinstance(value, dict) or not value:
        return repr(value)
    lines = [f"    {key!r}: {_pretty_inner(item)}," for key, item in value.items()]
    return "{\n" + "\n".join(lines) + "\n}"


def _pretty_inner(value: Any) -> str:
    if isinstance(value, dict) and value and isinstance(next(iter(value.values())), tuple):
        return "{\n" + "\n".join(f"        {k!r}: {v!r}," for k, v in value.items()) + "\n    }"
    if isinstance(value, tuple) and len(value) == 2 and isinstance(value[1], list):
        return "(" + repr(value[0]) + ", [\n" + "\n".join(f"        {row!r}," for row in value[1]) + "\n    ])"
    return repr(value)


def main() -> int:
    """Write the generated modules (run after changing a profile's declarations)."""
    DECLARED.mkdir(exist_ok=True)
    for name, text in generate().items():
        (DECLARED / name).write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
