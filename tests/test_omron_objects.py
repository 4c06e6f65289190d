"""The option board's objects (appendices C, D, E): attributes, access, services, the Table E-3
arithmetic and the error codes of Table E-5, through the device's message router."""

import pytest

from cipstack.cip.epath import request_path
from cipstack.cip.messages import MessageRouterRequest, MessageRouterResponse
from cipstack.cip.router import RequestContext
from cipstack.devices.omron.device import OmronDevice, build_omron_device
from cipstack.devices.omron.registers import function_code_path, modbus_path
from cipstack.devices.state import load_state

MX2 = "MX2-A2015-E"
RX = "RX-A4055-E"
GET, SET, RESET, GET_ALL = 0x0E, 0x10, 0x05, 0x01


def request(d: OmronDevice, service: int, cls: int, instance: int | None, attribute: int | None = None,
            data: bytes | str = b"", now: float = 1.0) -> MessageRouterResponse:
    d.advance(now)
    raw = bytes.fromhex(data) if isinstance(data, str) else data
    return d.router.dispatch(MessageRouterRequest(service, request_path(cls, instance, attribute), raw).encode(),
                             RequestContext(d.router, now))


def get(d: OmronDevice, cls: int, instance: int, attribute: int, now: float = 1.0) -> str:
    reply = request(d, GET, cls, instance, attribute, now=now)
    assert reply.general_status == 0, reply
    return reply.data.hex(" ")


def put(d: OmronDevice, cls: int, instance: int, attribute: int, data: str, now: float = 1.0) -> int:
    return request(d, SET, cls, instance, attribute, data, now).general_status


def fresh(name: str = MX2, **kwargs) -> OmronDevice:
    d = build_omron_device(name, **kwargs)
    d.advance(0.0)
    return d


# -- Identity (Table C-2) ---------------------------------------------------------------------------

@pytest.mark.parametrize(("name", "code", "product"), [(MX2, 1806, "3G3AX-MX2-CRT-AB015_A2015-E"),
                                                       (RX, 2073, "3G3AX-RX-CRT-A4055-E")])
def test_identity(name, code, product):
    d = fresh(name)
    assert get(d, 1, 1, 1) == "2f 00"                     # vendor 47
    assert get(d, 1, 1, 2) == "02 00"                     # AC drive
    assert int.from_bytes(bytes.fromhex(get(d, 1, 1, 3)), "little") == code
    assert bytes.fromhex(get(d, 1, 1, 7))[1:].decode() == product
    assert get(d, 1, 1, 5) == "01 00"                     # Table C-2: bit 0 always ON, bits 8-11 faults only
    assert get(d, 1, 1, 9) == "00 00"                     # configuration consistency value
    assert get(d, 1, 1, 0x65) == "01 01"                  # firmware revision
    assert request(d, GET_ALL, 1, 1).general_status == 0x08   # Table C-1: 0E and 05 only


def test_identity_status_is_the_boards_not_the_inverters():
    # Table C-2 (CompoNet manual): bits 0 (always ON) and 8-11 only. A trip of the inverter, even the one
    # the network forces (E62), is the Control Supervisor's (0x29 Faulted, Fault Code); the board's
    # status stays 0001h, as the MS indicator stays green (Table 4 lists board faults only).
    d = fresh(MX2)
    d.inject_trip(62)
    d.advance(2.0)
    assert get(d, 0x29, 1, 0x0A, now=2.0) == "01" and get(d, 1, 1, 5, now=2.0) == "01 00"
    d.rotary_switches = 5                                  # node address changed: Table 4, minor recoverable
    d.advance(3.0)
    assert get(d, 1, 1, 5, now=3.0) == "01 01"


def test_consistency_value_counts_saves_and_survives_restart(tmp_path):
    path = tmp_path / "mx2.json"
    d = fresh(MX2, state_path=path)
    assert put(d, 0x65, *function_code_path("P044"), "32 00") == 0
    assert put(d, 0x64, *modbus_path(0x0900), "01 00") == 0   # ENTER: EEPROM save (section E-2-2)
    assert get(d, 1, 1, 9) == "01 00"
    assert put(d, 0x64, 0x09, 0x00, "01 00") == 0
    assert get(d, 1, 1, 9) == "02 00"
    assert d.flush_saves(5)                                   # written off the caller's thread
    assert load_state(path, "mx2")[15044] == 50
    again = fresh(MX2, state_path=path)                       # power cycle on the same file
    p044 = function_code_path("P044")                         # 15044 = 3AC4h
    assert get(again, 0x65, *p044) == "32 00" and get(again, 1, 1, 9) == "02 00"
    unsaved = fresh(MX2, state_path=tmp_path / "other.json")
    put(unsaved, 0x65, *p044, "32 00")
    assert get(fresh(MX2, state_path=tmp_path / "other.json"), 0x65, *p044) == "00 00"


def test_identity_reset_restarts_the_option_board():
    d = fresh(MX2)
    put(d, 0x94, 1, 0x64, "04")                           # P046 = 4: takes effect at the next start
    assert d.default_pair == (21, 71)
    assert request(d, RESET, 1, 1).general_status == 0     # appendix E Example 1
    assert d.default_pair == (101, 151)
    assert request(d, RESET, 1, 1, data="05").general_status == 0x20   # Table E-5: invalid parameter


# -- Connection, Unit Parameter, CompoNet Link (Tables C-8, C-14, C-16) ----------------------------------

def test_connection_object():
    d = fresh(MX2)
    assert [get(d, 5, 1, a) for a in (1, 2, 3, 7, 8, 9, 0x0C)] == ["01", "01", "83", "10 00", "10 00", "00 00", "00"]
    assert get(d, 5, 1, 0x0E) == "20 04 24 47 30 03"      # produced: input 71 (P046 = 1)
    assert get(d, 5, 1, 0x10) == "20 04 24 15 30 03"      # consumed: output 21
    # Table C-8 (CompoNet manual): the "number of bytes" of each path, which agrees with the path.
    assert get(d, 5, 1, 0x0D) == "06 00" and get(d, 5, 1, 0x0F) == "06 00"
    assert put(d, 5, 1, 9, "0a 00") == 0 and get(d, 5, 1, 9) == "0a 00"
    assert put(d, 5, 1, 0x0E, "20 04 24 99 30 03") == 0 and d.default_pair == (21, 153)
    assert put(d, 5, 1, 0x0E, "20 04 24 96") == 0 and get(d, 5, 1, 0x0D) == "04 00"   # no attribute: 4 bytes
    assert put(d, 5, 1, 0x0E, "20 04 24 15 30 03") == 0x09   # 21 is an output
    assert put(d, 5, 1, 1, "02") == 0x0E
    assert request(d, GET, 5, 2, 1).general_status == 0x16


def test_unit_parameter_is_p046():
    d = fresh(MX2)
    assert get(d, 0x94, 1, 0x64) == "01"
    assert put(d, 0x94, 1, 0x64, "03") == 0 and d.inverter.read_code("P046") == 3
    assert put(d, 0x94, 1, 0x64, "08") == 0x09


def test_componet_link_node_address():
    d = fresh(MX2, rotary_switches=12)
    assert [get(d, 0xF7, 1, a) for a in (1, 2, 5, 6, 8, 0x0A)] == ["0c", "00 00", "02 00", "00", "0c 00", "00 00"]
    assert put(d, 0xF7, 1, 1, "05") == 0x0E
    p = fresh(MX2, rotary_switches=70)                      # 64-99: P190 sets the address
    put(p, 0x65, *function_code_path("P190"), "21 00")
    assert get(p, 0xF7, 1, 1) == "00" and get(p, 0xF7, 1, 6) == "01"   # changed after power-on
    assert p.identity.get(1, 5) & 0x0100
    p.reset(0)
    assert get(p, 0xF7, 1, 1) == "21" and get(p, 0xF7, 1, 6) == "00"


# -- Discrete points (Tables C-10, C-12) --------------------------------------------------------------

def test_discrete_input_point_value_and_override():
    d = fresh(MX2)
    d.inverter.set_terminals(1.0, 0b1000)                  # section 4-6-1: input terminal [4] ON
    assert get(d, 8, 4, 3) == "01" and get(d, 8, 3, 3) == "00"
    assert put(d, 8, 3, 0x69, "01") == 0
    assert get(d, 8, 3, 3) == "01" and get(d, 8, 3, 0x69) == "01"
    assert put(d, 8, 3, 3, "00") == 0x0E
    assert request(d, GET, 8, 8, 3).general_status == 0x16   # MX2: 7 terminals
    rx = fresh(RX)
    rx.inverter.set_local_run(1.0, 1)
    assert get(rx, 8, 9, 3) == "01"                         # RX instance 9: the FW terminal


def test_discrete_output_point():
    d = fresh(MX2)
    d.inverter.write_code("C021", 63, 0.0)
    assert put(d, 9, 1, 3, "01") == 0 and get(d, 9, 1, 3) == "01"
    assert d.inverter.read_code("d006") == 1
    assert request(d, GET, 9, 4, 3).general_status == 0x16  # MX2: 11, 12, relay
    assert request(d, GET, 9, 6, 3, now=1.0).general_status == 0x16
    assert get(fresh(RX), 9, 6, 3) == "00"


# -- Motor Data (Table D-2) -------------------------------------------------------------------------

def test_motor_type_set_semantics_mx2():
    d = fresh(MX2)
    assert get(d, 0x28, 1, 3) == "07"
    assert put(d, 0x28, 1, 3, "03") == 0                     # to PM: d060 = 3, inverter and board reset
    assert d.inverter.read_code("d060") == 3 and get(d, 0x28, 1, 3) == "03"
    assert d.inverter.option_board_resets == 1
    assert put(d, 0x28, 1, 3, "07") == 0                     # back: ND mode, d060 = 1
    assert d.inverter.read_code("d060") == 1
    assert put(d, 0x28, 1, 3, "05") == 0x09


def test_motor_data_rx_and_poles():
    d = fresh(RX)
    assert put(d, 0x28, 1, 3, "03") == 0x09                  # RX: fixed to 7
    assert get(d, 0x28, 1, 7) == "90 01"                     # 400 V
    assert get(d, 0x28, 1, 8) == "7c 15"                     # 5.5 kW
    assert put(d, 0x28, 1, 0x0C, "04 00") == 0 and d.inverter.read_code("P049") == 4
    assert put(d, 0x28, 1, 0x0C, "05 00") == 0x09            # even pole counts only
    assert put(d, 0x28, 1, 0x0C, "28 00") == 0x09            # 0 - 38


# -- Control Supervisor (Tables D-4, D-5) -----------------------------------------------------------

def test_control_supervisor_run_stop():
    d = fresh(MX2)
    assert put(d, 0x29, 1, 5, "01") == 0                     # Net Ctrl
    put(d, 0x2A, 1, 4, "01")                                 # Net Ref
    put(d, 0x2A, 1, 8, "e8 03")                              # 10.00 Hz
    assert put(d, 0x29, 1, 3, "01") == 0                     # Run1
    assert get(d, 0x29, 1, 6) == "04 00" and get(d, 0x29, 1, 7) == "01"
    d.advance(d.next_deadline())
    assert get(d, 0x2A, 1, 3) == "01" and get(d, 0x2A, 1, 7, now=3.0) == "e8 03"
    assert get(d, 0x29, 1, 0x0F) == "01" and get(d, 0x2A, 1, 0x1D) == "01"
    put(d, 0x29, 1, 3, "00", now=3.0)
    assert get(d, 0x29, 1, 6, now=3.0) == "05 00"           # stopping
    put(d, 0x29, 1, 4, "01", now=3.0)                       # Run2 after a stop
    d.advance(10.0)
    assert get(d, 0x29, 1, 8, now=10.0) == "01"
    assert get(d, 0x29, 1, 0x64, now=10.0) == "01"          # running
    assert put(d, 0x29, 1, 6, "03 00") == 0x0E


@pytest.mark.parametrize(("name", "trip", "fault_code"), [
    (MX2, 5, "20 22"), (MX2, 1, "00 22"), (MX2, 12, "00 90"), (MX2, 64, "20 63"), (RX, 74, "20 63"),
    (RX, 70, "10 75"), (MX2, 81, "01 84")])
def test_fault_code_conversion_table_d5(name, trip, fault_code):
    d = fresh(name)
    d.inject_trip(trip)
    assert get(d, 0x29, 1, 0x0A) == "01" and get(d, 0x29, 1, 9) == "00 00"
    assert get(d, 0x29, 1, 0x0D) == fault_code
    assert get(d, 0x29, 1, 0x65) == f"{trip:02x}"
    assert get(d, 0x29, 1, 6) == "07 00" and get(d, 0x29, 1, 0x64) == "0a"


def test_inject_trip_by_number_or_name():
    d = fresh(RX)
    assert d.inject_trip("E74").cip_code == 0x6320
    assert d.inverter.trip == 74
    with pytest.raises(KeyError):
        fresh(MX2).inject_trip(74)                             # E70-E79 are the RX's (Table D-5)
    assert "trip E74" in d.status_line()


def test_force_fault_examples_2_and_3():
    d = fresh(MX2)
    assert put(d, 0x29, 1, 0x11, "01") == 0                  # Example 3
    assert get(d, 0x29, 1, 0x65) == "3e"                     # Example 2: E62
    assert get(d, 0x29, 1, 0x12) == "01"                     # Force Status
    put(d, 0x29, 1, 0x11, "00")
    put(d, 0x29, 1, 0x0C, "00")
    assert put(d, 0x29, 1, 0x0C, "01") == 0                  # Fault Rst
    assert get(d, 0x29, 1, 0x0A) == "00" and get(d, 0x29, 1, 0x12) == "00"


def test_fault_rst_resets_whenever_written_to_1():
    # Table D-4 (CompoNet manual): Fault Rst "Reset fault / trip state of inverter when written to 1";
    # Force Fault, in the same table, is "on rising edge". A 1 written while it reads 1 resets too.
    d = fresh(MX2)
    d.inject_trip(5)
    assert put(d, 0x29, 1, 0x0C, "01") == 0 and get(d, 0x29, 1, 0x0A) == "00"
    d.inject_trip(5)
    assert get(d, 0x29, 1, 0x0C) == "01" and get(d, 0x29, 1, 0x0A) == "01"
    assert put(d, 0x29, 1, 0x0C, "01") == 0 and get(d, 0x29, 1, 0x0A) == "00"
    d.inject_trip(5)
    assert put(d, 0x29, 1, 0x0C, "00") == 0 and get(d, 0x29, 1, 0x0A) == "01"   # 0 resets nothing


def test_net_fault_and_idle_modes():
    d = fresh(MX2)
    assert get(d, 0x29, 1, 0x10) == "02 00" and get(d, 0x29, 1, 0x14) == "02"   # P045 = P048 = 0: vendor
    assert put(d, 0x29, 1, 0x10, "00 00") == 0 and d.inverter.read_code("P045") == 1
    assert put(d, 0x29, 1, 0x10, "01 00") == 0 and d.inverter.read_code("P045") == 2
    assert put(d, 0x29, 1, 0x14, "00") == 0 and d.inverter.read_code("P048") == 4
    assert put(d, 0x29, 1, 0x14, "01") == 0 and d.inverter.read_code("P048") == 2
    assert get(d, 0x29, 1, 0x14) == "01"
    assert put(d, 0x29, 1, 0x14, "03") == 0x09


# -- AC/DC Drive (Table D-7) ------------------------------------------------------------------------

def test_ac_dc_drive_attributes():
    d = fresh(MX2)
    assert get(d, 0x2A, 1, 0x12) == "10 27"                  # 10000 ms = F002 10.00 s
    assert put(d, 0x2A, 1, 0x12, "b8 0b") == 0 and d.inverter.read_code("F002") == 300   # 3.00 s
    assert put(d, 0x2A, 1, 0x13, "05 00") == 0x09            # below 10 ms
    assert put(d, 0x2A, 1, 6, "00") == 0 and put(d, 0x2A, 1, 6, "01") == 0x09
    assert put(d, 0x2A, 1, 0x78, "14 00") == 0 and d.inverter.option_command.torque_reference == 20
    assert put(d, 0x2A, 1, 0x78, "c9 00") == 0x09            # 0 - 200 %
    assert put(d, 0x2A, 1, 0x79, "38 ff") == 0 and d.inverter.option_command.torque_bias == -200
    assert put(d, 0x2A, 1, 0x77, "00 00") == 0x0E            # the torque monitor d012 is read only
    assert get(d, 0x2A, 1, 0x7A) == "01"


def test_example_4_speed_actual_in_tenths():
    d = fresh(MX2)
    for code, value in {"b171": 2, "b180": 1, "A001": 4, "A002": 4}.items():
        d.inverter.write_code(code, value, 0.0)
    d.reset(0)
    put(d, 0x2A, 1, 8, "64 00")
    put(d, 0x29, 1, 3, "01")
    d.advance(d.next_deadline())
    assert get(d, 0x2A, 1, 7, now=d.now) == "64 00"          # 10.0 Hz read as 0064h (appendix E Example 4)


def test_torque_outside_constant_torque_mode_is_a_device_state_conflict():
    d = fresh(MX2)
    d.inverter.write_code("b049", 1, 0.0)
    d.inverter.write_code("b180", 1, 0.0)                    # VT mode: d060 = 1
    assert put(d, 0x2A, 1, 0x78, "14 00") == 0x10
    assert put(d, 0x65, *function_code_path("P034"), "14 00") == 0x10


# -- Function Code object (Table E-3) ----------------------------------------------------------------

def test_function_code_arithmetic_of_table_e3():
    assert function_code_path("d005") == (0x0B, 0xBD)        # 3 * 1000 + 005 = 3005 = 0BBDh
    assert function_code_path("P060") == (0x3A, 0xD4)        # 15 * 1000 + 060 = 15060 = 3AD4h
    assert function_code_path("A001") == (0x00, 0x01)
    assert function_code_path("b001") == (0x03, 0xE9)
    assert function_code_path("F002") == (0x13, 0x8A)        # section 4-6-2: F002 = 5002 = 138Ah
    assert function_code_path("U999") == (0x52, 0x07)


def test_function_code_examples_1_and_2():
    d = fresh(MX2)
    d.inverter.set_terminals(1.0, 0b1)
    assert get(d, 0x65, 0x0B, 0xBD) == "01 00"               # Example 1: d005, input 1 set
    assert put(d, 0x65, 0x3A, 0xD4, "00 f4 01 00") == 0      # Example 2: P060 = 128000 (01F400h)
    assert d.inverter.read_code("P060") == 128000
    assert get(d, 0x65, 0x3A, 0xD4) == "00 f4 01 00"
    assert put(d, 0x65, 0x13, 0x8A, "2c 01 00 00") == 0      # section 4-6-2: F002 = 3.00 s
    assert d.inverter.read_code("F002") == 300


def test_function_code_f001_and_b127():
    d = fresh(MX2)
    assert get(d, 0x65, *function_code_path("F001")) == "00 00 00 00"
    assert put(d, 0x65, *function_code_path("F001"), "e8 03 00 00") == 0x0E   # not writable here
    assert put(d, 0x64, 0x00, 0x01, "e8 03 00 00") == 0                      # but through Modbus 0001h
    assert get(d, 0x65, *function_code_path("F001")) == "e8 03 00 00"
    assert get(d, 0x65, *function_code_path("b127")) == "00 00 00 00"        # two words by function code
    assert put(d, 0x65, *function_code_path("b127"), "05 00") == 0x13
    assert put(d, 0x65, *function_code_path("b127"), "05 00 00 00") == 0


# -- Modbus Register object (section E-3) -----------------------------------------------------------

def test_modbus_register_split_and_examples():
    d = fresh(MX2)
    assert modbus_path(0x1E01) == (0x1E, 0x01)
    assert get(d, 0x64, 0x1E, 0x01) == "02 00"               # Example 1: coil data 1, Rdy
    assert put(d, 0x64, 0x09, 0x00, "01 00") == 0            # Example 2: EEPROM save
    assert get(d, 0x64, 0x16, 0x3E) == "00 00 00 00"         # P060 at 163Eh: a double word
    assert put(d, 0x64, 0x16, 0x3F, "10 00") == 0            # its low word alone: high word zero
    assert d.inverter.read_code("P060") == 16
    assert get(d, 0x64, 0x16, 0x3F) == "10 00"
    assert put(d, 0x64, 0x12, 0x04, "58 02") == 0 and d.inverter.read_code("A004") == 600


# -- Table E-5 ----------------------------------------------------------------------------------------

def test_error_codes_of_table_e5():
    d = fresh(MX2)
    status = {
        "08 service not supported": request(d, RESET, 0x65, 0x3A, None).general_status,
        "08 on 0x29": request(d, GET_ALL, 0x29, 1).general_status,
        "09 invalid attribute value": put(d, 0x65, *function_code_path("P046"), "09 00"),
        "0E attribute not settable": put(d, 0x64, 0x10, 0x07, "00 00"),
        "13 not enough data": put(d, 0x64, 0x11, 0x03, "2c 01"),
        "14 attribute not supported": request(d, GET, 0x65, 0x00, 0x03).general_status,
        "14 no parameter A999": request(d, GET, 0x65, 0x03, 0xE7).general_status,   # Table E-3 range, no A999
        "16 no function group": request(d, GET, 0x65, 0x10, 0x01).general_status,   # 4097: between d and F
        "14 no Modbus register": request(d, GET, 0x64, 0x10, 0xFF).general_status,
        "14 no attribute": request(d, GET, 0x29, 1, 0x99).general_status,
        "15 too much data": put(d, 0x64, 0x12, 0x04, "58 02 00 00"),
        "16 object does not exist": request(d, GET, 0x64, 0x77, 0x01).general_status,
        "16 no instance": request(d, GET, 0x2A, 2, 3).general_status,
        "20 invalid parameter": request(d, RESET, 1, 1, data="07").general_status,
    }
    assert status == {"08 service not supported": 0x08, "08 on 0x29": 0x08, "09 invalid attribute value": 0x09,
                      "0E attribute not settable": 0x0E, "13 not enough data": 0x13,
                      "14 attribute not supported": 0x14, "14 no parameter A999": 0x14, "16 no function group": 0x16,
                      "14 no Modbus register": 0x14, "14 no attribute": 0x14,
                      "15 too much data": 0x15, "16 object does not exist": 0x16, "16 no instance": 0x16,
                      "20 invalid parameter": 0x20}
    put(d, 0x29, 1, 5, "01")
    put(d, 0x2A, 1, 4, "01")
    put(d, 0x2A, 1, 8, "e8 03")
    put(d, 0x29, 1, 3, "01")
    assert put(d, 0x94, 1, 0x64, "02", now=1.5) == 0x10      # 10: P046 cannot change while running
    d.inverter_link_ok = False
    assert request(d, GET, 0x65, 0x0B, 0xBD, now=1.6).general_status == 0x02   # 02: no link to the inverter
    assert request(d, GET, 0x29, 1, 6, now=1.6).general_status == 0x02
