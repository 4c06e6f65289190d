"""The ACG register map against the tables of the ACG-ET2 manual (appendix B) and the ACG RS-485 manual (chapter 5)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cipstack.cip.types import INT, UINT
from cipstack.devices.acg import registers as acg
from cipstack.devices.acg import status_words as words
from cipstack.devices.acg.registers import (
    ACG_REGISTERS,
    ALIASES,
    CIP_INPUT_INSTANCES,
    CIP_OUTPUT_INSTANCES,
    class64_path,
    class64_register,
    modbus_rtu_number,
    modbus_tcp_number,
    normalize_code,
    register_for_code,
)
from cipstack.devices.registers import Register, RegisterAccess, RegisterError, RegisterMap, RegisterRefusal


def code(text: str) -> Register:
    return ACG_REGISTERS.by_code(text)


# --- areas of the ACG RS-485 manual -----------------------------------------------------------------------

@pytest.mark.parametrize(("first", "last", "group"), [
    (0x0000, 0x001B, "common"),     # Compatible Common Area Parameter
    (0x0300, 0x034C, "monitor"),    # Monitoring Area Parameter (Read Only)
    (0x0380, 0x0395, "control"),    # Control Area Parameter (Read/Write)
    (0x03E0, 0x03EC, "memory"),     # Drive Memory Control Area Parameter
])
def test_every_word_of_each_area_is_declared(first: int, last: int, group: str) -> None:
    addresses = [r.address for r in ACG_REGISTERS.group(group)]
    assert addresses == list(range(first, last + 1))


def test_monitoring_area_is_read_only_but_the_virtual_inputs_the_chapter_writes() -> None:
    """0x0322 is written in the ACG RS-485 manual's own example ("assign a 0h0001 value to the communication
    address 0h0322"): it is the value of 0x0385; every other monitoring word is read only."""
    writable = [r.address for r in ACG_REGISTERS.group("monitor") if r.access is not RegisterAccess.READ]
    assert writable == [0x0322]


def test_common_area_values_from_the_table() -> None:
    assert ACG_REGISTERS[0x0000].default == 16 and ACG_REGISTERS[0x0000].enum == {16: "ACG"}
    assert ACG_REGISTERS[0x0001].enum[256] == "0.4 kW (1/2 hp)"
    assert ACG_REGISTERS[0x0005].scale == 0.01 and ACG_REGISTERS[0x0005].unit == "Hz"
    assert (ACG_REGISTERS[0x0007].scale, ACG_REGISTERS[0x0007].unit) == (0.1, "s")
    assert ACG_REGISTERS[0x000A].access is RegisterAccess.READ
    assert ACG_REGISTERS[0x001A].enum == {0: "Hz", 1: "Rpm"}


def test_monitoring_values_from_the_table() -> None:
    assert ACG_REGISTERS[0x0300].default == 0x0010
    assert ACG_REGISTERS[0x0301].enum[0x40B0] == "11 kW"
    assert ACG_REGISTERS[0x0302].enum[0x0431] == "460V 3-phase forced cooling"
    assert ACG_REGISTERS[0x0311].name == "Output frequency" and ACG_REGISTERS[0x0311].scale == 0.01
    # 0x0313 motor feedback speed is directional: -32768..32767 rpm.
    assert ACG_REGISTERS[0x0313].type is INT
    assert (ACG_REGISTERS[0x0313].raw_minimum, ACG_REGISTERS[0x0313].raw_maximum) == (-32768, 32767)
    assert ACG_REGISTERS[0x034A].enum == {0: "None", 11: "EtherNet/IP or Mod TCP"}


def test_trip_and_warning_bits_from_the_monitoring_table() -> None:
    assert words.LatchTrip1.FUSE_OPEN == 1 << 15 and words.LatchTrip1.OVERLOAD == 1
    assert words.LatchTrip2.NO_MOTOR == 1 << 9 and words.LatchTrip2.FAN_TRIP == 1 << 3
    assert words.LevelTrip.BX == 1 and words.LevelTrip.LOST_COMMAND == 1 << 2
    assert words.WarningInformation.LOST_COMMAND == 1 << 3
    assert words.OperationStatus.SPEED_REACHED == 1 << 6
    assert words.OperationStatus.FREQUENCY_FROM_COMMUNICATION == 1 << 14


def test_control_word_examples() -> None:
    # ACG RS-485 manual: "Forward operation command 0003h, Reverse operation command 0001h."
    assert words.ControlCommand.RUN | words.ControlCommand.FORWARD == 0x0003
    assert words.ControlCommand.RUN == 0x0001


def test_memory_control_marks() -> None:
    # "R/W" without the run mark: writable when stopped only; the run-marked ones in run too.
    assert ACG_REGISTERS[0x03E0].access is RegisterAccess.WRITE_STOPPED
    assert ACG_REGISTERS[0x03E0].enum == {0: "No", 1: "Yes"}
    assert ACG_REGISTERS[0x03E2].access is RegisterAccess.WRITE_STOPPED
    assert ACG_REGISTERS[0x03E2].enum[14] == "Operation Grp" and 10 not in ACG_REGISTERS[0x03E2].enum
    for address in (0x03E3, 0x03E5, 0x03E6, 0x03E7, 0x03E8, 0x03EA, 0x03EB, 0x03EC):
        assert ACG_REGISTERS[address].access is RegisterAccess.READ_WRITE
    assert (ACG_REGISTERS[0x03E7].raw_minimum, ACG_REGISTERS[0x03E7].raw_maximum) == (0, 9999)


def test_registered_parameter_areas() -> None:
    status = [r for r in ACG_REGISTERS.group("registered") if r.access is RegisterAccess.READ]
    control = [r for r in ACG_REGISTERS.group("registered") if r.access is RegisterAccess.READ_WRITE]
    assert [r.address for r in status] == list(range(0x0100, 0x0108))
    assert [r.address for r in control] == list(range(0x0110, 0x0118))


# --- keypad groups ---------------------------------------------------------------------------

# Rows of the ACG RS-485 manual's "Drive Parameter Modbus Communication Addresses": code, Modbus RTU decimal.
# Several carry the OCR'd hex address with "B" read as "8" (dr.11 "1108", bA.11 "1208" ...);
# the decimal column gives the true address.
ADDRESS_ROWS = [
    ("dr.9", 44361), ("dr.11", 44363), ("dr.20", 44372), ("dr.91", 44443), ("dr.98", 44450),
    ("bA.1", 44609), ("bA.11", 44619), ("bA.75", 44683), ("bA.83", 44691),
    ("Ad.1", 44865), ("Ad.86", 44950), ("Cn.11", 45131), ("Cn.83", 45203),
    ("In.1", 45377), ("In.99", 45475), ("OU.30", 45662), ("OU.72", 45704),
    ("CM.1", 45889), ("CM.23", 45911), ("CM.24", 45912), ("CM.91", 45979), ("CM.93", 45981),
    ("AP.1", 46145), ("AP.45", 46189), ("Pr.12", 46924), ("Pr.13", 46925), ("Pr.14", 46926),
    ("Pr.42", 46954), ("Pr.96", 47008), ("M2.4", 47172), ("M2.42", 47210),
    ("ACC", 47937), ("dEC", 47938), ("drv", 47939), ("Frq", 47940), ("drC", 47949),
]


@pytest.mark.parametrize(("keypad_code", "rtu"), ADDRESS_ROWS)
def test_address_table_rows(keypad_code: str, rtu: int) -> None:
    register = code(keypad_code)
    assert modbus_rtu_number(register.address) == rtu
    assert modbus_tcp_number(register.address) == rtu + 1


def test_every_listed_code_is_at_group_base_plus_number_or_as_printed() -> None:
    assert acg.PRINTED_ADDRESSES == {"M2.34": 0x1C12}
    for group, numbers in acg.LISTED_CODES.items():
        declared = {r.code for r in ACG_REGISTERS.group(group)}
        for number in numbers:
            register = code(f"{group}.{number}")
            expected = acg.PRINTED_ADDRESSES.get(register.code, acg.GROUP_BASES[group] + number)
            assert register.address == expected
        assert {f"{group}.{n}" for n in numbers} <= declared


def test_group_counts() -> None:
    counts = {group: len(ACG_REGISTERS.group(group)) for group in acg.KEYPAD_GROUPS}
    assert counts == {"dr": 23, "bA": 44, "Ad": 61, "Cn": 30, "In": 44, "OU": 25, "CM": 73, "AP": 28, "Pr": 58,
                      "M2": 25, "operation": 14}


def test_codes_without_an_address_are_not_declared() -> None:
    # bA.20-bA.24, Ad.83 and M2.17-M2.20 are printed with "-" for their address.
    for missing in ("bA.20", "bA.24", "Ad.83", "M2.17", "M2.20"):
        with pytest.raises(KeyError):
            code(missing)


def test_m2_34_reconstructed_address() -> None:
    # Printed 1C12 / 47186 (ACG RS-485 manual), hex and decimal agreeing, away from the group rule's 0x1C22.
    assert code("M2.34").address == 0x1C12 and modbus_rtu_number(0x1C12) == 47186
    assert 0x1C22 not in ACG_REGISTERS
    assert class64_register(12, 34) is code("M2.34") and class64_path(code("M2.34")) == (12, 34)
    assert class64_register(12, 18) is None                  # M2.18 has no address


def test_operation_group() -> None:
    assert [r.code for r in ACG_REGISTERS.group("operation")] == list(acg.OPERATION_CODES)
    assert code("drv").default == 1 and code("drv").enum[4] == "Field Bus" and code("drv").raw_maximum == 4
    assert code("Frq").default == 0 and code("Frq").enum[8] == "Field Bus" and code("Frq").raw_maximum == 8
    assert code("Frq").enum[6] == "Int485" and code("drv").enum[3] == "Int485"
    assert code("Cur").access is RegisterAccess.READ


# ACG-ET2 manual, "Keypad Parameters Related to ACG-ET2 Communication Board", every row:
# code, name, default, minimum, maximum.
ET2_TABLE = [
    ("CM.7", "FBus ID", 10, 0, 220),
    ("CM.10", "Opt Parameter 1", 192, 0, 255), ("CM.11", "Opt Parameter 2", 168, 0, 255),
    ("CM.12", "Opt Parameter 3", 1, 0, 255), ("CM.13", "Opt Parameter 4", 101, 0, 255),
    ("CM.14", "Opt Parameter 5", 255, 0, 255), ("CM.15", "Opt Parameter 6", 255, 0, 255),
    ("CM.16", "Opt Parameter 7", 255, 0, 255), ("CM.17", "Opt Parameter 8", 0, 0, 255),
    ("CM.18", "Opt Parameter 9", 192, 0, 255), ("CM.19", "Opt Parameter 10", 168, 0, 255),
    ("CM.20", "Opt Parameter 11", 1, 0, 255), ("CM.21", "Opt Parameter 12", 10, 0, 255),
    ("CM.22", "Opt Parameter 13", 0, 0, 0),
    ("CM.23", "Opt Parameter 14", 1, 0, 11), ("CM.24", "Opt Parameter 15", 1, 0, 11),
    ("CM.30", "Para Status Num", 3, 0, 8),
    ("CM.31", "Para Status-1", 0x000A, 0, 0xFFFF), ("CM.32", "Para Status-2", 0x000E, 0, 0xFFFF),
    ("CM.33", "Para Status-3", 0x000F, 0, 0xFFFF), ("CM.34", "Para Status-4", 0, 0, 0xFFFF),
    ("CM.35", "Para Status-5", 0, 0, 0xFFFF), ("CM.36", "Para Status-6", 0, 0, 0xFFFF),
    ("CM.37", "Para Status-7", 0, 0, 0xFFFF), ("CM.38", "Para Status-8", 0, 0, 0xFFFF),
    ("CM.50", "Para Ctrl Num", 2, 0, 8),
    ("CM.51", "Para Control-1", 0x0005, 0, 0xFFFF), ("CM.52", "Para Control-2", 0x0006, 0, 0xFFFF),
    ("CM.53", "Para Control-3", 0, 0, 0xFFFF), ("CM.54", "Para Control-4", 0, 0, 0xFFFF),
    ("CM.55", "Para Control-5", 0, 0, 0xFFFF), ("CM.56", "Para Control-6", 0, 0, 0xFFFF),
    ("CM.57", "Para Control-7", 0, 0, 0xFFFF), ("CM.58", "Para Control-8", 0, 0, 0xFFFF),
    ("drv", "Cmd Source", 1, 0, 4), ("Frq", "Freq Ref Src", 0, 0, 8),
    ("Pr.12", "Lost Cmd Mode", 0, 0, 5), ("Pr.13", "Lost Cmd Time", 10, 1, 1200),
]


@pytest.mark.parametrize(("keypad_code", "name", "default", "minimum", "maximum"), ET2_TABLE)
def test_et2_keypad_table(keypad_code: str, name: str, default: int, minimum: int, maximum: int) -> None:
    register = code(keypad_code)
    assert (register.name, register.default) == (name, default)
    assert (register.raw_minimum, register.raw_maximum) == (minimum, maximum)
    assert register.check(default) == default
    with pytest.raises(RegisterError) as refused:
        register.check(maximum + 1)
    assert refused.value.refusal is RegisterRefusal.OUT_OF_RANGE


def test_et2_table_read_only_and_run_lock() -> None:
    assert code("CM.6").access is RegisterAccess.READ and code("CM.6").default == 0x0101
    assert code("CM.9").access is RegisterAccess.READ
    # "The setting cannot be written while the drive is operating."
    assert code("CM.23").access is RegisterAccess.WRITE_STOPPED
    assert code("CM.24").access is RegisterAccess.WRITE_STOPPED
    assert code("CM.94").enum == {0: "NO", 1: "YES"} and code("CM.94").default == 0


def test_lost_command_parameters() -> None:
    assert code("Pr.12").enum == {0: "None", 1: "Free-Run", 2: "Dec", 3: "Hold Input", 4: "Hold Output",
                                  5: "Lost Preset"}
    # Pr.13: 1.0 s by default, 0.1-120 s, in 0.1 s.
    assert code("Pr.13").default * code("Pr.13").scale == pytest.approx(1.0)
    assert code("Pr.13").raw_minimum * code("Pr.13").scale == pytest.approx(0.1)
    assert code("Pr.13").raw_maximum * code("Pr.13").scale == pytest.approx(120)
    assert (code("Pr.14").default, code("Pr.14").scale, code("Pr.14").unit) == (0, 0.01, "Hz")
    # Pr.14: 0.05-60.00 Hz (ACG-ET2 manual), with the table's default 0.00.
    assert (code("Pr.14").raw_minimum, code("Pr.14").raw_maximum) == (0, 6000)


def test_serial_cm_parameters() -> None:
    assert (code("CM.1").default, code("CM.1").raw_minimum, code("CM.1").raw_maximum) == (1, 1, 250)
    assert code("CM.3").default == 3 and code("CM.3").enum[3] == "9,600 bps"
    assert code("CM.4").enum[2] == "D8/PE/S1"
    assert code("CM.5").raw_maximum == 1000 and code("CM.5").unit == "ms"
    with pytest.raises(RegisterError):
        code("CM.2").check(1)       # 0 Modbus-RTU or 2, nothing else


def test_instance_tables() -> None:
    # ACG-ET2 manual, "CM.23 and CM.24 Settings Comparison".
    pairs = [(i.instance, o.instance) for i, o in zip(CIP_INPUT_INSTANCES, CIP_OUTPUT_INSTANCES, strict=True)]
    assert pairs == [(70, 20), (71, 21), (110, 100), (111, 101), *((140 + n, 120 + n) for n in range(1, 9))]
    for selection in (*CIP_INPUT_INSTANCES, *CIP_OUTPUT_INSTANCES):
        if selection.parameters is None:
            assert selection.size == 4 and selection.setting <= 3
        else:
            assert selection.size == 2 * selection.parameters and selection.parameters == selection.setting - 3
    assert code("CM.23").enum[4] == "instance 141" and code("CM.24").enum[11] == "instance 128"


def test_motor_data_parameters() -> None:
    # Class 0x28 attributes 6/7: BAS-13 Rated Curr 0.0-1000.0 A in 0.1 A, BAS-15 Rated Voltage 0-690 V.
    assert register_for_code("BAS-13") is code("bA.13")
    assert (code("bA.13").raw_maximum, code("bA.13").scale) == (10000, 0.1)
    assert code("bA.15").raw_maximum == 690


def test_aliases_share_their_target_declaration() -> None:
    for address, target in ALIASES.items():
        alias, holder = ACG_REGISTERS[address], ACG_REGISTERS[target]
        assert (alias.type, alias.scale, alias.unit, alias.raw_minimum, alias.raw_maximum) == (
            holder.type, holder.scale, holder.unit, holder.raw_minimum, holder.raw_maximum)
        assert not alias.saved
    assert ALIASES[0x0007] == ALIASES[0x0383] == code("ACC").address


def test_saved_flags() -> None:
    for register in ACG_REGISTERS.values():
        if register.group in ("common", "monitor", "control", "memory", "registered"):
            assert not register.saved, register
    assert code("ACC").saved and code("CM.23").saved and code("Pr.12").saved
    assert not code("CM.94").saved and not code("CM.6").saved and not code("Cur").saved


def test_declared_once() -> None:
    registers = list(ACG_REGISTERS.values())
    codes = [r.code for r in registers if r.code]
    assert len(codes) == len(set(codes))
    assert len({r.address for r in registers}) == len(registers) == len(ACG_REGISTERS)
    with pytest.raises(ValueError, match="declared twice"):
        RegisterMap([*registers, registers[0]])


def test_register_counts_per_area() -> None:
    assert len(ACG_REGISTERS) == 28 + 16 + 77 + 22 + 13 + 411 + 14


# --- lookups ---------------------------------------------------------------------------------

@pytest.mark.parametrize(("text", "expected"), [
    ("CM.07", "CM.7"), ("cm-94", "CM.94"), ("COM-94", "CM.94"), ("BAS-13", "bA.13"), ("APP-01", "AP.1"),
    ("pr.12", "Pr.12"), ("Fr9", "Frq"), ("acc", "ACC"), ("0.00", "0.00"), ("dr.09", "dr.9"),
])
def test_normalize_code(text: str, expected: str) -> None:
    assert normalize_code(text) == expected


def test_normalize_code_rejects_other_text() -> None:
    with pytest.raises(KeyError):
        normalize_code("XY.3")
    with pytest.raises(KeyError, match="no communication address"):
        register_for_code("bA.20")


def test_class_0x64_paths() -> None:
    # ACG-ET2 manual, Class 0x64: instance per group, attribute = code number.
    assert class64_register(7, 23) is code("CM.23")
    assert class64_register(11, 12) is code("Pr.12")
    assert class64_register(1, 20) is code("dr.20")
    assert class64_register(7, 25) is None          # no CM.25
    assert class64_register(10, 1) is code("AP.1")  # "10 (AP Group)", ACG-ET2 manual
    for group in acg.CLASS_64_INSTANCES:
        for register in ACG_REGISTERS.group(group):
            path = class64_path(register)
            assert path is not None and class64_register(*path) is register
    assert class64_path(code("ACC")) is None


# --- words -----------------------------------------------------------------------------------

@given(st.sampled_from(sorted(ACG_REGISTERS)), st.data())
def test_word_split_and_join(address: int, data: st.DataObject) -> None:
    register = ACG_REGISTERS[address]
    value = data.draw(st.integers(register.raw_minimum, register.raw_maximum))
    words = register.to_words(value)
    assert len(words) == register.words == 1
    assert all(0 <= w <= 0xFFFF for w in words)
    assert register.from_words(words) == value


def test_signed_word_on_the_wire() -> None:
    assert ACG_REGISTERS[0x0313].to_words(-1800) == [0xF8F8]
    assert ACG_REGISTERS[0x0313].from_words([0xF8F8]) == -1800
    assert ACG_REGISTERS[0x0311].type is UINT and ACG_REGISTERS[0x0311].to_words(6000) == [0x1770]
