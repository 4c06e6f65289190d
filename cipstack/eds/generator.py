"""Writing the EDS file of a device from its ``EdsDescription``.

``generate_eds`` builds an ``EdsDocument``; ``eds_text`` writes it with ``format_eds`` (ASCII,
CRLF). The same description always gives the same bytes: nothing depends on the clock, the
host or dictionary order. The file's dates are, in this order of preference:

1. the ``created`` argument;
2. the ``SOURCE_DATE_EPOCH`` environment variable (seconds since 1970-01-01 UTC), the
   reproducible-builds convention;
3. ``DEFAULT_CREATED``, 2026-01-01 00:00:00 UTC: a fixed date, so that two runs on two days
   still write the same file. The current time is never used.

Choices the EDS format leaves open, made once here:

* Parameters are numbered in declaration order, then come the parameters made for assembly
  fields, then one ``Requested Packet Interval`` parameter that every connection's RPI fields
  refer to, its range the device's. An assembly member refers to a declared parameter when that
  parameter carries the field's value in the field's form and its name gives the field's name by
  ``assemblies.names.field_name``; otherwise to a parameter made for the field: named
  ``display_name(field)`` ("Ctrl From Net" for ``ctrl_from_net``), with the field's help text,
  and with the declared attribute's link path, type and range when one carries the value in the
  same form (else an empty link path: one link path names one value, and a Hz word is not the
  rpm attribute; empty too for an attribute of an object whose attributes the description
  declares, but not that one: the device does not serve it). So reading the file back
  (``interpret.assembly_schema``) gives exactly the device's field names.
* A scale such as 0.01 Hz is written as multiplier/divider 1/100 (base 1, offset 0) with two
  decimal places, descriptor bit 2 set. Without a scale the scaling fields are empty.
* Enumerated strings (``EnumN``, descriptor bit 1) are written when the names cover every
  value the device accepts; names of a few values in a wider range go to the help text.
* Assembly members are the bits of each field in order; bits no field declares are padding
  members with an empty reference. Input-only and listen-only connections name heartbeat
  assemblies of size 0 at their connection points.
* ``[Connection Manager]`` field 1 / field 2 words are composed from the bits of the EDS
  format (see ``connection_words``) and give the values in wide use: exclusive owner
  0x04010002 / 0x44640405, input only 0x02010002 / 0x44640305, listen only 0x01010002 /
  0x44240305.
* ``[Capacity]`` has one ``TSpecN`` per data size the connections carry, at the packet rate
  of the shortest RPI the device accepts.
* Object classes with a section name the EDS format fixes get that section; another class
  gets a vendor-specific section ``[<vendor id>_<class name> Class]`` with its name and
  code. The Assembly and Connection Manager classes have their own sections already.
* CompoNet: ``[CompoNet_IO]`` gives the input and output lengths of the default connection
  path in words (unit 2), as section 3-4 of the Omron option board manual shows them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from fractions import Fraction
from typing import Any

from ..assemblies.names import display_name, field_name
from ..assemblies.schema import AssemblyField, AssemblySchema
from ..cip.epath import LogicalSegment, LogicalType, encode_path, request_path
from ..cip.types import BOOL, UDINT, UINT, USINT, IntegerType, RealType
from ..cip.units import decimal_places
from ..eip.wire.cm_messages import TriggerType
from ..errors import BadRequest
from .description import EdsDescription, EdsObjectClass, EdsParameter, IoOffer, Link
from .model import EdsDocument, Field, Section
from .writer import format_eds

#: The date written when neither ``created`` nor ``SOURCE_DATE_EPOCH`` gives one.
DEFAULT_CREATED = datetime(2026, 1, 1, 0, 0, 0, tzinfo=timezone.utc)

ASSEMBLY_CLASS = 0x04
#: Assembly attribute 3, the data.
ASSEMBLY_DATA = 3

#: Object classes whose EDS section name the EDS format fixes.
PUBLIC_CLASS_SECTIONS: dict[int, str] = {
    0x01: "Identity Class",
    0x02: "Message Router Class",
    0x03: "DeviceNet Class",
    0x05: "Connection Class",
    0x07: "Register Class",
    0x08: "Discrete Input Class",
    0x09: "Discrete Output Class",
    0x0A: "Analog Input Class",
    0x0B: "Analog Output Class",
    0x37: "File Class",
    0x47: "DLR Class",
    0x48: "QoS Class",
    0xF5: "TCP/IP Interface Class",
    0xF6: "Ethernet Link Class",
}
#: Classes described by their own sections ([Assembly], [Connection Manager]).
OWN_SECTION_CLASSES = frozenset({0x04, 0x06})

# -- ParamN descriptor bits ------------------------------------------------------------------------
DESCRIPTOR_ENUMERATED = 1 << 1
DESCRIPTOR_SCALING = 1 << 2
DESCRIPTOR_READ_ONLY = 1 << 4
DESCRIPTOR_MONITOR = 1 << 5

# -- ConnectionN field 1: trigger and transport ----------------------------------------------------
TRANSPORT_CLASS_1 = 1 << 1
TRIGGER_SHIFT = 16  # bit 16 cyclic, 17 change of state, 18 application triggered
LISTEN_ONLY = 1 << 24
INPUT_ONLY = 1 << 25
EXCLUSIVE_OWNER = 1 << 26

# -- ConnectionN field 2: connection parameters ----------------------------------------------------
O_T_FIXED = 1 << 0
T_O_FIXED = 1 << 2
O_T_FORMAT_SHIFT = 8
T_O_FORMAT_SHIFT = 12
FORMAT_MODELESS = 0
FORMAT_ZERO_LENGTH = 1
FORMAT_HEARTBEAT = 3
FORMAT_RUN_IDLE = 4
O_T_TYPE_SHIFT = 16
T_O_TYPE_SHIFT = 20
TYPE_MULTICAST = 1 << 1
TYPE_POINT_TO_POINT = 1 << 2
O_T_PRIORITY_SHIFT = 24
T_O_PRIORITY_SHIFT = 28
PRIORITY_SCHEDULED = 1 << 2

EXCLUSIVE_OWNER_KIND = "exclusive owner"
INPUT_ONLY_KIND = "input only"
LISTEN_ONLY_KIND = "listen only"

#: ``[CompoNet_IO]`` length units (Omron option board manual, section 3-4 Step 7).
COMPONET_UNIT_WORDS = 2

#: Largest range whose values are checked one by one for enumerated names.
_ENUM_SPAN_LIMIT = 4096


def connection_words(kind: str, triggers: frozenset[TriggerType] = frozenset({TriggerType.CYCLIC})) -> tuple[int, int]:
    """ConnectionN fields 1 and 2 of a class 1 connection of ``kind``.

    Every kind is transport class 1 with the device's triggers, fixed sizes, a modeless T->O
    and scheduled priority. An exclusive owner sends its output assembly after the 32-bit
    run/idle header; input only and listen only send the heartbeat. O->T is point-to-point;
    T->O is multicast or point-to-point, and multicast only for listen only, which shares
    the production of another connection.
    """
    trigger = TRANSPORT_CLASS_1
    for item in sorted(triggers):
        trigger |= 1 << (TRIGGER_SHIFT + int(item))
    trigger |= {EXCLUSIVE_OWNER_KIND: EXCLUSIVE_OWNER, INPUT_ONLY_KIND: INPUT_ONLY, LISTEN_ONLY_KIND: LISTEN_ONLY}[kind]
    o_t_format = FORMAT_RUN_IDLE if kind == EXCLUSIVE_OWNER_KIND else FORMAT_HEARTBEAT
    t_o_types = TYPE_MULTICAST if kind == LISTEN_ONLY_KIND else TYPE_MULTICAST | TYPE_POINT_TO_POINT
    parameters = (
        O_T_FIXED | T_O_FIXED
        | o_t_format << O_T_FORMAT_SHIFT | FORMAT_MODELESS << T_O_FORMAT_SHIFT
        | TYPE_POINT_TO_POINT << O_T_TYPE_SHIFT | t_o_types << T_O_TYPE_SHIFT
        | PRIORITY_SCHEDULED << O_T_PRIORITY_SHIFT | PRIORITY_SCHEDULED << T_O_PRIORITY_SHIFT
    )
    return trigger, parameters


def creation_time(created: datetime | None = None) -> datetime:
    """The date and time the file says it was made (see the module docstring)."""
    if created is not None:
        return created
    epoch = os.environ.get("SOURCE_DATE_EPOCH", "").strip()
    if epoch:
        try:
            return datetime.fromtimestamp(int(epoch), tz=timezone.utc)
        except (ValueError, OverflowError, OSError):
            raise BadRequest(f"SOURCE_DATE_EPOCH is not a number of seconds: {epoch!r}") from None
    return DEFAULT_CREATED


# -- parameters ------------------------------------------------------------------------------------

def _type_limits(param: EdsParameter) -> tuple[int | float | None, int | float | None]:
    cip_type = param.type
    if cip_type is BOOL:
        return 0, 1
    if isinstance(cip_type, IntegerType):
        return cip_type.minimum, cip_type.maximum
    return None, None


def parameter_limits(param: EdsParameter) -> tuple[Any, Any, Any]:
    """(minimum, maximum, default) as the EDS file states them: the declared range, the
    enumerated values when only those are accepted, else the data type's range; a missing
    default is 0 when the range holds it, else the minimum."""
    low, high = _type_limits(param)
    if param.enum_only and param.enum:
        low, high = min(param.enum), max(param.enum)
    if param.minimum is not None:
        low = param.minimum
    if param.maximum is not None:
        high = param.maximum
    default = param.default
    if default is None and low is not None and high is not None:
        default = 0 if low <= 0 <= high else low
    return low, high, default


def _enumerated(param: EdsParameter, low: Any, high: Any) -> bool:
    """Whether the names of ``param.enum`` cover every value the device accepts."""
    if not param.enum:
        return False
    if param.enum_only:
        return True
    if not isinstance(low, int) or not isinstance(high, int) or high - low > _ENUM_SPAN_LIMIT:
        return False
    return all(value in param.enum for value in range(low, high + 1))


def scaling(scale: float) -> tuple[int, int, int] | None:
    """(multiplier, divider, decimal places) of a scale, or None for no scaling: 0.01 -> (1, 100, 2)."""
    if scale == 1:
        return None
    if scale <= 0:
        raise BadRequest(f"a scale must be positive, not {scale}")
    exact = Fraction(repr(float(scale)))
    return exact.numerator, exact.denominator, decimal_places(scale)


def _value_field(param: EdsParameter, value: Any) -> Field:
    if value is None:
        return Field.empty()
    if isinstance(param.type, RealType):
        return Field.real(float(value))
    if isinstance(value, str):
        return Field.string(value)
    return Field.integer(int(value))


def _data_size(param: EdsParameter) -> int:
    if param.type.size is not None:
        return param.type.size
    # A string: its length prefix (1 byte for SHORT_STRING, 2 for STRING) and the default text.
    prefix = 1 if param.type.code == 0xDA else 2
    return prefix + len(str(param.default or ""))


def _help_text(param: EdsParameter, enumerated: bool) -> str:
    if not param.enum or enumerated:
        return param.help
    names = ", ".join(f"{value} = {name}" for value, name in sorted(param.enum.items()))
    return f"{param.help}; {names}" if param.help else names


def link_path(link: Link | None) -> bytes:
    return b"" if link is None else request_path(*link)


def _add_param(section: Section, number: int, param: EdsParameter) -> None:
    low, high, default = parameter_limits(param)
    enumerated = _enumerated(param, low, high)
    scaled = scaling(param.scale)
    descriptor = 0
    if enumerated:
        descriptor |= DESCRIPTOR_ENUMERATED
    if scaled is not None:
        descriptor |= DESCRIPTOR_SCALING
    if not param.settable:
        descriptor |= DESCRIPTOR_READ_ONLY
    if param.monitor:
        descriptor |= DESCRIPTOR_MONITOR
    path = link_path(param.link)
    assert param.type.code is not None
    if scaled is None:
        scaling_fields = [Field.empty()] * 4
        places = 0
    else:
        multiplier, divider, places = scaled
        scaling_fields = [Field.integer(multiplier), Field.integer(divider), Field.integer(1), Field.integer(0)]
    section.add(f"Param{number}", [
        Field.integer(0),
        Field.integer(len(path)), Field.epath(path),
        Field.integer(descriptor, hex_digits=4),
        Field.integer(param.type.code, hex_digits=2), Field.integer(_data_size(param)),
        Field.string(param.name),
        Field.string(param.unit),
        Field.string(_help_text(param, enumerated)),
        _value_field(param, low), _value_field(param, high), _value_field(param, default),
        *scaling_fields,
        *[Field.empty()] * 4,
        Field.integer(places),
    ])
    if enumerated and param.enum:
        pairs: list[Field] = []
        for value, name in sorted(param.enum.items()):
            if param.enum_only or low <= value <= high:
                pairs.extend([Field.integer(value), Field.string(name)])
        section.add(f"Enum{number}", pairs)


# -- assembly members --------------------------------------------------------------------------------

def _compatible(param: EdsParameter, item: AssemblyField) -> bool:
    """Whether an assembly field carries the value of a declared parameter as that parameter
    describes it (a flag of a BOOL attribute, or a word of the same size, unit and scale)."""
    if item.bits:
        return (item.bits == 1 and param.type is BOOL) or (param.type.size or 0) * 8 == item.bits
    return param.type.size == item.type.size and param.unit == item.unit and param.scale == item.scale


def _field_parameter(item: AssemblyField, output: bool, same_value: EdsParameter | None = None) -> EdsParameter:
    """The parameter made for an assembly field: named after the field, with its help text. With
    ``same_value`` (a declared parameter carrying the field's value in the same form under another
    name), that parameter's link, type, range and enumeration; else the field's own."""
    if same_value is not None:
        return replace(same_value, name=display_name(item.name), help=item.help or same_value.help, group="",
                       monitor=not output)
    cip_type = BOOL if item.bits == 1 else item.type
    if item.bits > 1:
        # A multi-bit field: the smallest unsigned integer type that holds it.
        cip_type = USINT if item.bits <= 8 else UINT if item.bits <= 16 else UDINT
    return EdsParameter(
        name=display_name(item.name), type=cip_type, link=item.link, settable=output, monitor=not output,
        scale=item.scale, unit=item.unit, help=item.help,
        maximum=(1 << item.bits) - 1 if item.bits > 1 else None,
    )


@dataclass
class _Plan:
    """Every ParamN in order, and each assembly's members as (bits, ParamN or None)."""

    params: list[EdsParameter]
    members: dict[int, list[tuple[int, int | None]]]
    rpi_param: int | None


def _plan(description: EdsDescription) -> _Plan:
    params = list(description.parameters)
    declared_by_link: dict[Link, list[int]] = {}
    for index, param in enumerate(params):
        if param.link is not None:
            declared_by_link.setdefault(param.link, []).append(index)
    made: dict[tuple[Any, ...], int] = {}
    #: Instances 1..N of each object class the description counts (the Omron Discrete Input Point:
    #: 7 on the MX2, 9 on the RX, Table C-10).
    counted = {item.spec.class_id: item.instances for item in description.object_classes}
    outputs = {schema.instance for schema in description.outputs}
    members: dict[int, list[tuple[int, int | None]]] = {}
    for schema in description.assemblies:
        output = schema.instance in outputs
        layout: list[tuple[int, int | None]] = []
        position = 0
        for item in schema.fields:
            if item.start_bit > position:
                layout.append((item.start_bit - position, None))
            if item.link is not None and item.link[0] in counted and not 1 <= item.link[1] <= counted[item.link[0]]:
                # The field is there on another model of the family (CI8 is the RX's): this device has
                # no such instance, and a path to it would be answered 0x16.
                item = replace(item, link=None)
            index = _member_parameter(item, output, schema, params, declared_by_link, made)
            layout.append((item.size_bits, index + 1))
            position = item.start_bit + item.size_bits
        if position < 8 * schema.size:
            layout.append((8 * schema.size - position, None))
        members[schema.instance] = layout
    rpi_param = None
    if description.io is not None and description.io.pairs:
        io = description.io
        params.append(EdsParameter(
            name="Requested Packet Interval", type=UDINT, settable=True, default=io.rpi_default_us,
            minimum=io.rpi_min_us, maximum=io.rpi_max_us, unit="microseconds",
            help="Interval at which the I/O data of a connection is sent; the device accepts "
                 f"{io.rpi_min_us} to {io.rpi_max_us} microseconds",
        ))
        rpi_param = len(params)
    return _Plan(params, members, rpi_param)


def _member_parameter(item: AssemblyField, output: bool, schema: AssemblySchema, params: list[EdsParameter],
                      declared_by_link: dict[Link, list[int]], made: dict[tuple[Any, ...], int]) -> int:
    """The index in ``params`` of the parameter an assembly member refers to (see the module docstring).

    The device's manuals name one value twice: ACG-ET2 manual calls Control Supervisor attribute 10
    "Drive Fault" in its object table and "Faulted" in the input instance table; Omron's Table D-4
    has "Run1" where Tables B-1/B-2 have "FWD". Both names are right where they stand. The declared
    attribute's parameter keeps the object table's name, which explicit access shows and a user
    looks up in the object table; the member's parameter takes the assembly field's name (the
    name scripts use for the I/O data, kept stable), and both carry the same link path, so a
    configuration tool and ``adapter --eds`` see one attribute under its two names.
    """
    name = display_name(item.name)
    if field_name(name) != item.name:
        raise BadRequest(f"assembly {schema.instance}: field {item.name!r} is not in field-name form "
                         f"(the rule gives {field_name(item.name)!r}): an EDS could not give it back")
    same_value: EdsParameter | None = None
    if item.link is not None:
        own_link = item.link  # narrowed for the generator below (``item`` is reassigned)
        declared = declared_by_link.get(own_link, ())
        compatible = [index for index in declared if _compatible(params[index], item)]
        for index in compatible:
            if field_name(params[index].name) == item.name:
                return index  # the attribute's own name is the field's: one parameter for both
        if compatible:
            same_value = params[compatible[0]]
        elif declared:
            # The field carries the attribute in another form (a Hz word for an rpm attribute): its
            # parameter is not that attribute's value, so it gets no link path of its own.
            item = replace(item, link=None)
        elif any(link[:2] == own_link[:2] for link in declared_by_link):
            # The description declares that object's attributes but not this one: the device does not
            # serve it (ACG-ET2 manual: Net Control 0x29/5 and Net Reference 0x2A/4 are "N/A"), so a path to
            # it would be answered 0x14.
            item = replace(item, link=None)
        key: tuple[Any, ...] = ("link", item.name, item.link, item.bits, item.type.code, item.unit, item.scale,
                                output)
    else:
        key = ("field", schema.instance, item.name)
    if key not in made:
        params.append(_field_parameter(item, output, same_value))
        made[key] = len(params) - 1
    return made[key]


# -- sections ----------------------------------------------------------------------------------------

def _file_section(doc: EdsDocument, description: EdsDescription, when: datetime) -> None:
    identity = description.identity
    header = [
        f"EDS file of the {description.catalog}: product {identity.product_name}, vendor ID {identity.vendor_id}, "
        f"product code {identity.product_code}, revision {identity.revision[0]}.{identity.revision[1]:02d}",
        "Written by cipstack from the declarations its device emulator serves; regenerate it instead of",
        "editing it, so that the file and the device keep saying the same thing.",
    ]
    section = doc.section("File", comment=header)
    section.add("DescText", [Field.string(description.description)])
    section.add("CreateDate", [Field.date(when.date())])
    section.add("CreateTime", [Field.time(when.time().replace(microsecond=0))])
    section.add("ModDate", [Field.date(when.date())])
    section.add("ModTime", [Field.time(when.time().replace(microsecond=0))])
    section.add("Revision", [Field.revision(*description.file_revision)])


def _device_section(doc: EdsDocument, description: EdsDescription) -> None:
    identity = description.identity
    section = doc.section("Device")
    section.add("VendCode", [Field.integer(identity.vendor_id)])
    section.add("VendName", [Field.string(description.vendor_name)])
    section.add("ProdType", [Field.integer(identity.device_type)])
    section.add("ProdTypeStr", [Field.string(description.product_type_name)])
    section.add("ProdCode", [Field.integer(identity.product_code)])
    section.add("MajRev", [Field.integer(identity.revision[0])])
    section.add("MinRev", [Field.integer(identity.revision[1])])
    section.add("ProdName", [Field.string(identity.product_name)])
    section.add("Catalog", [Field.string(description.catalog)])


def _groups_section(doc: EdsDocument, description: EdsDescription, plan: _Plan) -> None:
    groups = description.groups
    if not groups:
        return
    section = doc.section("Groups")
    for number, group in enumerate(groups, start=1):
        indexes = [index + 1 for index, param in enumerate(plan.params) if param.group == group]
        section.add(f"Group{number}", [Field.string(group), Field.integer(len(indexes)),
                                       *(Field.integer(index) for index in indexes)])


def _assembly_path(instance: int) -> Field:
    return Field.epath(request_path(ASSEMBLY_CLASS, instance, ASSEMBLY_DATA))


def _assembly_section(doc: EdsDocument, description: EdsDescription, plan: _Plan) -> None:
    io = description.io
    heartbeats: list[tuple[int, str]] = []
    if io is not None and io.pairs:
        if io.input_only_point is not None:
            heartbeats.append((io.input_only_point, "Input Only Heartbeat"))
        if io.listen_only_point is not None:
            heartbeats.append((io.listen_only_point, "Listen Only Heartbeat"))
    if not description.assemblies and not heartbeats:
        return
    section = doc.section("Assembly")
    for schema in description.assemblies:
        member_fields: list[Field] = []
        for bits, number in plan.members[schema.instance]:
            member_fields.extend([Field.integer(bits),
                                  Field.empty() if number is None else Field.keyword(f"Param{number}")])
        comment = schema.description or None
        section.add(f"Assem{schema.instance}", [
            Field.string(schema.name), _assembly_path(schema.instance), Field.integer(schema.size),
            Field.integer(0, hex_digits=4), Field.empty(), Field.empty(), *member_fields,
        ], comment=comment)
    for point, name in heartbeats:
        section.add(f"Assem{point}", [Field.string(name), _assembly_path(point), Field.integer(0),
                                      Field.integer(0, hex_digits=4), Field.empty(), Field.empty()])


def _connection_path(config: int, output: int, input_: int) -> Field:
    segments = [LogicalSegment(LogicalType.CLASS_ID, ASSEMBLY_CLASS), LogicalSegment(LogicalType.INSTANCE_ID, config),
                LogicalSegment(LogicalType.CONNECTION_POINT, output),
                LogicalSegment(LogicalType.CONNECTION_POINT, input_)]
    return Field.epath(encode_path(segments))


def _connections(io: IoOffer, description: EdsDescription) -> list[tuple[str, int, int, str, str]]:
    """(kind, O->T point, T->O point, name, help) of every connection, in listing order."""
    out: list[tuple[str, int, int, str, str]] = []
    for output, input_ in io.pairs:
        note = io.pair_notes.get((output, input_), "")
        text = f"{description.assembly(output).name} / {description.assembly(input_).name}"
        out.append((EXCLUSIVE_OWNER_KIND, output, input_, f"Exclusive Owner {output}/{input_}",
                    f"{text}; {note}" if note else text))
    for input_ in io.input_instances:
        name = description.assembly(input_).name
        note = io.input_notes.get(input_, "")
        if io.input_only_point is not None:
            out.append((INPUT_ONLY_KIND, io.input_only_point, input_, f"Input Only {input_}",
                        f"{name}; {note}" if note else name))
        if io.listen_only_point is not None:
            listen = f"{name}; needs a connection that multicasts it"
            out.append((LISTEN_ONLY_KIND, io.listen_only_point, input_, f"Listen Only {input_}",
                        f"{listen}; {note}" if note else listen))
    return out


def _connection_section(doc: EdsDocument, description: EdsDescription, plan: _Plan) -> None:
    io = description.io
    if io is None or not io.pairs:
        return
    section = doc.section("Connection Manager")
    rpi = Field.keyword(f"Param{plan.rpi_param}")
    for number, (kind, o_t, t_o, name, help_text) in enumerate(_connections(io, description), start=1):
        trigger, parameters = connection_words(kind, io.triggers)
        o_t_size = description.assembly(o_t).size if kind == EXCLUSIVE_OWNER_KIND else 0
        section.add(f"Connection{number}", [
            Field.integer(trigger, hex_digits=8), Field.integer(parameters, hex_digits=8),
            rpi, Field.integer(o_t_size), Field.keyword(f"Assem{o_t}"),
            rpi, Field.integer(description.assembly(t_o).size), Field.keyword(f"Assem{t_o}"),
            Field.empty(), Field.empty(), Field.empty(), Field.empty(),
            Field.string(name), Field.string(help_text), _connection_path(io.config_instance, o_t, t_o),
        ])


def _port_section(doc: EdsDocument, description: EdsDescription) -> None:
    if not description.ports:
        return
    section = doc.section("Port")
    for number, port in enumerate(description.ports, start=1):
        section.add(f"Port{number}", [Field.keyword(port.kind), Field.string(port.name),
                                      Field.epath(request_path(*port.path)), Field.integer(port.number)])


def _capacity_section(doc: EdsDocument, description: EdsDescription) -> None:
    capacity = description.capacity
    if capacity is None:
        return
    section = doc.section("Capacity")
    section.add("MaxIOConnections", [Field.integer(capacity.max_io_connections)])
    section.add("MaxMsgConnections", [Field.integer(capacity.max_msg_connections)])
    io = description.io
    if io is None or not io.pairs:
        return
    sizes = sorted({description.assembly(instance).size for pair in io.pairs for instance in pair} - {0})
    packets = 1_000_000 // io.rpi_min_us
    for number, size in enumerate(sizes, start=1):
        section.add(f"TSpec{number}", [Field.keyword("TxRx"), Field.integer(size), Field.integer(packets)])


def class_section_name(item: EdsObjectClass, vendor_id: int) -> str | None:
    class_id = item.spec.class_id
    if class_id in OWN_SECTION_CLASSES:
        return None
    return PUBLIC_CLASS_SECTIONS.get(class_id) or f"{vendor_id}_{item.spec.name} Class"


def _class_sections(doc: EdsDocument, description: EdsDescription) -> None:
    for item in sorted(description.object_classes, key=lambda c: c.spec.class_id):
        name = class_section_name(item, description.identity.vendor_id)
        if name is None:
            continue
        section = doc.section(name)
        spec = item.spec
        if spec.class_id not in PUBLIC_CLASS_SECTIONS:
            section.add("Object_Name", [Field.string(spec.name)])
            section.add("Object_Class_Code", [Field.integer(spec.class_id, hex_digits=2)])
        section.add("Revision", [Field.integer(spec.revision)])
        section.add("MaxInst", [Field.integer(spec.max_instance or item.instances)])
        section.add("Number_Of_Static_Instances", [Field.integer(item.instances)])
        section.add("Max_Number_Of_Dynamic_Instances", [Field.integer(0)])


def componet_io_lengths(description: EdsDescription) -> tuple[int, int] | None:
    """(input words, output words) of the default connection path, or None."""
    if description.componet_io is None:
        return None
    output, input_ = description.componet_io
    return (description.assembly(input_).size + 1) // 2, (description.assembly(output).size + 1) // 2


def _componet_section(doc: EdsDocument, description: EdsDescription) -> None:
    lengths = componet_io_lengths(description)
    if lengths is None:
        return
    output, input_ = description.componet_io or (0, 0)
    section = doc.section("CompoNet_IO", comment=(
        f"Default connection path: output assembly {output}, input assembly {input_}"))
    for keyword, length in (("CompoNet_Input_Info", lengths[0]), ("CompoNet_Output_Info", lengths[1])):
        unit = Field.integer(COMPONET_UNIT_WORDS)
        unit.comment = "length unit: 0 bits, 1 bytes, 2 words"
        size = Field.integer(length)
        size.comment = "length"
        section.add(keyword, [unit, size])


def generate_eds(description: EdsDescription, created: datetime | None = None) -> EdsDocument:
    """The EDS document of ``description``; ``created`` dates it (see the module docstring)."""
    when = creation_time(created)
    plan = _plan(description)
    doc = EdsDocument()
    _file_section(doc, description, when)
    _device_section(doc, description)
    doc.section("Device Classification").add("Class1", [Field.keyword(description.network)])
    if plan.params:
        params = doc.section("Params")
        for number, param in enumerate(plan.params, start=1):
            _add_param(params, number, param)
    _groups_section(doc, description, plan)
    _assembly_section(doc, description, plan)
    _connection_section(doc, description, plan)
    _port_section(doc, description)
    _capacity_section(doc, description)
    _componet_section(doc, description)
    _class_sections(doc, description)
    return doc


def eds_text(description: EdsDescription, created: datetime | None = None) -> str:
    """The EDS file of ``description`` as text (ASCII, CRLF line ends)."""
    return format_eds(generate_eds(description, created))
