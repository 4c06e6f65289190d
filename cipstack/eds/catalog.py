"""An EDS file as a scanner's catalog, for any device: ``catalog_from_eds("drive.eds")``.

Every ``ParamN`` with a link path (field 3) declares the attribute it names (and is a parameter of
a recipe, ``cipstack params``): type (field 5),
access (descriptor bit 4), range and default (10-12), enumeration (``EnumN``), unit (8) and
scaling (13-16 multiplier, divider, base, offset; 21 decimal places; the EDS specification), so
a reply decodes, scales and prints as it does with a device profile. Every assembly with members
gives the field names of its class 1 data. What the file does not declare falls back to the
standard objects (Identity, TCP/IP, ...).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from ..catalog import Catalog, Parameter
from ..cip.model import Access, AttributeSpec
from .interpret import ParamInfo, read_view
from .model import EdsDocument
from .reader import read_eds

#: (class, instance, attribute) -> declaration.
_Table = dict[tuple[int, int, int], AttributeSpec]


def attribute_of(param: ParamInfo) -> AttributeSpec:
    """The attribute a ``ParamN`` with a link path declares."""
    assert param.link is not None
    number = param.keyword[len("Param"):] if param.keyword.startswith("Param") else param.keyword
    return AttributeSpec(param.link[2], param.name or param.keyword, param.type,
                         Access.GET_SET if param.settable else Access.GET, default=param.default,
                         minimum=param.minimum, maximum=param.maximum, enum=param.enum, unit=param.unit,
                         scale=param.scale, help=param.help or f"EDS Param{number}", offset=param.offset,
                         decimals=param.decimals)


def catalog_from_eds(eds: str | os.PathLike[str] | EdsDocument, name: str | None = None) -> Catalog:
    """The declarations of an EDS file (a path or a read ``EdsDocument``) as a ``Catalog``:
    ``Scanner.connect(host, eds="drive.eds")`` uses it. ``name`` names the file in messages."""
    if isinstance(eds, EdsDocument):
        doc, label = eds, name or ""
    else:
        doc, label = read_eds(eds), name or Path(eds).name
    view = read_view(doc)
    table: _Table = {}
    parameters = []
    for param in view.params.values():
        if param.link is not None and param.link not in table:   # the first parameter naming it wins
            table[param.link] = attribute_of(param)
            parameters.append(Parameter(param.keyword, *param.link, table[param.link]))
    standard = Catalog()
    by_class: dict[int, _Table] = {}
    for link, spec in table.items():
        by_class.setdefault(link[0], {})[link] = spec

    def resolver(class_id: int, entries: _Table) -> Callable[[int, int], AttributeSpec | None]:
        def resolve(instance: int, attribute: int) -> AttributeSpec | None:
            return entries.get((class_id, instance, attribute)) or standard.attribute(class_id, instance, attribute)
        return resolve

    schemas = [schema for info in view.assemblies.values() if info.instance is not None
               for schema in [view.schema(info.instance)] if schema is not None]
    device = doc.get("Device")
    product = ""
    if device is not None:
        entry = device.get("ProdName")
        field = entry.field(1) if entry is not None else None
        product = f"({field.value})" if field is not None and isinstance(field.value, str) else ""
    return Catalog(assemblies=schemas, resolvers={c: resolver(c, e) for c, e in by_class.items()},
                   source=" ".join(part for part in ("EDS file", label, product) if part), parameters=parameters)


__all__ = ["attribute_of", "catalog_from_eds"]
