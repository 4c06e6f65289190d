"""Known class declarations, for decoding replies into Python values.

The scanner looks an attribute up here; a device profile's declarations extend the
standard ones, so a profile's attributes decode by the same declaration the emulator serves.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from functools import cache
from typing import TYPE_CHECKING, Any, NamedTuple

from .cip.model import AttributeSpec, ClassSpec
from .cip.types import UINT

if TYPE_CHECKING:
    # A catalog holds schemas; decoding an attribute (a one-shot ``get``) needs none of their machinery.
    from .assemblies.schema import AssemblySchema

    #: The standard objects' declarations by class id (as the objects that serve them declare them).
    STANDARD_CLASSES: dict[int, ClassSpec]


@cache
def standard_classes() -> dict[int, ClassSpec]:
    """The standard objects' declarations by class id, from the modules of the objects that serve them
    (imported on first use: a one-shot command decodes by their compact data, ``devices.decoding``)."""
    from .eip.wire.cm_spec import SPEC as CONNECTION_MANAGER_SPEC
    from .objects.assembly import SPEC as ASSEMBLY_SPEC
    from .objects.identity import identity_spec
    from .objects.message_router import SPEC as MESSAGE_ROUTER_SPEC
    from .objects.tcpip import ETHERNET_LINK_SPEC, TCPIP_SPEC

    return {spec.class_id: spec for spec in (identity_spec(), MESSAGE_ROUTER_SPEC, ASSEMBLY_SPEC,
                                             CONNECTION_MANAGER_SPEC, TCPIP_SPEC, ETHERNET_LINK_SPEC)}


@cache
def compact_standard_classes() -> dict[int, ClassSpec]:
    """The standard objects' declarations for decoding replies, from their compact data
    (``objects/declared.py``, generated from ``standard_classes`` and held equal to it): what a
    one-shot command decodes by without importing the objects (``cip.compact`` says what a row keeps)."""
    from .cip.compact import class_specs
    from .objects.declared import CLASSES

    return {spec.class_id: spec for spec in class_specs(CLASSES)}


def __getattr__(name: str) -> Any:
    if name == "STANDARD_CLASSES":
        return standard_classes()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

#: Standard class attributes every class has (instance 0).
CLASS_ATTRIBUTES: dict[int, AttributeSpec] = {
    1: AttributeSpec(1, "Revision", UINT),
    2: AttributeSpec(2, "Max Instance", UINT),
    3: AttributeSpec(3, "Number of Instances", UINT),
    6: AttributeSpec(6, "Maximum ID Number Class Attributes", UINT),
    7: AttributeSpec(7, "Maximum ID Number Instance Attributes", UINT),
}


#: For a class whose attributes depend on the instance (a register map behind instance/attribute):
#: the declaration at (instance, attribute), or None.
AttributeResolver = Callable[[int, int], "AttributeSpec | None"]


class Parameter(NamedTuple):
    """A device parameter a recipe holds (``cipstack params``): where it is and how it is declared.

    ``code`` is the manual's name for it (the ACG's keypad code ``dr.20``, the Omron function code
    ``F002``, an EDS ``ParamN``); a catalog lists its parameters in the order they can be written
    safely (the ones that bound the others' ranges first)."""

    code: str
    class_id: int
    instance: int
    attribute: int
    spec: AttributeSpec

    @property
    def path(self) -> tuple[int, int, int]:
        return self.class_id, self.instance, self.attribute

    @property
    def settable(self) -> bool:
        return self.spec.access.settable


class SaveProcedure(NamedTuple):
    """How a device makes written parameters survive a power cycle over CIP, where its manual gives a
    way (``cipstack params load`` saves with it): point the attribute ``pointer`` at ``target`` (the
    register the save command is), write each of ``edges`` into ``trigger`` as ``width`` octets (a
    change saving), then give ``pointer`` back its value."""

    pointer: tuple[int, int, int]
    target: int
    trigger: tuple[int, int, int]
    edges: tuple[int, ...]
    width: int


#: What a catalog of the standard objects alone says of itself.
STANDARD_ONLY = "the standard objects only"


class Catalog:
    """The declarations a scanner decodes replies and names class 1 fields with.

    ``source`` says where they come from (a device profile, an EDS file, the standard objects
    alone and why), so that an attribute or a field it does not know can say where it looked.
    ``standard``: the standard objects' declarations under ``classes`` (default: the objects' own,
    ``standard_classes``; ``compact_standard_classes`` for decoding only).
    """

    def __init__(self, classes: Iterable[ClassSpec] = (), assemblies: Iterable[AssemblySchema] = (),
                 resolvers: Mapping[int, AttributeResolver] | None = None, source: str = STANDARD_ONLY,
                 parameters: Iterable[Parameter] = (), profile: str | None = None,
                 standard: Mapping[int, ClassSpec] | None = None, save: SaveProcedure | None = None) -> None:
        #: Where the declarations come from, for messages: "profile acg (...)", "EDS file x.eds", ...
        self.source = source
        self.classes: dict[int, ClassSpec] = dict(standard_classes() if standard is None else standard)
        for spec in classes:
            self.classes[spec.class_id] = spec
        #: Assembly schemas by instance, when the device profile is known.
        self.assemblies: dict[int, AssemblySchema] = {a.instance: a for a in assemblies}
        #: Classes that declare their attributes per instance, instance 0 included (the Omron 0x64/0x65
        #: registers): what the device declares there is what a reply decodes by.
        self.resolvers: dict[int, AttributeResolver] = dict(resolvers or {})
        #: The parameters a recipe holds, in a safe order to write them (empty: none declared).
        self.parameters: tuple[Parameter, ...] = tuple(parameters)
        #: The device profile these declarations are of (``acg``, ``mx2``, ``rx``), None otherwise.
        self.profile = profile
        #: How the device saves its parameters, where it has a save command (None: it has none).
        self.save = save

    def add(self, spec: ClassSpec) -> None:
        self.classes[spec.class_id] = spec

    def copy(self, source: str | None = None) -> Catalog:
        """A catalog with the same declarations (shared: they are immutable) and tables of its own."""
        other = Catalog(source=self.source if source is None else source)
        other.classes = dict(self.classes)
        other.assemblies = dict(self.assemblies)
        other.resolvers = dict(self.resolvers)
        other.parameters = self.parameters
        other.profile = self.profile
        other.save = self.save
        return other

    def __repr__(self) -> str:
        return f"<Catalog: {self.source}>"

    def attribute(self, class_id: int, instance: int, attribute_id: int) -> AttributeSpec | None:
        resolve = self.resolvers.get(class_id)
        if resolve is not None:
            return resolve(instance, attribute_id)
        if instance == 0:
            return CLASS_ATTRIBUTES.get(attribute_id)
        spec = self.classes.get(class_id)
        return spec.instance_attribute(attribute_id) if spec is not None else None

    def parameter(self, code: str) -> Parameter | None:
        """The parameter whose code is exactly ``code``, or None (``parameter_codes.find_parameter``
        also takes a code as a person types it, and a name)."""
        for parameter in self.parameters:
            if parameter.code == code:
                return parameter
        return None

    def get_all_layout(self, class_id: int) -> list[AttributeSpec] | None:
        """The attributes of a Get_Attributes_All reply of ``class_id``, in order (None: unknown class)."""
        spec = self.classes.get(class_id)
        if spec is None:
            return None
        return [a for a in spec.instance_attributes if a.in_get_all and a.access.readable]
