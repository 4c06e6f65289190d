"""MX2/RX registers, function codes (Table E-3), trip codes (Table D-5) and family traits."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from cipstack.cip.types import DINT, UDINT
from cipstack.devices.omron.models import Family
from cipstack.devices.omron.registers import (
    COIL_DATA_0,
    COIL_DATA_1,
    CONNECTION_PATHS,
    EEPROM_SAVE,
    FUNCTION_GROUPS,
    TRAITS,
    TRIP_CODES,
    SpeedUnit,
    centihertz_to_speed,
    function_code_from_number,
    function_code_from_path,
    function_code_number,
    function_code_path,
    modbus_address,
    modbus_path,
    normalize_code,
    register_map,
    register_set,
    speed_to_centihertz,
    trip_code,
)
from cipstack.devices.registers import Register, RegisterAccess, RegisterError, RegisterRefusal

MX2 = register_set(Family.MX2)
RX = register_set(Family.RX)


# -- Table E-3 ------------------------------------------------------------------------------------

def test_examples_of_section_e2():
    # Example 1: "3 (d) * 1000 + 005 equals 3005 or 0BBD Hex".
    assert function_code_number("d005") == 3005 == 0x0BBD
    assert function_code_path("d005") == (0x0B, 0xBD)
    # Example 2: "15 (P) * 1000 + 060 equals 15060 or 3AD4 Hex".
    assert function_code_number("P060") == 15060 == 0x3AD4
    assert function_code_path("P060") == (0x3A, 0xD4)
    # Section 4-6-2: "F002 corresponds to address 5002 (138A Hex)".
    assert function_code_number("F002") == 5002 == 0x138A


@pytest.mark.parametrize(("first", "last", "low", "high"), [
    ("A001", "A999", 0x0001, 0x03E7),
    ("b001", "b999", 0x03E9, 0x07CF),
    ("C001", "C999", 0x07D1, 0x0BB7),
    ("d001", "d999", 0x0BB9, 0x0F9F),
    ("F001", "F999", 0x1389, 0x176F),
    ("H001", "H999", 0x1B59, 0x1F3F),
    ("P001", "P999", 0x3A99, 0x3E7F),
    ("U001", "U999", 0x4E21, 0x5207),
])
def test_hexadecimal_ranges_of_table_e3(first, last, low, high):
    assert function_code_number(first) == low
    assert function_code_number(last) == high
    assert function_code_from_number(low) == first
    assert function_code_from_path(high >> 8, high & 0xFF) == last


def test_group_letters_and_spelling():
    assert set(FUNCTION_GROUPS) == {"A", "b", "C", "d", "F", "H", "P", "U"}
    assert normalize_code("p044") == "P044"
    assert normalize_code("B049") == "b049"
    assert function_code_number("B049") == function_code_number("b049") == 1049


@pytest.mark.parametrize("code", ["E001", "P000", "P1000", "X12", "", "d0x5"])
def test_not_function_codes(code):
    with pytest.raises(ValueError):
        function_code_number(code)


@pytest.mark.parametrize("number", [0, 1000, 4001, 6500, 15000, 21000])
def test_numbers_outside_table_e3(number):
    with pytest.raises(ValueError):
        function_code_from_number(number)


@given(st.sampled_from(sorted(FUNCTION_GROUPS)), st.integers(1, 999))
def test_function_code_path_round_trip(group, number):
    code = f"{group}{number:03d}"
    instance, attribute = function_code_path(code)
    assert 0 <= instance <= 0xFF and 0 <= attribute <= 0xFF
    assert function_code_from_path(instance, attribute) == code


def test_modbus_register_object_path():
    # Section E-3-2: address XXYYh is instance XX, attribute YY; Table C-2: 0900h is instance 09h, attribute 0.
    assert modbus_path(EEPROM_SAVE) == (0x09, 0x00)
    assert modbus_path(COIL_DATA_1) == (0x1E, 0x01)
    assert modbus_address(0x1F, 0x01) == COIL_DATA_0
    with pytest.raises(ValueError):
        modbus_path(0x10000)


# -- the registers the manual uses ---------------------------------------------------------------

def test_coil_data_0_bits_of_table_18():
    coils = MX2.at(COIL_DATA_0)
    assert coils is not None and coils.access is RegisterAccess.READ_WRITE
    assert [(b.index, b.name) for b in coils.bits[:4]] == [(1, "Opr"), (2, "Dir"), (3, "EXT"), (4, "RS")]
    # Table 25: "the Trip reset coil (04h) in coil register 0x1F01".
    assert coils.bit("RS").coil == 0x04 and coils.bit("RS").index == 4
    assert coils.bit("In1").index == 7 and coils.bit("In7").index == 13
    with pytest.raises(KeyError):
        coils.bit("In8")                    # "In8 RX: only applicable for the RX Inverter"
    assert RX.at(COIL_DATA_0).bit("In8").index == 14
    # Table 18 note: bit 15, the operation status coil 000Fh, is not for the output area.
    assert not coils.bit("RUN_STATUS").writable and coils.bit("RUN_STATUS").coil == 0x0F
    assert coils.writable_bits == 0x3F9E      # bits 1-4 and 7-13; 0, 5 and 6 are unused
    assert RX.at(COIL_DATA_0).writable_bits == 0x7F9E


def test_coil_data_1_bits_of_table_19():
    coils = MX2.at(COIL_DATA_1)
    assert coils.access is RegisterAccess.READ
    names = {b.index: b.name for b in coils.bits}
    assert names == {0: "Dir", 1: "Rdy", 3: "RUN", 4: "FA1", 5: "FA2", 6: "OL", 7: "OD", 8: "AL", 9: "FA3",
                     10: "OTQ", 12: "UV", 13: "TRQ", 14: "RNT", 15: "ONT"}
    assert [b.coil for b in coils.bits][:2] == [0x10, 0x11]      # coils 0010h to 001Fh
    # Table 21: 001Ah reads Rdy, RUN and FA1.
    assert {names[i] for i in range(16) if 0x001A >> i & 1} == {"Rdy", "RUN", "FA1"}


def test_f001_and_d001_are_double_words_high_word_first():
    for registers in (MX2, RX):
        f001 = registers.by_code("F001")
        assert (f001.address, f001.words, f001.type, f001.scale, f001.unit) == (0x0001, 2, UDINT, 0.01, "Hz")
        # Table 20: 10.00 Hz is 0000h at 0001h and 03E8h at 0002h.
        assert f001.register.to_words(1000) == [0x0000, 0x03E8]
        assert registers.word(0x0002) == (f001, 1)
        d001 = registers.by_code("d001")
        assert (d001.address, d001.words, d001.access) == (0x1001, 2, RegisterAccess.READ)
        assert registers.word(0x1002) == (d001, 1)
        assert registers.at(0x0005).name == "Inverter status C"
        assert registers.at(EEPROM_SAVE).access is RegisterAccess.WRITE
    assert not MX2.by_code("F001").function_code_writable      # section E-2-2


def test_componet_parameters_of_tables_9_10_12():
    for registers in (MX2, RX):
        p044 = registers.by_code("P044")
        assert (p044.minimum, p044.maximum, p044.scale, p044.unit) == (0, 9999, 0.1, "s")
        for code in ("P045", "P048"):
            action = registers.by_code(code)
            assert action.default == 0 and dict(action.enum)[0] == "inverter trip"
            assert dict(action.enum)[4] == "deceleration and stop" and action.maximum == 4
        p046 = registers.by_code("P046")
        assert p046.default == 1 and len(p046.enum) == 8 and p046.enum[6] == "Flexible Format"
        assert (registers.by_code("P190").minimum, registers.by_code("P190").maximum) == (0, 63)
        for code in ("P044", "P045", "P046", "P048", "P049", "P160", "P177", "P190", "A001", "A002"):
            assert registers.by_code(code).access is RegisterAccess.WRITE_STOPPED, code
        for code in ("F001", "F002", "F003", "C102"):
            assert registers.by_code(code).access is RegisterAccess.READ_WRITE, code
    assert CONNECTION_PATHS[1] == ("Extended Speed IO", 21, 71)
    assert CONNECTION_PATHS[6][1:] == (139, 159)


def test_p049_takes_even_pole_counts_only():
    p049 = MX2.by_code("P049")
    assert p049.check(38) == 38 and p049.check(0) == 0
    for bad in (3, 40, -2):
        with pytest.raises(RegisterError) as caught:
            p049.check(bad)
        assert caught.value.refusal is RegisterRefusal.OUT_OF_RANGE


def test_source_selection_values_differ_per_family():
    assert MX2.by_code("A001").enum[4] == "Option Board Interface"
    assert RX.by_code("A001").enum[5] == "Option Board Interface 2"
    assert MX2.by_code("A002").enum[3] == RX.by_code("A002").enum[3] == "Modbus network input"
    assert MX2.by_code("P033").enum[6] == "Option Board Interface"
    assert RX.by_code("P033").enum[7] == "Option Board Interface 2"
    assert MX2.by_code("P036").enum[5] == "Option Board Interface"
    assert RX.by_code("P036").enum[6] == "Option Board Interface 2"
    assert (TRAITS[Family.MX2].option_source, TRAITS[Family.RX].option_source) == (4, 5)


def test_terminals_and_outputs_per_family():
    assert "C007" in MX2.by_key and "C008" not in MX2.by_key
    assert "C008" in RX.by_key
    assert "C023" not in MX2.by_key and "C025" in RX.by_key
    assert TRAITS[Family.MX2].output_terminals == ("11", "12", "AL")
    assert TRAITS[Family.RX].output_terminals == ("11", "12", "13", "14", "15", "AL")
    assert (TRAITS[Family.MX2].discrete_inputs, TRAITS[Family.RX].discrete_inputs) == (7, 9)
    assert "b171" in MX2.by_key and "b171" not in RX.by_key     # section 4-1: b171 on the MX2, b084 on the RX


def test_flexible_mapping_parameters():
    codes = [f"P16{n}" for n in range(10)] + [f"P17{n}" for n in range(10)]
    for code in codes:
        parameter = MX2.by_code(code)
        assert parameter.default == 0 and parameter.maximum == 0xFFFF
    assert [MX2.by_code(c).address for c in ("P160", "P169", "P170", "P179")] == [0x16A2, 0x16AB, 0x16AC, 0x16B5]


def test_torque_related_registers():
    torque = {p.code for p in MX2.parameters if p.torque_related}
    assert torque == {"P033", "P034", "P036", "P037", "P039", "P040", "d012"}


def test_p060_is_a_signed_double_word():
    p060 = MX2.by_code("P060")
    assert (p060.type, p060.words, p060.function_code_number) == (DINT, 2, 15060)
    assert p060.register.to_words(128000) == [0x0001, 0xF400]    # section E-2-2 Example 2: 01F400h


def test_modbus_view_is_a_register_map():
    mx2 = register_map(Family.MX2)
    assert isinstance(mx2[0x162E], Register) and mx2[0x162E].code == "P044"
    assert mx2.by_code("F002").address == 0x1103
    # The RX has Modbus addresses only where this manual gives them.
    assert sorted(register_map(Family.RX)) == [0x0001, 0x0005, 0x0900, 0x1001, 0x1E01, 0x1F01]
    assert RX.by_code("P044").address is None and RX.by_code("P044").register is None


def test_every_family_has_the_registers_the_brief_lists():
    for registers in (MX2, RX):
        for code in ("F001", "F002", "F003", "A001", "A002", "C102", "b049", "b180", "d001", "d060", "P033",
                     "P036", "P044", "P045", "P046", "P048", "P049", "P160", "P179", "P190"):
            assert registers.by_code(code).code == code
    with pytest.raises(KeyError):
        MX2.by_code("P999")


def test_saved_parameters_are_keyed_by_function_code_number():
    assert MX2.by_number[15044].code == "P044"
    assert RX.by_number[1049].code == "b049"
    assert not MX2.by_code("d001").saved and MX2.by_code("d060").saved


# -- Table D-5 -----------------------------------------------------------------------------------------

@pytest.mark.parametrize(("family", "number", "cip", "name"), [
    (Family.MX2, 1, 0x2200, "Over-current event while at constant speed"),
    (Family.RX, 12, 0x9000, "External trip"),
    (Family.MX2, 14, 0x2120, "Ground fault"),
    (Family.MX2, 50, 0x6200, "EzSQ user trip 0"),
    (Family.MX2, 62, 0x7510, "Option error (External trip)"),
    (Family.MX2, 63, 0x7510, "Communication lost / idle"),
    (Family.MX2, 64, 0x6320, "Illegal flexible mapping"),
    (Family.RX, 72, 0x7510, "Option error (External trip)"),
    (Family.RX, 74, 0x6320, "Illegal flexible mapping"),
    (Family.RX, 83, 0x8501, "Position control range error"),
])
def test_error_code_conversion(family, number, cip, name):
    found = trip_code(family, number)
    assert (found.cip_code, found.name, found.code) == (cip, name, f"E{number:02d}")


def test_option_errors_belong_to_one_family():
    with pytest.raises(KeyError):
        trip_code(Family.RX, 64)
    with pytest.raises(KeyError):
        trip_code(Family.MX2, 74)
    with pytest.raises(KeyError):
        trip_code(Family.MX2, 17)        # not in Table D-5
    assert trip_code(Family.MX2, 60).cip_name == "Serial Interface No 1"
    assert trip_code(Family.RX, 70).cip_name == "Serial Interface No 2"
    assert len({(t.number, t.families) for t in TRIP_CODES}) == len(TRIP_CODES)


def test_option_trip_codes_per_family():
    mx2, rx = TRAITS[Family.MX2], TRAITS[Family.RX]
    assert (mx2.trip_force_fault, mx2.trip_network, mx2.trip_flexible_mapping) == (62, 63, 64)
    assert (rx.trip_force_fault, rx.trip_network, rx.trip_flexible_mapping) == (72, 73, 74)


# -- speed scaling (section 4-2-5, Table B-2) ---------------------------------------------------------

def test_speed_units():
    mx2, rx = TRAITS[Family.MX2], TRAITS[Family.RX]
    assert mx2.speed_unit(0, 0) is SpeedUnit.CENTIHERTZ
    assert mx2.speed_unit(0, 2) is SpeedUnit.DECIHERTZ       # high-frequency mode
    assert mx2.speed_unit(4, 2) is SpeedUnit.RPM             # P049 wins
    assert rx.speed_unit(0, 2) is SpeedUnit.CENTIHERTZ       # the RX has no high-frequency mode
    assert rx.speed_unit(2, 0) is SpeedUnit.RPM


def test_speed_conversions():
    assert speed_to_centihertz(1500, SpeedUnit.RPM, 4) == 5000      # 1500 rpm, 4 poles: 50 Hz
    assert speed_to_centihertz(100, SpeedUnit.DECIHERTZ) == 1000    # 10.0 Hz
    assert centihertz_to_speed(5000, SpeedUnit.RPM, 2) == 3000
    assert centihertz_to_speed(1000, SpeedUnit.CENTIHERTZ) == 1000


@given(st.integers(0, 40000), st.sampled_from(range(2, 40, 2)))
def test_rpm_round_trip(centihertz, poles):
    rpm = centihertz_to_speed(centihertz, SpeedUnit.RPM, poles)
    assert abs(speed_to_centihertz(rpm, SpeedUnit.RPM, poles) - centihertz) <= poles * 100 / 240 + 1e-9
