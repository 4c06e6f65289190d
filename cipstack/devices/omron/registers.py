"""MX2 and RX registers, function codes and trip codes, declared once.

The option board is a gateway onto the inverter's Modbus registers: the Modbus Register
object (class 0x64) addresses them by Modbus address, the Function Code object (class 0x65)
by keypad function code (Table E-3), and the flexible format (appendix F) maps them into the
I/O data word by word. Every register the manual uses is declared once in ``PARAMETERS``;
``register_set(family)`` turns the rows of one family into the ``Register`` objects of
``cipstack.devices.registers`` (for the Modbus view) plus lookups by function code.

Where the manual gives a Modbus address it is used for both families (Tables 18-21, E-3,
appendix F). The manual sends the reader to the inverter manuals for the others: MX2
addresses below come from the MX2 User's Manual (I570) section B-4-2; the RX register list
(I560 section 4-4) is not at hand, so RX parameters outside this manual have no Modbus
address here and are reachable by function code only.

MX2/RX differences are data, not code paths: rows carry the families they exist on (two
rows when the families differ), and ``FamilyTraits`` holds the values the option board
behaviour depends on (source selection values, terminal counts, option trip codes, speed
scaling).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from types import MappingProxyType
from typing import Any

from ...cip.types import DINT, INT, UDINT
from ...errors import BadRequest, UnknownKey
from ..registers import Register, RegisterAccess, RegisterError, RegisterMap, RegisterRefusal
from .models import Family

R = RegisterAccess.READ
RW = RegisterAccess.READ_WRITE
#: Not run-mode editable: "x" in the MX2 "Run Mode Edit" column (I570 section 3), "No" in the
#: RX "Change during operation" column (I560 appendix 1); appendix F forbids mapping these as outputs.
STOPPED = RegisterAccess.WRITE_STOPPED
W = RegisterAccess.WRITE

MX2 = (Family.MX2,)
RX = (Family.RX,)
BOTH = (Family.MX2, Family.RX)


# -- function codes (Table E-3) ------------------------------------------------------------------

#: Decimal base of each function group: its "sequence number (A = 0, B = 1, etc) * 1000" (Table E-3).
#: Table E-3 prints the b range as "1000 - 1999"; by its own rule and its hex column (03E9h) it
#: starts at 1001, like every other group.
FUNCTION_GROUPS: Mapping[str, int] = MappingProxyType(
    {"A": 0, "b": 1000, "C": 2000, "d": 3000, "F": 5000, "H": 7000, "P": 15000, "U": 20000})
_GROUP_BY_BASE = {base: group for group, base in FUNCTION_GROUPS.items()}


def _split_code(code: str) -> tuple[str, int]:
    text = code.strip()
    if len(text) != 4 or not text[1:].isdigit():
        raise BadRequest(f"not a function code: {code!r} (expected a group letter and three digits, e.g. P044)")
    letter = text[0].upper()
    group = next((g for g in FUNCTION_GROUPS if g.upper() == letter), None)
    number = int(text[1:])
    if group is None or not 1 <= number <= 999:
        raise BadRequest(f"not a function code of Table E-3: {code!r}")
    return group, number


def normalize_code(code: str) -> str:
    """The manual's spelling of a function code: "p044" -> "P044", "B049" -> "b049"."""
    group, number = _split_code(code)
    return f"{group}{number:03d}"


def function_code_number(code: str) -> int:
    """Table E-3: group base + code number, e.g. d005 -> 3005, P060 -> 15060."""
    group, number = _split_code(code)
    return FUNCTION_GROUPS[group] + number


def function_code_path(code: str) -> tuple[int, int]:
    """Instance (high byte) and attribute (low byte) of ``code`` in class 0x65 (Table E-3):
    d005 -> (0x0B, 0xBD), P060 -> (0x3A, 0xD4)."""
    number = function_code_number(code)
    return number >> 8, number & 0xFF


def function_code_from_number(number: int) -> str:
    """Inverse of ``function_code_number``; ``ValueError`` for numbers outside Table E-3."""
    base, code = divmod(number, 1000)
    group = _GROUP_BY_BASE.get(base * 1000)
    if group is None or code == 0:
        raise BadRequest(f"{number} is not a function code number of Table E-3")
    return f"{group}{code:03d}"


def function_code_from_path(instance: int, attribute: int) -> str:
    """The function code a class 0x65 instance/attribute pair addresses."""
    if not (0 <= instance <= 0xFF and 0 <= attribute <= 0xFF):
        raise BadRequest("instance and attribute are one byte each")
    return function_code_from_number(instance << 8 | attribute)


def modbus_path(address: int) -> tuple[int, int]:
    """Instance and attribute of Modbus address XXYYh in class 0x64: (XX, YY) (section E-3-2)."""
    if not 0 <= address <= 0xFFFF:
        raise BadRequest(f"Modbus address out of range: {address}")
    return address >> 8, address & 0xFF


def modbus_address(instance: int, attribute: int) -> int:
    if not (0 <= instance <= 0xFF and 0 <= attribute <= 0xFF):
        raise BadRequest("instance and attribute are one byte each")
    return instance << 8 | attribute


# -- declarations -------------------------------------------------------------------------------

@dataclass(frozen=True)
class Bit:
    """One bit of a bit-field register (the coil data words of Tables 18-21)."""

    index: int
    name: str
    description: str
    #: Modbus coil number of the bit (coil data 0 holds coils 0000h-000Fh, coil data 1 0010h-001Fh).
    coil: int
    writable: bool = True


@dataclass(frozen=True, eq=False)
class Parameter(Register):
    """One inverter register as the manual describes it (the row of the table below): a ``Register``
    (``address`` is None where no Modbus address is known for the family; ``code`` the function
    code as the manual spells it, "P044", "b049", or empty for Modbus-only registers) with what the
    option board adds. Build rows with ``parameter()``. Compared and hashed by identity."""

    families: tuple[Family, ...] = BOTH
    #: Unavailable unless the inverter is in constant-torque induction-motor mode, d060 = 0 (Tables 22/23).
    torque_related: bool = False
    #: "F001 can not be written using the Function code object" (section E-2-2).
    function_code_writable: bool = True
    #: Words the Function Code object carries when they differ from the Modbus register's (section E-2-2:
    #: "B127 has a data size of 2 words (different from the Modbus register size of 1 word)"); 0: ``words``.
    function_code_words: int = 0
    bits: tuple[Bit, ...] = ()

    __eq__ = object.__eq__
    __hash__ = object.__hash__

    @property
    def key(self) -> str:
        """Unique name within a family: the function code, or the Modbus address for the others."""
        return self.code or f"{self.address:04X}h"

    @property
    def function_code_number(self) -> int | None:
        return function_code_number(self.code) if self.code else None

    @property
    def writable_bits(self) -> int:
        """Mask of the bits a write may set (all bits for a register without a bit table)."""
        if not self.bits:
            return (1 << (16 * self.words)) - 1
        mask = 0
        for bit in self.bits:
            if bit.writable:
                mask |= 1 << bit.index
        return mask

    def check(self, value: int) -> int:
        """``value`` if the register can hold it, else ``RegisterError(OUT_OF_RANGE)``."""
        where = self.address if self.address is not None else (self.function_code_number or 0)
        if isinstance(value, bool) or not isinstance(value, int):
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, where, f"{value!r} is not an integer")
        if not self.raw_minimum <= value <= self.raw_maximum:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, where,
                                f"{self.key}: {value} not in {self.raw_minimum}..{self.raw_maximum}")
        if self.enum is not None and self.minimum is None and value not in self.enum:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, where, f"{self.key}: {value} not enumerated")
        return value

    def bit(self, name: str) -> Bit:
        for bit in self.bits:
            if bit.name == name:
                return bit
        raise UnknownKey(f"{self.key} has no bit {name!r}")

    @property
    def register(self) -> Register | None:
        """The parameter as a register of the Modbus view, or None when no address is known."""
        return self if self.address is not None else None


def parameter(code: str, name: str, address: int | None, families: tuple[Family, ...] = BOTH,
              **fields: Any) -> Parameter:
    """A row of the table: function code, name, Modbus address (None: not known for the family)."""
    return Parameter(address, code, name, families=families, **fields)  # type: ignore[arg-type]


def _enum(**names: str) -> Mapping[int, str]:
    return MappingProxyType({int(k[1:]): v for k, v in names.items()})


def _frozen(mapping: Mapping[int, str]) -> Mapping[int, str]:
    return MappingProxyType(dict(mapping))


# Lost-command actions of P045 and P048 (Table 12).
NETWORK_ACTIONS = _frozen({0: "inverter trip", 1: "deceleration and trip", 2: "no action",
                           3: "stop due to free-run", 4: "deceleration and stop"})

# Default connection path (Table 10): P046 value -> name, (output assembly, input assembly).
CONNECTION_PATHS: Mapping[int, tuple[str, int, int]] = MappingProxyType({
    0: ("Basic Speed IO", 20, 70),
    1: ("Extended Speed IO", 21, 71),
    2: ("Extended Speed and Torque Control", 123, 173),
    3: ("Special IO", 100, 150),
    4: ("Extended Control IO", 101, 151),
    5: ("Extended Control IO and Multi Function IO Monitor", 101, 153),
    6: ("Flexible Format", 139, 159),
    7: ("Extended Speed and Acceleration Control", 110, 111),
})
FLEXIBLE_FORMAT = 6
#: Paths whose output assembly carries the torque reference (Tables B-9, B-18): torque-related data
#: in the process area, which trips the inverter when torque control is not available (Tables 22/23 note).
TORQUE_PATHS = frozenset({2, 4, 5})

# Input terminal functions (C001-C008) the manual uses: FRS (section 4-2-4) and ATR (section 4-4).
# The inverters have many more; the simulation acts on these two and keeps any other number.
TERMINAL_FRS = 11
TERMINAL_ATR = 52
NO_FUNCTION = 255
# Output terminal source "Option Board" (Tables 15/16).
OUTPUT_FROM_OPTION = 63

# Inverter mode, d060 (Tables 22/23): the MX2 also has high-frequency and permanent-magnet modes.
MX2_MODES = _frozen({0: "IM constant torque (1-C)", 1: "IM variable torque (1-v)",
                     2: "high frequency (H-1)", 3: "permanent magnet (P)"})
RX_MODES = _frozen({0: "IM constant torque (1-C)", 1: "IM variable torque (1-v)"})

# Inverter status C at 0005h: Table 19 reads 1 when stopped, Table 21 reads 3 at constant speed;
# the other values are those of I570 section B-4-2 that the simulation produces.
STATUS_C = _frozen({1: "stopping", 2: "decelerating", 3: "constant-speed operation", 4: "accelerating"})

# Modbus addresses this manual gives (both families).
F001_ADDRESS = 0x0001          # Table 18: F001 at 0001h/0002h
STATUS_C_ADDRESS = 0x0005      # section 4-7-1 Step 4
EEPROM_SAVE = 0x0900           # section E-2-2 / Table C-2: ENTER, write 01h
D001_ADDRESS = 0x1001          # Table 19: d001 at 1001h/1002h
COIL_DATA_1 = 0x1E01           # Table 19: coils 0010h-001Fh
COIL_DATA_0 = 0x1F01           # Table 18: coils 0000h-000Fh

_COIL_DATA_0_COMMON = (
    Bit(1, "Opr", "Operation command", 0x01),
    Bit(2, "Dir", "Rotation direction command (1: reverse)", 0x02),
    Bit(3, "EXT", "External trip", 0x03),
    Bit(4, "RS", "Trip reset", 0x04),
    *(Bit(6 + n, f"In{n}", f"Intelligent input terminal [{n}]", 6 + n) for n in range(1, 8)),
    # Table 18 note: the operation status coil (000Fh) cannot be used in the output process area.
    Bit(15, "RUN_STATUS", "Operation status (read only)", 0x0F, writable=False),
)
# Table 18 marks In8 (bit 14) "RX only"; Table 20 prints the same mark garbled as "In8 TRQ".
_COIL_DATA_0_RX = (*_COIL_DATA_0_COMMON[:-1], Bit(14, "In8", "Intelligent input terminal [8]", 0x0E),
                   _COIL_DATA_0_COMMON[-1])

# Table 19 / Table 21 (bits 2 and 11 are unused).
_COIL_DATA_1 = tuple(Bit(index, name, description, 0x10 + index, writable=False) for index, name, description in (
    (0, "Dir", "Rotation direction (1: reverse)"),
    (1, "Rdy", "Inverter ready"),
    (3, "RUN", "Running"),
    (4, "FA1", "Constant-speed reached"),
    (5, "FA2", "Set frequency overreached"),
    (6, "OL", "Overload advance notice"),
    (7, "OD", "Output deviation for PID control"),
    (8, "AL", "Alarm signal"),
    (9, "FA3", "Set frequency reached"),
    (10, "OTQ", "Over-torque"),
    (12, "UV", "Undervoltage"),
    (13, "TRQ", "Torque limited"),
    (14, "RNT", "Operation time over"),
    (15, "ONT", "Plug-in time over"),
))

_I570 = "I570 B-4-2"
_HZ: dict[str, Any] = {"scale": 0.01, "unit": "Hz"}


def _terminal_functions(family: tuple[Family, ...], count: int, base: int | None) -> tuple[Parameter, ...]:
    # C001..C007 (MX2) / C008 (RX): the function of each intelligent input terminal. The defaults
    # are the inverters' own and not in this manual; the emulator starts with "no function".
    return tuple(
        parameter(f"C{n:03d}", f"Input terminal [{n}] function", None if base is None else base + n - 1, family,
                  access=STOPPED, default=NO_FUNCTION, minimum=0, maximum=255, group="C",
                  enum=_frozen({TERMINAL_FRS: "FRS: free-run stop", TERMINAL_ATR: "ATR: torque command input",
                                NO_FUNCTION: "no function"}),
                  source=f"sections 4-2-4, 4-3, 4-4; address {_I570}" if base is not None else "sections 4-2-4, 4-3")
        for n in range(1, count + 1))


def _output_sources(family: tuple[Family, ...], codes: Iterable[tuple[str, str, int | None]]) -> tuple[Parameter, ...]:
    return tuple(
        parameter(code, f"{what} source", address, family, access=STOPPED, minimum=0, maximum=255, group="C",
                  enum=_frozen({OUTPUT_FROM_OPTION: "Option Board"}),
                  source="Tables 15/16" + (f"; address {_I570}" if address is not None else ""))
        for code, what, address in codes)


def _flexible_parameters() -> tuple[Parameter, ...]:
    rows: list[Parameter] = []
    # P160-P169 output words, P170-P179 input words (Table 17, appendix F). MX2 addresses from I570.
    for offset in range(10):
        for first, area, mx2_base in (("P16", "Output", 0x16A2), ("P17", "Input", 0x16AC)):
            code = f"{first}{offset}"
            reserved = offset >= 8
            name = (f"{area} register {offset + 1} contents" if not reserved
                    else f"{area} register {offset + 1} (keep zero)")
            for families, address in ((MX2, mx2_base + offset), (RX, None)):
                rows.append(parameter(code, name, address, families, access=STOPPED, default=0, minimum=0,
                                      maximum=0xFFFF, group="P", help="Modbus address mapped into the flexible format",
                                      source="Table 17, appendix F" + ("; address " + _I570 if address else "")))
    return tuple(rows)


def _per_family(code: str, name: str, mx2_address: int, **kwargs: Any) -> tuple[Parameter, Parameter]:
    """One parameter with the same meaning on both families, whose Modbus address is only known
    for the MX2 (I570); the RX row is reachable by function code."""
    source = kwargs.pop("source", "")
    return (parameter(code, name, mx2_address, MX2, source=f"{source}; address {_I570}", **kwargs),
            parameter(code, name, None, RX, source=source, **kwargs))


#: Every register the manual uses, one row per register and family variant.
PARAMETERS: tuple[Parameter, ...] = (
    # Monitoring and control words whose addresses this manual gives (both families).
    parameter("F001", "Output frequency setting", F001_ADDRESS, words=2, type=UDINT, minimum=0, maximum=40000,
              group="F", function_code_writable=False,
              help="Modbus frequency reference; the highest frequency that can be set is 400.00 Hz",
              source="Tables 18/20, section 4-2-5, section E-2-2", **_HZ),
    parameter("", "Inverter status C", STATUS_C_ADDRESS, access=R, saved=False, enum=STATUS_C, group="monitor",
              source="section 4-7-1 Step 4, Tables 19/21"),
    parameter("", "EEPROM save (ENTER)", EEPROM_SAVE, access=W, saved=False, minimum=1, maximum=1, group="command",
              help="write 01h to store all parameters in EEPROM", source="sections E-2-2, E-3-2, Table C-2"),
    parameter("d001", "Output frequency monitor", D001_ADDRESS, words=2, type=UDINT, access=R, saved=False,
              group="d", source="Tables 19/21", **_HZ),
    parameter("", "Coil data 1", COIL_DATA_1, access=R, saved=False, bits=_COIL_DATA_1, group="coil",
              source="Tables 19/21"),
    parameter("", "Coil data 0", COIL_DATA_0, MX2, saved=False, bits=_COIL_DATA_0_COMMON, group="coil",
              source="Tables 18/20"),
    parameter("", "Coil data 0", COIL_DATA_0, RX, saved=False, bits=_COIL_DATA_0_RX, group="coil",
              source="Tables 18/20"),

    # Monitors by function code.
    *_per_family("d005", "Intelligent input terminal status", 0x1007, access=R, saved=False, group="d",
                 source="section E-2-2 Example 1"),
    *_per_family("d006", "Intelligent output terminal status", 0x1008, access=R, saved=False, group="d",
                 source="Tables C-10/C-12"),
    *_per_family("d012", "Output torque monitor", 0x1010, type=INT, access=R, saved=False, unit="%", group="d",
                 torque_related=True, source="section 4-4 Step 10"),
    # The mode is set by the initialization (b180) and survives a restart, so the save keeps it.
    parameter("d060", "Inverter mode", 0x1057, MX2, access=R, enum=MX2_MODES, group="d",
              source=f"Table 22; address {_I570}"),
    parameter("d060", "Inverter mode", None, RX, access=R, enum=RX_MODES, group="d", source="Table 23"),
    *_per_family("d081", "Trip monitor 1 (trip cause)", 0x0012, access=R, saved=False, minimum=0, maximum=99,
                 group="d", help="latest trip: n for En", source="section 5-1-1"),

    # F group: acceleration and deceleration time 1; 0.01 s, double word. Table D-7 gives the
    # range (10 ms - 3600 s) and the default (10 s) through the AC/DC Drive Accel/Decel Time.
    *_per_family("F002", "Acceleration time 1", 0x1103, type=UDINT, words=2, minimum=1, maximum=360000,
                 default=1000, scale=0.01, unit="s", group="F", source="section 4-2-1 Step 2, Table D-7"),
    *_per_family("F003", "Deceleration time 1", 0x1105, type=UDINT, words=2, minimum=1, maximum=360000,
                 default=1000, scale=0.01, unit="s", group="F", source="section 4-2-1 Step 2, Table D-7"),

    # A group: frequency and run command sources (Tables 13/14), maximum frequency (the ramp base).
    parameter("A001", "Frequency source", 0x1201, MX2, access=STOPPED, default=1, minimum=0, maximum=10,
              enum=_enum(v1="control terminal", v2="digital operator (F001)", v3="Modbus network input",
                         v4="Option Board Interface"),
              group="A", source=f"Table 13; address {_I570}"),
    parameter("A001", "Frequency source", None, RX, access=STOPPED, default=1, minimum=0, maximum=10,
              enum=_enum(v1="control terminal", v2="digital operator (F001)", v3="Modbus network input",
                         v5="Option Board Interface 2"),
              group="A", source="Table 14"),
    parameter("A002", "Run command source", 0x1202, MX2, access=STOPPED, default=1, minimum=1, maximum=4,
              enum=_enum(v1="control terminal", v2="digital operator", v3="Modbus network input",
                         v4="Option Board Interface"),
              group="A", source=f"Table 13; address {_I570}"),
    parameter("A002", "Run command source", None, RX, access=STOPPED, default=1, minimum=1, maximum=5,
              enum=_enum(v1="control terminal", v2="digital operator", v3="Modbus network input",
                         v5="Option Board Interface 2"),
              group="A", source="Table 14"),
    *_per_family("A004", "Maximum frequency", 0x1204, access=STOPPED, default=500, minimum=300, maximum=4000,
                 scale=0.1, unit="Hz", group="A",
                 help="acceleration and deceleration times run between 0 Hz and this frequency",
                 source="the inverter manuals (ramp base frequency)"),

    # b group: inverter mode and rating, initialization (section 4-1 Step 1).
    *_per_family("b031", "Software lock mode", 0x1320, default=1, minimum=0, maximum=10, group="b",
                 source="appendix F Tip (set 10 to edit parameters in run mode)"),
    *_per_family("b049", "Dual rating selection", 0x1333, access=STOPPED, enum=_enum(v0="CT", v1="VT"),
                 group="b", source="section 4-1 Step 1, Tables 22/23"),
    parameter("b084", "Initialization selection", None, RX, access=STOPPED, minimum=0, maximum=3, group="b",
              source="section 4-1 Step 1 (RX)"),
    parameter("b171", "Inverter mode selection", 0x13AE, MX2, access=STOPPED, minimum=0, maximum=3,
              enum=_enum(v0="no function", v1="induction motor", v2="high-frequency induction motor",
                         v3="permanent magnet motor"),
              group="b", source=f"section 4-1 Step 1, Table D-2 note; address {_I570}"),
    # Section E-2-2: b127 is one Modbus word but two words through the Function Code object. The manual
    # gives neither its meaning nor its address; the emulator keeps a plain word behind the function code.
    parameter("b127", "Function code b127", None, group="b", maximum=0xFFFF, function_code_words=2,
              source="section E-2-2 (double word by function code)"),
    *_per_family("b180", "Initialization trigger", 0x13B7, access=STOPPED, saved=False,
                 enum=_enum(v0="no action", v1="initialize"), group="b", source="section 4-1 Step 1"),

    # C group: terminals (sections 4-2-4, 4-3, 4-4), output sources (Tables 15/16), reset mode (Table 11).
    *_terminal_functions(MX2, 7, 0x1401),
    *_terminal_functions(RX, 8, None),
    *_output_sources(MX2, (("C021", "Output terminal 11", 0x1415), ("C022", "Output terminal 12", 0x1416),
                           ("C026", "Alarm relay", 0x141A))),
    *_output_sources(RX, (("C021", "Output terminal 11", None), ("C022", "Output terminal 12", None),
                          ("C023", "Output terminal 13", None), ("C024", "Output terminal 14", None),
                          ("C025", "Output terminal 15", None), ("C026", "Alarm relay", None))),
    *_per_family("C102", "Reset mode selection", 0x146A, minimum=0, maximum=3,
                 enum=_enum(v0="trip reset at ON", v1="trip reset at OFF", v2="trip reset at ON, only while tripped",
                            v3="resetting only trip"),
                 group="C", source="Table 11 (3 recommended)"),

    # P group: torque control (Tables 15/16, section 4-4) ...
    parameter("P033", "Torque command source", 0x1621, MX2, access=STOPPED, minimum=0, maximum=6,
              enum=_enum(v3="digital operator input", v6="Option Board Interface"), torque_related=True,
              group="P", source=f"Table 15, section 4-4 Step 4; address {_I570}"),
    parameter("P033", "Torque command source", None, RX, access=STOPPED, minimum=0, maximum=7,
              enum=_enum(v3="digital operator input", v7="Option Board Interface 2"), torque_related=True,
              group="P", source="Table 16, section 4-4 Step 4"),
    *_per_family("P034", "Torque command setting", 0x1622, minimum=0, maximum=200, unit="%", torque_related=True,
                 group="P", source="Table D-7 Torque Ref (0 - 200 %)"),
    parameter("P036", "Torque bias mode", 0x1624, MX2, access=STOPPED, minimum=0, maximum=5,
              enum=_enum(v0="digital operator input", v5="Option Board Interface"), torque_related=True,
              group="P", source=f"Table 15; address {_I570}"),
    parameter("P036", "Torque bias mode", None, RX, access=STOPPED, minimum=0, maximum=6,
              enum=_enum(v0="digital operator input", v6="Option Board Interface 2"), torque_related=True,
              group="P", source="Table 16"),
    *_per_family("P037", "Torque bias value", 0x1625, type=INT, minimum=-200, maximum=200, unit="%",
                 torque_related=True, group="P", source="Table D-7 Torque Compensation Bias (-200 - 200 %)"),
    *_per_family("P039", "Speed limit in torque control (forward)", 0x1627, type=UDINT, words=2, minimum=0,
                 maximum=40000, torque_related=True, group="P", source="section 4-4 Step 6", **_HZ),
    *_per_family("P040", "Speed limit in torque control (reverse)", 0x1629, type=UDINT, words=2, minimum=0,
                 maximum=40000, torque_related=True, group="P", source="section 4-4 Step 6", **_HZ),
    # ... the CompoNet parameters (Tables 9, 10, 12, section 4-2-5) ...
    *_per_family("P044", "Network error timer", 0x162E, access=STOPPED, minimum=0, maximum=9999, scale=0.1, unit="s",
                 group="P", help="watchdog while running; 0 disables", source="Table 12"),
    *_per_family("P045", "Action on network error", 0x162F, access=STOPPED, minimum=0, maximum=4,
                 enum=NETWORK_ACTIONS, group="P", source="Table 12 (default 0)"),
    *_per_family("P046", "Default connection path", 0x1630, access=STOPPED, default=1, minimum=0, maximum=7,
                 enum=_frozen({k: v[0] for k, v in CONNECTION_PATHS.items()}), group="P",
                 source="Table 10, Table C-14 (default 1)"),
    *_per_family("P048", "Action on network idle mode", 0x1632, access=STOPPED, minimum=0, maximum=4,
                 enum=NETWORK_ACTIONS, group="P", source="Table 12 (default 0)"),
    # Only even pole counts, 0 to 38 (Table D-2 PoleCount); 0 selects Hz units (section 4-2-5).
    *_per_family("P049", "Motor poles setting for RPM", 0x1633, access=STOPPED,
                 enum=_frozen({0: "frequency units", **{n: f"{n} poles" for n in range(2, 40, 2)}}),
                 group="P", source="section 4-2-5, Table D-2"),
    # ... a double-word position (the example of section E-2-2) ...
    *_per_family("P060", "Multistage position 0", 0x163E, type=DINT, words=2, group="P",
                 source="section E-2-2 Example 2"),
    # ... the flexible format mapping (Table 17) and the node address (Table 9).
    *_flexible_parameters(),
    *_per_family("P190", "CompoNet node address", 0x16C0, access=STOPPED, minimum=0, maximum=63, group="P",
                 source="Table 9 (0 - 63, default 0)"),
)


# -- trip codes (Table D-5) ---------------------------------------------------------------------

@dataclass(frozen=True)
class TripCode:
    """An inverter trip (error) code and the CIP fault code the option board reports for it."""

    number: int
    name: str
    cip_code: int
    cip_name: str
    families: tuple[Family, ...] = BOTH

    @property
    def code(self) -> str:
        return f"E{self.number:02d}"

    @property
    def label(self) -> str:
        """How the emulator's messages name it: "E05 Overload protection"."""
        return f"{self.code} {self.name}"


def _option_errors(family: tuple[Family, ...], base: int, interface: str) -> tuple[TripCode, ...]:
    names = ("Option error (inverter communications error)", "Option error (Duplicated MAC ID)",
             "Option error (External trip)", "Communication lost / idle", "Illegal flexible mapping",
             *("Option error (reserved)",) * 4, "Option error (inverter communication lost error)")
    return tuple(TripCode(base + n, name, 0x6320 if n == 4 else 0x7510,
                          "Parameter error" if n == 4 else f"Serial Interface {interface}", family)
                 for n, name in enumerate(names))


# Table D-5. The extracted table prints the first EzSQ user trip row as "E50... 59" and then lists
# E51-E59 again: it is E50 (user trip 0). It labels E63 "CRT/CRT Communication lost / idle"; the
# doubled prefix is an extraction artefact. E60-E69 are the MX2's option errors, E70-E79 the RX's.
TRIP_CODES: tuple[TripCode, ...] = (
    TripCode(1, "Over-current event while at constant speed", 0x2200, "Current Inside the Device"),
    TripCode(2, "Over-current event during deceleration", 0x2214, "Overcurrent during Slowdown"),
    TripCode(3, "Over-current event during acceleration", 0x2213, "Overcurrent during Startup"),
    TripCode(4, "Over-current event during other conditions", 0x2200, "Current Inside the Device"),
    TripCode(5, "Overload protection", 0x2220, "Continuous Overcurrent"),
    TripCode(6, "Braking resistor overload protection", 0x7112, "Brake Chopper overcurrent"),
    TripCode(7, "Over-voltage protection", 0x3210, "Overvoltage inside the device"),
    TripCode(8, "EEPROM error", 0x6320, "Parameter Error"),
    TripCode(9, "Under-voltage error", 0x3220, "Undervoltage inside the Device"),
    TripCode(10, "Current detection error", 0x5210, "Measurement Circuit"),
    TripCode(11, "CPU error", 0x6100, "Internal Software"),
    TripCode(12, "External trip", 0x9000, "External Malfunction"),
    TripCode(13, "USP", 0x9000, "External Malfunction"),
    TripCode(14, "Ground fault", 0x2120, "Short to Earth"),
    TripCode(15, "Input over-voltage", 0x3110, "Mains overvoltage"),
    TripCode(16, "Momentary electricity failure protection", 0x3120, "Mains undervoltage"),
    TripCode(20, "Temperature error with cooling fan frequency lowering", 0x4000, "Temperature"),
    TripCode(21, "Inverter thermal trip", 0x4200, "Device Temperature"),
    TripCode(22, "CPU error", 0x5000, "Device Hardware"),
    TripCode(24, "Phase Failure", 0x3130, "Phase Failure"),
    TripCode(25, "Main circuit error", 0x5410, "Output Stages"),
    TripCode(30, "Driver error", 0x5400, "Power section"),
    TripCode(35, "Thermistor", 0x7300, "Sensor"),
    TripCode(36, "Braking error", 0x9000, "External Malfunction"),
    TripCode(37, "Safe Stop", 0x9000, "External Malfunction"),
    TripCode(38, "Low-speed overload protection", 0x2221, "Continuous Overcurrent no1"),
    TripCode(40, "Operator connection", 0x5300, "Operator control circuit"),
    TripCode(41, "Modbus communication error", 0x7500, "Communication"),
    TripCode(43, "EzSQ invalid instruction", 0x6200, "User Software"),
    TripCode(44, "EzSQ nesting count error", 0x6200, "User Software"),
    TripCode(45, "EzSQ instruction error", 0x6200, "User Software"),
    *(TripCode(50 + n, f"EzSQ user trip {n}", 0x6200, "User Software") for n in range(10)),
    *_option_errors(MX2, 60, "No 1"),
    *_option_errors(RX, 70, "No 2"),
    TripCode(80, "Encoder disconnection", 0x7305, "Incremental Encoder 1 Defective"),
    TripCode(81, "Excessive speed", 0x8401, "Velocity following error"),
    TripCode(82, "Positioning error", 0x8500, "Position"),
    TripCode(83, "Position control range error", 0x8501, "Position Following Error"),
)


def trip_code(family: Family, number: int) -> TripCode:
    """The Table D-5 row of trip En on ``family``; ``KeyError`` if that family has no such trip."""
    for trip in TRIP_CODES:
        if trip.number == number and family in trip.families:
            return trip
    raise UnknownKey(f"{family.value} has no trip code E{number:02d} in Table D-5")


# -- family traits -----------------------------------------------------------------------------

class SpeedUnit(Enum):
    """Unit of the assemblies' Rotational Speed Reference/Monitor and the 0x2A Speed Ref/Actual."""

    CENTIHERTZ = "0.01 Hz"
    DECIHERTZ = "0.1 Hz"
    RPM = "RPM"


@dataclass(frozen=True)
class FamilyTraits:
    """What the option board's behaviour depends on, per inverter family."""

    family: Family
    #: Intelligent input terminals: 7 on the MX2, 8 on the RX (Tables 18, C-10, B-19).
    input_terminals: int
    #: Output terminals in Discrete Output Point order (Table C-12): 11, 12 (MX2) or 11-15 (RX), then the relay.
    output_terminals: tuple[str, ...]
    #: Source-selection parameter of each output terminal, in the same order (Tables 15/16).
    output_sources: tuple[str, ...]
    #: A001/A002 value "Option Board Interface" (Tables 13/14).
    option_source: int
    #: P033 and P036 values selecting the option board (Tables 15/16).
    torque_source_option: int
    torque_bias_option: int
    #: First of the option board's trip codes: E60 (MX2) or E70 (RX) (Table D-5).
    option_trip_base: int
    #: d060 value whose speed unit is 0.1 Hz: high-frequency mode on the MX2 (Table 22); the RX has none (Table 23).
    high_frequency_mode: int | None
    #: Discrete Input Point instances: 1-7 on the MX2, 1-8 plus 9 (FW terminal) on the RX (Table C-10).
    discrete_inputs: int
    #: A001/A002 value "Modbus network input", used with the flexible format (Tables 13/14).
    modbus_source: int = 3
    #: A001 value taking the frequency from F001 (digital operator).
    operator_source: int = 2

    @property
    def trip_force_fault(self) -> int:
        """Force Fault from the network: E62 / E72 (section E-1 Example 2, Table D-5)."""
        return self.option_trip_base + 2

    @property
    def trip_network(self) -> int:
        """Communication lost / idle: E63 / E73 (Table D-5)."""
        return self.option_trip_base + 3

    @property
    def trip_flexible_mapping(self) -> int:
        """Illegal flexible mapping: E64 / E74 (appendix F Note 5, Table D-5)."""
        return self.option_trip_base + 4

    def speed_unit(self, motor_poles: int, inverter_mode: int) -> SpeedUnit:
        """Unit of the rotational speed words (section 4-2-5, Table B-2): RPM when P049 is not zero,
        else 0.1 Hz in the MX2's high-frequency mode and 0.01 Hz otherwise."""
        if motor_poles:
            return SpeedUnit.RPM
        if self.high_frequency_mode is not None and inverter_mode == self.high_frequency_mode:
            return SpeedUnit.DECIHERTZ
        return SpeedUnit.CENTIHERTZ


TRAITS: Mapping[Family, FamilyTraits] = MappingProxyType({
    Family.MX2: FamilyTraits(Family.MX2, input_terminals=7, output_terminals=("11", "12", "AL"),
                             output_sources=("C021", "C022", "C026"), option_source=4,
                             torque_source_option=6, torque_bias_option=5, option_trip_base=60,
                             high_frequency_mode=2, discrete_inputs=7),
    Family.RX: FamilyTraits(Family.RX, input_terminals=8, output_terminals=("11", "12", "13", "14", "15", "AL"),
                            output_sources=("C021", "C022", "C023", "C024", "C025", "C026"), option_source=5,
                            torque_source_option=7, torque_bias_option=6, option_trip_base=70,
                            high_frequency_mode=None, discrete_inputs=9),
})


def speed_to_centihertz(raw: int, unit: SpeedUnit, motor_poles: int = 0) -> float:
    """A rotational speed word in ``unit`` as a frequency in 0.01 Hz (rpm = 120 f / poles)."""
    if unit is SpeedUnit.RPM:
        return raw * motor_poles * 100 / 120
    return raw * (10 if unit is SpeedUnit.DECIHERTZ else 1)


def centihertz_to_speed(centihertz: float, unit: SpeedUnit, motor_poles: int = 0) -> int:
    if unit is SpeedUnit.RPM:
        return round(centihertz * 120 / (motor_poles * 100))
    return round(centihertz / (10 if unit is SpeedUnit.DECIHERTZ else 1))


# -- per-family lookups ---------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class RegisterSet:
    """The registers of one family: by key, function code, function code number and Modbus address."""

    family: Family
    parameters: tuple[Parameter, ...]
    by_key: Mapping[str, Parameter] = field(init=False)
    by_number: Mapping[int, Parameter] = field(init=False)
    modbus: RegisterMap = field(init=False)
    _by_address: Mapping[int, Parameter] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        by_key: dict[str, Parameter] = {}
        for parameter in self.parameters:
            if parameter.key in by_key:
                raise BadRequest(f"{self.family.value}: {parameter.key} declared twice")
            by_key[parameter.key] = parameter
        object.__setattr__(self, "by_key", MappingProxyType(by_key))
        object.__setattr__(self, "by_number", MappingProxyType(
            {p.function_code_number: p for p in self.parameters if p.code}))
        object.__setattr__(self, "modbus", RegisterMap(p.register for p in self.parameters if p.register))
        object.__setattr__(self, "_by_address", MappingProxyType(
            {p.address: p for p in self.parameters if p.address is not None}))

    @property
    def traits(self) -> FamilyTraits:
        return TRAITS[self.family]

    def by_code(self, code: str) -> Parameter:
        """Parameter with function code ``code`` (any letter case); ``KeyError`` if the family lacks it."""
        try:
            return self.by_key[normalize_code(code)]
        except (KeyError, ValueError):
            raise UnknownKey(f"{self.family.value} has no function code {code!r}") from None

    def at(self, address: int) -> Parameter | None:
        """The parameter whose first word is at Modbus ``address``."""
        return self._by_address.get(address)

    def word(self, address: int) -> tuple[Parameter, int] | None:
        """The parameter holding word ``address`` and the index of that word (0 = first/high word)."""
        found = self.modbus.word(address)
        if found is None:
            return None
        register, index = found
        return self._by_address[register.address], index


_SETS: dict[Family, RegisterSet] = {
    family: RegisterSet(family, tuple(p for p in PARAMETERS if family in p.families)) for family in Family}


def register_set(family: Family) -> RegisterSet:
    return _SETS[family]


def register_map(family: Family) -> RegisterMap:
    """The Modbus view of ``family``: ``Register`` objects by address (for class 0x64)."""
    return _SETS[family].modbus
