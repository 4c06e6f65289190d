"""The option board's assemblies: appendix B layouts, Table C-6 sizes, Special I/O (Tables B-13 to
B-17) and the flexible format (section 4-7, appendix F), byte for byte."""

import pytest

from cipstack.assemblies.drive_profile import extended_speed_control_output
from cipstack.devices.omron.assemblies import (
    CENTIHERTZ,
    RPM,
    SIZES,
    componet_io_words,
    flexible_schema,
    omron_schemas,
    pair_sizes,
)
from cipstack.devices.omron.device import OmronDevice, build_omron_device
from cipstack.devices.omron.inverter import FlexibleRule
from cipstack.devices.omron.registers import CONNECTION_PATHS

MX2 = "MX2-A2015-E"
RX = "RX-A4055-E"


def device(name: str = MX2, **codes: int) -> OmronDevice:
    """A device with parameters written by function code, then the option board reset (they take effect)."""
    d = build_omron_device(name)
    d.advance(0.0)
    for code, value in codes.items():
        if code == "F001":
            d.inverter.write(0x0001, value, 0.0)
        else:
            d.inverter.write_code(code, value, 0.0)
    d.reset(0)
    return d


def option(name: str = MX2, **codes: int) -> OmronDevice:
    """Section 4-2-1 Step 1: A001 = A002 = 4 (MX2) / 5 (RX)."""
    source = 4 if name.startswith("MX2") else 5
    return device(name, A001=source, A002=source, **codes)


def out(d: OmronDevice, instance: int, data: bytes | str, now: float) -> None:
    d.advance(now)
    d.assembly.deliver(instance, bytes.fromhex(data) if isinstance(data, str) else data, now)


def settle(d: OmronDevice) -> float:
    end = d.next_deadline()
    assert end is not None
    d.advance(end)
    return end


def data(d: OmronDevice, instance: int) -> str:
    return d.assembly.data(instance).hex(" ")


# -- declarations -----------------------------------------------------------------------------------

def test_sizes_are_those_of_table_c6():
    schemas = omron_schemas()
    assert {i: s.size for i, s in schemas.items()} == dict(SIZES)
    assert {20: 4, 21: 4, 70: 4, 71: 4, 100: 8, 101: 8, 110: 8, 111: 8, 123: 6, 150: 8, 151: 8,
            153: 10}.items() <= dict(SIZES).items()
    # 20/21/70/71 are the AC drive profile layouts the ACG shares; 110/111 are the board's own.
    assert schemas[21].fields == extended_speed_control_output(21, "Hz", 0.01).fields
    assert "Acceleration" in schemas[110].name and schemas[110].name.startswith("Omron")
    assert flexible_schema(139, 8).size == 16 and flexible_schema(159, 1).size == 2


def test_componet_io_sizes_of_section_3_4():
    # Step 6/7: assemblies 101 and 153 give 8 bytes out and 10 bytes in: input 5 words, output 4 words.
    assert componet_io_words(101, 153) == (5, 4)
    assert componet_io_words(21, 71) == (2, 2)
    assert pair_sizes(139, 159, (3, 4)) == (6, 8)
    assert {path: pair_sizes(o, i) for path, (_, o, i) in CONNECTION_PATHS.items() if path != 6} == {
        0: (4, 4), 1: (4, 4), 2: (6, 6), 3: (8, 8), 4: (8, 8), 5: (8, 10), 7: (8, 8)}


def test_bit_positions_of_appendix_b():
    s = omron_schemas()
    assert s[21].encode(run_forward=1, run_reverse=1, fault_reset=1, net_ctrl=1, net_ref=1, speed_reference=1000) \
        == bytes.fromhex("67 00 e8 03")
    assert s[101].encode(run_forward=1, override_input_3=1, override_input_8=1, force_fault=1, fault_reset=1,
                         set_output_3=1, set_relay=1, set_output_1=1, set_output_2=1) \
        == bytes.fromhex("85 e7 00 00 00 00 00 00")
    assert s[110].encode(free_run=1, net_ref=1, accel_time=50, decel_time=36000) == \
        bytes.fromhex("48 00 00 00 32 00 a0 8c")
    assert s[111].encode(running_forward=1, faulted=1, input_1=1, input_4=1, forward_terminal=1, ref_from_net=1,
                         drive_state_detail=10, trip_cause=62) == bytes.fromhex("25 0a 00 00 00 00 3e a1")
    assert s[153].encode(ctrl_from_net=1, relay_output=1, output_4=1, input_8=1) == \
        bytes.fromhex("00 8c 00 00 00 00 00 00 80 00")
    assert omron_schemas(RPM)[70].field("speed_actual").unit == "rpm"
    assert omron_schemas(CENTIHERTZ)[70].field("speed_actual").scale == 0.01


# -- 20/70, 21/71, 123/173 --------------------------------------------------------------------------

@pytest.mark.parametrize("name", [MX2, RX])
def test_extended_speed_run_stop_and_state(name):
    d = option(name)
    assert data(d, 71) == "70 03 00 00"      # CFN, RFN (A001/A002 = option board), ready, state 3 Ready
    out(d, 21, "00 00 e8 03", 1.0)
    out(d, 21, "01 00 e8 03", 1.0)          # FWD, 10.00 Hz
    assert d.assembly.data(71)[1] == 4      # Enabled
    settle(d)
    assert data(d, 71) == "f4 04 e8 03"      # ARF RFN CFN RDY DFR, 10.00 Hz
    assert data(d, 70) == "04 00 e8 03"      # DFR
    out(d, 21, "00 00 e8 03", 10.0)         # decelerated stop
    assert d.assembly.data(71)[:2] == bytes.fromhex("74 05")   # stopping: DFR still set, state 5
    settle(d)
    assert data(d, 71) == "70 03 00 00"


def test_reverse_and_net_overrides():
    d = device(MX2)                          # A001/A002 not the option board
    assert data(d, 71) == "10 03 00 00"      # ready, not from the network
    out(d, 21, "00 00 d0 07", 1.0)
    out(d, 21, "62 00 d0 07", 1.0)          # REV with CTR and REF: network control (section 4-2-1 note)
    settle(d)
    assert data(d, 71) == "f8 04 d0 07"      # ARF RFN CFN RDY DRR, 20.00 Hz


def test_rising_edge_after_power_on():
    d = option(MX2)
    out(d, 21, "01 00 e8 03", 1.0)          # FWD already set at power on: no run (Table B-6 note)
    d.advance(5.0)
    assert data(d, 71) == "70 03 00 00"


def test_speed_units_of_section_4_2_5():
    d = option(MX2, P049=4)                 # 4 poles: RPM
    out(d, 20, "00 00 dc 05", 1.0)
    out(d, 20, "01 00 dc 05", 1.0)          # 1500 rpm = 50.00 Hz
    settle(d)
    assert data(d, 70) == "04 00 dc 05"
    assert d.inverter.read_code("d001") == 5000


def test_high_frequency_mode_speed_in_tenths_of_hertz():
    d = build_omron_device(MX2)
    d.advance(0.0)
    for code, value in {"b171": 2, "b180": 1, "A001": 4, "A002": 4}.items():
        d.inverter.write_code(code, value, 0.0)
    d.reset(0)
    out(d, 21, "00 00 64 00", 1.0)
    out(d, 21, "01 00 64 00", 1.0)          # 100 x 0.1 Hz = 10.0 Hz
    settle(d)
    assert data(d, 71) == "f4 04 64 00"
    assert d.inverter.read_code("d001") == 1000


def test_trip_and_reset_through_21_71():
    d = option(MX2)
    out(d, 21, "00 00 e8 03", 1.0)
    out(d, 21, "01 00 e8 03", 1.0)
    d.inject_trip(5)
    assert data(d, 71) == "61 07 00 00"      # FLT, CFN, RFN; Faulted (7); speed 0
    out(d, 21, "00 00 e8 03", 2.0)          # section 4-5-2: clear FWD, then RST
    out(d, 21, "04 00 e8 03", 2.0)
    assert data(d, 71) == "70 03 00 00"


def test_torque_assemblies_123_173():
    d = option(MX2, P046=2)
    assert d.default_pair == (123, 173)
    out(d, 123, "00 00 e8 03 14 00", 1.0)
    out(d, 123, "01 00 e8 03 14 00", 1.0)   # 20 % torque reference
    assert d.inverter.option_command.torque_reference == 20
    settle(d)
    assert data(d, 173) == "f4 04 e8 03 00 00"


# -- 101/151/153 ------------------------------------------------------------------------------------

def test_extended_control_overrides_and_outputs():
    d = option(MX2, P046=4, C021=63, C022=63, C026=63)
    out(d, 101, "04 c0 00 00 00 00 00 00", 1.0)      # CI3; CO1, CO2
    assert d.inverter.read_code("d005") == 0b100      # terminal [3] overridden (d005, section E-2-2)
    assert data(d, 151) == "22 34 00 00 00 00 00 00"  # DZS, RDY; CFN, MO1, MO2
    assert data(d, 153) == "22 34 00 00 00 00 00 00 04 00"   # MI3
    out(d, 101, "00 20 00 00 00 00 00 00", 1.0)      # CR: the relay
    assert data(d, 151) == "22 0c 00 00 00 00 00 00"  # MR
    out(d, 101, "00 01 00 00 00 00 00 00", 2.0)      # FFL: E62 (section 4-5-1)
    assert d.inverter.trip == 62
    assert d.assembly.data(151)[0] == 0x82            # FLT, DZS


def test_rx_terminal_8_and_outputs_3_to_5():
    d = option(RX, P046=5, C021=63, C022=63, C023=63, C024=63, C025=63, C026=63)
    out(d, 101, "80 1c 00 00 00 00 00 00", 1.0)      # CI8; CO3, CO4, CO5
    assert data(d, 153) == "22 c4 00 00 00 00 00 00 80 00"   # MO3, MO4 (outputs 13, 14), MI8


def test_free_run_through_110_111():
    d = option(MX2, P046=7)
    out(d, 110, "00 00 e8 03 00 00 00 00", 1.0)
    out(d, 110, "41 00 e8 03 0a 00 0a 00", 1.0)      # FWD, REF: 1.0 s ramps
    end = settle(d)
    assert end == pytest.approx(1.2)                  # 10 Hz of 50 Hz in 1.0 s
    assert data(d, 111) == "11 01 e8 03 00 00 00 c0"  # DFR, ARF; running; CFN RFN
    out(d, 110, "49 00 e8 03 0a 00 0a 00", 2.0)      # FRS: speed drops to 0 at once (section 4-2-4)
    assert data(d, 111) == "00 03 00 00 00 00 00 c0"  # free running
    d.inject_trip(12)
    assert d.assembly.data(111)[6] == 12              # trip cause E12


# -- Special I/O (Tables B-13 to B-17) ------------------------------------------------------------

def special(d: OmronDevice, request: str, now: float = 1.0) -> str:
    out(d, 100, request, now)
    return data(d, 150)


def test_special_io_reads_and_writes():
    d = device(MX2)
    # 43h: read double word F002 at 1103h: 1000 (10.00 s), least significant word first.
    assert special(d, "43 00 03 11 00 00 00 00") == "43 00 03 11 e8 03 00 00"
    # 50h: write F002 = 70000 (011170h): low word 1170h, high word 0001h.
    assert special(d, "50 00 03 11 70 11 01 00") == "50 00 03 11 00 00 00 00"
    assert d.inverter.read_code("F002") == 70000
    # 10h: write single word A004 at 1204h = 600 (60.0 Hz); 03h reads it back.
    assert special(d, "10 00 04 12 58 02 00 00") == "10 00 04 12 00 00 00 00"
    assert special(d, "03 00 04 12 00 00 00 00") == "03 00 04 12 58 02 00 00"


def test_special_io_fault_codes():
    d = option(MX2)
    assert special(d, "05 00 04 12 00 00 00 00") == "85 00 04 12 01 00 00 00"   # 01h function code error
    assert special(d, "03 00 ff 7f 00 00 00 00") == "83 00 ff 7f 02 00 00 00"   # 02h register number error
    assert special(d, "10 00 30 16 09 00 00 00") == "90 00 30 16 21 00 00 00"   # 21h P046 = 9 out of range
    assert special(d, "03 00 03 11 00 00 00 00") == "83 00 03 11 23 00 00 00"   # 23h word read of a double word
    assert special(d, "43 00 04 12 00 00 00 00") == "c3 00 04 12 23 00 00 00"   # 23h double read of a word
    assert special(d, "10 00 07 10 00 00 00 00") == "90 00 07 10 22 00 00 00"   # 22h d005 is a monitor
    out(d, 21, "00 00 e8 03", 1.0)
    out(d, 21, "01 00 e8 03", 1.0)
    assert special(d, "10 00 30 16 02 00 00 00", 1.5) == "90 00 30 16 22 00 00 00"  # 22h P046 while running
    d.inverter_link_ok = False
    assert special(d, "03 00 04 12 00 00 00 00", 1.6) == "83 00 04 12 04 00 00 00"  # 04h slave device failure


def test_special_io_write_acts_once_per_new_request():
    d = device(MX2)
    special(d, "10 00 04 12 58 02 00 00")
    d.inverter.write_code("A004", 500, 1.0)
    special(d, "10 00 04 12 58 02 00 00", 2.0)       # the same output again: no second write
    assert d.inverter.read_code("A004") == 500


# -- flexible format (section 4-7, appendix F) --------------------------------------------------------

TYPICAL = dict(P046=6, P160=0x1F01, P161=0x0001, P162=0x0002, P170=0x0005, P171=0x1E01, P172=0x1001, P173=0x1002)


@pytest.mark.parametrize("name", [MX2, RX])
def test_typical_configuration_tables_18_to_21(name):
    d = device(name, **TYPICAL)
    # "the Output has a data size of 3 words and the Input has 4 words"
    assert (d.assembly.points[139].size, d.assembly.points[159].size) == (6, 8)
    assert d.pair_sizes() == (6, 8) and (139, 159) in d.pairs()
    assert data(d, 159) == "01 00 02 00 00 00 00 00"             # Table 19: 0001 0002 0000 0000
    d.inverter.write_code("A001", 3, 1.0)                         # Step 8: A001 = A002 = 3
    d.inverter.write_code("A002", 3, 1.0)
    out(d, 139, "02 00 00 00 e8 03", 1.0)                         # Table 20: 0002 0000 03E8
    settle(d)
    assert data(d, 159) == "03 00 1a 00 00 00 e8 03"             # Table 21: 0003 001A 0000 03E8
    out(d, 139, "06 00 00 00 e8 03", 5.0)                         # Step 11: Dir reverses
    assert d.assembly.data(159)[2] & 0x10 == 0                    # FA1 clears
    out(d, 139, "08 00 00 00 e8 03", 20.0)                        # section 4-7-3: EXT trips
    assert d.inverter.trip == 12 and d.assembly.data(159)[3] == 0x01   # AL (bit 8)


def test_reserved_words_and_size_from_highest_parameter():
    d = device(MX2, P046=6, P160=0x1F01, P162=0x0002, P170=0x0005, P172=0x1E01)   # Note 2: P161, P171 reserved
    assert (d.assembly.points[139].size, d.assembly.points[159].size) == (6, 6)
    assert data(d, 159) == "01 00 00 00 02 00"


def test_low_word_alone_in_output():
    # Section F Tip / Note 3: 0002h alone as frequency reference is allowed in the output area.
    d = device(MX2, P046=6, P160=0x1F01, P161=0x0002, P170=0x1E01, A001=3, A002=3)
    out(d, 139, "02 00 d0 07", 1.0)
    assert d.inverter.read_code("F001") == 2000


BROKEN = [
    (dict(P168=1), FlexibleRule.RESERVED_NOT_ZERO),
    (dict(P160=0), FlexibleRule.EMPTY_AREA),
    (dict(P161=0x7FFF), FlexibleRule.NO_SUCH_REGISTER),
    (dict(P171=0x1002, P172=0), FlexibleRule.DOUBLE_WORD_SPLIT),    # the low word alone in the input area
    (dict(P161=0x0001, P162=0x0001), FlexibleRule.DOUBLE_WORD_SPLIT),
    (dict(P161=0x1F01), FlexibleRule.DUPLICATE_OUTPUT),
    (dict(P161=0x1001), FlexibleRule.READ_ONLY_OUTPUT),
    (dict(P161=0x1630), FlexibleRule.NOT_RUN_MODE_EDITABLE),         # P046 is not run-mode editable
]


@pytest.mark.parametrize(("change", "rule"), BROKEN)
def test_every_flexible_rule_trips_e64(change, rule):
    codes = dict(P046=6, P160=0x1F01, P170=0x1E01, P171=0x1001, P172=0x1002)
    codes.update(change)
    d = device(MX2, **codes)
    assert d.inverter.trip == 64                          # Note 5: E64 (MX2)
    assert rule in {p.rule for p in d.inverter.flexible_error.problems}
    assert d.identity.get(1, 5) & 0x0400                  # Major Recoverable Fault
    assert 139 not in d.assembly.points and (139, 159) not in d.pairs()


def test_rx_illegal_mapping_trips_e74():
    d = device(RX, P046=6, P160=0x1F01, P170=0x1E01, P178=1)
    assert d.inverter.trip == 74


def test_torque_register_outside_constant_torque_mode():
    # Tables 22/23 note: torque-related registers in the process area without torque control trip.
    d = build_omron_device(MX2)
    d.advance(0.0)
    for code, value in {"b049": 1, "b180": 1, "P046": 6, "P160": 0x1622, "P170": 0x1E01}.items():
        d.inverter.write_code(code, value, 0.0)
    d.reset(0)
    assert d.inverter.trip == 64
    assert FlexibleRule.TORQUE_NOT_AVAILABLE in {p.rule for p in d.inverter.flexible_error.problems}


def test_corrected_mapping_takes_effect_after_reset():
    # Appendix F Note 5 / Table 25: correct the parameters, then reset the unit.
    d = device(MX2, P046=6, P160=0x1F01, P170=0x1E01, P179=5)
    assert d.inverter.trip == 64 and 159 not in d.assembly.points
    d.inverter.write_code("P179", 0, 1.0)
    d.reset(0)
    assert d.inverter.trip == 0 and d.identity.get(1, 5) & 0x0400 == 0
    assert (d.assembly.points[139].size, d.assembly.points[159].size) == (2, 2)
    assert data(d, 159) == "02 00"
