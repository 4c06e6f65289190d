"""A generic device emulated from any EDS file (``cipstack adapter --eds FILE``).

``build_eds_device(doc)`` serves what the file declares, read the way ``eds.interpret`` reads it:

* Identity from ``[Device]`` (VendCode, ProdType, ProdCode, MajRev/MinRev, ProdName; the serial
  number from the interface's MAC, as the profiles do).
* Every ``ParamN`` with a link path is an attribute at its (class, instance, attribute), with the
  parameter's data type, range, default, enumeration and access (descriptor bit 4: read only).
  Classes and instances are made as needed, one ``EdsObject`` per class; the standard objects
  every adapter has (Identity, Message Router, Assembly, Connection Manager, TCP/IP Interface,
  Ethernet Link) are kept and serve a linked attribute only if they have it.
* Every ``AssemN`` with an Assembly path (its own, or for an empty path the one its connections
  name: ``interpret.place_assemblies``) and a size is an Assembly instance of that size. It is an
  output (consumed) when a connection sends it O->T, an input when one produces it T->O, and
  otherwise an output when every parameter its members name is settable. Where a member carries a
  linked parameter whole (``assembly_schema``), an input's data shows the attribute and data
  written to an output sets it; other bytes are plain data, kept as written.
* ``[Connection Manager]``: the class 1 offer: one exclusive owner per (output, input) pair (the
  input a heartbeat point of size 0 where the owner only writes), the
  input-only and listen-only heartbeat points, the configuration instances, the triggers and the
  RPI range of the connections (the target's defaults where the file gives none), and
  ``[Capacity] MaxIOConnections``.
* A configuration instance that is an assembly (its own path, or field 12 naming it) takes the
  configuration data of a Forward_Open of its size (``IoProfile.config_sizes``), as an output
  takes O->T data; it is no connection point unless a connection's path makes it one.

What cannot be served is skipped and listed in ``EdsDevice.issues`` (one ``EdsIssue`` each), never
raised. A document without ``[Device]`` is not an EDS: ``EdsDeviceError``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..assemblies.schema import AssemblySchema
from ..cip.messages import MessageRouterRequest
from ..cip.model import Access, AttributeSpec, CipObject, ClassSpec, Instance
from ..cip.router import RequestContext
from ..cip.status import CipError, GeneralStatus
from ..cip.types import IntegerType, RealType
from ..devices.base import Device, DeviceLimits
from ..devices.profiles import DEFAULT_MAC, serial_from_mac
from ..eip.target.io_target import IoProfile
from ..errors import BadRequest
from ..objects.assembly import AssemblyPoint
from ..objects.identity import IdentityInfo
from ..objects.tcpip import NetworkInterface
from .interpret import EdsIssue, EdsView, ParamInfo, assembly_schema, read_view
from .model import EdsDocument, FieldKind
from .served import document_eds_file
from .writer import encode_eds, format_eds

if TYPE_CHECKING:
    from .keypad import EdsParameters

log = logging.getLogger(__name__)

Link = tuple[int, int, int]


class EdsDeviceError(BadRequest):
    """The document describes no device (no ``[Device]`` section)."""


class EdsObject(CipObject):
    """A class made from an EDS's parameters. Instances may declare different attributes (an EDS
    links each parameter on its own), so each instance keeps its own declarations; the class
    declaration holds the first declaration of each attribute id, for the class attributes."""

    def __init__(self, spec: ClassSpec, declared: Mapping[int, Mapping[int, AttributeSpec]]) -> None:
        super().__init__(spec)
        self.declared = {instance: dict(sorted(attributes.items())) for instance, attributes in declared.items()}
        for instance, attributes in sorted(self.declared.items()):
            created = self.add_instance(instance)
            created.values = {attribute.id: attribute.default for attribute in attributes.values()}

    def _instance_spec(self, instance_id: int, attribute_id: int | None) -> AttributeSpec:
        found = self.declared.get(instance_id, {}).get(attribute_id) if attribute_id is not None else None
        if found is None:
            raise CipError(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED,
                           message=f"{self.spec.name} instance {instance_id} has no attribute {attribute_id}")
        return found

    def _attribute(self, instance: Instance | None, attribute_id: int | None
                   ) -> tuple[AttributeSpec, Callable[[], Any] | None]:
        if instance is None or attribute_id is None:
            return super()._attribute(instance, attribute_id)
        return self._instance_spec(instance.instance_id, attribute_id), None

    def get(self, instance_id: int, attribute_id: int) -> Any:
        return self.read_attribute(self.instances[instance_id], self._instance_spec(instance_id, attribute_id))

    def set(self, instance_id: int, attribute_id: int, value: Any) -> None:
        self.write_attribute(self.instances[instance_id], self._instance_spec(instance_id, attribute_id), value)

    def get_attributes_all(self, instance: Instance | None, path: Any, request: MessageRouterRequest,
                           context: RequestContext) -> bytes:
        if instance is None:
            return super().get_attributes_all(instance, path, request, context)
        if request.data:
            raise CipError(GeneralStatus.TOO_MUCH_DATA)
        return b"".join(spec.type.encode(self.read_attribute(instance, spec))
                        for spec in self.declared[instance.instance_id].values() if spec.access.readable)


@dataclass
class EdsDevice(Device):
    """The device an EDS describes; ``issues`` lists what of the file it does not serve."""

    issues: list[EdsIssue] = field(default_factory=list)

    def __post_init__(self) -> None:
        super().__post_init__()
        self._io: IoProfile | None = None
        #: The Assembly instances made from the file, with the schema their data is decoded by.
        self.schemas: dict[int, AssemblySchema] = {}
        #: The file's parameters, in its order (what ``keypad`` offers of them).
        self.params: list[ParamInfo] = []

    def data_schema(self, instance: int) -> AssemblySchema | None:
        return self.schemas.get(instance)

    def eds_object(self, link: Link) -> tuple[EdsObject, int, int] | None:
        """The object made from the file that serves ``link`` (class, instance, attribute), with the
        instance and attribute; None where the link is not one of those."""
        class_id, instance, attribute = link
        obj = self.router.objects.get(class_id)
        if isinstance(obj, EdsObject) and attribute in obj.declared.get(instance, {}):
            return obj, instance, attribute
        return None

    def keypad(self) -> EdsParameters | None:
        """The file's parameters that link an integer attribute of an object made from it, as a keypad
        (``cipstack.eds.keypad``): what the front panel shows and ``cipstack drive parameter`` reads;
        None where the file has no such parameter."""
        from .keypad import EdsParameters

        parameters = EdsParameters(self, self.params)
        return parameters if parameters.codes.listed else None

    def io_profile(self) -> IoProfile | None:
        return self._io

    def power_cycle(self, now: float) -> None:
        """An EDS says nothing of what a device keeps over a power loss, so the emulated device keeps
        nothing it was told: every attribute made from a ``ParamN`` is back at the file's default and
        every assembly holds zeros. The standard objects (Identity, TCP/IP Interface, Ethernet Link)
        keep their configuration, as CIP has them keep it in non-volatile memory."""
        for obj in self.router.objects.values():
            if isinstance(obj, EdsObject):
                for instance_id, attributes in obj.declared.items():
                    obj.instances[instance_id].values = {a.id: a.default for a in attributes.values()}
        super().power_cycle(now)

    def attribute(self, link: Link) -> tuple[CipObject, int, int] | None:
        """The object serving ``link`` and its instance and attribute, if any object does."""
        class_id, instance, attribute = link
        obj = self.router.objects.get(class_id)
        if obj is None or instance not in obj.instances:
            return None
        if isinstance(obj, EdsObject):
            return (obj, instance, attribute) if attribute in obj.declared.get(instance, {}) else None
        return (obj, instance, attribute) if obj.spec.instance_attribute(attribute) is not None else None


# -- identity --------------------------------------------------------------------------------------------

_IDENTITY_KEYWORDS = (("VendCode", 0xFFFF), ("ProdType", 0xFFFF), ("ProdCode", 0xFFFF), ("MajRev", 0xFF),
                      ("MinRev", 0xFF))


def identity_from_eds(doc: EdsDocument, serial_number: int, issues: list[EdsIssue]) -> IdentityInfo:
    """Identity attributes 1-4 and 7 from ``[Device]`` (eds.md: they must equal each other)."""
    section = doc.get("Device")
    if section is None:
        raise EdsDeviceError("no [Device] section: not an EDS file")
    numbers: dict[str, int] = {}
    for keyword, limit in _IDENTITY_KEYWORDS:
        entry = section.get(keyword)
        value = entry.value() if entry is not None and entry.fields[0].kind is FieldKind.INT else None
        if value is None or not 0 <= value <= limit:
            issues.append(EdsIssue(entry.line if entry else section.line,
                                   f"[Device] {keyword} is missing or not a number 0..{limit}: 0 served"))
            value = 0
        numbers[keyword] = value
    entry = section.get("ProdName")
    name = entry.value() if entry is not None and entry.fields[0].kind is FieldKind.STRING else None
    if name is None:
        issues.append(EdsIssue(entry.line if entry else section.line, "[Device] ProdName is missing: \"\" served"))
        name = ""
    encoded = name.encode("latin-1", "replace")[:255].decode("latin-1")
    return IdentityInfo(vendor_id=numbers["VendCode"], device_type=numbers["ProdType"],
                        product_code=numbers["ProdCode"], revision=(numbers["MajRev"], numbers["MinRev"]),
                        serial_number=serial_number, product_name=encoded)


# -- parameters as attributes ---------------------------------------------------------------------------

def attribute_spec(param: ParamInfo, attribute_id: int, issues: list[EdsIssue]) -> AttributeSpec:
    """The attribute a parameter declares: its type, range, enumeration and access, and its
    default when that is a value of the type in range (else the minimum, or zero)."""
    cip_type = param.type
    numeric = isinstance(cip_type, (IntegerType, RealType))
    minimum = param.minimum if numeric else None
    maximum = param.maximum if numeric else None
    if isinstance(cip_type, IntegerType):
        minimum = int(minimum) if isinstance(minimum, (int, float)) else None
        maximum = int(maximum) if isinstance(maximum, (int, float)) else None
    spec = AttributeSpec(attribute_id, param.name or param.keyword, cip_type,
                         Access.GET_SET if param.settable else Access.GET, minimum=minimum, maximum=maximum,
                         enum=param.enum, unit=param.unit, help=param.help)
    default = param.default
    if isinstance(cip_type, IntegerType) and isinstance(default, float) and default.is_integer():
        default = int(default)
    try:
        value = spec.validate(default)
    except CipError:
        fallback = ("" if not numeric else 0.0 if isinstance(cip_type, RealType)
                    else minimum if minimum is not None else 0)
        issues.append(EdsIssue(param.line, f"{param.keyword}: default {default!r} is not a valid {cip_type.name} "
                                           f"in its range: {fallback!r} served"))
        value = fallback
    return AttributeSpec(attribute_id, spec.name, cip_type, spec.access, default=value, minimum=minimum,
                         maximum=maximum, enum=param.enum, unit=param.unit, help=param.help)


def _add_parameter_objects(device: EdsDevice, view: EdsView, issues: list[EdsIssue]) -> list[ParamInfo]:
    """Objects for the parameters of non-standard classes; the parameters that link a standard
    object are returned, to be checked once the assemblies exist too."""
    standard = dict(device.router.objects)
    deferred: list[ParamInfo] = []
    declared: dict[int, dict[int, dict[int, AttributeSpec]]] = {}
    #: Parameters that link a class attribute (instance 0): served read-only, at their default.
    class_level: dict[int, dict[int, AttributeSpec]] = {}
    first: dict[Link, ParamInfo] = {}
    for param in view.params.values():
        if param.link is None:
            continue
        class_id, instance, attribute = param.link
        if param.link in first:
            earlier = first[param.link]
            if earlier.type is not param.type:
                issues.append(EdsIssue(param.line, f"{param.keyword} links the attribute {earlier.keyword} declares, "
                                                   f"with another type: {earlier.keyword}'s is served"))
            continue
        first[param.link] = param
        if class_id in standard:
            deferred.append(param)
            continue
        if instance == 0 and 1 <= class_id <= 0xFFFF and 1 <= attribute <= 0xFFFF:
            class_level.setdefault(class_id, {})[attribute] = attribute_spec(param, attribute, issues)
            continue
        if not (1 <= class_id <= 0xFFFF and 1 <= instance <= 0xFFFF and 1 <= attribute <= 0xFFFF):
            issues.append(EdsIssue(param.line, f"{param.keyword}: link {param.link} is no instance attribute: "
                                               "not served"))
            continue
        spec = attribute_spec(param, attribute, issues)
        declared.setdefault(class_id, {}).setdefault(instance, {})[attribute] = spec
    for class_id in sorted(declared.keys() | class_level.keys()):
        instances = declared.get(class_id, {})
        union: dict[int, AttributeSpec] = {}
        for attributes in instances.values():
            for attribute_id, spec in attributes.items():
                union.setdefault(attribute_id, spec)
        extra = class_level.get(class_id, {})
        class_spec = ClassSpec(class_id, f"Class 0x{class_id:02X}", instance_attributes=tuple(
            union[key] for key in sorted(union)), extra_class_attributes=tuple(extra[key] for key in sorted(extra)))
        device.router.register(EdsObject(class_spec, instances))
    return deferred


def _check_standard_links(device: EdsDevice, params: list[ParamInfo], issues: list[EdsIssue]) -> None:
    for param in params:
        assert param.link is not None
        if device.attribute(param.link) is None:
            class_id, instance, attribute = param.link
            name = device.router.objects[class_id].spec.name
            issues.append(EdsIssue(param.line, f"{param.keyword}: the standard {name} object has no instance "
                                               f"{instance} attribute {attribute}: not served"))


# -- assemblies -----------------------------------------------------------------------------------------

def _value_for(value: Any) -> Any:
    """An attribute's value as an assembly field holds it (flags as 0/1)."""
    return int(value) if isinstance(value, bool) else value


def _add_assemblies(device: EdsDevice, view: EdsView, issues: list[EdsIssue]) -> dict[int, AssemblyPoint]:
    o_t_points = {c.o_t_point for c in view.connections if not c.heartbeat}
    t_o_points = {c.t_o_point for c in view.connections}
    heartbeats = {c.o_t_point for c in view.connections if c.heartbeat}
    t_o_heartbeats = {c.t_o_point for c in view.connections if c.t_o_heartbeat}
    configs = {c.config for c in view.connections}
    points: dict[int, AssemblyPoint] = {}
    # An assembly that is a member of another (a module's data in a modular station) needs no instance.
    members = {m.reference for a in view.assemblies.values() for m in a.members if m.reference}
    for info in view.assemblies.values():
        if info.instance is None:
            # No path, and no connection names it (or names it twice: place_assemblies said so).
            if info.keyword not in members and not any(issue.line == info.line for issue in view.issues):
                issues.append(EdsIssue(info.line, f"{info.keyword} has no path and no connection names it: "
                                                  "not served"))
            continue
        if info.size == 0:
            # A heartbeat point: an input-only or listen-only connection's O->T, served by the
            # Connection Manager; an owner's T->O, served by _add_raw_points.
            if info.instance not in heartbeats and info.instance not in t_o_heartbeats:
                issues.append(EdsIssue(info.line, f"{info.keyword}: an assembly of size 0 that no connection uses as "
                                                  "its heartbeat: not served"))
            continue
        if info.instance in points:
            issues.append(EdsIssue(info.line, f"{info.keyword}: instance {info.instance} is declared twice: "
                                              "the first is served"))
            continue
        if not 1 <= info.instance <= 0xFFFF or info.instance in heartbeats:
            issues.append(EdsIssue(info.line, f"{info.keyword}: instance {info.instance} cannot be an assembly "
                                              "here: not served"))
            continue
        if info.instance in o_t_points and info.instance in t_o_points:
            issues.append(EdsIssue(info.line, f"{info.keyword}: connections both consume and produce instance "
                                              f"{info.instance}: served as an output"))
        if info.instance in o_t_points or info.instance in configs:
            output = True   # a configuration assembly takes the Forward_Open's configuration data
        elif info.instance in t_o_points:
            output = False
        else:
            named = [view.params[m.reference] for m in info.members if m.reference in view.params]
            output = bool(named) and all(p.settable for p in named)
        schema = assembly_schema(info, view.params)
        linked = [] if schema is None else [f for f in schema.fields if f.link and device.attribute(f.link)]
        if schema is not None:
            device.schemas[info.instance] = schema
        point = _point(device, info.instance, info.size, output, schema, linked, info.name, info.variable)
        points[info.instance] = point
        device.assembly.add_assembly(point)
    _add_raw_points(device, view, points, heartbeats)
    return points


def _add_raw_points(device: EdsDevice, view: EdsView, points: dict[int, AssemblyPoint], heartbeats: set[int]) -> None:
    """A connection point no assembly of the file declares, with the size the connection gives it
    (a number, or a ParamN's default: files that size their I/O by parameters), is served as raw
    data of that size: an output when a connection sends it O->T, else an input. A connection
    whose format field names an assembly gets none (that assembly's placement decides)."""
    for connection in view.connections:
        wanted = [] if connection.t_o_assembly and not connection.t_o_heartbeat else [
            (connection.t_o_point, connection.t_o_size, False)]
        if not connection.heartbeat and not connection.o_t_assembly:
            wanted.insert(0, (connection.o_t_point, connection.o_t_size, True))
        for instance, size, output in wanted:
            # An exclusive owner whose T->O point is a heartbeat (198, 254: an output-only device, a
            # controller's "write data" connection) is legal: the target produces no data, only the
            # connection's sequence count. The point may be the O->T heartbeat of the file's
            # input-only connections too: the Forward_Open's O->T point tells the two uses apart.
            heartbeat_input = not output and connection.t_o_heartbeat
            if instance in points or (instance in heartbeats and not heartbeat_input) \
                    or (size <= 0 and not heartbeat_input) or not 1 <= instance <= 0xFFFF:
                continue
            point = _point(device, instance, size, output, None, [], f"Connection{connection.number} data", False)
            points[instance] = point
            device.assembly.add_assembly(point)


def _point(device: EdsDevice, instance: int, size: int, output: bool, schema: AssemblySchema | None,
           linked: list[Any], name: str, variable: bool) -> AssemblyPoint:
    if output:
        def consume(data: bytes, now: float) -> None:
            if schema is None or not linked:
                return
            values = schema.decode(data)
            for item in linked:
                found = device.attribute(item.link)
                assert found is not None
                obj, inst, attribute = found
                try:
                    obj.set(inst, attribute, values[item.name])
                except (CipError, ValueError, TypeError) as exc:
                    log.debug("assembly %d: %s refused: %s", instance, item.name, exc)

        return AssemblyPoint(instance, size, consumed=True, consume=consume, name=name, variable=variable)

    def produce() -> bytes:
        data = bytes(device.assembly.stores[instance])
        if schema is None:
            return data
        for item in linked:
            found = device.attribute(item.link)
            assert found is not None
            obj, inst, attribute = found
            try:
                data = schema.with_field(data, item.name, _value_for(obj.get(inst, attribute)))
            except (CipError, ValueError, TypeError, KeyError):
                continue  # a value the member cannot hold: the bytes stay as they were
        return data

    return AssemblyPoint(instance, size, consumed=False, produce=produce, name=name, variable=variable)


# -- class 1 ----------------------------------------------------------------------------------------------

def _io_profile(doc: EdsDocument, view: EdsView, points: Mapping[int, AssemblyPoint],
                issues: list[EdsIssue]) -> IoProfile | None:
    defaults = IoProfile(consumed=dict, produced=dict)
    pairs: set[tuple[int, int]] = set()
    heartbeat: dict[str, int] = {}
    config: set[int] = set()
    rpi_min: list[int] = []
    rpi_max: list[int] = []
    triggers: set[Any] = set()
    usable = 0
    heartbeat_kinds: dict[int, str] = {}
    multicast_inputs = {c.t_o_point for c in view.connections if c.kind != "listen only" and c.t_o_multicast}
    for connection in view.connections:
        where = f"Connection{connection.number} ({connection.name})"
        produced = points.get(connection.t_o_point)
        if produced is None or produced.consumed:
            issues.append(EdsIssue(connection.line, f"{where}: T->O point {connection.t_o_point} is no input "
                                                    "assembly: not offered"))
            continue
        if connection.t_o_size != produced.size and not (produced.variable and connection.t_o_size < produced.size):
            issues.append(EdsIssue(connection.line, f"{where}: T->O size {connection.t_o_size} but point "
                                                    f"{connection.t_o_point} is {produced.size} bytes: not offered"))
            continue
        if connection.kind == "listen only":
            # Refused at start what every Forward_Open would be refused (0x0108, 0x0119) for.
            if not connection.t_o_multicast:
                issues.append(EdsIssue(connection.line, f"{where}: listen only, but the file allows its T->O "
                                                        "point-to-point only (field 2 bits 20-23), and a listener "
                                                        "receives its owner's multicast: not offered"))
                continue
            if connection.t_o_point not in multicast_inputs:
                issues.append(EdsIssue(connection.line, f"{where}: listen only, and no other connection of the file "
                                                        f"produces input {connection.t_o_point} by multicast for it "
                                                        "to listen to: not offered"))
                continue
        if connection.heartbeat:
            kind = "listen only" if connection.kind == "listen only" else "input only"
            earlier = heartbeat_kinds.setdefault(connection.o_t_point, kind)
            if earlier != kind:
                issues.append(EdsIssue(connection.line, f"{where}: heartbeat point {connection.o_t_point} is also an "
                                                        f"{earlier} point, which a Forward_Open cannot tell from "
                                                        f"{kind}: not offered"))
                continue
            heartbeat.setdefault(kind, connection.o_t_point)
        else:
            consumed = points.get(connection.o_t_point)
            if consumed is None or not consumed.consumed:
                issues.append(EdsIssue(connection.line, f"{where}: O->T point {connection.o_t_point} is no output "
                                                        "assembly: not offered"))
                continue
            if connection.o_t_size != consumed.size and not (consumed.variable
                                                             and connection.o_t_size < consumed.size):
                issues.append(EdsIssue(connection.line, f"{where}: O->T size {connection.o_t_size} but point "
                                                        f"{connection.o_t_point} is {consumed.size} bytes: "
                                                        "not offered"))
                continue
            pairs.add((connection.o_t_point, connection.t_o_point))
        usable += 1
        config.add(connection.config)
        triggers |= connection.triggers
        if connection.rpi_min_us is not None:
            rpi_min.append(connection.rpi_min_us)
        if connection.rpi_max_us is not None:
            rpi_max.append(connection.rpi_max_us)
    if not usable:
        return None
    capacity = doc.entry("Capacity", "MaxIOConnections")
    max_connections = capacity.value() if capacity is not None and isinstance(capacity.value(), int) else None
    low = min(rpi_min) if rpi_min else defaults.rpi_min_us
    high = max(rpi_max) if rpi_max else defaults.rpi_max_us
    if low < 1 or high < low:
        issues.append(EdsIssue(0, f"RPI range {low}..{high} us is empty: the target's default range is served"))
        low, high = defaults.rpi_min_us, defaults.rpi_max_us
    # A configuration instance that is an assembly takes configuration data, and is no I/O point
    # unless a connection sends or produces it.
    io_points = {c.o_t_point for c in view.connections} | {c.t_o_point for c in view.connections}
    configurations = {i: p.size for i, p in points.items() if i in config and i not in io_points}
    return IoProfile(
        consumed=lambda: {i: p for i, p in points.items() if p.consumed and i not in configurations},
        produced=lambda: {i: p for i, p in points.items() if not p.consumed},
        config_instances=frozenset(config), config_sizes=lambda: configurations,
        input_only_point=heartbeat.get("input only", defaults.input_only_point),
        listen_only_point=heartbeat.get("listen only", defaults.listen_only_point),
        more_input_only_points=frozenset(p for p, k in heartbeat_kinds.items() if k == "input only"),
        more_listen_only_points=frozenset(p for p, k in heartbeat_kinds.items() if k == "listen only"),
        rpi_min_us=low, rpi_max_us=high,
        max_connections=max_connections if max_connections and max_connections > 0 else defaults.max_connections,
        triggers=frozenset(triggers), pairs=lambda: set(pairs),
    )


def build_eds_device(doc: EdsDocument, interface: NetworkInterface | None = None,
                     limits: DeviceLimits | None = None, served: bytes | None = None) -> EdsDevice:
    """The device ``doc`` describes (module docstring); what it cannot serve is in ``.issues``.
    ``served``: the file's bytes, which the device then serves through its File object, as a device
    that carries its EDS does (default: the document as ``format_eds`` writes it)."""
    interface = interface or NetworkInterface(mac=DEFAULT_MAC)
    issues: list[EdsIssue] = []
    identity = identity_from_eds(doc, serial_from_mac(interface.mac), issues)
    view = read_view(doc)
    issues.extend(view.issues)
    data = served if served is not None else encode_eds(format_eds(doc))
    device = EdsDevice(identity, interface, limits or DeviceLimits(), issues=issues,
                       files=(document_eds_file(data, identity.revision),))
    standard_links = _add_parameter_objects(device, view, issues)
    device.params = list(view.params.values())
    points = _add_assemblies(device, view, issues)
    _check_standard_links(device, standard_links, issues)
    device._io = _io_profile(doc, view, points, issues)
    if device._io is not None:
        device.update_io_status()
    issues.sort(key=lambda issue: issue.line)
    return device


__all__ = ["EdsDevice", "EdsDeviceError", "EdsObject", "attribute_spec", "build_eds_device", "identity_from_eds"]
