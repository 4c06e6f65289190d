"""What an EDS file says about a device, gathered from the device's own declarations.

``EdsDescription`` is the one input of the EDS generator (``generator.generate_eds``). It holds
no value of its own: a device module fills it from what it already declares (its
``IdentityInfo``, its ``Register`` table or the ``AttributeSpec`` entries of its classes, its
``AssemblySchema`` instances, the class 1 offer of its ``IoProfile``), so the EDS file and the
device the emulator serves can never disagree.

The pieces:

* ``EdsParameter``: one ``ParamN``. Built from a drive ``Register`` (the Omron ``Parameter`` is
  one) with ``from_register``, from a CIP ``AttributeSpec``
  with ``from_attribute``, or, by the generator, from an assembly field that links no declared
  parameter. ``link`` is the (class, instance, attribute) the parameter mirrors.
* ``IoOffer``: the class 1 connections the device accepts, as ``IoProfile`` states them: the
  exclusive-owner pairs, the input-only and listen-only heartbeat points, the RPI range.
* ``EdsPort``, ``EdsCapacity``, ``EdsObjectClass``: ``[Port]``, ``[Capacity]`` and the object
  class sections.
* ``componet_io``: for a CompoNet slave, the (output, input) assemblies of its default
  connection path, whose sizes go to ``[CompoNet_IO]``.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any, Literal

from ..assemblies.schema import AssemblySchema
from ..cip.model import AttributeSpec, ClassSpec
from ..cip.types import DINT, UDINT, CipType, IntegerType
from ..devices.registers import Register
from ..eip.target.io_target import IoProfile
from ..eip.wire.cm_messages import TriggerType
from ..errors import BadRequest, UnknownKey
from ..objects.identity import IdentityInfo

Network = Literal["EtherNetIP", "CompoNet"]
NETWORKS: tuple[str, ...] = ("EtherNetIP", "CompoNet")

#: (class, instance, attribute) of the CIP attribute a parameter or assembly field mirrors.
Link = tuple[int, int, int]


def wire_type(cip_type: CipType, words: int) -> CipType:
    """The type a register of ``words`` 16-bit words has on the wire: a one-word type widened to
    its double-word form when the register is two words long (a UINT register of two words is
    read as a UDINT)."""
    if words == 2 and cip_type.size == 2:
        return DINT if isinstance(cip_type, IntegerType) and cip_type.signed else UDINT
    return cip_type


#: The ``[File]`` revision of the EDS files cipstack generates.
FILE_REVISION = (1, 0)


@dataclass(frozen=True)
class EdsParameter:
    """One ``ParamN``: values are raw (as on the wire), ``scale`` turns them into ``unit``."""

    name: str
    type: CipType
    #: The attribute whose value this parameter is; None for a parameter no path reads.
    link: Link | None = None
    #: Parameter group (``[Groups]``); empty for none.
    group: str = ""
    settable: bool = True
    #: A live value the device changes by itself (descriptor bit 5).
    monitor: bool = False
    default: Any = None
    minimum: int | float | None = None
    maximum: int | float | None = None
    #: Engineering value = raw value x scale (0.01 for a frequency in 0.01 Hz).
    scale: float = 1.0
    unit: str = ""
    enum: Mapping[int, str] | None = None
    #: True when only the enumerated values are accepted (no declared range around them).
    enum_only: bool = False
    help: str = ""

    def __post_init__(self) -> None:
        if self.type.code is None:
            raise BadRequest(f"parameter {self.name!r}: {self.type.name} has no EDS data type code")

    @classmethod
    def from_register(cls, register: Register, link: Link | None, *, group: str | None = None,
                      settable: bool | None = None, words: int | None = None) -> EdsParameter:
        """A parameter from a drive register: ``link`` is the attribute that reads it (class 0x64
        of the ACG-ET2, 0x65 of the Omron option board). ``settable`` overrides the register's
        access where the path is stricter than the register (Omron F001 by function code);
        ``words`` where the path carries another size than the register (Omron b127)."""
        size = words or register.words
        writable = register.access.writable if settable is None else settable
        name = register.name if not register.code or register.name == register.code else (
            f"{register.code} {register.name}")
        return cls(
            name=name, type=wire_type(register.type, size), link=link,
            group=register.group if group is None else group, settable=writable,
            monitor=not writable and not register.saved, default=register.default,
            minimum=register.minimum, maximum=register.maximum, scale=register.scale, unit=register.unit,
            enum=register.enum, enum_only=register.enum is not None and register.minimum is None,
            help=register.help,
        )

    @classmethod
    def from_attribute(cls, spec: AttributeSpec, link: Link, *, group: str = "",
                       monitor: bool = False) -> EdsParameter:
        """A parameter from a CIP attribute declaration, at (class, instance, attribute) ``link``."""
        return cls(
            name=spec.name, type=spec.type, link=link, group=group, settable=spec.access.settable,
            monitor=monitor, default=spec.default, minimum=spec.minimum, maximum=spec.maximum,
            scale=spec.scale, unit=spec.unit, enum=spec.enum,
            enum_only=spec.enum is not None and spec.minimum is None and spec.maximum is None, help=spec.help,
        )


#: The RPI an EDS proposes to a configuration tool, 10 ms: a choice of the EDS, not a device limit.
DEFAULT_RPI_US = 10_000

_IO_PROFILE_DEFAULTS: dict[str, Any] = {item.name: item.default for item in fields(IoProfile)}


@dataclass(frozen=True)
class IoOffer:
    """The class 1 connections a device accepts, as its ``IoProfile`` checks them: one exclusive
    owner per (output, input) pair, and input only / listen only connections that send the
    heartbeat point instead of an output assembly."""

    #: (output assembly, input assembly) pairs an exclusive owner may open, in listing order.
    pairs: tuple[tuple[int, int], ...]
    # The other defaults are those of ``IoProfile``: what the class 1 target accepts unless told otherwise.
    input_only_point: int | None = _IO_PROFILE_DEFAULTS["input_only_point"]
    listen_only_point: int | None = _IO_PROFILE_DEFAULTS["listen_only_point"]
    #: Configuration instance of the connection paths.
    config_instance: int = min(_IO_PROFILE_DEFAULTS["config_instances"])
    rpi_min_us: int = _IO_PROFILE_DEFAULTS["rpi_min_us"]
    rpi_max_us: int = _IO_PROFILE_DEFAULTS["rpi_max_us"]
    #: The RPI a configuration tool proposes.
    rpi_default_us: int = DEFAULT_RPI_US
    max_connections: int = _IO_PROFILE_DEFAULTS["max_connections"]
    triggers: frozenset[TriggerType] = _IO_PROFILE_DEFAULTS["triggers"]
    #: Help text per pair (which device settings make the device accept it), keyed by pair.
    pair_notes: Mapping[tuple[int, int], str] = field(default_factory=dict)
    #: Help text of the input-only and listen-only connections, keyed by input assembly.
    input_notes: Mapping[int, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.rpi_min_us <= self.rpi_default_us <= self.rpi_max_us:
            raise BadRequest(f"default RPI {self.rpi_default_us} us outside {self.rpi_min_us}..{self.rpi_max_us}")
        if len(set(self.pairs)) != len(self.pairs):
            raise BadRequest("an assembly pair is listed twice")

    @property
    def input_instances(self) -> tuple[int, ...]:
        """Input assemblies of the pairs, each once, in pair order."""
        return tuple(dict.fromkeys(pair[1] for pair in self.pairs))

    @classmethod
    def from_io_profile(cls, profile: IoProfile, *, rpi_default_us: int | None = None,
                        pair_notes: Mapping[tuple[int, int], str] | None = None,
                        input_notes: Mapping[int, str] | None = None) -> IoOffer:
        """What ``profile`` accepts now: its pairs (every output with every input when it
        declares none), heartbeat points, RPI range and connection limit."""
        if profile.pairs is not None:
            pairs = sorted(profile.pairs())
        else:
            pairs = list(itertools.product(sorted(profile.consumed()), sorted(profile.produced())))
        default = rpi_default_us if rpi_default_us is not None else min(
            max(DEFAULT_RPI_US, profile.rpi_min_us), profile.rpi_max_us)
        return cls(
            pairs=tuple(pairs), input_only_point=profile.input_only_point,
            listen_only_point=profile.listen_only_point, config_instance=min(profile.config_instances),
            rpi_min_us=profile.rpi_min_us, rpi_max_us=profile.rpi_max_us, rpi_default_us=default,
            max_connections=profile.max_connections, triggers=frozenset(profile.triggers),
            pair_notes=dict(pair_notes or {}), input_notes=dict(input_notes or {}),
        )


@dataclass(frozen=True)
class EdsPort:
    """``PortN = type, name, path, port number;``: the network port and the object behind it."""

    kind: str
    name: str
    #: (class, instance) of the port's link object, e.g. the TCP/IP Interface (0xF5, 1).
    path: tuple[int, int]
    number: int


@dataclass(frozen=True)
class EdsCapacity:
    """``[Capacity]``: the connection limits the device enforces."""

    max_io_connections: int
    max_msg_connections: int


@dataclass(frozen=True)
class EdsObjectClass:
    """An object class section: the class as declared, and how many instances the device has."""

    spec: ClassSpec
    instances: int = 1


@dataclass(frozen=True)
class EdsDescription:
    identity: IdentityInfo
    vendor_name: str
    #: ``ProdTypeStr``: the name of the device type (2 is "AC Drive").
    product_type_name: str
    catalog: str
    network: Network
    #: ``DescText`` of ``[File]``.
    description: str
    parameters: tuple[EdsParameter, ...] = ()
    #: Output (consumed, O->T) and input (produced, T->O) assemblies.
    outputs: tuple[AssemblySchema, ...] = ()
    inputs: tuple[AssemblySchema, ...] = ()
    #: Class 1 connections (EtherNet/IP); None for a device that takes none over this network.
    io: IoOffer | None = None
    ports: tuple[EdsPort, ...] = ()
    capacity: EdsCapacity | None = None
    object_classes: tuple[EdsObjectClass, ...] = ()
    #: CompoNet: (output, input) assembly instances of the default connection path.
    componet_io: tuple[int, int] | None = None
    #: Name of the EDS file; empty lets ``eds_file_name`` make one up from the catalog and revision.
    file_name: str = ""
    #: ``Revision`` of ``[File]``: the revision of the EDS file itself.
    file_revision: tuple[int, int] = FILE_REVISION

    def __post_init__(self) -> None:
        if self.network not in NETWORKS:
            raise BadRequest(f"network must be one of {', '.join(NETWORKS)}, not {self.network!r}")
        instances = [schema.instance for schema in self.assemblies]
        if len(set(instances)) != len(instances):
            raise BadRequest("an assembly instance is declared twice")
        outputs = {schema.instance for schema in self.outputs}
        inputs = {schema.instance for schema in self.inputs}
        if self.io is not None:
            for output, input_ in self.io.pairs:
                if output not in outputs or input_ not in inputs:
                    raise BadRequest(f"connection pair {output}/{input_} names an assembly the description lacks")
            heartbeats = {self.io.input_only_point, self.io.listen_only_point} - {None}
            if heartbeats & set(instances):
                raise BadRequest("a heartbeat connection point is also an assembly instance")
        if self.componet_io is not None:
            output, input_ = self.componet_io
            if output not in outputs or input_ not in inputs:
                raise BadRequest(f"CompoNet default path {output}/{input_} names an assembly the description lacks")

    @property
    def assemblies(self) -> tuple[AssemblySchema, ...]:
        """Every assembly, outputs then inputs, each in declaration order."""
        return (*self.outputs, *self.inputs)

    def assembly(self, instance: int) -> AssemblySchema:
        for schema in self.assemblies:
            if schema.instance == instance:
                return schema
        raise UnknownKey(f"no assembly {instance}")

    @property
    def groups(self) -> tuple[str, ...]:
        """Parameter groups in order of their first parameter."""
        return tuple(dict.fromkeys(p.group for p in self.parameters if p.group))


def attribute_parameters(spec: ClassSpec, instance: int = 1, *, group: str | None = None,
                         ids: Iterable[int] | None = None) -> tuple[EdsParameter, ...]:
    """A parameter for each instance attribute of a declared class (those of ``ids`` when given)
    whose type an EDS can name; attributes of a structure type have no EDS data type and are
    left out. ``group`` defaults to the class name."""
    wanted = None if ids is None else set(ids)
    return tuple(
        EdsParameter.from_attribute(attribute, (spec.class_id, instance, attribute.id),
                                    group=spec.name if group is None else group)
        for attribute in spec.instance_attributes
        if attribute.type.code is not None and (wanted is None or attribute.id in wanted)
    )
