"""What an EDS file says about a device, read back for use.

``read_view(doc)`` gives an ``EdsView``: the parameters with the CIP attribute each one mirrors
(its link path), the assemblies with their members, and the class 1 connections of
``[Connection Manager]``. The emulator of ``eds.emulated_device`` serves that view and the scanner
opens its connections (``Scanner.io_connection_from_eds``), so both read an EDS the same way.

Reading is forgiving: a construct this module cannot use is reported as an ``EdsIssue`` (its
line and what was skipped) and costs that entry only; nothing here raises on file content.
Field numbers below are those of the EDS specification (CIP Vol. 1, chapter 7) (ParamN, AssemN, ConnectionN).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from ..assemblies.names import field_name, unique_field_names
from ..assemblies.schema import AssemblyField, AssemblySchema
from ..cip.epath import ElectronicKey, LogicalSegment, LogicalType, PortSegment, decode_path
from ..cip.status import CipError
from ..cip.types import BY_CODE, UDINT, UINT, ULINT, USINT, CipType, IntegerType, RealType
from ..cip.values import Scaling
from ..eip.wire.cm_messages import TriggerType
from ..errors import UnknownKey
from .generator import (
    EXCLUSIVE_OWNER,
    EXCLUSIVE_OWNER_KIND,
    FORMAT_HEARTBEAT,
    FORMAT_ZERO_LENGTH,
    INPUT_ONLY,
    INPUT_ONLY_KIND,
    LISTEN_ONLY,
    LISTEN_ONLY_KIND,
    T_O_FORMAT_SHIFT,
    T_O_TYPE_SHIFT,
    TRANSPORT_CLASS_1,
    TRIGGER_SHIFT,
    TYPE_MULTICAST,
    TYPE_POINT_TO_POINT,
)
from .model import EdsDocument, Entry, Field, FieldKind

#: (class, instance, attribute) a parameter mirrors.
Link = tuple[int, int, int]

#: ConnectionN field 1 bit 27: redundant owner (eds.md, "Field 1 bits").
REDUNDANT_OWNER = 1 << 27
#: ConnectionN field 2 bits 1 and 3: O->T and T->O variable size (eds.md, "Field 2 bits").
O_T_VARIABLE = 1 << 1
T_O_VARIABLE = 1 << 3
_REFERENCE = re.compile(r"(Param|Assem)([0-9]+)")


@dataclass(frozen=True)
class EdsIssue:
    """A construct of the file that was skipped, and why."""

    line: int
    message: str

    def __str__(self) -> str:
        return f"line {self.line}: {self.message}"


@dataclass(frozen=True)
class ParamInfo:
    """One ``ParamN``: the attribute it mirrors and how (fields 3-12 and its ``EnumN``)."""

    keyword: str
    name: str
    link: Link | None
    type: CipType
    #: Field 6, the data size in bytes.
    size: int
    #: Descriptor bit 4 clear.
    settable: bool
    minimum: Any = None
    maximum: Any = None
    default: Any = None
    enum: Mapping[int, str] | None = None
    unit: str = ""
    help: str = ""
    line: int = 0
    #: Engineering value = (raw + offset) x scale, scale = multiplier x base / divider (fields 13-16),
    #: when descriptor bit 2 says the parameter scales.
    scale: float = 1.0
    offset: float = 0.0
    #: Field 21, the decimal places of the engineering value (None: not given).
    decimals: int | None = None

    @property
    def scaling(self) -> Scaling:
        return Scaling(self.unit, self.scale, self.offset, self.decimals, self.enum)


@dataclass(frozen=True)
class AssemblyMember:
    """One (size in bits, reference) pair of an ``AssemN``, at its bit offset."""

    start_bit: int
    bits: int
    #: ``ParamN``, ``AssemN`` or None for padding.
    reference: str | None


@dataclass(frozen=True)
class AssemblyInfo:
    keyword: str
    name: str
    #: From the path of field 2; for an empty path, from the connection paths that name the assembly
    #: (``place_assemblies``); None when neither gives one.
    instance: int | None
    size: int
    members: tuple[AssemblyMember, ...]
    line: int = 0
    #: An ``AssemExaN``: its size is that of its default configuration (a parameter's default, its
    #: members); a variable-size connection may carry less of it.
    variable: bool = False
    #: Declared with an empty size (the modular I/O of field-bus blocks): the size field of the
    #: connections that name it gives its size (``size_by_connections``); 0 until then.
    sized_by_connection: bool = False
    #: The line of its size field, for what is said of it.
    size_line: int = 0


@dataclass(frozen=True)
class ConnectionInfo:
    """One class 1 ``ConnectionN``: kind, connection points, sizes, RPI and T->O types."""

    number: int
    name: str
    kind: str
    config: int
    #: The O->T connection point: the output assembly, or the heartbeat point.
    o_t_point: int
    t_o_point: int
    #: O->T data size (0 for a heartbeat) and T->O data size, in bytes.
    o_t_size: int
    t_o_size: int
    #: The RPI the file proposes and the range it allows, in microseconds (None: not given).
    rpi_us: int | None
    rpi_min_us: int | None
    rpi_max_us: int | None
    #: T->O connection types the file allows (field 2 bits 21 and 22).
    t_o_multicast: bool
    t_o_point_to_point: bool
    triggers: frozenset[TriggerType]
    #: The O->T and T->O assemblies of fields 5 and 8 (their keywords), when named.
    o_t_assembly: str | None = None
    t_o_assembly: str | None = None
    line: int = 0
    #: The configuration assembly of field 12 (its keyword), when the field names an AssemN.
    config_assembly: str | None = None

    #: An exclusive owner whose O->T carries no data (size 0): it sends to a heartbeat point, as
    #: devices without outputs declare their owner connection.
    o_t_heartbeat: bool = False
    #: Field 2 bits 1 and 3: the O->T / T->O size is variable (up to the size above).
    o_t_variable: bool = False
    t_o_variable: bool = False

    @property
    def t_o_heartbeat(self) -> bool:
        """An exclusive owner whose T->O carries no data (size 0): its T->O point is a heartbeat
        (198, 254), as output-only devices and controllers' "write data" connections declare it. The
        target produces packets of the sequence count alone, and the owner's O->T keeps the watchdog."""
        return self.kind == EXCLUSIVE_OWNER_KIND and self.t_o_size == 0

    @property
    def heartbeat(self) -> bool:
        """Input only and listen only send the heartbeat point, not output data; so does an
        exclusive owner of no O->T data."""
        return self.kind != EXCLUSIVE_OWNER_KIND or self.o_t_heartbeat


@dataclass
class EdsView:
    params: dict[str, ParamInfo] = field(default_factory=dict)
    #: By keyword (``Assem21``).
    assemblies: dict[str, AssemblyInfo] = field(default_factory=dict)
    connections: list[ConnectionInfo] = field(default_factory=list)
    issues: list[EdsIssue] = field(default_factory=list)
    #: Why no class 1 connection is usable, when none is (no [Connection Manager]: a DeviceNet or
    #: CompoNet file; or each ConnectionN skipped).
    why_none: str = ""

    def connection(self, which: int | str) -> ConnectionInfo:
        """ConnectionN by its number N (``1``, ``"1"``, ``"Connection1"``) or by its name (field 13)."""
        text = str(which).strip()
        if text.startswith("Connection") and text[len("Connection"):].isdigit():
            text = text[len("Connection"):]
        for item in self.connections:
            if (text.isdigit() and item.number == int(text)) or item.name == str(which):
                return item
        known = ", ".join(f"{c.number} ({c.name})" for c in self.connections) or f"none usable: {self.why_none}"
        raise UnknownKey(f"no class 1 connection {which!r} in the EDS (known: {known})")

    def assembly_at(self, instance: int) -> AssemblyInfo | None:
        """The assembly whose path names ``instance``."""
        return next((a for a in self.assemblies.values() if a.instance == instance), None)

    def schema(self, instance: int) -> AssemblySchema | None:
        """The assembly's members as a schema (see :func:`assembly_schema`), or None."""
        found = self.assembly_at(instance)
        return None if found is None else assembly_schema(found, self.params)


# -- fields ---------------------------------------------------------------------------------------------

def _int(item: Field | None) -> int | None:
    return item.value if item is not None and item.kind is FieldKind.INT else None


def _number(item: Field | None) -> int | float | None:
    return item.number if item is not None else None


def _text(item: Field | None) -> str:
    return item.value if item is not None and item.kind is FieldKind.STRING else ""


def _keyword(item: Field | None) -> str | None:
    return item.value if item is not None and item.kind is FieldKind.KEYWORD else None


def _path_bytes(entry: Entry, number: int, params: Mapping[str, ParamInfo]) -> tuple[bytes | None, str | None]:
    """The bytes of an EPATH field, ``[ParamN]`` items replaced by that parameter's default;
    (None, why) when that cannot be done, (b"", None) for an empty field."""
    item = entry.field(number)
    if item is None or item.kind is FieldKind.EMPTY:
        return b"", None
    if item.kind is not FieldKind.EPATH:
        return None, f"field {number} is not an EPATH"
    out = bytearray()
    for part in item.value:
        if isinstance(part, int):
            out.append(part)
            continue
        param = params.get(part)
        value = param.default if param is not None else None
        if not isinstance(value, int) or isinstance(value, bool) or not 0 <= value <= 0xFF:
            return None, f"path item [{part}] has no byte value as its default"
        out.append(value)
    return bytes(out), None


def _segments(data: bytes) -> list[Any] | None:
    try:
        return decode_path(data)
    except (CipError, ValueError, IndexError):
        return None


# -- [Params] -------------------------------------------------------------------------------------------

def _param(entry: Entry, enum_entry: Entry | None, issues: list[EdsIssue]) -> ParamInfo | None:
    keyword = entry.keyword
    if len(entry.fields) < 12:
        issues.append(EdsIssue(entry.line, f"{keyword} has {len(entry.fields)} fields, fewer than 12: skipped"))
        return None
    code = _int(entry.field(5))
    cip_type = BY_CODE.get(code) if code is not None else None
    if cip_type is None:
        type_item = entry.field(5)
        written = type_item.raw if type_item is not None else "?"
        issues.append(EdsIssue(entry.line_of(5), f"{keyword}: data type {written} is not one this emulator "
                                                 "serves: skipped"))
        return None
    size = _int(entry.field(6))
    if cip_type.size is not None and size is not None and size != cip_type.size:
        issues.append(EdsIssue(entry.line_of(6), f"{keyword}: data size {size} is not the {cip_type.size} bytes of "
                                                 f"{cip_type.name}; {cip_type.size} used"))
    size = cip_type.size if cip_type.size is not None else (size or 0)
    descriptor = _int(entry.field(4)) or 0
    link: Link | None = None
    path, why = _path_bytes(entry, 3, {})
    if path is None:
        issues.append(EdsIssue(entry.line_of(3), f"{keyword}: link path: {why}; served by no attribute"))
    elif path:
        link, why = _link(path)
        if link is None:
            issues.append(EdsIssue(entry.line_of(3), f"{keyword}: link path {path.hex(' ').upper()}: {why}; "
                                                     "served by no attribute"))
    enum: dict[int, str] | None = None
    if enum_entry is not None:
        values = enum_entry.fields
        enum = {}
        for value_item, name_item in zip(values[0::2], values[1::2], strict=False):
            value = _int(value_item)
            if value is None or name_item.kind is not FieldKind.STRING:
                issues.append(EdsIssue(enum_entry.line, f"{enum_entry.keyword}: a value/name pair is malformed: "
                                                        "the enumeration is left out"))
                enum = None
                break
            enum[value] = name_item.value
    numeric = isinstance(cip_type, (IntegerType, RealType))
    minimum, maximum, number = (_number(entry.field(n)) if numeric else None for n in (10, 11, 12))
    default: int | float | str | None = number if numeric else _text(entry.field(12))
    scale, offset, decimals = _scaling(entry, keyword, descriptor, issues) if numeric else (1.0, 0.0, None)
    return ParamInfo(keyword, _text(entry.field(7)), link, cip_type, size, not descriptor & 0x10, minimum, maximum,
                     default, enum or None, _text(entry.field(8)), _text(entry.field(9)), entry.line,
                     scale, offset, decimals)


def _scaling(entry: Entry, keyword: str, descriptor: int, issues: list[EdsIssue]) -> tuple[float, float, int | None]:
    """(scale, offset, decimal places) of a parameter whose descriptor says it scales (bit 2): fields
    13-16 and 21, engineering = (raw + offset) x multiplier x base / divider (an empty field is 1, an
    empty offset 0). Without bit 2 the parameter is unscaled; factors that are not positive, which
    would make every value 0, infinite or reversed, are reported and left out."""
    if not descriptor & 0x04:
        return 1.0, 0.0, None
    multiplier, divider, base = (_number(entry.field(n)) for n in (13, 14, 15))
    offset, decimals = _number(entry.field(16)), _int(entry.field(21))
    factors = [1 if factor is None else factor for factor in (multiplier, divider, base)]
    if any(factor <= 0 for factor in factors):
        issues.append(EdsIssue(entry.line, f"{keyword}: scaling multiplier/divider/base not positive: values left "
                                           "unscaled"))
        return 1.0, 0.0, None
    if decimals is not None and not 0 <= decimals <= 15:
        decimals = None
    return float(factors[0]) * float(factors[2]) / float(factors[1]), float(offset or 0), decimals


def _link(path: bytes) -> tuple[Link | None, str | None]:
    segments = _segments(path)
    if segments is None:
        return None, "not a valid EPATH"
    values: dict[LogicalType, int] = {}
    for segment in segments:
        if not isinstance(segment, LogicalSegment) or segment.kind in values or segment.kind not in (
                LogicalType.CLASS_ID, LogicalType.INSTANCE_ID, LogicalType.ATTRIBUTE_ID):
            return None, "not a class/instance/attribute path"
        values[segment.kind] = segment.value
    if len(values) != 3:
        return None, "not a class/instance/attribute path"
    return (values[LogicalType.CLASS_ID], values[LogicalType.INSTANCE_ID], values[LogicalType.ATTRIBUTE_ID]), None


def read_params(doc: EdsDocument, issues: list[EdsIssue]) -> dict[str, ParamInfo]:
    section = doc.get("Params")
    out: dict[str, ParamInfo] = {}
    if section is None:
        return out
    # The first EnumN of each number, as Section.get finds it, looked up once rather than by a scan
    # of the section per parameter (a file of a thousand parameters made that a million comparisons).
    enums: dict[str, Entry] = {}
    for entry in section:
        enums.setdefault(entry.keyword, entry)
    for entry in section:
        match = re.fullmatch(r"Param([0-9]+)", entry.keyword)
        if match is None:
            continue
        if entry.keyword in out:
            issues.append(EdsIssue(entry.line, f"{entry.keyword} is defined twice: the first is kept"))
            continue
        found = _param(entry, enums.get(f"Enum{match[1]}"), issues)
        if found is not None:
            out[entry.keyword] = found
    return out


# -- [Assembly] -----------------------------------------------------------------------------------------

def _assembly(entry: Entry, params: Mapping[str, ParamInfo], sizes: Mapping[str, int],
              issues: list[EdsIssue]) -> AssemblyInfo | None:
    keyword = entry.keyword
    if len(entry.fields) < 3:
        issues.append(EdsIssue(entry.line, f"{keyword} has {len(entry.fields)} fields, fewer than 3: skipped"))
        return None
    instance = None
    path, why = _path_bytes(entry, 2, params)
    if path is None:
        issues.append(EdsIssue(entry.line_of(2), f"{keyword}: path: {why}: skipped"))
        return None
    if path:
        segments = _segments(path)
        instances = [s.value for s in segments or () if isinstance(s, LogicalSegment)
                     and s.kind is LogicalType.INSTANCE_ID]
        classes = [s.value for s in segments or () if isinstance(s, LogicalSegment) and s.kind is LogicalType.CLASS_ID]
        if segments is None or classes != [0x04] or len(instances) != 1:
            issues.append(EdsIssue(entry.line_of(2), f"{keyword}: path {path.hex(' ').upper()} is not an Assembly "
                                                     "instance: skipped"))
            return None
        instance = instances[0]
    members: list[AssemblyMember] = []
    position = 0
    for size_item, reference_item in zip(entry.fields[6::2], entry.fields[7::2], strict=False):
        reference = _keyword(reference_item)
        bits = _int(size_item)
        if bits is None and reference is not None:
            # A member naming its own assembly is the instance's own data (a drive vendor's idiom).
            bits = 8 * sizes[reference] if reference in sizes else (
                8 * params[reference].size if reference in params else None)
        if bits is None or bits < 0:
            issues.append(EdsIssue(entry.line_of(7), f"{keyword}: a member has no size: its members are left out"))
            members = []
            break
        members.append(AssemblyMember(position, bits, None if reference == keyword else reference))
        position += bits
    size = sizes.get(keyword)
    if size is None:
        size_field = entry.field(3)
        written = size_field.raw if size_field is not None else ""
        if not written.strip() and not members:
            # The field-bus block's style: the connection that names it says how big it is.
            return AssemblyInfo(keyword, _text(entry.field(1)), instance, 0, (), entry.line,
                                variable=keyword.startswith("AssemExa"), sized_by_connection=True,
                                size_line=entry.line_of(3))
        issues.append(EdsIssue(entry.line_of(3), f"{keyword}: size {written or '(empty)'} is not a number of bytes, "
                                                 "nor a ParamN with a default, nor members of known sizes (a modular "
                                                 "or variable-size assembly needs one of them): skipped"))
        return None
    if members and position != 8 * size:
        issues.append(EdsIssue(entry.line, f"{keyword}: members add up to {position} bits, not {8 * size}: "
                                           "served as plain data"))
        members = []
    return AssemblyInfo(keyword, _text(entry.field(1)), instance, size, tuple(members), entry.line,
                        variable=keyword.startswith("AssemExa"))


#: The assemblies the emulator and the scanner read: fixed (AssemN) and variable-size (AssemExaN,
#: how IO-Link masters and modular stations declare process data whose size their parameters set).
ASSEMBLY_KEYWORD = re.compile(r"Assem(?:Exa)?[0-9]+")


def raw_param_sizes(doc: EdsDocument) -> dict[str, tuple[int | None, Any]]:
    """(data size, default) of every ParamN as written (fields 6 and 12), whatever its type: an
    assembly member or size may name a parameter the emulator cannot serve as an attribute."""
    section = doc.get("Params")
    out: dict[str, tuple[int | None, Any]] = {}
    for entry in section or ():
        if re.fullmatch(r"Param[0-9]+", entry.keyword) and entry.keyword not in out:
            out[entry.keyword] = (_int(entry.field(6)), _number(entry.field(12)))
    return out


def assembly_sizes(doc: EdsDocument) -> dict[str, int]:
    """The size in bytes of every assembly the file sizes: field 3 when a number; the default of
    the ParamN field 3 names (a variable-size or modular assembly at its default configuration);
    else, for an empty field 3, the sum of its members (each its size in bits, or, empty, the
    size of the parameter or assembly it names: a member naming its own assembly sizes nothing)."""
    section = doc.get("Assembly")
    entries = {e.keyword: e for e in section or () if ASSEMBLY_KEYWORD.fullmatch(e.keyword)}
    params = raw_param_sizes(doc)
    sizes: dict[str, int] = {}
    resolving: set[str] = set()

    def size_of(keyword: str) -> int | None:
        if keyword in sizes:
            return sizes[keyword]
        entry = entries.get(keyword)
        if entry is None or keyword in resolving:
            return None
        resolving.add(keyword)
        try:
            found = _entry_size(entry)
        finally:
            resolving.discard(keyword)
        if found is not None:
            sizes[keyword] = found
        return found

    def _entry_size(entry: Entry) -> int | None:
        size_item = entry.field(3)
        written = _int(size_item)
        if written is not None:
            return written if written >= 0 else None
        reference = _keyword(size_item)
        if reference is not None:
            default = params.get(reference, (None, None))[1]
            return int(default) if isinstance(default, (int, float)) and default >= 0 and \
                float(default).is_integer() else None
        if size_item is not None and size_item.kind is not FieldKind.EMPTY:
            return None
        bits = 0
        for member_size, member in zip(entry.fields[6::2], entry.fields[7::2], strict=False):
            count = _int(member_size)
            name = _keyword(member)
            if count is None and name is not None and name != entry.keyword:
                if name in params and (param_size := params[name][0]) is not None:
                    count = 8 * param_size
                elif (inner := size_of(name)) is not None:
                    count = 8 * inner
            if count is None or count < 0:
                return None
            bits += count
        return (bits + 7) // 8 if bits else None

    for keyword in entries:
        size_of(keyword)
    return sizes


def read_assemblies(doc: EdsDocument, params: Mapping[str, ParamInfo],
                    issues: list[EdsIssue]) -> dict[str, AssemblyInfo]:
    section = doc.get("Assembly")
    out: dict[str, AssemblyInfo] = {}
    if section is None:
        return out
    sizes = assembly_sizes(doc)
    raw = raw_param_sizes(doc)
    # Members may name parameters the emulator serves no attribute for: their size is as written.
    member_params = {**{k: ParamInfo(k, k, None, USINT, size or 0, False) for k, (size, _) in raw.items()
                        if size is not None}, **params}
    params = member_params
    for entry in section:
        if not ASSEMBLY_KEYWORD.fullmatch(entry.keyword):
            continue
        if entry.keyword in out:
            issues.append(EdsIssue(entry.line, f"{entry.keyword} is defined twice: the first is kept"))
            continue
        found = _assembly(entry, params, sizes, issues)
        if found is not None:
            out[entry.keyword] = found
    return out


def _member_name(reference: str, params: Mapping[str, ParamInfo]) -> str:
    param = params.get(reference)
    return (field_name(param.name) if param is not None else "") or field_name(reference)


def assembly_schema(info: AssemblyInfo, params: Mapping[str, ParamInfo]) -> AssemblySchema | None:
    """The members of an assembly as named fields, or None when they cannot be (no instance, no
    members, a member that crosses a byte boundary without filling whole bytes).

    A member referring to a parameter is named after it by ``field_name`` (a parameter without a
    usable name, or a member naming an assembly, after its keyword: ``param12``), repeats made
    distinct by ``unique_field_names``: the rule the profiles' own field names follow, so the EDS
    of a device and its profile give one set of names. A member keeps the parameter's link when it
    carries that parameter's value whole (a 1-bit member of a BOOL or integer, or whole bytes of
    the parameter's own size), which is what the emulator and the scanner decode by.
    """
    if info.instance is None or not info.members:
        return None
    fields: list[AssemblyField] = []
    named = [member for member in info.members if member.reference is not None and member.bits]  # the rest: padding
    names = unique_field_names(_member_name(member.reference or "", params) for member in named)
    for member, name in zip(named, names, strict=True):
        param = params.get(member.reference or "")
        offset, bit = divmod(member.start_bit, 8)
        unit, scale, scale_help = (param.unit, param.scale, param.help) if param is not None else ("", 1.0, "")
        if bit + member.bits <= 8 and member.bits < 8:
            whole = param is not None and isinstance(param.type, IntegerType) and (
                member.bits == 1 or member.bits == 8 * param.size)
            fields.append(AssemblyField(name, offset, bits=member.bits, bit=bit, unit=unit, scale=scale,
                                        help=scale_help,
                                        link=param.link if whole and param is not None else None))
        elif bit == 0 and member.bits % 8 == 0:
            cip_type: CipType | None = None
            link = None
            if param is not None and param.type.size == member.bits // 8:
                cip_type, link = param.type, param.link
            else:
                cip_type = {8: USINT, 16: UINT, 32: UDINT, 64: ULINT}.get(member.bits)
            if cip_type is None:
                return None
            fields.append(AssemblyField(name, offset, cip_type, unit=unit, scale=scale, help=scale_help, link=link))
        else:
            return None
    try:
        return AssemblySchema(info.instance, info.name or info.keyword, info.size, fields)
    except ValueError:
        return None


# -- [Connection Manager] --------------------------------------------------------------------------------

def _rpi(item: Field | None, params: Mapping[str, ParamInfo]) -> tuple[int | None, int | None, int | None]:
    """(proposed, minimum, maximum) of an RPI field: a number, or a parameter's default and range."""
    value = _int(item)
    if value is not None:
        return value, None, None
    reference = _keyword(item)
    param = params.get(reference) if reference else None
    if param is None:
        return None, None, None

    def whole(number: Any) -> int | None:
        return int(number) if isinstance(number, (int, float)) and not isinstance(number, bool) else None

    return whole(param.default), whole(param.minimum), whole(param.maximum)


def _connection(entry: Entry, number: int, params: Mapping[str, ParamInfo], assemblies: Mapping[str, AssemblyInfo],
                issues: list[EdsIssue], heartbeat_points: frozenset[int] = frozenset()) -> ConnectionInfo | None:
    """One ``ConnectionN``; ``heartbeat_points``: the O->T points the file's input-only and
    listen-only connections send their heartbeat to (an exclusive owner whose T->O is one of them
    produces no data)."""
    keyword = entry.keyword
    if len(entry.fields) < 15:
        issues.append(EdsIssue(entry.line, f"{keyword} has {len(entry.fields)} fields, not 15: skipped"))
        return None
    trigger, parameters = _int(entry.field(1)), _int(entry.field(2))
    if trigger is None or parameters is None:
        issues.append(EdsIssue(entry.line, f"{keyword}: fields 1 and 2 are not numbers: skipped"))
        return None
    if not trigger & TRANSPORT_CLASS_1:
        issues.append(EdsIssue(entry.line_of(1), f"{keyword}: transport 0x{trigger & 0xFFFF:04X} is not class 1: "
                                                 "skipped"))
        return None
    if trigger & REDUNDANT_OWNER:
        issues.append(EdsIssue(entry.line_of(1), f"{keyword}: redundant owner connections are not supported: "
                                                 "skipped"))
        return None
    o_t_name, t_o_name, config_name = _keyword(entry.field(5)), _keyword(entry.field(8)), _keyword(entry.field(12))
    o_t_assembly, t_o_assembly = assemblies.get(o_t_name or ""), assemblies.get(t_o_name or "")
    path, why = _path_bytes(entry, 15, params)
    if path is None:
        issues.append(EdsIssue(entry.line_of(15), f"{keyword}: path: {why}: skipped"))
        return None
    segments = _segments(path) if path else []
    config, points, bad = 1, [], segments is None
    for segment in segments or ():
        if isinstance(segment, LogicalSegment) and segment.kind is LogicalType.CLASS_ID:
            bad = bad or segment.value != 0x04
        elif isinstance(segment, LogicalSegment) and segment.kind is LogicalType.INSTANCE_ID:
            config = segment.value
        elif isinstance(segment, LogicalSegment) and segment.kind is LogicalType.CONNECTION_POINT:
            points.append(segment.value)
        elif not isinstance(segment, (ElectronicKey, PortSegment)):
            bad = True  # a data segment (configuration data written into the path): not offered
    if path and (bad or not points):
        issues.append(EdsIssue(entry.line_of(15), f"{keyword}: path {path.hex(' ').upper()} is not an assembly "
                                                  "connection path: skipped"))
        return None
    if len(points) == 3:
        config, points = points[0], points[1:]
    if len(points) == 1:
        points = [o_t_assembly.instance if o_t_assembly and o_t_assembly.instance is not None else -1, points[0]]
    if not points:
        points = [a.instance if a and a.instance is not None else -1 for a in (o_t_assembly, t_o_assembly)]
    o_t, t_o = points
    if o_t < 0 or t_o < 0:
        issues.append(EdsIssue(entry.line, f"{keyword}: its connection points are unknown: skipped"))
        return None
    if trigger & LISTEN_ONLY:
        kind = LISTEN_ONLY_KIND
    elif trigger & INPUT_ONLY:
        kind = INPUT_ONLY_KIND
    elif trigger & EXCLUSIVE_OWNER:
        kind = EXCLUSIVE_OWNER_KIND
    else:
        # No application type bit: older files; a connection with no O->T data sends the heartbeat.
        o_t_data = o_t_assembly.size if o_t_assembly is not None and not o_t_assembly.sized_by_connection \
            else (_int(entry.field(4)) or 0)
        kind = EXCLUSIVE_OWNER_KIND if o_t_data else INPUT_ONLY_KIND

    # The file says the owner's T->O is a heartbeat: its T->O real-time format is heartbeat or zero
    # length (field 2 bits 12-14, eds.md), or its T->O point is where the file's input-only or
    # listen-only connections send their heartbeat. A size it leaves open is then 0, not a guess.
    t_o_format = (parameters >> T_O_FORMAT_SHIFT) & 0x7
    t_o_heartbeat = kind == EXCLUSIVE_OWNER_KIND and (
        t_o in heartbeat_points or t_o_format in (FORMAT_HEARTBEAT, FORMAT_ZERO_LENGTH))

    def size(number: int, assembly: AssemblyInfo | None) -> int | None:
        if assembly is not None and not assembly.sized_by_connection:
            return assembly.size
        value = _int(entry.field(number))
        if value is not None:
            return value
        heartbeat = number == 7 and t_o_heartbeat
        given = entry.field(number)
        if heartbeat and (given is None or given.kind is FieldKind.EMPTY):
            return 0
        reference = _keyword(entry.field(number))
        param = params.get(reference) if reference else None
        if param is None or not isinstance(param.default, int):
            return None
        if param.default == 0 and heartbeat:
            return 0
        if param.default == 0 and isinstance(param.maximum, int) and param.maximum > 0:
            # Nothing mapped yet (a gateway's default): offered at the smallest size it allows.
            smallest = max(param.minimum if isinstance(param.minimum, int) else 0, 1)
            direction = "O->T" if number == 4 else "T->O"
            unit = "byte" if smallest == 1 else "bytes"
            issues.append(EdsIssue(entry.line_of(number), f"{reference}, the {direction} size of {keyword}, defaults "
                                                          f"to 0: offered at {smallest} {unit}, the smallest non-zero "
                                                          "size it allows"))
            return smallest
        return param.default

    o_t_size = 0 if kind != EXCLUSIVE_OWNER_KIND else size(4, o_t_assembly)
    t_o_size = size(7, t_o_assembly)
    if o_t_size is None or t_o_size is None:
        issues.append(EdsIssue(entry.line, f"{keyword}: a data size is unknown: skipped"))
        return None
    rpi, rpi_min, rpi_max = _rpi(entry.field(6), params)
    o_t_rpi = _rpi(entry.field(3), params)
    rpi = rpi if rpi is not None else o_t_rpi[0]
    rpi_min = rpi_min if rpi_min is not None else o_t_rpi[1]
    rpi_max = rpi_max if rpi_max is not None else o_t_rpi[2]
    t_o_types = (parameters >> T_O_TYPE_SHIFT) & 0xF
    triggers = frozenset(t for t in TriggerType if trigger & (1 << (TRIGGER_SHIFT + int(t)))) or frozenset(
        {TriggerType.CYCLIC})
    return ConnectionInfo(
        number, _text(entry.field(13)) or keyword, kind, config, o_t, t_o, o_t_size, t_o_size, rpi, rpi_min, rpi_max,
        bool(t_o_types & TYPE_MULTICAST), bool(t_o_types & TYPE_POINT_TO_POINT) or not t_o_types, triggers,
        o_t_name, t_o_name, entry.line, config_name if config_name in assemblies else None,
        o_t_heartbeat=kind == EXCLUSIVE_OWNER_KIND and o_t_size == 0,
        o_t_variable=bool(parameters & O_T_VARIABLE), t_o_variable=bool(parameters & T_O_VARIABLE))


def read_connections(doc: EdsDocument, params: Mapping[str, ParamInfo], assemblies: Mapping[str, AssemblyInfo],
                     issues: list[EdsIssue]) -> list[ConnectionInfo]:
    section = doc.get("Connection Manager")
    out: list[ConnectionInfo] = []
    if section is None:
        return out
    numbered = [(entry, int(match[1])) for entry in section
                if (match := re.fullmatch(r"Connection([0-9]+)", entry.keyword)) is not None]
    # A first reading finds the heartbeat points (what it says is said again by the second).
    first = [_connection(entry, number, params, assemblies, []) for entry, number in numbered]
    heartbeats = frozenset(c.o_t_point for c in first if c is not None and c.kind != EXCLUSIVE_OWNER_KIND)
    for entry, number in numbered:
        found = _connection(entry, number, params, assemblies, issues, heartbeats)
        if found is not None:
            out.append(found)
    return out


def place_assemblies(assemblies: Mapping[str, AssemblyInfo], connections: list[ConnectionInfo],
                     issues: list[EdsIssue]) -> dict[str, AssemblyInfo]:
    """Give an assembly written with an empty path (``Assem100 = "Input", "", 32, ...``: most files
    do) the instance the connection paths name for it: the O->T point of the connections whose
    field 5 names it, the T->O point of those whose field 8 does, the configuration instance of
    those whose field 12 does. Its own path wins when it has one; the AssemN number is not taken
    for an instance (only the paths say where data goes). Connections that name it as two
    instances: not placed, one issue."""
    named: dict[str, set[int]] = {}
    for connection in connections:
        if connection.o_t_assembly and not connection.heartbeat:
            named.setdefault(connection.o_t_assembly, set()).add(connection.o_t_point)
        if connection.t_o_assembly:
            named.setdefault(connection.t_o_assembly, set()).add(connection.t_o_point)
        if connection.config_assembly:
            named.setdefault(connection.config_assembly, set()).add(connection.config)
    placed = dict(assemblies)
    for keyword, info in assemblies.items():
        points = named.get(keyword, set())
        if info.instance is not None or not points:
            continue
        if len(points) > 1:
            issues.append(EdsIssue(info.line, f"{keyword} has no path and its connections name it as instances "
                                              f"{', '.join(str(p) for p in sorted(points))}: not served"))
            continue
        placed[keyword] = replace(info, instance=points.pop())
    return placed


def size_by_connections(assemblies: Mapping[str, AssemblyInfo], connections: list[ConnectionInfo],
                        issues: list[EdsIssue]) -> dict[str, AssemblyInfo]:
    """Give an assembly declared with an empty size the size the connections that name it give it
    (their size field: a number, or a ParamN with its default); one they do not size, or size
    differently, is skipped with the reason."""
    sized = dict(assemblies)
    for keyword, info in assemblies.items():
        if not info.sized_by_connection:
            continue
        sizes = {c.o_t_size for c in connections if c.o_t_assembly == keyword and not c.heartbeat}
        sizes |= {c.t_o_size for c in connections if c.t_o_assembly == keyword}
        if len(sizes) == 1 and min(sizes) > 0:
            sized[keyword] = replace(info, size=sizes.pop(), sized_by_connection=False)
            continue
        why = (f"its connections give it the sizes {', '.join(str(n) for n in sorted(sizes))}" if len(sizes) > 1
               else "no connection that names it gives a size")
        issues.append(EdsIssue(info.size_line or info.line, f"{keyword}: size (empty), and {why} (a modular or "
                                                            "variable-size assembly needs a size, a ParamN with a "
                                                            "default, members of known sizes or a connection that "
                                                            "sizes it): skipped"))
        del sized[keyword]
    return sized


def read_view(doc: EdsDocument) -> EdsView:
    """Parameters, assemblies and class 1 connections of ``doc``, with what was skipped."""
    issues: list[EdsIssue] = []
    params = read_params(doc, issues)
    assemblies = read_assemblies(doc, params, issues)
    connections = read_connections(doc, params, assemblies, issues)
    assemblies = size_by_connections(assemblies, connections, issues)
    view = EdsView(params, place_assemblies(assemblies, connections, issues), connections, issues)
    if not connections:
        view.why_none = _why_no_connection(doc, issues)
    return view


def _why_no_connection(doc: EdsDocument, issues: list[EdsIssue]) -> str:
    section = doc.get("Connection Manager")
    if section is None:
        classification = doc.get("Device Classification")
        networks = [str(entry.value()) for entry in classification if entry.fields] if classification else []
        network = next((n for n in networks if n in ("CompoNet", "DeviceNet", "ControlNet")), None)
        if network is None and doc.get("IO_Info") is not None:
            network = "DeviceNet"
        kind = f"a {network} file" if network else "a DeviceNet or CompoNet file"
        return (f"the file has no [Connection Manager] ({kind}: its I/O is not described as EtherNet/IP "
                "connections); give --output N --input M to take only the field names from it")
    skipped = [issue.message for issue in issues if re.match(r"Connection[0-9]+\b", issue.message)]
    return "every ConnectionN was skipped (" + "; ".join(skipped) + ")" if skipped else \
        "[Connection Manager] has no ConnectionN"


__all__ = [
    "AssemblyInfo", "AssemblyMember", "ConnectionInfo", "EdsIssue", "EdsView", "ParamInfo", "assembly_schema",
    "place_assemblies", "read_assemblies", "read_connections", "read_params", "read_view", "size_by_connections",
]
