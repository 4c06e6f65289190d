"""The catalog a scanner decodes a device's replies by, from its profile's compact declarations.

A scanner identifies the device, then decodes every reply and finds every parameter code by the
declarations of the device's profile. Building the profile's whole catalog (``devices.profiles
.catalog_for``) means building its device model, which imports the emulator's side (the target,
asyncio) and costs a script most of its time. The profile's declarations are also generated as
compact data (``devices/declared/``, by ``python -m cipstack.devices.decoding``, and held equal to
the device model's by ``tests/test_decoding_data.py``): the attributes' rows (name, type, access,
unit, scale, range, enumeration) and where each parameter code is. ``decoding_catalog`` builds a
catalog from them: the same ``source``, ``profile``, attributes and parameters as ``catalog_for``'s,
each declaration built when first asked for, the assembly schemas (class 1 fields by name) included.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from .catalog import Catalog, Parameter, SaveProcedure, compact_standard_classes
from .cip.compact import Row, attribute_spec, class_specs
from .cip.model import AttributeSpec

if TYPE_CHECKING:
    from .assemblies.schema import AssemblySchema

#: Where the generated declarations are: ``{PACKAGE}`` (profiles by identity), ``{PACKAGE}.NAME``.
DECLARED_PACKAGE = "cipstack.devices.declared"


def no_profile_source(vendor_id: int, product_code: int) -> str:
    """What a catalog of no profile says of itself (``catalog_for`` says the same)."""
    return f"the standard objects only: no profile for vendor {vendor_id} product code {product_code} " \
           "(give eds= or catalog=)"


class ProfileCatalog(Catalog):
    """A profile's catalog from its compact declarations: attributes, parameters and assembly schemas
    as ``catalog_for`` declares them, each built when first asked for."""

    def __init__(self, name: str, source: str) -> None:
        data: Any = importlib.import_module(f"{DECLARED_PACKAGE}.{name}")
        self._data = data
        resolvers = {class_id: _resolver(rows) for class_id, rows in data.RESOLVED.items()}
        self._assemblies: dict[int, AssemblySchema] | None = None
        self._parameters: tuple[Parameter, ...] | None = None
        #: Parameter code -> (class, instance, attribute), as the generated data lists them.
        self._codes: dict[str, tuple[int, int, int]] = {code: (c, i, a) for code, c, i, a in data.PARAMETERS}
        super().__init__(class_specs(data.CLASSES), resolvers=resolvers, profile=data.PROFILE, source=source,
                         standard=compact_standard_classes(),
                         save=SaveProcedure(*data.SAVE) if data.SAVE is not None else None)

    # The base class assigns both in its constructor; the property keeps them lazy.
    @property  # a lazy attribute where Catalog has a plain one
    def assemblies(self) -> dict[int, AssemblySchema]:
        """The profile's assembly schemas, built from the compact data the first time."""
        if self._assemblies is None:
            from .assemblies.compact import assembly_schema

            self._assemblies = {instance: assembly_schema(instance, data)
                                for instance, data in self._data.ASSEMBLIES.items()}
        return self._assemblies

    @assemblies.setter
    def assemblies(self, assemblies: dict[int, AssemblySchema]) -> None:
        # Catalog's constructor gives an empty table: the profile's are loaded when first asked for.
        self._assemblies = assemblies or None

    @property  # a lazy attribute where Catalog has a plain one
    def parameters(self) -> tuple[Parameter, ...]:
        """The profile's parameters in the order its declaration lists them (a safe order to write them)."""
        if self._parameters is None:
            self._parameters = tuple(self._parameter(code, path) for code, path in self._codes.items())
        return self._parameters

    @parameters.setter
    def parameters(self, parameters: tuple[Parameter, ...]) -> None:
        self._parameters = parameters or None

    def copy(self, source: str | None = None) -> Catalog:
        """A catalog with the same declarations and tables of its own, still loading the assemblies
        and parameters when first asked for."""
        other = object.__new__(ProfileCatalog)
        other.__dict__.update(self.__dict__)
        other.classes, other.resolvers = dict(self.classes), dict(self.resolvers)
        other._assemblies = None if self._assemblies is None else dict(self._assemblies)
        if source is not None:
            other.source = source
        return other

    def parameter(self, code: str) -> Parameter | None:
        if self._parameters is None:   # one code, one declaration built: not the whole list
            path = self._codes.get(code)
            return None if path is None else self._parameter(code, path)
        return super().parameter(code)

    def _parameter(self, code: str, path: tuple[int, int, int]) -> Parameter:
        spec = self.attribute(*path)
        assert spec is not None, f"{code}: no declaration at {path}"  # the generator checks it
        return Parameter(code, *path, spec)


def decoding_catalog(vendor_id: int, product_code: int, device_type: int | None = None) -> Catalog:
    """The catalog of the profile of (vendor id, product code), from its compact declarations
    (``ProfileCatalog``) for cipstack's own families; for a family another distribution brings (the
    ``cipstack.devices`` entry points, read only for an identity none of cipstack's families has), its
    declaration's (``devices.profiles.catalog_for``); else the standard objects', with a ``source`` that
    says so."""
    from .devices.declared import DESCRIPTIONS, PROFILES

    name = PROFILES.get((vendor_id, product_code))
    if name is None:
        from .devices.profiles import profile_for

        installed = profile_for(vendor_id, product_code, device_type)
        if installed is not None:
            from .devices.profiles import catalog_for

            return catalog_for(vendor_id, product_code, device_type)
        return Catalog(source=no_profile_source(vendor_id, product_code), standard=compact_standard_classes())
    return ProfileCatalog(name, f"profile {name} (vendor {vendor_id} product code {product_code}: "
                                f"{DESCRIPTIONS[name]})")


def _resolver(rows: Mapping[tuple[int, int], Row]) -> Callable[[int, int], AttributeSpec | None]:
    built: dict[tuple[int, int], AttributeSpec] = {}

    def resolve(instance: int, attribute: int) -> AttributeSpec | None:
        spec = built.get((instance, attribute))
        if spec is None:
            row = rows.get((instance, attribute))
            if row is None:
                return None
            spec = built[instance, attribute] = attribute_spec(row)
        return spec

    return resolve


__all__ = ["ProfileCatalog", "decoding_catalog", "no_profile_source"]
