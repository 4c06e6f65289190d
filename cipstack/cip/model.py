"""The CIP object model: classes declared once, instances that hold or bind their values.

A class is declared with ``ClassSpec``: its id, name and revision, its instance (and any extra
class) attributes as ``AttributeSpec`` entries, and the services it answers at class and at
instance level. The standard class attributes 1-3, 6 and 7 (revision, max instance, number
of instances, max class/instance attribute id) are derived from the declaration, never
written by hand. ``CipObject`` is the runtime of a declared class: it stores instances and
serves the common services; objects with behaviour subclass it or bind attributes to a
value source (``Binding``) such as a drive register.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping
from enum import Enum
from functools import lru_cache, partial
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

from ..errors import BadRequest, ReadOnlyField, UnknownKey, WrongType
from .epath import ApplicationPath
from .messages import MessageRouterRequest, Service
from .status import CipError, GeneralStatus
from .types import UINT, CipType, IntegerType
from .values import Scaling

if TYPE_CHECKING:
    from .router import RequestContext


class Access(Enum):
    GET = "Get"
    SET = "Set"  # write-only (rare)
    GET_SET = "Get/Set"

    @property
    def readable(self) -> bool:
        return self is not Access.SET

    @property
    def settable(self) -> bool:
        return self is not Access.GET


class AttributeSpec(NamedTuple):
    """One attribute, declared once; runtime, EDS parameters, decoding and docs derive from it."""

    id: int
    name: str
    type: CipType
    access: Access = Access.GET
    default: Any = None
    minimum: int | float | None = None
    maximum: int | float | None = None
    #: Enumerated values: raw value -> meaning.
    enum: Mapping[int, str] | None = None
    #: Engineering unit of the scaled value ("Hz", "rpm", "A").
    unit: str = ""
    #: Engineering value = raw value x scale (e.g. 0.01 for a frequency in 0.01 Hz).
    scale: float = 1.0
    help: str = ""
    #: Part of the Get_Attributes_All reply.
    in_get_all: bool = True
    #: Engineering value = (raw value + offset) x scale (an EDS ParamN's field 16; 0 for every device here).
    offset: float = 0.0
    #: Decimal places of the engineering value (None: those of ``scale``; an EDS ParamN's field 21).
    decimals: int | None = None

    @property
    def scaling(self) -> Scaling:
        """Unit, scale, offset, decimal places and enumeration: how a raw value reads."""
        return Scaling(self.unit, self.scale, self.offset, self.decimals, self.enum)

    def validate(self, value: Any) -> Any:
        """Check a value about to be stored: type (a BOOL is 0 or 1), declared range, enumeration
        (0x09). Every object runtime calls it before a write changes anything."""
        value = self.type.check(value)
        if self.minimum is not None and value < self.minimum:
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE,
                           message=f"{self.name}: {value} below minimum {self.minimum}")
        if self.maximum is not None and value > self.maximum:
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE,
                           message=f"{self.name}: {value} above maximum {self.maximum}")
        if self.enum is not None and self.minimum is None and self.maximum is None and value not in self.enum:
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE,
                           message=f"{self.name}: {value} is not one of {sorted(self.enum)}")
        return value

    def describe(self, value: Any) -> str:
        """A raw value as a person reads it (``5.0 s``): the scanner's ``Value`` text."""
        return self.scaling.text(value)

    def out_of_range(self, raw: Any, label: str) -> str | None:
        """Why ``raw`` is outside what this declares (its range, else its integer type's), worded in the
        attribute's unit for a person about to write it (``Scaling.range_text``: ``ACC (Acceleration
        Time) takes 0.0..6000.0 s``); None when it is inside, or not a number. A writer checks it before
        sending; the target's own check is ``validate`` (0x09)."""
        if isinstance(raw, bool) or not isinstance(raw, (int, float)):
            return None
        minimum, maximum = self.minimum, self.maximum
        if isinstance(self.type, IntegerType):
            minimum = self.type.minimum if minimum is None else minimum
            maximum = self.type.maximum if maximum is None else maximum
        if (minimum is None or raw >= minimum) and (maximum is None or raw <= maximum):
            return None
        scaling = self.scaling
        if minimum is None or maximum is None:
            bound = (f"at least {scaling.number(minimum)}" if minimum is not None
                     else f"at most {scaling.number(maximum)}")
            return f"{label} takes {bound}" + (f" {self.unit}" if self.unit else "")
        return scaling.range_text(label, minimum, maximum)


_INSTANCE_SERVICES = frozenset({Service.GET_ATTRIBUTES_ALL, Service.GET_ATTRIBUTE_SINGLE, Service.SET_ATTRIBUTE_SINGLE,
                                Service.GET_ATTRIBUTE_LIST, Service.SET_ATTRIBUTE_LIST})


class ClassSpec:
    """A CIP class, declared once: id, name, revision, instance attributes, services.

    Immutable once made (``replace`` gives a changed copy), checked when made (an instance
    attribute id declared twice is a ``ValueError``), and indexed by attribute id then, for the
    lookup every request does.
    """

    __slots__ = ("_index", "_keys", "class_id", "class_services", "extra_class_attributes", "instance_attributes",
                 "instance_services", "max_instance", "name", "revision")
    #: The fields, in the order ``__init__`` takes them.
    _FIELDS: ClassVar[tuple[str, ...]] = ("class_id", "name", "revision", "instance_attributes",
                                          "extra_class_attributes", "class_services", "instance_services",
                                          "max_instance")

    class_id: int
    name: str
    revision: int
    instance_attributes: tuple[AttributeSpec, ...]
    #: Class attributes beyond the standard 1-3, 6, 7 (rare).
    extra_class_attributes: tuple[AttributeSpec, ...]
    class_services: frozenset[int]
    instance_services: frozenset[int]
    #: Declared maximum instance number when it exceeds the instances created (attribute 2).
    max_instance: int | None
    _index: dict[int, AttributeSpec]
    _keys: dict[str, int]

    def __init__(self, class_id: int, name: str, revision: int = 1, instance_attributes: tuple[AttributeSpec, ...] = (),
                 extra_class_attributes: tuple[AttributeSpec, ...] = (),
                 class_services: frozenset[int] = frozenset({Service.GET_ATTRIBUTE_SINGLE}),
                 instance_services: frozenset[int] = _INSTANCE_SERVICES, max_instance: int | None = None) -> None:
        index = {a.id: a for a in instance_attributes}
        if len(index) != len(instance_attributes):
            raise BadRequest(f"{name}: an instance attribute id is declared twice")
        values = (class_id, name, revision, tuple(instance_attributes), tuple(extra_class_attributes), class_services,
                  instance_services, max_instance)
        for field, value in zip(self._FIELDS, values, strict=True):
            object.__setattr__(self, field, value)  # set here once: __setattr__ refuses later
        object.__setattr__(self, "_index", index)
        # Each attribute's id by its key, made once with the declaration: every instance of the class
        # looks its overrides up here (a fleet adds thousands).
        object.__setattr__(self, "_keys", {attribute_key(a): a.id for a in instance_attributes})

    def instance_attribute(self, attribute_id: int) -> AttributeSpec | None:
        return self._index.get(attribute_id)

    def attribute_ids_by_key(self) -> Mapping[str, int]:
        """Each instance attribute's id by its ``attribute_key``, made with the declaration."""
        return self._keys

    def replace(self, **changes: Any) -> ClassSpec:
        """A copy with ``changes`` (field name -> value), checked as a new declaration is."""
        unknown = changes.keys() - set(self._FIELDS)
        if unknown:
            raise WrongType(f"ClassSpec has no field {', '.join(sorted(unknown))}")
        return ClassSpec(**{field: changes.get(field, getattr(self, field)) for field in self._FIELDS})

    def _values(self) -> tuple[Any, ...]:
        return tuple(getattr(self, field) for field in self._FIELDS)

    def __setattr__(self, name: str, value: Any) -> None:
        raise ReadOnlyField(f"ClassSpec is immutable: {name} cannot be set (use replace)")

    def __delattr__(self, name: str) -> None:
        raise ReadOnlyField(f"ClassSpec is immutable: {name} cannot be deleted")

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ClassSpec):
            return NotImplemented
        return self._values() == other._values()

    def __hash__(self) -> int:
        return hash(self._values())

    def __repr__(self) -> str:
        return "ClassSpec(" + ", ".join(f"{field}={getattr(self, field)!r}" for field in self._FIELDS) + ")"

    def __reduce__(self) -> tuple[Any, ...]:
        return ClassSpec, self._values()


class Binding:
    """A value that lives elsewhere (a drive register, a live counter).

    Store one as an instance's value to have reads call ``get`` and writes call ``set``.
    """

    def __init__(self, get: Callable[[], Any], set: Callable[[Any], None] | None = None) -> None:
        self.get = get
        self.set = set


class Instance:
    """An instance of a declared class; holds plain values or ``Binding`` entries."""

    __slots__ = ("instance_id", "values")

    def __init__(self, instance_id: int, values: dict[int, Any]) -> None:
        self.instance_id = instance_id
        self.values = values


_UINT_PAIR = struct.Struct("<HH")


class CipObject:
    """Runtime of a declared CIP class: its instances and the common services.

    ``handle`` is called by the message router with the already-resolved application path.
    Subclasses add services by listing them in ``extra_services`` (code -> method name) and
    may override ``read_attribute`` / ``write_attribute`` for attributes with behaviour.
    """

    extra_services: ClassVar[Mapping[int, str]] = {}
    #: The status of a request to an instance that does not exist: CIP's 0x05 (path destination
    #: unknown); a device whose manual gives another (the Omron board's 0x16) sets its own.
    missing_instance_status: GeneralStatus = GeneralStatus.PATH_DESTINATION_UNKNOWN

    def __init__(self, spec: ClassSpec) -> None:
        self.spec = spec
        self.instances: dict[int, Instance] = {}
        self._class_attributes = self._standard_class_attributes()

    # -- instances -----------------------------------------------------------------------
    def add_instance(self, instance_id: int, **overrides: Any) -> Instance:
        """Create an instance with every attribute at its declared default.

        ``overrides`` maps attribute names (as declared, lower-cased with underscores) or
        ``attr_<id>`` to a value or a ``Binding``.
        """
        if instance_id in self.instances or instance_id < 1:
            raise BadRequest(f"{self.spec.name}: instance {instance_id} exists or is invalid")
        values = {a.id: a.default for a in self.spec.instance_attributes}
        by_key = self.spec.attribute_ids_by_key()
        for key, value in overrides.items():
            attr_id = by_key.get(key)
            if attr_id is None and key.startswith("attr_"):
                attr_id = int(key[5:])
            if attr_id is None or attr_id not in values:
                raise UnknownKey(f"{self.spec.name} has no attribute {key!r}")
            values[attr_id] = value
        instance = Instance(instance_id, values)
        self.instances[instance_id] = instance
        return instance

    def bind(self, instance_id: int, attribute_id: int, binding: Binding) -> None:
        self.instances[instance_id].values[attribute_id] = binding

    # -- values ---------------------------------------------------------------------------
    def read_attribute(self, instance: Instance, spec: AttributeSpec) -> Any:
        value = instance.values.get(spec.id)
        if isinstance(value, Binding):
            return value.get()
        return value

    def write_attribute(self, instance: Instance, spec: AttributeSpec, value: Any,
                        context: RequestContext | None = None) -> None:
        value = spec.validate(value)
        current = instance.values.get(spec.id)
        if isinstance(current, Binding):
            if current.set is None:
                raise CipError(GeneralStatus.ATTRIBUTE_NOT_SETTABLE, message=spec.name)
            current.set(value)
        else:
            instance.values[spec.id] = value

    def get(self, instance_id: int, attribute_id: int) -> Any:
        """Read a value directly (for devices and tests)."""
        instance = self.instances[instance_id]
        return self.read_attribute(instance, self._spec_or_raise(attribute_id))

    def set(self, instance_id: int, attribute_id: int, value: Any) -> None:
        """Write a value directly, bypassing the access rule (device side)."""
        self.write_attribute(self.instances[instance_id], self._spec_or_raise(attribute_id), value)

    def _spec_or_raise(self, attribute_id: int) -> AttributeSpec:
        spec = self.spec.instance_attribute(attribute_id)
        if spec is None:
            raise CipError(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED,
                           message=f"{self.spec.name} has no attribute {attribute_id}")
        return spec

    # -- class level ------------------------------------------------------------------------
    def _standard_class_attributes(self) -> dict[int, tuple[AttributeSpec, Callable[[], Any]]]:
        spec = self.spec
        max_class_attr = max([7, *(a.id for a in spec.extra_class_attributes)])
        max_inst_attr = max((a.id for a in spec.instance_attributes), default=0)
        table: dict[int, tuple[AttributeSpec, Callable[[], Any]]] = {
            1: (AttributeSpec(1, "Revision", UINT), lambda: spec.revision),
            2: (AttributeSpec(2, "Max Instance", UINT),
                lambda: max([spec.max_instance or 0, *self.instances], default=0)),
            3: (AttributeSpec(3, "Number of Instances", UINT), lambda: len(self.instances)),
            6: (AttributeSpec(6, "Maximum ID Number Class Attributes", UINT), lambda: max_class_attr),
            7: (AttributeSpec(7, "Maximum ID Number Instance Attributes", UINT), lambda: max_inst_attr),
        }
        for extra in spec.extra_class_attributes:
            table[extra.id] = (extra, partial(getattr, extra, "default"))
        return table

    def class_attribute_ids(self) -> list[int]:
        return sorted(self._class_attributes)

    # -- dispatch ------------------------------------------------------------------------------
    def handle(self, path: ApplicationPath, request: MessageRouterRequest, context: RequestContext) -> bytes:
        """Serve one request; returns reply data or raises ``CipError``."""
        instance: Instance | None
        if path.member is not None:
            raise CipError(GeneralStatus.PATH_SEGMENT_ERROR, message="member addressing is not supported here")
        if not path.instance:
            instance = None
            allowed = self.spec.class_services
        else:
            instance = self.instances.get(path.instance)
            if instance is None:
                raise CipError(self.missing_instance_status,
                               message=f"{self.spec.name} has no instance {path.instance}")
            allowed = self.spec.instance_services
        service = request.service
        if service not in allowed:
            raise CipError(GeneralStatus.SERVICE_NOT_SUPPORTED,
                           message=f"{self.spec.name} does not support service 0x{service:02X} here")
        method_name = self.extra_services.get(service) or _COMMON_SERVICES.get(service)
        if method_name is None:
            raise CipError(GeneralStatus.SERVICE_NOT_SUPPORTED)
        handler: Callable[..., bytes] = getattr(self, method_name)
        return handler(instance, path, request, context)

    def _attribute(self, instance: Instance | None,
                   attribute_id: int | None) -> tuple[AttributeSpec, Callable[[], Any] | None]:
        if attribute_id is None:
            raise CipError(GeneralStatus.PATH_SEGMENT_ERROR, message="no attribute in the path")
        if instance is None:
            entry = self._class_attributes.get(attribute_id)
            if entry is None:
                raise CipError(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED)
            return entry
        spec = self.spec.instance_attribute(attribute_id)
        if spec is None:
            raise CipError(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED)
        return spec, None

    def _encoded(self, instance: Instance | None, attribute_id: int | None) -> bytes:
        spec, getter = self._attribute(instance, attribute_id)
        if getter is not None:
            return spec.type.encode(getter())
        if not spec.access.readable:
            raise CipError(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED, message=f"{spec.name} is write-only")
        assert instance is not None
        return spec.type.encode(self.read_attribute(instance, spec))

    def _set_one(self, instance: Instance | None, attribute_id: int, data: bytes, offset: int,
                 context: RequestContext, exact: bool) -> int:
        spec, getter = self._attribute(instance, attribute_id)
        if getter is not None or not spec.access.settable:
            raise CipError(GeneralStatus.ATTRIBUTE_NOT_SETTABLE, message=spec.name)
        assert instance is not None
        # The value as sent (a BOOL of 2 stays 2): ``write_attribute`` validates it against the
        # declaration before anything changes.
        if exact:
            value = spec.type.decode_written(data[offset:])
            end = len(data)
        else:
            value, end = spec.type.decode_written_from(data, offset)
        self.write_attribute(instance, spec, value, context)
        return end

    # -- common services -----------------------------------------------------------------------
    def get_attribute_single(self, instance: Instance | None, path: ApplicationPath,
                             request: MessageRouterRequest, context: RequestContext) -> bytes:
        if request.data:
            raise CipError(GeneralStatus.TOO_MUCH_DATA)
        return self._encoded(instance, path.attribute)

    def set_attribute_single(self, instance: Instance | None, path: ApplicationPath,
                             request: MessageRouterRequest, context: RequestContext) -> bytes:
        if path.attribute is None:
            raise CipError(GeneralStatus.PATH_SEGMENT_ERROR, message="no attribute in the path")
        self._set_one(instance, path.attribute, request.data, 0, context, exact=True)
        return b""

    def get_attributes_all(self, instance: Instance | None, path: ApplicationPath,
                           request: MessageRouterRequest, context: RequestContext) -> bytes:
        if request.data:
            raise CipError(GeneralStatus.TOO_MUCH_DATA)
        if instance is None:
            return b"".join(self._encoded(None, a) for a in self.class_attribute_ids())
        return b"".join(
            spec.type.encode(self.read_attribute(instance, spec))
            for spec in self.spec.instance_attributes
            if spec.in_get_all and spec.access.readable
        )

    def get_attribute_list(self, instance: Instance | None, path: ApplicationPath,
                           request: MessageRouterRequest, context: RequestContext) -> bytes:
        ids = _attribute_id_list(request.data)
        out = bytearray(UINT.encode(len(ids)))
        failed = False
        for attribute_id in ids:
            try:
                value = self._encoded(instance, attribute_id)
            except CipError as exc:
                out += _UINT_PAIR.pack(attribute_id, exc.general)
                failed = True
            else:
                out += _UINT_PAIR.pack(attribute_id, 0) + value
        if failed:
            raise CipError(GeneralStatus.ATTRIBUTE_LIST_ERROR, data=bytes(out))
        return bytes(out)

    def set_attribute_list(self, instance: Instance | None, path: ApplicationPath,
                           request: MessageRouterRequest, context: RequestContext) -> bytes:
        data = request.data
        count, offset = UINT.decode_from(data, 0)
        out = bytearray(UINT.encode(count))
        failed = False
        for _ in range(count):
            attribute_id, offset = UINT.decode_from(data, offset)
            try:
                offset = self._set_one(instance, attribute_id, data, offset, context, exact=False)
            except CipError as exc:
                out += _UINT_PAIR.pack(attribute_id, exc.general)
                failed = True
                if exc.general in (GeneralStatus.ATTRIBUTE_NOT_SUPPORTED, GeneralStatus.NOT_ENOUGH_DATA):
                    # The size of an unknown attribute's value is unknown: the rest of the list
                    # cannot be parsed, so processing stops here.
                    break
                spec = self.spec.instance_attribute(attribute_id) if instance is not None else None
                if spec is not None:
                    _, offset = spec.type.decode_from(data, offset)
            else:
                out += _UINT_PAIR.pack(attribute_id, 0)
        else:
            if offset != len(data):
                raise CipError(GeneralStatus.TOO_MUCH_DATA)
        if failed:
            raise CipError(GeneralStatus.ATTRIBUTE_LIST_ERROR, data=bytes(out))
        return bytes(out)

    def reset(self, instance: Instance | None, path: ApplicationPath,
              request: MessageRouterRequest, context: RequestContext) -> bytes:
        reset_type = 0
        if request.data:
            if len(request.data) > 1:
                raise CipError(GeneralStatus.TOO_MUCH_DATA)
            reset_type = request.data[0]
        self.perform_reset(instance, reset_type, context)
        return b""

    def perform_reset(self, instance: Instance | None, reset_type: int, context: RequestContext) -> None:
        """Objects that declare Reset override this; the default accepts type 0 only."""
        if reset_type != 0:
            raise CipError(GeneralStatus.INVALID_PARAMETER_VALUE, message=f"reset type {reset_type}")


_COMMON_SERVICES: dict[int, str] = {
    Service.GET_ATTRIBUTE_SINGLE: "get_attribute_single",
    Service.SET_ATTRIBUTE_SINGLE: "set_attribute_single",
    Service.GET_ATTRIBUTES_ALL: "get_attributes_all",
    Service.GET_ATTRIBUTE_LIST: "get_attribute_list",
    Service.SET_ATTRIBUTE_LIST: "set_attribute_list",
    Service.RESET: "reset",
}


def _attribute_id_list(data: bytes) -> list[int]:
    count, _ = UINT.decode_from(data, 0)
    needed = 2 + 2 * count
    if len(data) < needed:
        raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message="attribute list shorter than its count")
    if len(data) > needed:
        raise CipError(GeneralStatus.TOO_MUCH_DATA)
    return list(struct.unpack_from(f"<{count}H", data, 2))


def attribute_key(spec: AttributeSpec) -> str:
    """Python-friendly name of an attribute: "Product Name" -> "product_name"."""
    return _key_of_name(spec.name)


@lru_cache(maxsize=4096)
def _key_of_name(name: str) -> str:
    out = []
    for ch in name.lower():
        out.append(ch if ch.isalnum() else "_")
    return "_".join(part for part in "".join(out).split("_") if part)


def services(*codes: int) -> frozenset[int]:
    return frozenset(codes)


__all__ = [
    "Access", "AttributeSpec", "Binding", "CipObject", "ClassSpec", "Instance",
    "attribute_key", "services",
]
