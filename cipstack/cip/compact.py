"""Attribute declarations as compact data: a row of literals per attribute, and back.

A one-shot command (``cipstack get HOST 1/1/7``) decodes one reply by one declaration; importing
the modules that declare them (the objects that serve the standard classes, a device's model)
would cost it most of its time. Generated modules hold the declarations as rows instead
(``objects/declared.py`` for the standard objects, ``devices/declared/`` for the profiles), written
by ``python -m cipstack.devices.decoding`` from the declarations themselves and held equal to them
by ``tests/test_decoding_data.py``. A row keeps what decoding a reply and writing a value use: id,
name, type, access, unit, scale, offset, decimals, enumeration, whether Get_Attributes_All holds
it, and the declared range (a value is checked against it before ``cipstack set`` sends it); not the
defaults and help the emulator serves.
"""

from __future__ import annotations

from typing import Any

from ..errors import BadRequest
from . import types
from .model import Access, AttributeSpec, ClassSpec
from .types import ArrayType, CipType, OctetString, RemainingBytes, StructType, type_by_name

#: A type as data: its name (``UINT``, ``REVISION``, ``bytes:NAME``), or a structure, array or octet
#: string spelled out: ``("struct", NAME, ((MEMBER, TYPE), ...))``, ``("array", TYPE, COUNT, NAME)``,
#: ``("octets", SIZE, NAME)``.
TypeData = Any
#: One attribute's declaration as data: id, name, type, access, unit, scale, offset, decimals,
#: enumeration, in Get_Attributes_All, minimum, maximum.
Row = tuple[int, str, TypeData, str, str, float, float, "int | None", "dict[int, str] | None", bool,
            "int | float | None", "int | float | None"]
#: Classes as data: class id -> (class name, its instance attributes' rows).
Classes = dict[int, tuple[str, list[Row]]]

_BYTES = "bytes:"


def cip_type(data: TypeData) -> CipType:
    """The type ``data`` names: an elementary type, another type ``cip.types`` defines (REVISION),
    ``bytes:NAME`` (the remaining bytes under that name), or a structure, array or octet string
    spelled out (``type_data``)."""
    if isinstance(data, tuple):
        kind = data[0]
        if kind == "struct":
            return StructType(data[1], [(member, cip_type(of)) for member, of in data[2]])
        if kind == "array":
            return ArrayType(cip_type(data[1]), data[2], data[3])
        return OctetString(data[1], data[2])
    if data.startswith(_BYTES):
        return RemainingBytes(data[len(_BYTES):])
    defined = getattr(types, data, None)
    return defined if isinstance(defined, CipType) else type_by_name(data)


def type_data(of: CipType) -> TypeData:
    """What ``cip_type`` builds ``of`` again from: its name when ``cip.types`` has it by that name,
    else how it is made (the structures the standard objects declare: Object List, ...)."""
    if isinstance(of, RemainingBytes):
        return _BYTES + of.name
    try:
        if cip_type(of.name) is of:
            return of.name
    except ValueError:
        pass
    if isinstance(of, StructType):
        return ("struct", of.name, tuple((member, type_data(member_type)) for member, member_type in of.members))
    if isinstance(of, ArrayType):
        return ("array", type_data(of.element), of.count, of.name)
    if isinstance(of, OctetString):
        return ("octets", of.size, of.name)
    raise BadRequest(f"type {of.name} cannot be named in the compact data")


def attribute_spec(row: Row) -> AttributeSpec:
    """The declaration a row holds (for decoding)."""
    attribute, name, type_name, access, unit, scale, offset, decimals, enum, in_get_all, minimum, maximum = row
    return AttributeSpec(attribute, name, cip_type(type_name), Access(access), enum=enum, unit=unit, scale=scale,
                         in_get_all=in_get_all, offset=offset, decimals=decimals, minimum=minimum, maximum=maximum)


def row_of(spec: AttributeSpec) -> Row:
    """The data of one declaration (what decoding a reply and writing a value use of it)."""
    try:
        data = type_data(spec.type)
    except ValueError as exc:
        raise BadRequest(f"{spec.name}: {exc}") from None
    return (spec.id, spec.name, data, spec.access.value, spec.unit, float(spec.scale), float(spec.offset),
            spec.decimals, {int(k): str(v) for k, v in spec.enum.items()} if spec.enum is not None else None,
            spec.in_get_all, spec.minimum, spec.maximum)


def class_specs(classes: Classes) -> list[ClassSpec]:
    """The classes ``classes`` holds, their instance attributes declared by their rows."""
    return [ClassSpec(class_id, class_name, instance_attributes=tuple(attribute_spec(row) for row in rows))
            for class_id, (class_name, rows) in classes.items()]


def classes_data(classes: dict[int, ClassSpec]) -> Classes:
    """``classes`` as data, in class id order."""
    return {class_id: (spec.name, [row_of(a) for a in spec.instance_attributes])
            for class_id, spec in sorted(classes.items())}


__all__ = ["Classes", "Row", "TypeData", "attribute_spec", "cip_type", "class_specs", "classes_data", "row_of",
           "type_data"]
