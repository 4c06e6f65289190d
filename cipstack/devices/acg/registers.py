"""The ACG drive's register map, declared once.

Sources (the ACG-ET2 manual and the ACG RS-485 manual):

* ACG RS-485 manual, chapter 5 "Serial communications" of the ACG user manual: the Compatible Common
  Area (0x0000-0x001B), the Monitoring Area (0x0300-0x034C, read only), the Control Area
  (0x0380-0x0395), the Drive Memory Control Area (0x03E0-0x03EC), the registered-parameter
  area (0x0100-0x0107, 0x0110-0x0117), the communication parameters CM.1-CM.5 and the
  "Drive Parameter Modbus Communication Addresses" tables of every keypad group.
* ACG-ET2 manual, appendix B (ACG-ET2 card): the table "Keypad Parameters Related to ACG-ET2
  Communication Board" (drv, Frq, CM.6-CM.94, Pr.12-Pr.14), the CIP input/output instance
  tables of CM.23/CM.24, and the motor rating parameters behind the Motor Data object 0x28.

What is and is not covered:

* The common, monitoring, control and memory-control areas are declared in full, reserved
  words included (they read as 0, as on the drive).
* The keypad groups dr, bA, Ad, Cn, In, OU, CM, AP, Pr, M2 and the operation group: every code
  that the address tables list is declared at its address. The manuals describe only some of
  them (CM, Pr.12-Pr.14, drv, Frq, bA.13, bA.15, bA.70, bA.71, AP.1, Pr.30, In.65-In.69); the
  others are declared with their address and code only, the full 16-bit range and default 0,
  and ``help`` says so. Their chapter-4 tables (name, default, range) are not in the ACG manuals.
* Three parameters the simulation cannot do without are described from the ACG keypad
  parameter list, which is outside the ACG manuals: dr.20 Max Freq, bA.11 Pole Number and the
  factory acceleration/deceleration times of ACC/dEC. Their ``source`` says so.
* The address tables are OCR text: several hex addresses lost a "B" to an "8" (dr.11 "1108",
  bA.11 "1208", bA.75 "1248", Cn.11 "1408", dr.91 "1158", CM.91 "1758"). Every address is
  the group base plus the code number, which the decimal Modbus columns (40000 + address)
  confirm, so the addresses here are computed by that rule.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace

from ...cip.types import INT
from ...errors import UnknownKey
from ..registers import Register, RegisterAccess, RegisterMap

R = RegisterAccess.READ
RW = RegisterAccess.READ_WRITE
RW_STOPPED = RegisterAccess.WRITE_STOPPED

# Where each declaration comes from; ``Register.source`` holds one of these.
COMMON_TABLE = "ACG RS-485 manual, Compatible Common Area Parameter"
MONITOR_TABLE = "ACG RS-485 manual, Monitoring Area Parameter (Read Only)"
CONTROL_TABLE = "ACG RS-485 manual, Control Area Parameter (Read/Write)"
MEMORY_TABLE = "ACG RS-485 manual, Drive Memory Control Area Parameter (Read and Write)"
REGISTERED_TABLE = "ACG RS-485 manual, Currently Registered CM Group Parameter"
ADDRESS_TABLE = "ACG RS-485 manual, Drive Parameter Modbus Communication Addresses"
SERIAL_TABLE = "ACG RS-485 manual, Communication Parameters Setting Details"
ET2_TABLE = "ACG-ET2 manual, Keypad Parameters Related to ACG-ET2 Communication Board"
MOTOR_DATA_TABLE = "ACG-ET2 manual, Motor data object (Class 0x28, Instance 1)"
OUTSIDE_MANUALS = "ACG keypad parameter list (not in the ACG manuals)"

LISTED_ONLY = "listed in the address tables of the ACG RS-485 manual without a description"

# Group bases: ACG RS-485 manual, "Total Memory Map for Communication" (the operation group at 0x1F00
# comes from the address table of that group).
GROUP_BASES: Mapping[str, int] = {
    "dr": 0x1100, "bA": 0x1200, "Ad": 0x1300, "Cn": 0x1400, "In": 0x1500, "OU": 0x1600,
    "CM": 0x1700, "AP": 0x1800, "Pr": 0x1B00, "M2": 0x1C00, "operation": 0x1F00,
}
KEYPAD_GROUPS = ("dr", "bA", "Ad", "Cn", "In", "OU", "CM", "AP", "Pr", "M2", "operation")

# Class 0x64 instance of each keypad group; the attribute number is the code number (ACG-ET2 manual,
# "Class 0x64 (Drive Object)").
CLASS_64_INSTANCES: Mapping[str, int] = {
    "dr": 1, "bA": 2, "Ad": 3, "Cn": 4, "In": 5, "OU": 6, "CM": 7, "AP": 8, "Pr": 11, "M2": 12,
}
# The table lists "10 (AP Group)" as well as "8 (AP Group)" (ACG-ET2 manual). The register map has
# no group at 0x1A00 (ACG RS-485 manual lists 0x1100-0x1800, 0x1B00 and 0x1C00), so instance 10
# cannot be another group: it is served as the table names it, a second instance of the AP group
# (instance 8 stays the one the EDS and the scanner name).
CLASS_64_ALIASES: Mapping[int, str] = {10: "AP"}

# Codes each group's address table lists (ACG RS-485 manual). Codes printed with "-" instead of an
# address (bA.20-bA.24, Ad.83, M2.17-M2.20) have no communication address and are left out.
# CM.94 is printed with "-" too (ACG RS-485 manual, "CM.94 - - -"), but ACG-ET2 manual describes it (the
# ACG-ET2 keypad table, 000:211) and reaches every keypad parameter by its code in class 0x64
# (000:753-760: instance = group, attribute = code number): it is declared, under the key
# 0x175E of the group rule, as not addressed: class 0x64 instance 7 attribute 94 serves it, and
# Modbus refuses 0x175E as it refuses bA.20's 0x1214 (see COMM_UPDATE).
# Pr.42 and Pr.96 are the two rows printed without their code (0x1B2A, 0x1B60).
LISTED_CODES: Mapping[str, tuple[int, ...]] = {
    "dr": (9, *range(11, 21), 26, 27, 28, 80, 81, 89, 91, 93, 94, 95, 97, 98),
    "bA": (*range(1, 6), *range(7, 20), *range(41, 49), *range(53, 57), *range(70, 84)),
    "Ad": (*range(1, 11), *range(12, 18), *range(20, 34), 41, 42, *range(44, 48), 50, 51,
           *range(60, 69), 70, 71, 72, *range(74, 83), 85, 86),
    "Cn": (4, 5, 9, 10, 11, *range(21, 25), 29, 30, *range(53, 58), *range(70, 84)),
    "In": (1, 2, *range(5, 18), 35, *range(37, 42), 46, 47, 50, *range(52, 57), 61, 62,
           *range(65, 70), *range(84, 91), 99),
    "OU": (*range(1, 7), 30, 31, 33, 41, *range(50, 59), *range(67, 73)),
    "CM": (*range(1, 25), *range(30, 47), *range(50, 67), 68, *range(70, 78), 86, *range(90, 94)),
    "AP": (1, *range(16, 33), *range(34, 41), 43, 44, 45),
    "Pr": (*range(4, 11), *range(12, 16), *range(17, 23), *range(25, 34), *range(40, 44), 45,
           *range(50, 60), 66, *range(77, 83), *range(86, 90), *range(91, 97)),
    "M2": (*range(4, 9), *range(10, 17), *range(25, 35), 40, 41, 42),
}
# Codes the address table prints away from base + number. M2.34 is printed at 1C12 with the
# decimal numbers 47186/47187 (ACG RS-485 manual): hex and decimal agree, so this is the table's
# address and no OCR slip; 0x1C12 is free, M2.18 having none ("-"). Served there, as printed.
PRINTED_ADDRESSES: Mapping[str, int] = {"M2.34": 0x1C12}

# Operation group, ACG RS-485 manual address table: code -> address. "Fr9" in the OCR text is Frq.
OPERATION_CODES: Mapping[str, int] = {
    "0.00": 0x1F00, "ACC": 0x1F01, "dEC": 0x1F02, "drv": 0x1F03, "Frq": 0x1F04, "St1": 0x1F05,
    "St2": 0x1F06, "St3": 0x1F07, "Cur": 0x1F08, "RPM": 0x1F09, "dCL": 0x1F0A, "vOL": 0x1F0B,
    "nOn": 0x1F0C, "drC": 0x1F0D,
}

NO_YES = {0: "No", 1: "Yes"}




# ---------------------------------------------------------------------------------------------
# CM.23 / CM.24: the assemblies the card serves (ACG-ET2 manual, "CIP Input Instance (CM.23)" and
# "CIP Output Instance (CM.24)")
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class InstanceSelection:
    setting: int
    instance: int
    #: Data size in bytes.
    size: int
    #: "Parameter Number" column: how many Para Status/Control words; None where it reads "X".
    parameters: int | None


CIP_INPUT_INSTANCES: tuple[InstanceSelection, ...] = (
    InstanceSelection(0, 70, 4, None), InstanceSelection(1, 71, 4, None),
    InstanceSelection(2, 110, 4, None), InstanceSelection(3, 111, 4, None),
    InstanceSelection(4, 141, 2, 1), InstanceSelection(5, 142, 4, 2), InstanceSelection(6, 143, 6, 3),
    InstanceSelection(7, 144, 8, 4), InstanceSelection(8, 145, 10, 5), InstanceSelection(9, 146, 12, 6),
    InstanceSelection(10, 147, 14, 7), InstanceSelection(11, 148, 16, 8),
)
CIP_OUTPUT_INSTANCES: tuple[InstanceSelection, ...] = (
    InstanceSelection(0, 20, 4, None), InstanceSelection(1, 21, 4, None),
    InstanceSelection(2, 100, 4, None), InstanceSelection(3, 101, 4, None),
    InstanceSelection(4, 121, 2, 1), InstanceSelection(5, 122, 4, 2), InstanceSelection(6, 123, 6, 3),
    InstanceSelection(7, 124, 8, 4), InstanceSelection(8, 125, 10, 5), InstanceSelection(9, 126, 12, 6),
    InstanceSelection(10, 127, 14, 7), InstanceSelection(11, 128, 16, 8),
)


def _instance_enum(selections: Iterable[InstanceSelection]) -> dict[int, str]:
    return {s.setting: f"instance {s.instance}" for s in selections}


# ---------------------------------------------------------------------------------------------
# Builders
# ---------------------------------------------------------------------------------------------

def _reserved(address: int, group: str, source: str, access: RegisterAccess = R) -> Register:
    return Register(address, "", "Reserved", access=access, group=group, saved=False, source=source)


def _reserved_range(first: int, last: int, group: str, source: str) -> list[Register]:
    return [_reserved(a, group, source) for a in range(first, last + 1)]


def _parameter(group: str, number: int, name: str, **fields: object) -> Register:
    """A keypad parameter of ``group`` at the group base plus its code number (or as printed)."""
    fields.setdefault("source", ADDRESS_TABLE)
    code = f"{group}.{number}"
    address = PRINTED_ADDRESSES.get(code, GROUP_BASES[group] + number)
    return Register(address, code, name, group=group, **fields)  # type: ignore[arg-type]


def _listed(group: str, number: int) -> Register:
    return _parameter(group, number, f"{group}.{number}", help=LISTED_ONLY)


def _alias(target: Register, address: int, name: str, group: str, source: str) -> Register:
    """Another address of the same value: type, scale, unit and range come from ``target``."""
    return replace(target, address=address, code="", name=name, group=group, saved=False, source=source,
                   help=f"the value of {target.code or target.name} at 0x{target.address:04X}")


# ---------------------------------------------------------------------------------------------
# Operation group (0x1F00-0x1F0D) and the few described parameters the areas refer to
# ---------------------------------------------------------------------------------------------

TARGET_FREQUENCY = Register(
    0x1F00, "0.00", "Target frequency", default=0, minimum=0, maximum=40000, scale=0.01, unit="Hz",
    group="operation", source=ADDRESS_TABLE,
    help="keypad frequency; upper limit is dr.20 Max Freq (400.00 Hz at most, ACG-ET2 manual class 0x2A attribute 101)")
# ACC/dEC: the range 0-6000.0 s is class 0x2A attributes 102/103 of the ACG-ET2 manual ("Value at DRV-03/04");
# the factory values 5.0 s and 10.0 s come from the ACG keypad parameter list.
ACCEL_TIME = Register(
    0x1F01, "ACC", "Acc Time", default=50, minimum=0, maximum=60000, scale=0.1, unit="s", group="operation",
    source=f"ACG-ET2 manual, class 0x2A attribute 102; default from {OUTSIDE_MANUALS}")
DECEL_TIME = Register(
    0x1F02, "dEC", "Dec Time", default=100, minimum=0, maximum=60000, scale=0.1, unit="s", group="operation",
    source=f"ACG-ET2 manual, class 0x2A attribute 103; default from {OUTSIDE_MANUALS}")
# drv values: ACG-ET2 manual "4: Field Bus", ACG RS-485 manual "3 Int485", and the command-source list of the
# common area word 0x0006 B6-B8 (0 Keypad, 1 FX/RX-1, 2 FX/RX-2, 3 built-in 485, 4 option).
CMD_SOURCE = Register(
    0x1F03, "drv", "Cmd Source", default=1, minimum=0, maximum=4,
    enum={0: "Keypad", 1: "Fx/Rx-1", 2: "Fx/Rx-2", 3: "Int485", 4: "Field Bus"}, group="operation",
    source=ET2_TABLE)
# Frq values named in the ACG manuals: 0 Keypad-1 (ACG RS-485 manual, frequency save note), 6 Int485 (ACG RS-485 manual,
# Setting Operation Command and Frequency), 8 Field Bus (ACG-ET2 manual). The others of 0-8 are valid
# settings whose names the ACG manuals do not give.
FREQ_REF_SOURCE = Register(
    0x1F04, "Frq", "Freq Ref Src", default=0, minimum=0, maximum=8,
    enum={0: "Keypad-1", 6: "Int485", 8: "Field Bus"}, group="operation", source=ET2_TABLE)

CMD_SOURCE_FIELDBUS = 4
FREQ_REF_SOURCE_FIELDBUS = 8
#: drv 3 / Frq 6 "Int485": the built-in RS-485 port (ACG RS-485 manual, Setting Operation Command and Frequency).
CMD_SOURCE_INT485 = 3
FREQ_REF_SOURCE_INT485 = 6
#: drv 1 / 2 "Fx/Rx-1", "Fx/Rx-2": the terminals' FX and RX functions (0x0006 B6-B8 command sources).
CMD_SOURCE_FX_RX_1 = 1
CMD_SOURCE_FX_RX_2 = 2

_OPERATION: list[Register] = [
    TARGET_FREQUENCY, ACCEL_TIME, DECEL_TIME, CMD_SOURCE, FREQ_REF_SOURCE,
    *(Register(OPERATION_CODES[c], c, c, group="operation", source=ADDRESS_TABLE, help=LISTED_ONLY)
      for c in ("St1", "St2", "St3")),
    # The display codes Cur, RPM, dCL and vOL show the output current, motor speed, DC link and
    # output voltages, the monitors of 0x0310, 0x0312, 0x0315 and 0x0314.
    Register(0x1F08, "Cur", "Output current", access=R, scale=0.1, unit="A", group="operation", saved=False,
             source=ADDRESS_TABLE, simulated=False),
    Register(0x1F09, "RPM", "Motor rpm", access=R, unit="rpm", group="operation", saved=False,
             source=ADDRESS_TABLE),
    Register(0x1F0A, "dCL", "DC link voltage", access=R, unit="V", group="operation", saved=False,
             source=ADDRESS_TABLE),
    Register(0x1F0B, "vOL", "Output voltage", access=R, unit="V", group="operation", saved=False,
             source=ADDRESS_TABLE),
    *(Register(OPERATION_CODES[c], c, c, group="operation", source=ADDRESS_TABLE, help=LISTED_ONLY)
      for c in ("nOn", "drC")),
]

MAX_FREQUENCY = _parameter("dr", 20, "Max Freq", default=6000, minimum=4000, maximum=40000, scale=0.01, unit="Hz",
                           source=OUTSIDE_MANUALS)
POLE_NUMBER = _parameter("bA", 11, "Pole Number", default=4, minimum=2, maximum=48, source=OUTSIDE_MANUALS)
# bA.13 / bA.15 stand behind class 0x28 attributes 6 and 7 (ACG-ET2 manual: "BAS-13 Rated Curr",
# "BAS-15 Rated Voltage"). Their factory values depend on the drive's rating; the ACG manuals give none.
RATED_CURRENT = _parameter("bA", 13, "Rated Curr", minimum=0, maximum=10000, scale=0.1, unit="A",
                           source=MOTOR_DATA_TABLE)
RATED_VOLTAGE = _parameter("bA", 15, "Rated Volt", minimum=0, maximum=690, unit="V", source=MOTOR_DATA_TABLE)
# bA.70/bA.71: the multi-step acceleration/deceleration time 1 of the Modbus-RTU example in the ACG RS-485 manual
# (0x1246 = 5.0 s is written as 50, 0x1247 = 10.0 s as 100).
MULTI_STEP_ACCEL_TIME_1 = _parameter("bA", 70, "Multi-step acceleration time 1", scale=0.1, unit="s",
                                     source="ACG RS-485 manual, Example of Modbus-RTU Communication in Use")
MULTI_STEP_DECEL_TIME_1 = _parameter("bA", 71, "Multi-step deceleration time 1", scale=0.1, unit="s",
                                     source="ACG RS-485 manual, Example of Modbus-RTU Communication in Use")
APP_MODE = _parameter("AP", 1, "App Mode", source="ACG-ET2 manual, class 0x2A attribute 6 note 1")
TRIP_OUT_MODE = _parameter("Pr", 30, "Trip Out Mode", source="ACG RS-485 manual, Monitoring Area 0x0305")

# Pr.12-Pr.14: ACG-ET2 manual, ET2 table and "PR Group (Lost Command)"; ACG RS-485 manual, "Command Loss
# Protective Operation".
LOST_CMD_MODE = _parameter(
    "Pr", 12, "Lost Cmd Mode", default=0, minimum=0, maximum=5,
    enum={0: "None", 1: "Free-Run", 2: "Dec", 3: "Hold Input", 4: "Hold Output", 5: "Lost Preset"},
    source=ET2_TABLE)
LOST_CMD_TIME = _parameter("Pr", 13, "Lost Cmd Time", default=10, minimum=1, maximum=1200, scale=0.1, unit="s",
                           source=ET2_TABLE)
# ACG-ET2 manual prints range 0.05-60.00 and default 0.00, which the range excludes; 000:257 says
# "from the start frequency to the max frequency". The range is the table's: at most 60.00, and
# 0.05 at least, with the table's own default 0.00 (no preset) accepted too, so a tool can write
# the default back; 0.01-0.04 are refused (``drive.py``), and so is a value above the present
# dr.20 Max Freq.
LOST_PRESET_FREQ = _parameter("Pr", 14, "Lost Preset F", default=0, minimum=0, maximum=6000, scale=0.01,
                              unit="Hz", source=ET2_TABLE)
#: Pr.14's lowest setting but the default 0.00 (ACG-ET2 manual): 0.05 Hz.
LOST_PRESET_MINIMUM = 5

# The functions a multi-function input (In.65-In.69, CM.70-CM.77) is set to. ACG RS-485 manual gives the
# range 0-49 and "0: None" only; the numbers of the functions the simulation models are those of
# the ACG keypad parameter list (In.65-In.69), which is outside the ACG manuals. Settings 6-49 (jog,
# multi-step speeds, ...) are accepted and do nothing here.
MULTI_FUNCTIONS: Mapping[int, str] = {0: "None", 1: "FX", 2: "RX", 3: "RST", 4: "External Trip", 5: "BX"}

_MULTI_FUNCTION_INPUTS = [
    _parameter("In", 65 + i, f"Multi-function input P{i + 1}",
               source="ACG RS-485 manual, Setting Virtual Multi-Function Input",
               help="a function of MULTI_FUNCTIONS (0-5 modelled); no setting may be that of a CM.70-CM.77")
    for i in range(5)
]


# ---------------------------------------------------------------------------------------------
# CM group
# ---------------------------------------------------------------------------------------------

def _cm(number: int, name: str, **fields: object) -> Register:
    fields.setdefault("source", ET2_TABLE)
    return _parameter("CM", number, name, **fields)


_OCTET = {"minimum": 0, "maximum": 255}
_HEX_ADDRESS = {"minimum": 0x0000, "maximum": 0xFFFF}

#: CM.94 Comm Update. The ACG RS-485 manual's address table prints no Modbus RTU or TCP address for it
#: (001:1384, "CM.94 - - -"), as for bA.20-bA.24; ACG-ET2 manual lists it among the card's keypad
#: parameters (000:211, Protocol "E/M": it applies the settings of both protocols, which says
#: what it concerns, not where it is addressed) and serves keypad parameters by code in class
#: 0x64 (000:753). So: over CIP at class 0x64/7/94, never over Modbus (exception 02, as bA.20).
COMM_UPDATE = Register(
    0x175E, "CM.94", "Comm Update", default=0, enum={0: "NO", 1: "YES"}, group="CM", saved=False,
    addressed=False, source=f"{ET2_TABLE}; no communication address (ACG RS-485 manual prints '-'): class 0x64 only")

_CM: list[Register] = [
    _cm(1, "Int485 St ID", default=1, minimum=1, maximum=250, source=SERIAL_TABLE),
    _cm(2, "Int485 Proto", default=0, enum={0: "Modbus-RTU", 2: "Not supported"}, source=SERIAL_TABLE),
    # CM.3: the setting numbers 0-7 are garbled in the OCR text; the eight speeds are listed in
    # order. "56 Kbps" and "115 Kbps" are the 57,600 and 115,200 bps of the standards table.
    _cm(3, "Int485 Baudrate", default=3, enum={0: "1,200 bps", 1: "2,400 bps", 2: "4,800 bps", 3: "9,600 bps",
                                                4: "19,200 bps", 5: "38,400 bps", 6: "57,600 bps", 7: "115,200 bps"},
        source=SERIAL_TABLE),
    _cm(4, "Int485 Mode", default=0, enum={0: "D8/PN/S1", 1: "D8/PN/S2", 2: "D8/PE/S1", 3: "D8/PO/S1"},
        source=SERIAL_TABLE),
    _cm(5, "Resp Delay", default=5, minimum=0, maximum=1000, unit="ms", source=SERIAL_TABLE),
    # CM.6 shows the card version, which Identity attribute 4 reports as 0x0101 (ACG-ET2 manual).
    _cm(6, "FBus S/W Ver", access=R, default=0x0101, saved=False),
    # The table gives 0-220; the CM group text says 64 IDs 0-63. The table's range is kept.
    _cm(7, "FBus ID", default=10, minimum=0, maximum=220),
    _listed("CM", 8),
    _cm(9, "FBus Led", access=R, saved=False),
    _cm(10, "Opt Parameter 1", default=192, help="IP address, 1st octet", **_OCTET),
    _cm(11, "Opt Parameter 2", default=168, help="IP address, 2nd octet", **_OCTET),
    _cm(12, "Opt Parameter 3", default=1, help="IP address, 3rd octet", **_OCTET),
    _cm(13, "Opt Parameter 4", default=101, help="IP address, 4th octet", **_OCTET),
    _cm(14, "Opt Parameter 5", default=255, help="subnet mask, 1st octet", **_OCTET),
    _cm(15, "Opt Parameter 6", default=255, help="subnet mask, 2nd octet", **_OCTET),
    _cm(16, "Opt Parameter 7", default=255, help="subnet mask, 3rd octet", **_OCTET),
    _cm(17, "Opt Parameter 8", default=0, help="subnet mask, 4th octet", **_OCTET),
    _cm(18, "Opt Parameter 9", default=192, help="gateway, 1st octet", **_OCTET),
    _cm(19, "Opt Parameter 10", default=168, help="gateway, 2nd octet", **_OCTET),
    _cm(20, "Opt Parameter 11", default=1, help="gateway, 3rd octet", **_OCTET),
    _cm(21, "Opt Parameter 12", default=10, help="gateway, 4th octet", **_OCTET),
    _cm(22, "Opt Parameter 13", default=0, minimum=0, maximum=0, help="network speed, fixed to 100 Mbps auto"),
    _cm(23, "Opt Parameter 14", access=RW_STOPPED, default=1, minimum=0, maximum=11,
        enum=_instance_enum(CIP_INPUT_INSTANCES), help="CIP Input Instance"),
    _cm(24, "Opt Parameter 15", access=RW_STOPPED, default=1, minimum=0, maximum=11,
        enum=_instance_enum(CIP_OUTPUT_INSTANCES), help="CIP Output Instance"),
    # CM.34-CM.38 and CM.53-CM.58 print "-" as their default: no address registered, 0 here.
    _cm(30, "Para Status Num", default=3, minimum=0, maximum=8),
    *(_cm(30 + n, f"Para Status-{n}", default={1: 0x000A, 2: 0x000E, 3: 0x000F}.get(n, 0), **_HEX_ADDRESS)
      for n in range(1, 9)),
    *(_listed("CM", n) for n in range(39, 47)),
    _cm(50, "Para Ctrl Num", default=2, minimum=0, maximum=8),
    *(_cm(50 + n, f"Para Control-{n}", default={1: 0x0005, 2: 0x0006}.get(n, 0), **_HEX_ADDRESS)
      for n in range(1, 9)),
    *(_listed("CM", n) for n in (*range(59, 67), 68)),
    *(_cm(69 + n, f"Virtual DI {n}", default=0, minimum=0, maximum=49, enum=dict(MULTI_FUNCTIONS),
          source=f"ACG RS-485 manual, Setting Virtual Multi-Function Input; names from {OUTSIDE_MANUALS}",
          help=f"communication multi-function input: the function bit {n - 1} of 0x0385 operates")
      for n in range(1, 9)),
    _cm(86, "Virt DI Status", access=R, saved=False, source="ACG RS-485 manual, Setting Virtual Multi-Function Input"),
    *(_listed("CM", n) for n in range(90, 94)),
    COMM_UPDATE,
]

#: CM parameters that take effect only after CM.94 (Comm Update): "CM.7 and CM.10-CM.25"
#: (ACG-ET2 manual, Comm Update (CM.94)); CM.25 is not a listed code.
COMM_UPDATE_CODES: tuple[str, ...] = ("CM.7", *(f"CM.{n}" for n in range(10, 25)))


def _groups() -> list[Register]:
    described = [MAX_FREQUENCY, POLE_NUMBER, RATED_CURRENT, RATED_VOLTAGE, MULTI_STEP_ACCEL_TIME_1,
                 MULTI_STEP_DECEL_TIME_1, APP_MODE, TRIP_OUT_MODE, LOST_CMD_MODE, LOST_CMD_TIME, LOST_PRESET_FREQ,
                 *_MULTI_FUNCTION_INPUTS, *_CM]
    by_code = {r.code: r for r in described}
    registers: list[Register] = []
    for group, numbers in LISTED_CODES.items():
        for number in numbers:
            code = f"{group}.{number}"
            registers.append(by_code.pop(code) if code in by_code else _listed(group, number))
    registers.extend(by_code.values())  # CM.94, the one described code no address table lists
    return registers


# ---------------------------------------------------------------------------------------------
# Common area 0x0000-0x001B (ACG RS-485 manual, "Compatible Common Area Parameter")
# ---------------------------------------------------------------------------------------------

# 0x0001: capacity code 3 is lost in the OCR text; the others are as printed.
_COMMON_CAPACITY = {0: "0.75 kW (1 hp)", 1: "1.5 kW (2 hp)", 2: "2.2 kW (3 hp)", 4: "5.5 kW (7.5 hp)",
                    5: "7.5 kW (10 hp)", 6: "11 kW (15 hp)", 7: "15 kW (20 hp)", 8: "18.5 kW (25 hp)",
                    9: "22 kW (30 hp)", 256: "0.4 kW (1/2 hp)", 259: "4.0 kW (5 hp)"}

SPEED_REFERENCE = Register(0x0380, "", "Frequency command", scale=0.01, unit="Hz", minimum=0, maximum=40000,
                           group="control", saved=False, source=CONTROL_TABLE, help="command frequency setting")

_COMMON: list[Register] = [
    Register(0x0000, "", "Drive Model", access=R, default=16, enum={16: "ACG"}, group="common", saved=False,
             source=COMMON_TABLE),
    Register(0x0001, "", "Drive capacity", access=R, default=0, enum=_COMMON_CAPACITY, group="common", saved=False,
             source=COMMON_TABLE),
    Register(0x0002, "", "Drive input voltage", access=R, default=0, enum={0: "230V level", 1: "460V level"},
             group="common", saved=False, source=COMMON_TABLE),
    Register(0x0003, "", "Version", access=R, default=0x0100, group="common", saved=False, source=COMMON_TABLE,
             help="0x0100 is version 1.00"),
    _reserved(0x0004, "common", COMMON_TABLE, access=RW),
    _alias(SPEED_REFERENCE, 0x0005, "Target frequency", "common", COMMON_TABLE),
    Register(0x0006, "", "Operation command (option)", group="common", saved=False, source=COMMON_TABLE,
             help="write: B0 stop, B1 forward, B2 reverse, B3 trip reset (0->1), B4 emergency stop; "
                  "read: B6-B8 command source, B9-B14 frequency source"),
    _alias(ACCEL_TIME, 0x0007, "Acceleration time", "common", COMMON_TABLE),
    _alias(DECEL_TIME, 0x0008, "Deceleration time", "common", COMMON_TABLE),
    Register(0x0009, "", "Output current", access=R, scale=0.1, unit="A", group="common", saved=False,
             source=COMMON_TABLE, simulated=False),
    Register(0x000A, "", "Output frequency", access=R, scale=0.01, unit="Hz", group="common", saved=False,
             source=COMMON_TABLE),
    Register(0x000B, "", "Output voltage", access=R, unit="V", group="common", saved=False, source=COMMON_TABLE),
    Register(0x000C, "", "DC link voltage", access=R, unit="V", group="common", saved=False, source=COMMON_TABLE),
    Register(0x000D, "", "Output power", access=R, scale=0.1, unit="kW", group="common", saved=False,
             source=COMMON_TABLE, simulated=False),
    Register(0x000E, "", "Operation status", access=R, group="common", saved=False, source=COMMON_TABLE,
             help="bits: OperationStatus"),
    Register(0x000F, "", "Fault trip information", access=R, group="common", saved=False, source=COMMON_TABLE,
             help="bits: FaultTripInformation"),
    # 0x0010: the row is garbled ("o 7| a Trs"); B0-B4 are P1-P5, the input terminals.
    Register(0x0010, "", "Input terminal information", access=R, group="common", saved=False, source=COMMON_TABLE,
             help="B0-B4: P1-P5"),
    Register(0x0011, "", "Output relay information", access=R, group="common", saved=False, source=COMMON_TABLE,
             help="B0 Relay1, B1 Relay2"),
    Register(0x0012, "", "V1", access=R, scale=0.01, unit="%", group="common", saved=False, source=COMMON_TABLE,
             help="V1 voltage input"),
    Register(0x0013, "", "V0", access=R, scale=0.01, unit="%", group="common", saved=False, source=COMMON_TABLE,
             help="potentiometer voltage input"),
    Register(0x0014, "", "I2", access=R, scale=0.01, unit="%", group="common", saved=False, source=COMMON_TABLE,
             help="I2 current input"),
    Register(0x0015, "", "Motor rotation speed", access=R, unit="rpm", group="common", saved=False,
             source=COMMON_TABLE),
    *_reserved_range(0x0016, 0x0019, "common", COMMON_TABLE),
    Register(0x001A, "", "Select Hz/rpm", access=R, enum={0: "Hz", 1: "Rpm"}, group="common", saved=False,
             source=COMMON_TABLE),
    Register(0x001B, "", "Number of poles of the selected motor", access=R, group="common", saved=False,
             source=COMMON_TABLE),
]


# ---------------------------------------------------------------------------------------------
# Monitoring area 0x0300-0x034C (ACG RS-485 manual, "Monitoring Area Parameter (Read Only)")
# ---------------------------------------------------------------------------------------------

def _monitor(address: int, name: str, **fields: object) -> Register:
    return Register(address, "", name, access=R, group="monitor", saved=False, source=MONITOR_TABLE,
                    **fields)  # type: ignore[arg-type]


_MONITOR_CAPACITY = {0x1900: "0.4 kW", 0x3200: "0.75 kW", 0x4015: "1.5 kW", 0x4022: "2.2 kW", 0x4030: "3.0 kW",
                     0x4040: "4.0 kW", 0x4055: "5.5 kW", 0x4075: "7.5 kW", 0x40B0: "11 kW", 0x40F0: "15 kW",
                     0x4125: "18.5 kW", 0x4160: "22 kW"}
_MONITOR_INPUT = {0x0220: "230V single phase self cooling", 0x0221: "230V single phase forced cooling",
                  0x0230: "230V 3-phase self cooling", 0x0231: "230V 3-phase forced cooling",
                  0x0420: "460V single phase self cooling", 0x0421: "460V single phase forced cooling",
                  0x0430: "460V 3-phase self cooling", 0x0431: "460V 3-phase forced cooling"}

_MONITOR: list[Register] = [
    # The emulated drive is the 0.75 kW 230 V 3-phase self-cooled model: 0x0001 = 0, 0x0002 = 0.
    _monitor(0x0300, "Drive model", default=0x0010, enum={0x0010: "ACG"}),
    _monitor(0x0301, "Drive capacity", default=0x3200, enum=_MONITOR_CAPACITY),
    _monitor(0x0302, "Drive input voltage/power (single phase, 3-phase)/cooling method", default=0x0230,
             enum=_MONITOR_INPUT),
    _monitor(0x0303, "Drive S/W version", default=0x0100, help="0x0100 is version 1.00"),
    _reserved(0x0304, "monitor", MONITOR_TABLE),
    _monitor(0x0305, "Drive operation state",
             help="B12-B15 OperationHealth, B4-B7 OperationPhase, B0-B3 OperationDirection"),
    _monitor(0x0306, "Drive operation frequency command source",
             help="B8-B15 operation command source, B0-B7 frequency command source"),
    *_reserved_range(0x0307, 0x030F, "monitor", MONITOR_TABLE),
    # No motor or load model: the current, power and torque the ACG manuals give no figure to simulate
    # from (no no-load current, no load) read 0, declared "not simulated"; the inverter temperature and
    # the energy counted from the power likewise.
    _monitor(0x0310, "Output current", scale=0.1, unit="A", simulated=False),
    _monitor(0x0311, "Output frequency", scale=0.01, unit="Hz"),
    _monitor(0x0312, "Output rpm", unit="rpm"),
    _monitor(0x0313, "Motor feedback speed", type=INT, unit="rpm", help="-32768 rpm to 32767 rpm (directional)"),
    _monitor(0x0314, "Output voltage", unit="V"),
    _monitor(0x0315, "DC Link voltage", unit="V"),
    _monitor(0x0316, "Output power", scale=0.1, unit="kW", simulated=False),
    _monitor(0x0317, "Output torque", scale=0.1, unit="%", simulated=False),
    _monitor(0x0318, "PID reference", scale=0.1, unit="%"),
    _monitor(0x0319, "PID feedback", scale=0.1, unit="%"),
    _monitor(0x031A, "Number of poles of the first motor"),
    _monitor(0x031B, "Number of poles of the second motor"),
    _monitor(0x031C, "Number of poles of the selected motor"),
    _monitor(0x031D, "Select Hz/rpm", enum={0: "Hz", 1: "RPM"}),
    *_reserved_range(0x031E, 0x031F, "monitor", MONITOR_TABLE),
    _monitor(0x0320, "Digital input information", help="B0-B4: P1-P5 (I/O board)"),
    _monitor(0x0321, "Digital output information", help="B0 Relay1, B1 Relay2"),
    # 0x0322 stands in the read-only monitoring area, but the chapter operates the virtual inputs
    # by writing it: "set the BIT relevant to the function to 1 at 0h0322 to operate it", "assign
    # a 0h0001 value to the communication address 0h0322" (Setting Virtual Multi-Function Input),
    # as well as 0x0385 of the control area. It is served as the chapter's example uses it: the
    # value of 0x0385 (``ALIASES``), written and read alike.
    Register(0x0322, "", "Virtual digital input information", minimum=0, maximum=0x00FF, group="monitor",
             saved=False, source=MONITOR_TABLE,
             help="B0-B7: virtual DI 1-8 (CM.70-CM.77); the value of 0x0385, writable as the chapter's example"),
    _monitor(0x0323, "Display the selected motor", enum={0: "First Motor", 1: "Second Motor"}),
    _monitor(0x0324, "V1", scale=0.01, unit="%", help="analog input V1 (I/O board)"),
    _reserved(0x0325, "monitor", MONITOR_TABLE),
    _monitor(0x0326, "V0", scale=0.01, unit="%", help="potentiometer dial"),
    _monitor(0x0327, "I2", scale=0.01, unit="%", help="analog input I2 (I/O board)"),
    _monitor(0x0328, "AO1", scale=0.01, unit="%", help="analog output 1 (I/O board)"),
    _monitor(0x0329, "AO2", scale=0.01, unit="%", help="analog output 2 (I/O board)"),
    *_reserved_range(0x032A, 0x032C, "monitor", MONITOR_TABLE),
    # 0x032D-0x032F: the names are garbled in the OCR text; read with their units they are the
    # inverter temperature and the power consumption in kWh and MWh, which 0x03EA initializes.
    _monitor(0x032D, "Inverter temperature", unit="degC", simulated=False),
    _monitor(0x032E, "Power consumption", unit="kWh", simulated=False),
    _monitor(0x032F, "Power consumption", unit="MWh", simulated=False),
    _monitor(0x0330, "Latch type trip information - 1", help="bits: LatchTrip1"),
    _monitor(0x0331, "Latch type trip information - 2", help="bits: LatchTrip2"),
    _monitor(0x0332, "Level type trip information", help="bits: LevelTrip"),
    _monitor(0x0333, "H/W Diagnosis trip information", help="bits: HardwareDiagnosis"),
    _monitor(0x0334, "Warning information", help="bits: WarningInformation"),
    _monitor(0x0335, "Latch type trip information - 3", help="bits: LatchTrip3"),
    *_reserved_range(0x0336, 0x033F, "monitor", MONITOR_TABLE),
    _monitor(0x0340, "On Time date", unit="day", help="total number of days the drive has been powered on"),
    _monitor(0x0341, "On Time minute", unit="min", help="minutes beyond the On Time days"),
    _monitor(0x0342, "Run Time date", unit="day", help="total number of days the drive has driven the motor"),
    _monitor(0x0343, "Run Time minute", unit="min", help="minutes beyond the Run Time days"),
    _monitor(0x0344, "Fan Time date", unit="day", help="total number of days the heat sink fan has been running"),
    _monitor(0x0345, "Fan Time minute", unit="min", help="minutes beyond the Fan Time days"),
    *_reserved_range(0x0346, 0x0349, "monitor", MONITOR_TABLE),
    _monitor(0x034A, "Option 1", default=11, enum={0: "None", 11: "EtherNet/IP or Mod TCP"}),
    *_reserved_range(0x034B, 0x034C, "monitor", MONITOR_TABLE),
]


# ---------------------------------------------------------------------------------------------
# Control area 0x0380-0x0395 (ACG RS-485 manual, "Control Area Parameter (Read/Write)")
# ---------------------------------------------------------------------------------------------

def _control(address: int, name: str, **fields: object) -> Register:
    return Register(address, "", name, group="control", saved=False, source=CONTROL_TABLE,
                    **fields)  # type: ignore[arg-type]


_CONTROL: list[Register] = [
    SPEED_REFERENCE,
    _control(0x0381, "RPM command", unit="rpm", help="command rpm setting"),
    _control(0x0382, "Operation command", minimum=0, maximum=0x00FF, help="bits: ControlCommand (B4-B7 reserved)"),
    _alias(ACCEL_TIME, 0x0383, "Acceleration time", "control", CONTROL_TABLE),
    _alias(DECEL_TIME, 0x0384, "Deceleration time", "control", CONTROL_TABLE),
    _control(0x0385, "Virtual digital input control", minimum=0, maximum=0x00FF,
             help="B0-B7: virtual DI 1-8 (CM.70-CM.77), 0: off, 1: on"),
    _control(0x0386, "Digital output control", minimum=0, maximum=0x0003, help="B0 Relay1, B1 Relay2 (0: off, 1: on)"),
    _reserved(0x0387, "control", CONTROL_TABLE),
    _control(0x0388, "PID reference", scale=0.1, unit="%", help="PID reference command"),
    _control(0x0389, "PID feedback", scale=0.1, unit="%", help="PID feedback value"),
    _alias(RATED_CURRENT, 0x038A, "Motor rated current", "control", CONTROL_TABLE),
    _alias(RATED_VOLTAGE, 0x038B, "Motor rated voltage", "control", CONTROL_TABLE),
    *_reserved_range(0x038C, 0x038F, "control", CONTROL_TABLE),
    _control(0x0390, "Torque Ref", scale=0.1, unit="%", help="torque command"),
    _control(0x0391, "Fwd Pos Torque limit", scale=0.1, unit="%", help="forward motoring torque limit"),
    _control(0x0392, "Fwd Neg Torque limit", scale=0.1, unit="%", help="forward regenerative torque limit"),
    _control(0x0393, "Rev Pos Torque limit", scale=0.1, unit="%", help="reverse motoring torque limit"),
    _control(0x0394, "Rev Neg Torque limit", scale=0.1, unit="%", help="reverse regenerative torque limit"),
    _control(0x0395, "Torque Bias", scale=0.1, unit="%", help="torque bias"),
]


# ---------------------------------------------------------------------------------------------
# Memory control area 0x03E0-0x03EC (ACG RS-485 manual, "Drive Memory Control Area Parameter")
# The table marks each word "(run mark) R/W" (writable in run), "R/W" (writable when stopped)
# or read only. 0x03E1's mark is garbled ("LW"); like the other one-shot commands beside it
# it is taken as writable in run.
# ---------------------------------------------------------------------------------------------

def _memory(address: int, name: str, access: RegisterAccess, **fields: object) -> Register:
    return Register(address, "", name, access=access, group="memory", saved=False, source=MEMORY_TABLE,
                    **fields)  # type: ignore[arg-type]


SAVE_PARAMETERS = _memory(0x03E0, "Save parameters", RW_STOPPED, enum=NO_YES)
PARAMETER_INITIALIZATION_GROUPS: Mapping[int, str] = {
    0: "No", 1: "All Grp", 2: "Drv Grp", 3: "bA Grp", 4: "Ad Grp", 5: "Cn Grp", 6: "In Grp", 7: "OU Grp",
    8: "CM Grp", 9: "AP Grp", 12: "Pr Grp", 13: "M2 Grp", 14: "Operation Grp",
}
#: Group each 0x03E2 setting initializes ("Drv Grp" is the dr group).
PARAMETER_INITIALIZATION_TARGETS: Mapping[int, tuple[str, ...]] = {
    1: KEYPAD_GROUPS, 2: ("dr",), 3: ("bA",), 4: ("Ad",), 5: ("Cn",), 6: ("In",), 7: ("OU",), 8: ("CM",),
    9: ("AP",), 12: ("Pr",), 13: ("M2",), 14: ("operation",),
}

_MEMORY: list[Register] = [
    SAVE_PARAMETERS,
    _memory(0x03E1, "Monitor mode initialization", RW, enum=NO_YES),
    _memory(0x03E2, "Parameter initialization", RW_STOPPED, enum=dict(PARAMETER_INITIALIZATION_GROUPS),
            help="setting is prohibited during fault trip interruptions"),
    _memory(0x03E3, "Display changed parameters", RW, enum=NO_YES),
    _reserved(0x03E4, "memory", MEMORY_TABLE),
    _memory(0x03E5, "Delete all fault history", RW, enum=NO_YES),
    _memory(0x03E6, "Delete user-registered codes", RW, enum=NO_YES),
    _memory(0x03E7, "Hide parameter mode", RW, minimum=0, maximum=9999,
            help="write: password 0-9999; read: 0 unlock, 1 lock"),
    _memory(0x03E8, "Lock parameter mode", RW, minimum=0, maximum=9999,
            help="write: password 0-9999; read: 0 unlock, 1 lock"),
    _reserved(0x03E9, "memory", MEMORY_TABLE),
    _memory(0x03EA, "Initializing power consumption", RW, enum=NO_YES),
    _memory(0x03EB, "Initialize drive operation accumulative time", RW, enum=NO_YES),
    _memory(0x03EC, "Initialize cooling fan accumulated operation time", RW, enum=NO_YES),
]


# ---------------------------------------------------------------------------------------------
# Registered parameters 0x0100-0x0107 / 0x0110-0x0117 (ACG RS-485 manual, "Currently Registered CM Group
# Parameter"): the words at the addresses set in CM.31-CM.38 (read only) and CM.51-CM.58 (R/W).
# ---------------------------------------------------------------------------------------------

STATUS_PARAMETER_BASE = 0x0100
CONTROL_PARAMETER_BASE = 0x0110

_REGISTERED: list[Register] = [
    *(Register(STATUS_PARAMETER_BASE + i, "", f"Status Parameter-{i + 1}", access=R, group="registered",
               saved=False, source=REGISTERED_TABLE, help=f"the word at the address in CM.{31 + i}")
      for i in range(8)),
    *(Register(CONTROL_PARAMETER_BASE + i, "", f"Control Parameter-{i + 1}", group="registered", saved=False,
               source=REGISTERED_TABLE, help=f"the word at the address in CM.{51 + i}")
      for i in range(8)),
]


ACG_REGISTERS = RegisterMap([*_COMMON, *_REGISTERED, *_MONITOR, *_CONTROL, *_MEMORY, *_groups(), *_OPERATION])

#: Addresses that show another register's value: address -> address of the register that holds it.
#: The common area and control area acceleration/deceleration times are the operation group's
#: ACC/dEC (class 0x2A attributes 102/103 read "the value at Acc/Dec Time"), the control area's
#: motor rating words are bA.13/bA.15, and the common area target frequency is the network
#: frequency command 0x0380.
ALIASES: Mapping[int, int] = {
    0x0005: SPEED_REFERENCE.address,
    0x0007: ACCEL_TIME.address, 0x0383: ACCEL_TIME.address,
    0x0008: DECEL_TIME.address, 0x0384: DECEL_TIME.address,
    0x038A: RATED_CURRENT.address, 0x038B: RATED_VOLTAGE.address,
    0x0322: 0x0385,
}


# ---------------------------------------------------------------------------------------------
# Lookups
# ---------------------------------------------------------------------------------------------

# Long group names the manuals also use ("BAS-13 Rated Curr", "COM-94", "APP-01").
_GROUP_SPELLINGS = {g.lower(): g for g in GROUP_BASES if g != "operation"}
_GROUP_SPELLINGS.update({"bas": "bA", "com": "CM", "app": "AP", "prt": "Pr", "drv": "dr"})
_OPERATION_SPELLINGS = {c.lower(): c for c in OPERATION_CODES}
_OPERATION_SPELLINGS["fr9"] = "Frq"
_CODE_PATTERN = re.compile(r"^\s*([A-Za-z][A-Za-z0-9]?[A-Za-z]?)\s*[.\-_ ]?\s*0*(\d+)\s*$")


def normalize_code(text: str) -> str:
    """The keypad code as declared: "cm-07" -> "CM.7", "BAS-13" -> "bA.13", "acc" -> "ACC"."""
    lowered = text.strip().lower()
    if lowered in _OPERATION_SPELLINGS:
        return _OPERATION_SPELLINGS[lowered]
    match = _CODE_PATTERN.match(text)
    if match and match.group(1).lower() in _GROUP_SPELLINGS:
        return f"{_GROUP_SPELLINGS[match.group(1).lower()]}.{int(match.group(2))}"
    raise UnknownKey(f"not an ACG keypad code: {text!r}")


def register_for_code(text: str) -> Register:
    """The register of a keypad code, in any of the spellings ``normalize_code`` accepts."""
    code = normalize_code(text)
    try:
        return ACG_REGISTERS.by_code(code)
    except KeyError:
        raise UnknownKey(f"keypad code {code} has no communication address") from None


def class64_register(instance: int, attribute: int) -> Register | None:
    """The keypad parameter behind class 0x64 ``instance``/``attribute`` (ACG-ET2 manual)."""
    group = CLASS_64_ALIASES.get(instance)
    if group is None:
        group = next((g for g, number in CLASS_64_INSTANCES.items() if number == instance), None)
    if group is None:
        return None
    try:
        return ACG_REGISTERS.by_code(f"{group}.{attribute}")   # "Identical to the ACG Manual Code number"
    except KeyError:
        return None


def class64_path(register: Register) -> tuple[int, int] | None:
    """(instance, attribute) of a keypad parameter in class 0x64, or None outside its groups."""
    instance = CLASS_64_INSTANCES.get(register.group)
    return None if instance is None else (instance, int(register.code.rsplit(".", 1)[1]))


def modbus_rtu_number(address: int) -> int:
    """The decimal register number of the manual's "Modbus RTU" column (0x0300 -> 40768)."""
    return 40000 + address


def modbus_tcp_number(address: int) -> int:
    """The decimal register number of the manual's "Modbus TCP" column (0x0300 -> 40769)."""
    return 40001 + address


def input_instance(setting: int) -> InstanceSelection:
    """The CIP input assembly a CM.23 setting selects."""
    return CIP_INPUT_INSTANCES[setting]


def output_instance(setting: int) -> InstanceSelection:
    """The CIP output assembly a CM.24 setting selects."""
    return CIP_OUTPUT_INSTANCES[setting]
