"""Checking an EDS document against the rules of the EDS format and against a live device.

Each rule has a short stable name (:data:`RULES`) that scripts may filter on. A finding
points at the line of the field, entry or section at fault; line 0 means the whole file
(a section that is missing has no line of its own).
"""

from __future__ import annotations

import datetime
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from ..cip.types import BY_CODE
from .model import EdsDocument, Entry, Field, FieldKind, Section

RULES: dict[str, str] = {
    "required-section": "[File], [Device] and, except on DeviceNet, [Device Classification] are present",
    "required-keyword": "the required keywords of [File], [Device] and [Device Classification] are present",
    "duplicate-section": "a section appears once",
    "duplicate-keyword": "a keyword appears once in its section",
    "section-order": "public sections come in the order the specification lists them",
    "field-count": "an entry has the number of fields its keyword calls for",
    "field-type": "a field holds the kind of value its place calls for (number, string, keyword)",
    "unquoted-value": "a path or string is quoted (an unquoted one is read as what it evidently is)",
    "date-format": "dates are mm-dd-yyyy and exist",
    "time-format": "times are hh:mm:ss and exist",
    "revision-format": "the file revision is major.minor",
    "epath-format": "paths are hex bytes and [ParamN]; a link path size counts its bytes",
    "device-classification": "Class1 names a known network",
    "data-type": "a parameter's data type code is a known CIP type",
    "data-size": "a parameter's data size is its type's size (strings exempt)",
    "min-default-max": "a parameter's minimum <= default <= maximum",
    "value-range": "a parameter's minimum, maximum and default fit its data type",
    "param-reference": "every ParamN referred to (assemblies, connections, paths, groups) exists",
    "enum-reference": "every EnumN belongs to a ParamN, and an enumerated ParamN has its EnumN",
    "assembly-reference": "every AssemN referred to (assemblies, connections) exists",
    "assembly-size": "the member sizes of an assembly add up to its size in bits",
    "connection-size": "a connection's O->T and T->O sizes are those of the assemblies it names",
    "connection-format": "a connection's trigger/transport and parameter words are consistent",
    "connection-path": "a connection path's connection points are those of the assemblies it names, and it has one",
    "assembly-member": "an assembly does not contain itself through other assemblies (a loop)",
    "class-code": "an object class section's Object_Class_Code is that section's class",
    "keyword-case": "keywords are written in the specification's case (VendCode, not vendcode)",
    "encoding": "the file's text is ASCII or Latin-1 (a UTF-8 file is noted: its non-ASCII text reads otherwise)",
    "device-identity": "[Device] matches the Identity object of the live device",
    "live-parameter": "a linked ParamN's attribute exists on the live device with the file's size, in its range",
    "live-assembly": "an AssemN's size is the live device's Assembly attribute 4",
    "live-connection": "a class 1 ConnectionN opens on the live device as the file describes it",
    "live-refused": "what the live device refuses without saying the file is wrong (noted)",
}

#: Where each rule comes from: the EDS specification (CIP Vol. 1, Chapter 7) as open sources describe
#: it (EDS readers such as eds-pie, published files), what configuration tools and eds-pie accept, or
#: the CIP objects a live device serves. ``docs/eds.md`` lists them with their severities.
SOURCES: dict[str, str] = {
    "required-section": "EDS spec: [File] and [Device] are required; [Device Classification] on all but DeviceNet",
    "required-keyword": "EDS spec: the required entries of [File], [Device], [Device Classification]; Catalog is "
                        "optional as configuration tools accept files without it",
    "duplicate-section": "EDS spec: a section appears once; a tool reads only one of two",
    "duplicate-keyword": "EDS spec: a keyword appears once in its section; a tool reads only one of two",
    "section-order": "EDS spec: the order of the public sections; tools read any order: warning",
    "field-count": "EDS spec: fields per keyword (ParamN 21 (+3), AssemN 6 + pairs, ConnectionN 15 "
                   "(+2 CIP Safety))",
    "field-type": "EDS spec: the data type of each field (as eds-pie's ethernetip_lib.json lays them out)",
    "unquoted-value": "EDS spec: strings and EPATHs are quoted (its lexical rules); read as what they "
                      "evidently are: warning",
    "date-format": "EDS spec: dates mm-dd-yyyy (its lexical rules)",
    "time-format": "EDS spec: times hh:mm:ss (its lexical rules)",
    "revision-format": "EDS spec: the file revision is major.minor (its lexical rules)",
    "epath-format": "EDS spec: EPATHs are quoted hex bytes and [ParamN]; link path size counts them",
    "device-classification": "EDS spec: ClassN names a network; other names are warned of",
    "data-type": "CIP Vol. 1 Appendix C: data type codes",
    "data-size": "EDS spec: ParamN field 6 is the size of the type of field 5",
    "min-default-max": "EDS spec: ParamN fields 10-12",
    "value-range": "CIP Vol. 1 Appendix C: the range of each type; a tool clamps: warning",
    "param-reference": "EDS spec: a reference names an entry of the file",
    "enum-reference": "EDS spec: EnumN follows its ParamN ; a missing EnumN of an enumerated "
                      "ParamN shows numbers instead of names: warning",
    "assembly-reference": "EDS spec: a reference names an entry of the file",
    "assembly-size": "EDS spec: AssemN member sizes add up to its size x 8",
    "connection-size": "EDS spec: ConnectionN sizes are those of the formats it names",
    "connection-format": "EDS spec: ConnectionN fields 1 and 2 (their bits); real-time format 5 is the "
                         "CIP Safety format, accepted on safety connections as certified safety files carry it",
    "connection-path": "EDS spec: ConnectionN field 15, the connection points",
    "assembly-member": "EDS spec: members are parameters or other assemblies; an assembly naming itself is read "
                       "as its own data (an idiom of drive files), a loop through others has no size",
    "class-code": "CIP Vol. 1: the class codes of the object class sections",
    "keyword-case": "EDS spec: keywords are case sensitive; configuration tools and eds-pie read them in any "
                    "case: warning",
    "encoding": "EDS spec: text is ASCII/ISO 8859-1; a UTF-8 file shows its non-ASCII text garbled in a "
                "Latin-1 tool: noted (info)",
    "device-identity": "EDS spec: [Device] equals Identity attributes 1-4 and 7",
    "live-parameter": "EDS spec: ParamN field 3 is the path of the attribute it mirrors, fields 5, 6, 10, 11 its "
                      "type, size and range ; read with Get_Attribute_Single",
    "live-assembly": "CIP Vol. 1 Assembly object: attribute 4 is the instance's size (attribute 3's length)",
    "live-connection": "CIP Vol. 1 Connection Manager: the Forward_Open's status and extended status",
    "live-refused": "CIP Vol. 1 general status (0x08 service not supported, ...): the device's choice, noted",
}

ERROR = "error"
WARNING = "warning"
#: Noted, not wrong: neither fails a check nor counts as a warning (``--strict`` included).
INFO = "info"


@dataclass(frozen=True)
class Finding:
    rule: str
    severity: str
    line: int
    message: str

    def to_dict(self) -> dict[str, Any]:
        return {"rule": self.rule, "severity": self.severity, "line": self.line, "message": self.message}


#: CIP types an EDS may name beyond the elementary ones the stack encodes: code -> (name, size).
_MORE_TYPES: dict[int, tuple[str, int | None]] = {
    0xCC: ("STIME", 4),
    0xCD: ("DATE", 2),
    0xCE: ("TIME_OF_DAY", 4),
    0xCF: ("DATE_AND_TIME", 6),
    0xD5: ("STRING2", None),
    0xD6: ("FTIME", 4),
    0xD7: ("LTIME", 8),
    0xD8: ("ITIME", 2),
    0xD9: ("STRINGN", None),
    0xDB: ("TIME", 4),
    0xDC: ("EPATH", None),
    0xDD: ("ENGUNIT", 2),
    0xDE: ("STRINGI", None),
}


def data_type(code: int) -> tuple[str, int | None] | None:
    """Name and size in bytes (None when variable) of an EDS data type code, if known."""
    known = BY_CODE.get(code)
    if known is not None:
        return known.name, known.size
    return _MORE_TYPES.get(code)


REQUIRED_KEYWORDS: dict[str, tuple[str, ...]] = {
    "File": ("DescText", "CreateDate", "CreateTime", "Revision"),
    "Device": (
        # Catalog is optional (configuration tools accept files without it; EZ-EDS writes none).
        "VendCode", "VendName", "ProdType", "ProdTypeStr", "ProdCode", "MajRev", "MinRev", "ProdName",
    ),
    "Device Classification": ("Class1",),
}
SECTION_ORDER = (
    "File", "Device", "Device Classification", "Params", "EnumPar", "Groups", "Assembly",
    "Connection Manager", "Port", "Capacity",
)
#: Names a ``ClassN`` of [Device Classification] may give: the networks, and Safety (a CIP Safety device).
NETWORKS = ("EtherNetIP", "CompoNet", "DeviceNet", "ControlNet", "Safety")

_INT = frozenset({FieldKind.INT})
_NUMBER = frozenset({FieldKind.INT, FieldKind.FLOAT})
_STRING = frozenset({FieldKind.STRING})
_KEYWORD = frozenset({FieldKind.KEYWORD})
_EMPTY = frozenset({FieldKind.EMPTY})
_PATH = frozenset({FieldKind.EPATH, FieldKind.STRING, FieldKind.EMPTY})  # a bad string is epath-format's
_ANY = frozenset(FieldKind)

_SINGLE_VALUES: dict[str, dict[str, frozenset[FieldKind]]] = {
    "File": {"DescText": _STRING, "HomeURL": _STRING},
    "Device": {
        "VendCode": _INT, "VendName": _STRING, "ProdType": _INT, "ProdTypeStr": _STRING, "ProdCode": _INT,
        "MajRev": _INT, "MinRev": _INT, "ProdName": _STRING, "Catalog": _STRING, "Icon": _STRING,
    },
    "Capacity": {
        "MaxIOConnections": _INT, "MaxMsgConnections": _INT, "MaxCIPConnections": _INT, "ConnOverhead": _NUMBER,
    },
}
_PARAM_KINDS: tuple[frozenset[FieldKind], ...] = (
    _INT, _INT | _EMPTY, _PATH, _INT, _INT, _INT, _STRING, _STRING | _EMPTY, _STRING | _EMPTY,
    *([_NUMBER | _STRING | _EMPTY] * 3), *([_NUMBER | _EMPTY] * 4), *([_INT | _EMPTY] * 5),
    *([_STRING | _EMPTY] * 3),
)
_REFERENCE_OR_NUMBER = _INT | _KEYWORD | _EMPTY
_CONNECTION_KINDS: tuple[frozenset[FieldKind], ...] = (
    _INT, _INT, _REFERENCE_OR_NUMBER, _REFERENCE_OR_NUMBER, _KEYWORD | _EMPTY,
    _REFERENCE_OR_NUMBER, _REFERENCE_OR_NUMBER, _KEYWORD | _EMPTY, _REFERENCE_OR_NUMBER, _KEYWORD | _EMPTY,
    _REFERENCE_OR_NUMBER, _KEYWORD | _EMPTY, _STRING, _STRING | _EMPTY, _PATH,
    # CIP Safety connections (EZ-EDS 3.31): Asynchronous, Maximum Consumer Number.
    _INT | _KEYWORD | _EMPTY, _INT | _EMPTY,
)
_ASSEMBLY_HEAD_KINDS: tuple[frozenset[FieldKind], ...] = (
    _STRING, _PATH, _REFERENCE_OR_NUMBER, _INT | _EMPTY, _ANY, _ANY,
)

_PARAM = re.compile(r"Param([0-9]+)")
_ENUM = re.compile(r"Enum([0-9]+)")
_CONNECTION = re.compile(r"Connection[0-9]+")
_GROUP = re.compile(r"Group[0-9]+")
_PORT = re.compile(r"Port[0-9]+")
_TSPEC = re.compile(r"TSpec[0-9]+")
_CLASS = re.compile(r"Class[0-9]+")
_ANY_ASSEMBLY = re.compile(r"(?:Proxy|Proxied)?Assem(?:Exa)?[0-9]+")
_VENDOR_SPECIFIC = re.compile(r"[1-9][0-9]*_.*")

# ConnectionN fields 1 and 2, as the EDS specification lays out their bits.
_TRANSPORT_CLASSES = 0x0000FFFF
_TRIGGERS = 0x00070000
_LISTEN_ONLY = 1 << 24
# Real-time formats: 0 modeless, 1 zero length data, 3 heartbeat, 4 32-bit run/idle header;
# 2 is accepted as files in use carry it, 5 is CIP Safety's, 6 and 7 are reserved.
_REAL_TIME_FORMATS = frozenset({0, 1, 2, 3, 4})
#: Format 5: CIP Safety (an ODVA-certified safety I/O file carries it on its safety connections).
_SAFETY_FORMAT = 5
_HEARTBEAT_ONLY = (1, 3)
_MULTICAST_T_TO_O = 1 << 21
_INSTANCE = 1
_CONNECTION_POINT = 3


def _int(item: Field | None) -> int | None:
    return item.value if item is not None and item.kind is FieldKind.INT else None


def _number(item: Field | None) -> int | float | None:
    return item.number if item is not None else None


#: The class each object class section describes (the section names of the specification).
_SECTION_CLASSES = {
    "Identity Class": 0x01, "Message Router": 0x02, "Assembly": 0x04, "Connection Manager": 0x06,
    "Port": 0xF4, "TCP/IP Interface Class": 0xF5, "Ethernet Link Class": 0xF6,
}
#: Keywords of a fixed spelling, by their lower case.
_KNOWN_KEYWORDS = {keyword.lower(): keyword for keyword in (
    *(k for keys in REQUIRED_KEYWORDS.values() for k in keys), *(k for keys in _SINGLE_VALUES.values() for k in keys),
    "Catalog", "ModDate", "ModTime", "Revision", "Object_Name", "Object_Class_Code", "Number_Of_Static_Instances",
    "Max_Instance",
)}
_NUMBERED_PREFIXES = {prefix.lower(): prefix for prefix in (
    "Param", "Enum", "Assem", "AssemExa", "ProxyAssem", "ProxiedAssem", "Connection", "Group", "Port", "TSpec",
    "Class",
)}
_NUMBERED = re.compile(r"([a-z]+)([0-9]+)", re.IGNORECASE)


def _numbered_keyword(keyword: str) -> str | None:
    """``param12`` -> ``Param12`` (the spelling of a numbered keyword), or None."""
    match = _NUMBERED.fullmatch(keyword)
    prefix = None if match is None else _NUMBERED_PREFIXES.get(match[1].lower())
    return None if prefix is None or match is None else prefix + match[2]


def canonical_keyword(keyword: str) -> str:
    """A keyword in the specification's spelling (``Object_Class_code`` -> ``Object_Class_Code``,
    ``param3`` -> ``Param3``); configuration tools read keywords in any case, and so does the checker
    (it warns of the case once, under ``keyword-case``)."""
    return _KNOWN_KEYWORDS.get(keyword.lower()) or _numbered_keyword(keyword) or keyword


def _reference(item: Field | None) -> str | None:
    return canonical_keyword(item.value) if item is not None and item.kind is FieldKind.KEYWORD else None


def _get(section: Section, keyword: str) -> Entry | None:
    """The entry of ``keyword`` in any case (the first one)."""
    return next((entry for entry in section.entries if canonical_keyword(entry.keyword) == keyword), None)


class _Checker:
    def __init__(self, doc: EdsDocument, identity: Mapping[str, Any] | None) -> None:
        self.doc = doc
        self.identity = identity
        self.findings: list[Finding] = []
        self.params: dict[str, Entry] = {}
        self.enums: dict[str, Entry] = {}
        self.assemblies: dict[str, Entry] = {}
        params = doc.get("Params")
        for entry in params.entries if params else ():
            keyword = canonical_keyword(entry.keyword)
            if _PARAM.fullmatch(keyword):
                self.params.setdefault(keyword, entry)
            elif _ENUM.fullmatch(keyword):
                self.enums.setdefault(keyword, entry)
        assembly = doc.get("Assembly")
        for entry in assembly.entries if assembly else ():
            self.assemblies.setdefault(canonical_keyword(entry.keyword), entry)
        # The sizes of assemblies written with an empty size, from their members (interpret's reading).
        from .interpret import assembly_sizes
        self.summed_sizes = assembly_sizes(doc)

    def report(self, rule: str, line: int, message: str, severity: str = ERROR) -> None:
        self.findings.append(Finding(rule, severity, line, message))

    def run(self) -> list[Finding]:
        for line, what in self.doc.reader_notes:
            self.report("unquoted-value", line, what, WARNING)
        self.check_encoding()
        self.check_sections()
        per_section: dict[str, Callable[[Section], None]] = {
            "File": self.check_file,
            "Device": self.check_device,
            "Device Classification": self.check_classification,
            "Params": self.check_params,
            "Groups": self.check_groups,
            "Assembly": self.check_assemblies,
            "Connection Manager": self.check_connections,
            "Port": self.check_ports,
            "Capacity": self.check_capacity,
        }
        seen: set[str] = set()
        for section in self.doc.sections:
            self.check_duplicate_keywords(section)
            self.check_class_code(section)
            self.check_keyword_case(section)
            if section.name in per_section and section.name not in seen:
                per_section[section.name](section)
            seen.add(section.name)
        if self.identity is not None:
            self.check_identity(self.identity)
        return sorted(self.findings, key=lambda finding: finding.line)

    # -- document structure -----------------------------------------------------------------

    def check_sections(self) -> None:
        names = [section.name for section in self.doc.sections]
        for position, section in enumerate(self.doc.sections):
            if names.index(section.name) != position:
                self.report("duplicate-section", section.line, f"section [{section.name}] appears again")
        required = ["File", "Device"]
        # DeviceNet files describe their network in [IO_Info] and often have no classification.
        if "IO_Info" not in names:
            required.append("Device Classification")
        for name in required:
            if name not in names:
                self.report("required-section", 0, f"section [{name}] is missing")
        for name, keywords in REQUIRED_KEYWORDS.items():
            found = self.doc.get(name)
            if found is None:
                continue
            for keyword in keywords:
                if _get(found, keyword) is None:
                    self.report("required-keyword", found.line, f"[{name}] lacks {keyword}")
        self.check_order()

    def check_order(self) -> None:
        public = [section for section in self.doc.sections if section.name in SECTION_ORDER]
        if self.doc.sections and "File" in self.doc and self.doc.sections[0].name != "File":
            first = self.doc.sections[0]
            self.report("section-order", first.line, f"[File] must be the first section, not [{first.name}]", WARNING)
        latest: Section | None = None
        for section in public:
            if latest is not None and SECTION_ORDER.index(section.name) < SECTION_ORDER.index(latest.name):
                self.report(
                    "section-order", section.line, f"[{section.name}] belongs before [{latest.name}]", WARNING
                )
            elif latest is None or SECTION_ORDER.index(section.name) > SECTION_ORDER.index(latest.name):
                latest = section

    def check_encoding(self) -> None:
        """A file whose non-ASCII bytes are UTF-8 is noted: the reader (like the Latin-1 tools) reads
        each of its bytes as one character, so "Ü" reads as two."""
        source = self.doc.source
        text = source.text if source is not None else ""
        if text.isascii():
            return
        try:
            decoded = text.encode("latin-1").decode("utf-8")
        except (UnicodeEncodeError, UnicodeDecodeError):
            return  # Latin-1 (or already Unicode): read as written
        first = next(index for index, char in enumerate(text) if not char.isascii())
        line = text.count("\n", 0, first) + 1
        sample = next((word for word in re.findall(r"[^\s\"',;=$()]+", decoded) if not word.isascii()), "")
        self.report("encoding", line, f"the file is UTF-8 ({sample!r} on this line reads as "
                                      f"{sample.encode('utf-8').decode('latin-1')!r} in a Latin-1 tool)", INFO)

    def check_class_code(self, section: Section) -> None:
        """``Object_Class_Code`` of an object class section is the class the section is for."""
        expected = _SECTION_CLASSES.get(section.name)
        entry = _get(section, "Object_Class_Code")
        if expected is None or entry is None:
            return
        code = _int(entry.field(1))
        if code is not None and code != expected:
            self.report("class-code", entry.line,
                        f"[{section.name}] Object_Class_Code is 0x{code:02X}; the section is class 0x{expected:02X}")

    def check_keyword_case(self, section: Section) -> None:
        for entry in section.entries:
            known = canonical_keyword(entry.keyword)
            if known != entry.keyword:
                self.report("keyword-case", entry.line, f"[{section.name}] {entry.keyword} is written {known} "
                                                        "(read as such)", WARNING)

    def check_duplicate_keywords(self, section: Section) -> None:
        seen: set[str] = set()
        for entry in section.entries:
            keyword = canonical_keyword(entry.keyword)
            if keyword in seen:
                self.report("duplicate-keyword", entry.line, f"[{section.name}] has {keyword} more than once")
            seen.add(keyword)

    # -- helpers ----------------------------------------------------------------------------

    def check_kinds(self, entry: Entry, kinds: Iterable[frozenset[FieldKind]], first: int = 1) -> None:
        for number, allowed in enumerate(kinds, start=first):
            item = entry.field(number)
            if item is not None and item.kind not in allowed:
                expected = " or ".join(sorted(kind.value for kind in allowed if kind is not FieldKind.EMPTY))
                empty = " (or empty)" if FieldKind.EMPTY in allowed else ""
                self.report(
                    "field-type", item.line or entry.line,
                    f"{entry.keyword} field {number} is {item.kind.value} {item.raw!r}; expected {expected}{empty}",
                )

    def check_count(self, entry: Entry, counts: Iterable[int], what: str) -> bool:
        counts = tuple(counts)
        if len(entry.fields) in counts:
            return True
        expected = " or ".join(str(count) for count in counts)
        self.report("field-count", entry.line, f"{entry.keyword} has {len(entry.fields)} fields; {what} has {expected}")
        return False

    def check_at_least(self, entry: Entry, count: int, what: str) -> bool:
        if len(entry.fields) >= count:
            return True
        self.report(
            "field-count", entry.line, f"{entry.keyword} has {len(entry.fields)} fields; {what} has {count} or more"
        )
        return False

    def check_single_values(self, section: Section) -> None:
        kinds = _SINGLE_VALUES.get(section.name, {})
        for entry in section.entries:
            keyword = canonical_keyword(entry.keyword)
            if keyword in kinds:
                self.check_count(entry, (1,), "this keyword")
                self.check_kinds(entry, [kinds[keyword]])

    def check_path(self, entry: Entry, number: int, required: bool = False) -> None:
        item = entry.field(number)
        if item is None:
            return
        if item.kind is FieldKind.STRING:
            self.report("epath-format", item.line, f"{entry.keyword} field {number} is not an EPATH: {item.raw}")
        elif item.kind is FieldKind.EPATH:
            if required and not item.value:
                self.report("epath-format", item.line, f"{entry.keyword} field {number}: the path is empty")
            for reference in (part for part in item.value if isinstance(part, str)):
                self.check_param_reference(entry, item, reference)
        elif required and item.kind is FieldKind.EMPTY:
            self.report("epath-format", item.line, f"{entry.keyword} field {number}: the path is empty")

    def check_param_reference(self, entry: Entry, item: Field, reference: str) -> None:
        if not _PARAM.fullmatch(reference):
            self.report("param-reference", item.line, f"{entry.keyword}: {reference!r} is not a ParamN reference")
        elif reference not in self.params:
            self.report("param-reference", item.line, f"{entry.keyword} refers to {reference}, which [Params] lacks")

    def check_assembly_reference(self, entry: Entry, item: Field, reference: str) -> None:
        if not _ANY_ASSEMBLY.fullmatch(reference):
            self.report("assembly-reference", item.line, f"{entry.keyword}: {reference!r} is not an AssemN reference")
        elif reference not in self.assemblies:
            self.report(
                "assembly-reference", item.line, f"{entry.keyword} refers to {reference}, which [Assembly] lacks"
            )

    def check_member_reference(self, entry: Entry, item: Field) -> None:
        reference = _reference(item)
        if reference is None:
            return
        if _PARAM.fullmatch(reference):
            self.check_param_reference(entry, item, reference)
        elif _ANY_ASSEMBLY.fullmatch(reference):
            self.check_assembly_reference(entry, item, reference)
        else:
            self.report("param-reference", item.line, f"{entry.keyword}: {reference!r} is neither ParamN nor AssemN")

    # -- [File], [Device], [Device Classification] -------------------------------------------

    def check_file(self, section: Section) -> None:
        self.check_single_values(section)
        for entry in section.entries:
            keyword = canonical_keyword(entry.keyword)
            if keyword in ("CreateDate", "ModDate"):
                self.check_count(entry, (1,), "this keyword")
                self.check_date(entry)
            elif keyword in ("CreateTime", "ModTime"):
                self.check_count(entry, (1,), "this keyword")
                self.check_time(entry)
            elif keyword == "Revision":
                self.check_count(entry, (1,), "this keyword")
                item = entry.fields[0]
                if item.kind is not FieldKind.REVISION or not 1 <= item.value[0] <= 255 or item.value[1] > 255:
                    self.report("revision-format", item.line, f"Revision {item.raw} is not major.minor")

    def check_date(self, entry: Entry) -> None:
        item = entry.fields[0]
        valid = item.kind is FieldKind.DATE and re.fullmatch(r"[0-9]{2}-[0-9]{2}-[0-9]{4}", item.raw)
        if valid:
            month, day, year = item.value
            try:
                datetime.date(year, month, day)
            except ValueError:
                valid = None
        if not valid:
            self.report("date-format", item.line, f"{entry.keyword} {item.raw} is not a date written mm-dd-yyyy")

    def check_time(self, entry: Entry) -> None:
        item = entry.fields[0]
        valid = item.kind is FieldKind.TIME and re.fullmatch(r"[0-9]{2}:[0-9]{2}:[0-9]{2}", item.raw)
        if valid:
            hour, minute, second = item.value
            valid = hour < 24 and minute < 60 and second < 60
        if not valid:
            self.report("time-format", item.line, f"{entry.keyword} {item.raw} is not a time written hh:mm:ss")

    def check_device(self, section: Section) -> None:
        self.check_single_values(section)

    def check_classification(self, section: Section) -> None:
        for entry in section.entries:
            if not _CLASS.fullmatch(canonical_keyword(entry.keyword)):
                continue
            self.check_kinds(entry, [_KEYWORD])
            value = _reference(entry.field(1))
            if value is not None and value not in NETWORKS and not _VENDOR_SPECIFIC.fullmatch(value):
                self.report(
                    "device-classification", entry.line,
                    f"{entry.keyword} = {value} names no known network ({', '.join(NETWORKS)})", WARNING,
                )

    def check_identity(self, identity: Mapping[str, Any]) -> None:
        device = self.doc.get("Device")
        if device is None:
            return
        revision = identity.get("revision")
        if isinstance(revision, Mapping):
            revision = (revision.get("major"), revision.get("minor"))
        major, minor = revision if isinstance(revision, (tuple, list)) and len(revision) == 2 else (None, None)
        expected: dict[str, Any] = {
            "VendCode": identity.get("vendor_id"),
            "ProdType": identity.get("device_type"),
            "ProdCode": identity.get("product_code"),
            "MajRev": major,
            "MinRev": minor,
            "ProdName": identity.get("product_name"),
        }
        for keyword, value in expected.items():
            entry = device.get(keyword)
            if value is None or entry is None:
                continue
            if entry.value(1) != value:
                self.report(
                    "device-identity", entry.line_of(1),
                    f"{keyword} is {entry.fields[0].raw} but the device reports {value!r}",
                )

    # -- [Params] -----------------------------------------------------------------------------

    def check_params(self, section: Section) -> None:
        for entry in section.entries:
            if _PARAM.fullmatch(canonical_keyword(entry.keyword)):
                self.check_param(entry)
            elif match := _ENUM.fullmatch(canonical_keyword(entry.keyword)):
                self.check_enum(entry, f"Param{match[1]}")

    def check_param(self, entry: Entry) -> None:
        if not self.check_count(entry, (21, 24), "a parameter"):
            return
        self.check_kinds(entry, _PARAM_KINDS)
        self.check_path(entry, 3)
        path, size_field = entry.field(3), _int(entry.field(2))
        if (
            path is not None and path.kind is FieldKind.EPATH and size_field is not None
            and all(isinstance(part, int) for part in path.value) and size_field != len(path.value)
        ):
            self.report(
                "epath-format", entry.line_of(2),
                f"{entry.keyword} link path size is {size_field} but the path has {len(path.value)} bytes",
            )
        descriptor = _int(entry.field(4))
        number = entry.keyword[len("Param"):]
        if descriptor is not None and descriptor & 0x02 and f"Enum{number}" not in self.enums:
            self.report(
                "enum-reference", entry.line_of(4),
                f"{entry.keyword} has enumerated strings (descriptor bit 1) but no Enum{number}", WARNING,
            )
        code = _int(entry.field(5))
        if code is None:
            return
        known = data_type(code)
        if known is None:
            self.report("data-type", entry.line_of(5), f"{entry.keyword} data type 0x{code:02X} is not a CIP type")
            return
        name, size = known
        declared = _int(entry.field(6))
        if size is not None and declared is not None and declared != size:
            self.report(
                "data-size", entry.line_of(6), f"{entry.keyword} is a {name} of {size} bytes, not {declared}"
            )
        self.check_limits(entry, code)

    def check_limits(self, entry: Entry, code: int) -> None:
        minimum, maximum, default = (_number(entry.field(number)) for number in (10, 11, 12))
        cip_type = BY_CODE.get(code)
        low, high = getattr(cip_type, "minimum", None), getattr(cip_type, "maximum", None)
        if low is not None and high is not None:
            for number, value in ((10, minimum), (11, maximum), (12, default)):
                if value is not None and not low <= value <= high:
                    self.report(
                        "value-range", entry.line_of(number),
                        f"{entry.keyword} field {number} ({value}) is outside {cip_type} range {low}..{high}", WARNING,
                    )
        if minimum is not None and maximum is not None and minimum > maximum:
            self.report("min-default-max", entry.line_of(10), f"{entry.keyword} minimum {minimum} > maximum {maximum}")
        elif minimum is not None and maximum is not None and default is not None and not minimum <= default <= maximum:
            self.report(
                "min-default-max", entry.line_of(12),
                f"{entry.keyword} default {default} is outside {minimum}..{maximum}",
            )

    def check_enum(self, entry: Entry, param: str) -> None:
        if param not in self.params:
            self.report("enum-reference", entry.line, f"{entry.keyword} has no {param}")
        if len(entry.fields) % 2:
            self.report(
                "field-count", entry.line, f"{entry.keyword} has {len(entry.fields)} fields, not value/name pairs"
            )
            return
        self.check_kinds(entry, [_INT, _STRING] * (len(entry.fields) // 2))

    # -- [Groups] -----------------------------------------------------------------------------

    def check_groups(self, section: Section) -> None:
        for entry in section.entries:
            if not _GROUP.fullmatch(canonical_keyword(entry.keyword)) or not self.check_at_least(entry, 2, "a group"):
                continue
            self.check_kinds(entry, [_STRING, _INT] + [_INT] * (len(entry.fields) - 2))
            count = _int(entry.field(2))
            members = entry.fields[2:]
            if count is not None and count != len(members):
                self.report(
                    "field-count", entry.line_of(2), f"{entry.keyword} says {count} members but lists {len(members)}"
                )
            for item in members:
                if item.kind is FieldKind.INT:
                    self.check_param_reference(entry, item, f"Param{item.value}")

    # -- [Assembly] ---------------------------------------------------------------------------

    def check_assemblies(self, section: Section) -> None:
        for entry in section.entries:
            if not _ANY_ASSEMBLY.fullmatch(canonical_keyword(entry.keyword)):
                continue
            count = len(entry.fields)
            if count < 6 or count % 2:
                self.report(
                    "field-count", entry.line,
                    f"{entry.keyword} has {count} fields; an assembly has 6, then member size/reference pairs",
                )
                continue
            self.check_kinds(entry, _ASSEMBLY_HEAD_KINDS)
            self.check_kinds(entry, [_INT | _EMPTY, _KEYWORD | _EMPTY] * ((count - 6) // 2), first=7)
            self.check_path(entry, 2)
            size_item = entry.field(3)
            if size_item is not None and _reference(size_item) is not None:
                self.check_param_reference(entry, size_item, size_item.value)
            keyword = canonical_keyword(entry.keyword)
            for item in entry.fields[7::2]:
                if _reference(item) == keyword:
                    continue  # the idiom "its own data": see member_bits
                self.check_member_reference(entry, item)
            self.check_assembly_size(entry)
            loop = self.assembly_loop(keyword)
            if loop:
                self.report("assembly-member", entry.line,
                            f"{keyword} contains itself through {' -> '.join(loop)}: it has no size")

    def assembly_loop(self, keyword: str) -> list[str]:
        """The chain of other assemblies through which ``keyword`` is a member of itself, or [].
        A member naming its own assembly directly is no loop: drive files write every assembly
        as one member that names the assembly itself, meaning "this instance's data"."""
        def members(name: str) -> list[str]:
            entry = self.assemblies.get(name)
            found = [] if entry is None else [_reference(item) for item in entry.fields[7::2]]
            return [m for m in found if m is not None and m != name and m in self.assemblies]

        chain: list[str] = []
        seen: set[str] = set()

        def walk(name: str) -> bool:
            for member in members(name):
                if member == keyword:
                    return True
                if member in seen:
                    continue
                seen.add(member)
                chain.append(member)
                if walk(member):
                    return True
                chain.pop()
            return False

        return [*chain, keyword] if walk(keyword) else []

    def member_bits(self, size: Field, member: Field, owner: str = "") -> int | None:
        """A member's size in bits: as written, or else the size of what it refers to (a member
        naming its own assembly, empty-sized, is the assembly's whole data)."""
        if size.kind is FieldKind.INT:
            return _int(size)
        reference = _reference(member)
        if size.kind is not FieldKind.EMPTY or reference is None:
            return None
        if reference == owner:
            assembly_size = _int(self.assemblies[owner].field(3)) if owner in self.assemblies else None
            return None if assembly_size is None else assembly_size * 8
        if reference in self.params:
            data_size = _int(self.params[reference].field(6))
            return None if data_size is None else data_size * 8
        if reference in self.assemblies:
            assembly_size = _int(self.assemblies[reference].field(3))
            return None if assembly_size is None else assembly_size * 8
        return None

    def check_assembly_size(self, entry: Entry) -> None:
        size = _int(entry.field(3))
        pairs = list(zip(entry.fields[6::2], entry.fields[7::2], strict=True))
        if size is None or not pairs:
            return
        bits = [self.member_bits(size_item, member, canonical_keyword(entry.keyword)) for size_item, member in pairs]
        if None in bits:
            return
        total = sum(bit for bit in bits if bit is not None)
        if total != size * 8:
            self.report(
                "assembly-size", entry.line_of(3),
                f"{entry.keyword} is {size} bytes ({size * 8} bits) but its members add up to {total} bits",
            )

    # -- [Connection Manager] -------------------------------------------------------------------

    def check_connections(self, section: Section) -> None:
        for entry in section.entries:
            if not _CONNECTION.fullmatch(canonical_keyword(entry.keyword)) or not self.check_count(
                    entry, (15, 17), "a connection (17 with the CIP Safety fields)"):
                continue
            self.check_kinds(entry, _CONNECTION_KINDS)
            self.check_path(entry, 15, required=True)
            for number in (3, 4, 6, 7, 9, 11):
                item = entry.field(number)
                if item is not None and _reference(item) is not None:
                    self.check_param_reference(entry, item, item.value)
            for number in (5, 8, 10, 12):
                item = entry.field(number)
                reference = _reference(item)
                if item is None or reference is None:
                    continue
                if number == 12 and _PARAM.fullmatch(reference):
                    # The configuration format may be a parameter rather than an assembly.
                    self.check_param_reference(entry, item, reference)
                else:
                    self.check_assembly_reference(entry, item, reference)
            self.check_connection_sizes(entry)
            self.check_connection_words(entry)
            self.check_connection_points(entry)

    def check_connection_sizes(self, entry: Entry) -> None:
        for size_number, format_number, direction in ((4, 5, "O->T"), (7, 8, "T->O"), (11, 12, "configuration")):
            size = _int(entry.field(size_number))
            assembly = self.assemblies.get(_reference(entry.field(format_number)) or "")
            if size is None or assembly is None:
                continue
            assembly_size = _int(assembly.field(3))
            size_field = assembly.field(3)
            if assembly_size is None and size_field is not None and size_field.kind is FieldKind.EMPTY:
                # An empty size: the sum of the members (eds-pie: AssemExaN's size may be empty).
                assembly_size = self.summed_sizes.get(canonical_keyword(assembly.keyword))
            parameters = _int(entry.field(2))
            variable_bit = {4: 1 << 1, 7: 1 << 3}.get(size_number, 0)
            if parameters is not None and parameters & variable_bit and assembly_size is not None \
                    and size <= assembly_size:
                continue  # a variable-size connection carries up to its assembly's size
            if assembly_size is not None and assembly_size != size:
                self.report(
                    "connection-size", entry.line_of(size_number),
                    f"{entry.keyword} {direction} size is {size} but {assembly.keyword} is {assembly_size} bytes",
                )

    def check_connection_words(self, entry: Entry) -> None:
        trigger, parameters = _int(entry.field(1)), _int(entry.field(2))
        problems: list[tuple[int, str]] = []
        warnings: list[tuple[int, str]] = []
        if trigger is not None:
            if not trigger & _TRANSPORT_CLASSES:
                problems.append((1, "trigger and transport (field 1) names no transport class (bits 0-15)"))
            if not trigger & _TRIGGERS:
                problems.append((1, "trigger and transport (field 1) names no trigger (bits 16-18)"))
        if parameters is not None:
            for shift, direction in ((0, "O->T"), (2, "T->O")):
                if not (parameters >> shift) & 0x3:
                    problems.append((2, f"{direction} is neither fixed nor variable size"))
            for shift, direction in ((8, "O->T"), (12, "T->O")):
                real_time = (parameters >> shift) & 0x7
                if real_time == _SAFETY_FORMAT and not self.is_safety(entry):
                    warnings.append((2, f"{direction} real-time format 5 is the CIP Safety format, but neither the "
                                        "connection (17 fields) nor [Device Classification] (Safety) is safety"))
                elif real_time not in _REAL_TIME_FORMATS and real_time != _SAFETY_FORMAT:
                    problems.append((2, f"{direction} real-time format {real_time} is reserved"))
            for shift, what in ((16, "O->T connection type"), (20, "T->O connection type"),
                                (24, "O->T priority"), (28, "T->O priority")):
                if not (parameters >> shift) & 0xF:
                    problems.append((2, f"{what} (bits {shift}-{shift + 3}) is not set"))
            o_to_t_size = _int(entry.field(4))
            if (parameters >> 8) & 0x7 in _HEARTBEAT_ONLY and o_to_t_size:
                problems.append((4, f"O->T carries no data (real-time format heartbeat) but its size is {o_to_t_size}"))
            if trigger is not None and trigger & _LISTEN_ONLY and not parameters & _MULTICAST_T_TO_O:
                problems.append((2, "a listen-only connection needs a multicast T->O connection"))
        for number, problem in problems:
            self.report("connection-format", entry.line_of(number), f"{entry.keyword}: {problem}")
        for number, problem in warnings:
            self.report("connection-format", entry.line_of(number), f"{entry.keyword}: {problem}", WARNING)

    def is_safety(self, entry: Entry) -> bool:
        """A CIP Safety connection: written with the two safety fields (EZ-EDS), or of a device
        [Device Classification] says is a Safety device."""
        classification = self.doc.get("Device Classification")
        classes = [_reference(e.field(1)) for e in classification.entries] if classification else []
        return len(entry.fields) == 17 or "Safety" in classes

    def check_connection_points(self, entry: Entry) -> None:
        path = entry.field(15)
        if path is None or path.kind is not FieldKind.EPATH:
            return
        points = _logical_values(path.value, _CONNECTION_POINT)
        if not points and _logical_values(path.value, _INSTANCE):
            # 20 04 24 97 24 64: instances only; a target cannot tell where data goes.
            self.report("connection-path", path.line,
                        f"{entry.keyword} path names no connection point (a 2C segment): nothing says where its "
                        "data goes")
        for index, (format_number, direction) in enumerate(((5, "O->T"), (8, "T->O"))):
            assembly = self.assemblies.get(_reference(entry.field(format_number)) or "")
            if assembly is None or index >= len(points):
                continue
            assembly_path = assembly.field(2)
            if assembly_path is None or assembly_path.kind is not FieldKind.EPATH:
                continue
            instances = _logical_values(assembly_path.value, _INSTANCE)
            if instances and points[index] is not None and instances[0] != points[index]:
                self.report(
                    "connection-path", path.line,
                    f"{entry.keyword} {direction} connection point is {points[index]} but {assembly.keyword} "
                    f"is instance {instances[0]}",
                    WARNING,
                )

    # -- [Port], [Capacity] -------------------------------------------------------------------

    def check_ports(self, section: Section) -> None:
        for entry in section.entries:
            if _PORT.fullmatch(canonical_keyword(entry.keyword)) and self.check_at_least(entry, 4, "a port"):
                self.check_kinds(entry, [_KEYWORD | _INT, _STRING, _PATH, _INT])
                self.check_path(entry, 3)

    def check_capacity(self, section: Section) -> None:
        self.check_single_values(section)
        for entry in section.entries:
            if _TSPEC.fullmatch(canonical_keyword(entry.keyword)) and self.check_count(entry, (3,), "a TSpec"):
                self.check_kinds(entry, [_KEYWORD, _INT, _INT])


def _logical_values(items: tuple[int | str, ...], logical_type: int) -> list[int | None]:
    """Values of the logical segments of one type (1 instance, 3 connection point) at the
    start of an EPATH, in order; None where a parameter reference stands for the value."""
    values: list[int | None] = []
    index = 0
    while index < len(items):
        head = items[index]
        if not isinstance(head, int) or head & 0xE0 != 0x20 or head & 0x03 == 0x03:
            break  # not a logical segment: the part this check reads is over
        width = (1, 2, 4)[head & 0x03]
        start = index + 1 if width == 1 else index + 2  # wider values follow a pad byte
        value_items = items[start : start + width]
        if len(value_items) < width:
            break
        if (head >> 2) & 0x07 == logical_type:
            numbers = [item for item in value_items if isinstance(item, int)]
            values.append(int.from_bytes(bytes(numbers), "little") if len(numbers) == width else None)
        index = start + width
    return values


def check_eds(doc: EdsDocument, identity: Mapping[str, Any] | None = None) -> list[Finding]:
    """Every rule finding on ``doc``, in line order. ``identity`` holds what a live device's
    Identity object reports (vendor_id, device_type, product_code, revision (major, minor),
    product_name); [Device] must agree with it."""
    return _Checker(doc, identity).run()
