"""The ACG-ET2 CIP objects through the message router, against the ACG-ET2 manual's object tables."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from cipstack.adapter import Adapter, AdapterSettings
from cipstack.cip.epath import request_path
from cipstack.cip.messages import MessageRouterRequest, MessageRouterResponse
from cipstack.cip.router import RequestContext
from cipstack.devices.acg.device import AcgDevice, build_acg_device
from cipstack.devices.acg.drive import DriveState, Trip
from cipstack.devices.acg.objects import CATALOG_CLASSES
from cipstack.devices.acg.registers import ACG_REGISTERS, CLASS_64_INSTANCES, class64_path
from cipstack.devices.acg.status_words import OperationStatus
from cipstack.devices.profiles import serial_from_mac
from cipstack.devices.state import StateFileError
from cipstack.errors import StateRefused
from cipstack.objects.tcpip import NetworkInterface

GET, SET, GET_ALL, RESET, GET_LIST = 0x0E, 0x10, 0x01, 0x05, 0x03
MAC = bytes.fromhex("02CA10ABCDEF")


def addr(code: str) -> int:
    return ACG_REGISTERS.by_code(code).address


@pytest.fixture
def device() -> AcgDevice:
    dev = build_acg_device(NetworkInterface(mac=MAC), now=0.0)
    dev.drive.write(addr("drv"), 4, 0.0)
    dev.drive.write(addr("Frq"), 8, 0.0)
    return dev


def call(device: AcgDevice, service: int, class_id: int, instance: int | None = None, attribute: int | None = None,
         data: bytes = b"") -> MessageRouterResponse:
    raw = MessageRouterRequest(service, request_path(class_id, instance, attribute), data).encode()
    return MessageRouterResponse.decode(device.router.handle(raw, RequestContext(device.router)))


def get(device: AcgDevice, class_id: int, attribute: int, instance: int = 1) -> bytes:
    reply = call(device, GET, class_id, instance, attribute)
    assert reply.general_status == 0, f"0x{class_id:02X}/{instance}/{attribute}: status 0x{reply.general_status:02X}"
    return reply.data


def status_of_set(device: AcgDevice, class_id: int, attribute: int, data: bytes, instance: int = 1) -> int:
    return call(device, SET, class_id, instance, attribute, data).general_status


def u16(value: int) -> bytes:
    return struct.pack("<H", value)


# --- Identity (class 0x01) -------------------------------------------------------------------------

def test_identity_attributes(device: AcgDevice) -> None:
    assert get(device, 1, 1) == u16(259)
    assert get(device, 1, 2) == u16(2)
    assert get(device, 1, 3) == u16(100)
    assert get(device, 1, 4) == bytes((1, 1))                       # CM.6 = 0x0101: version 1.01
    assert get(device, 1, 5) == u16(0x0030)                         # no I/O connection (3), not owned
    assert get(device, 1, 6) == struct.pack("<I", serial_from_mac(MAC)) == bytes.fromhex("efcdab10")
    assert get(device, 1, 7) == b"\x04CENT"
    assert call(device, GET, 1, 1, 8).general_status == 0x14        # the table has attributes 1-7
    reply = call(device, GET_ALL, 1, 1)
    assert reply.general_status == 0 and reply.data == (
        u16(259) + u16(2) + u16(100) + bytes((1, 1)) + u16(0x30) + bytes.fromhex("efcdab10") + b"\x04CENT")


def test_identity_services(device: AcgDevice) -> None:
    # Class: none. Instance: 0x0E, 0x05, 0x01 only.
    assert call(device, GET, 1, 0, 1).general_status == 0x08
    assert call(device, GET_ALL, 1, 0).general_status == 0x08
    assert call(device, SET, 1, 1, 7, b"\x01X").general_status == 0x08
    assert call(device, GET_LIST, 1, 1, None, u16(1) + u16(1)).general_status == 0x08
    assert call(device, RESET, 1, 1).general_status == 0
    assert call(device, RESET, 1, 1, None, b"\x02").general_status == 0x03


@pytest.mark.parametrize(("trip", "expected"), [(Trip.OVER_HEAT, 0x0850), (Trip.HW_DIAG, 0x0450)])
def test_identity_fault_bits(device: AcgDevice, trip: Trip, expected: int) -> None:
    # Bits 4-7 = 5 "Major fault"; bit 10 for a drive H/W trip, bit 11 for any other trip.
    device.inject_trip(trip)
    assert get(device, 1, 5) == u16(expected)
    assert device.identity_record().state == 4  # major recoverable fault
    device.drive.set_fault_reset(True, 0.0)
    assert get(device, 1, 5) == u16(0x0030)


def test_identity_warning_bit(device: AcgDevice) -> None:
    # Bit 8: "Minor recoverable fault (Drive is in warning status)": Pr.12 Hold Input gives a Lost Command warning.
    device.drive.write(addr("Pr.12"), 3, 0.0)
    device.drive.on_modbus_activity(0.0)
    device.advance(5.0 + 1.0 + 0.1)
    assert device.drive.warning
    assert get(device, 1, 5) == u16(0x0130)


def test_identity_reset_types(device: AcgDevice) -> None:
    acc = addr("ACC")
    device.drive.write(acc, 123, 0.0)
    device.drive.write(0x03E0, 1, 0.0)         # save: 0 -> 1
    device.drive.write(acc, 77, 0.0)           # not saved
    assert call(device, RESET, 1, 1, None, b"\x00").general_status == 0
    assert device.drive.read(acc) == 123       # power cycle: the saved value, not the unsaved one
    assert call(device, RESET, 1, 1, None, b"\x01").general_status == 0
    assert device.drive.read(acc) == ACG_REGISTERS[acc].default
    assert device.drive.saved_parameters == {}


# --- Motor Data (class 0x28) -------------------------------------------------------------------------

def test_motor_data(device: AcgDevice) -> None:
    assert get(device, 0x28, 3) == b"\x07"                          # squirrel cage induction motor
    assert status_of_set(device, 0x28, 3, b"\x01") == 0x0E
    assert status_of_set(device, 0x28, 6, u16(123)) == 0            # 12.3 A into BAS-13 Rated Curr
    assert device.drive.read(addr("bA.13")) == 123 and get(device, 0x28, 6) == u16(123)
    assert status_of_set(device, 0x28, 6, u16(10001)) == 0x09       # above 1000.0 A
    assert status_of_set(device, 0x28, 7, u16(460)) == 0            # BAS-15 Rated Voltage
    assert device.drive.read(addr("bA.15")) == 460
    assert status_of_set(device, 0x28, 7, u16(691)) == 0x09         # above 690 V
    assert status_of_set(device, 0x28, 7, b"\x01") == 0x13
    assert call(device, GET, 0x28, 1, 1).general_status == 0x14
    assert call(device, GET, 0x28, 0, 1).general_status == 0x08     # no class services
    assert call(device, GET_ALL, 0x28, 1).general_status == 0x08
    assert call(device, GET, 0x28, 2, 3).general_status == 0x05


# --- Control Supervisor (class 0x29) -------------------------------------------------------------------

def test_control_supervisor_attributes(device: AcgDevice) -> None:
    assert [get(device, 0x29, a) for a in (3, 4, 6, 7, 8, 9, 10, 12, 14)] == [
        b"\x00", b"\x00", bytes((DriveState.READY,)), b"\x00", b"\x00", b"\x01", b"\x00", b"\x00", b"\x01"]
    assert get(device, 0x29, 13) == u16(0)
    assert call(device, GET, 0x29, 1, 11).general_status == 0x14    # Warning: not in the table
    # 5 Net Control, Access "N/A" (ACG-ET2 manual): served neither to Get nor to Set.
    assert call(device, GET, 0x29, 1, 5).general_status == 0x14
    assert status_of_set(device, 0x29, 5, b"\x01") == 0x14
    for attribute in (6, 7, 8, 9, 10, 13, 14):
        assert status_of_set(device, 0x29, attribute, b"\x01" if attribute != 13 else u16(1)) == 0x0E
    assert status_of_set(device, 0x29, 3, b"\x01") == 0
    device.advance(1.0)
    assert (get(device, 0x29, 3), get(device, 0x29, 6), get(device, 0x29, 7)) == (b"\x01", b"\x04", b"\x01")
    device.inject_trip(Trip.EXTERNAL_TRIP)
    assert (get(device, 0x29, 6), get(device, 0x29, 9), get(device, 0x29, 10)) == (b"\x06", b"\x00", b"\x01")
    assert get(device, 0x29, 13) == u16(0x9000)
    assert status_of_set(device, 0x29, 3, b"\x00\x00") == 0x15
    assert call(device, GET, 0x29, 0, 1).general_status == 0x08


def test_control_from_net_follows_drv(device: AcgDevice) -> None:
    device.drive.write(addr("drv"), 1, 0.0)
    assert get(device, 0x29, 14) == b"\x00"
    assert status_of_set(device, 0x29, 3, b"\x01") == 0              # the card keeps the command ...
    assert get(device, 0x29, 3) == b"\x01" and not device.drive.running  # ... the drive obeys drv


def test_control_from_net_is_served_at_14_and_15(device: AcgDevice) -> None:
    # ACG-ET2 manual gives it as 0x29 attribute 14 (Control Supervisor table, 000:661) and 15 (the input
    # instances' bit table, 000:458, as CIP's Control Supervisor has it): both ids serve the one value.
    assert get(device, 0x29, 14) == get(device, 0x29, 15) == b"\x01"
    device.drive.write(addr("drv"), 1, 0.0)
    assert get(device, 0x29, 14) == get(device, 0x29, 15) == b"\x00"
    assert status_of_set(device, 0x29, 15, b"\x01") == 0x0E                  # Get only, as attribute 14


# Drive Run table (ACG-ET2 manual, class 0x29): states (Run1, Run2) reached by single Set_Attribute_Single.
RUN_ROWS = [
    # (start, attribute set, value, expected direction after, row)
    ((0, 0), 3, 1, "fwd", "0->1, 0: Run1"),
    ((0, 0), 4, 1, "rev", "0, 0->1: Run2"),
    ((1, 0), 4, 1, "fwd", "1, 1: No Action"),
    ((0, 1), 3, 1, "rev", "1, 1: No Action"),
    ((1, 1), 3, 0, "rev", "1->0, 1: Run2"),
    ((1, 1), 4, 0, "fwd", "1, 1->0: Run1"),
    ((1, 0), 3, 0, "stop", "0, 0: Stop"),
    ((0, 1), 4, 0, "stop", "0, 0: Stop"),
]


def _direction(device: AcgDevice) -> str:
    """The command the drive executes: 0x000E B11 forward / B12 reverse operation command (ACG RS-485 manual)."""
    status = OperationStatus(device.drive.read(0x000E))
    if OperationStatus.FORWARD_COMMAND in status:
        return "fwd"
    return "rev" if OperationStatus.REVERSE_COMMAND in status else "stop"


@pytest.mark.parametrize(("start", "attribute", "value", "expected", "row"), RUN_ROWS, ids=[r[4] for r in RUN_ROWS])
def test_drive_run_table_through_0x29(device: AcgDevice, start: tuple[int, int], attribute: int, value: int,
                                      expected: str, row: str) -> None:
    device.drive.set_speed_reference(3000, 0.0)
    # Reach the start state one attribute at a time, as a scanner would.
    first = 3 if start[0] else 4
    if start[first - 3]:
        assert status_of_set(device, 0x29, first, b"\x01") == 0
    other = 7 - first
    if start[other - 3]:
        assert status_of_set(device, 0x29, other, b"\x01") == 0
    device.advance(1.0)
    assert status_of_set(device, 0x29, attribute, bytes((value,))) == 0
    device.advance(1.5)
    assert _direction(device) == expected


def test_drive_run_simultaneous_rows_through_assembly_21(device: AcgDevice) -> None:
    # "0 -> 1, 0 -> 1: No Action": both bits rise together in one output image.
    device.assembly.deliver(21, bytes.fromhex("03000000"), 0.0)
    assert not device.drive.running
    device.assembly.deliver(21, bytes.fromhex("01000000"), 0.0)   # "1, 1 -> 0": Run1
    assert device.drive.running_forward


def test_drive_fault_reset_on_rising_edge_only(device: AcgDevice) -> None:
    device.inject_trip(Trip.OVER_CURRENT_1)
    assert status_of_set(device, 0x29, 12, b"\x01") == 0            # FALSE -> TRUE: reset
    assert not device.drive.faulted and get(device, 0x29, 12) == b"\x01"
    device.inject_trip(Trip.OVER_CURRENT_1)
    assert status_of_set(device, 0x29, 12, b"\x01") == 0            # TRUE over TRUE: nothing
    assert device.drive.faulted and get(device, 0x29, 13) == u16(0x2310)
    assert status_of_set(device, 0x29, 12, b"\x00") == 0            # "write 0 first, then 1 again"
    assert device.drive.faulted
    assert status_of_set(device, 0x29, 12, b"\x01") == 0
    assert not device.drive.faulted


# --- AC/DC Drive (class 0x2A) --------------------------------------------------------------------------

def test_ac_dc_drive_attributes(device: AcgDevice) -> None:
    assert status_of_set(device, 0x2A, 8, u16(900)) == 0            # SpeedRef 900 rpm = 30.00 Hz
    assert device.drive.read(0x0380) == 3000 and get(device, 0x2A, 101) == u16(3000)
    assert status_of_set(device, 0x29, 3, b"\x01") == 0
    device.advance(1.25)
    assert get(device, 0x2A, 3) == b"\x00"
    assert get(device, 0x2A, 7) == u16(450) and get(device, 0x2A, 100) == u16(1500)
    device.advance(3.0)
    assert get(device, 0x2A, 3) == b"\x01" and get(device, 0x2A, 7) == u16(900) and get(device, 0x2A, 8) == u16(900)
    assert get(device, 0x2A, 29) == b"\x01"
    # 4 Net Reference, Access "N/A" (ACG-ET2 manual): served neither to Get nor to Set.
    assert call(device, GET, 0x2A, 1, 4).general_status == 0x14
    assert status_of_set(device, 0x2A, 4, b"\x01") == 0x14
    assert get(device, 0x2A, 6) == b"\x01"                          # open loop speed
    assert get(device, 0x2A, 9) == u16(0)                           # no motor model: 0.0 A
    assert get(device, 0x2A, 102) == u16(50) and get(device, 0x2A, 103) == u16(100)
    assert status_of_set(device, 0x2A, 102, u16(20)) == 0 and device.drive.read(addr("ACC")) == 20
    assert status_of_set(device, 0x2A, 103, u16(60001)) == 0x09      # 0-6000.0 s
    assert status_of_set(device, 0x2A, 101, u16(4500)) == 0 and get(device, 0x2A, 8) == u16(1350)
    assert status_of_set(device, 0x2A, 101, u16(7000)) == 0x09       # above dr.20 Max Freq 60.00 Hz
    assert status_of_set(device, 0x2A, 101, u16(40001)) == 0x09      # above 400.00 Hz
    assert status_of_set(device, 0x2A, 8, u16(24001)) == 0x09
    for attribute in (3, 6, 7, 9, 29, 100):
        assert status_of_set(device, 0x2A, attribute, u16(1) if attribute in (7, 9, 100) else b"\x01") == 0x0E
    assert call(device, GET, 0x2A, 1, 5).general_status == 0x14
    device.drive.write(addr("AP.1"), 2, 4.0)                         # App Mode: a process mode
    assert get(device, 0x2A, 6) == b"\x04"


# --- Class 0x64 -----------------------------------------------------------------------------------------

def test_every_keypad_parameter_reads_through_0x64(device: AcgDevice) -> None:
    count = 0
    for address, register in ACG_REGISTERS.items():
        path = class64_path(register)
        if path is None:
            continue
        assert get(device, 0x64, path[1], path[0]) == u16(device.drive.read(address) & 0xFFFF), register.code
        count += 1
    assert count == sum(len(ACG_REGISTERS.group(g)) for g in CLASS_64_INSTANCES)


def test_keypad_parameters_set_and_refusals(device: AcgDevice) -> None:
    cm, pr, dr = CLASS_64_INSTANCES["CM"], CLASS_64_INSTANCES["Pr"], CLASS_64_INSTANCES["dr"]
    assert get(device, 0x64, 23, cm) == u16(1)                                # CM.23 CIP Input Instance
    assert status_of_set(device, 0x64, 12, u16(5), pr) == 0                   # Pr.12 Lost Preset
    assert device.drive.read(addr("Pr.12")) == 5
    assert get(device, 0x64, 20, dr) == u16(6000)                             # dr.20 Max Freq 60.00 Hz
    assert status_of_set(device, 0x64, 6, u16(0x0102), cm) == 0x0E            # CM.6 is read only
    assert status_of_set(device, 0x64, 7, u16(221), cm) == 0x09               # CM.7 0-220
    assert status_of_set(device, 0x64, 12, u16(6), pr) == 0x09                # Pr.12 0-5
    assert status_of_set(device, 0x64, 12, b"\x05", pr) == 0x13
    assert status_of_set(device, 0x64, 12, u16(5) + b"\x00", pr) == 0x15
    assert call(device, GET, 0x64, cm, 99).general_status == 0x14
    assert call(device, GET, 0x64, 9, 1).general_status == 0x05               # no group at instance 9
    # "10 (AP Group)" (ACG-ET2 manual): a second instance of the AP group (8).
    ap = CLASS_64_INSTANCES["AP"]
    assert status_of_set(device, 0x64, 1, u16(2), 10) == 0 and device.drive.read(addr("AP.1")) == 2
    assert get(device, 0x64, 1, 10) == get(device, 0x64, 1, ap) == u16(2)
    assert call(device, GET, 0x64, 10, 99).general_status == 0x14
    assert call(device, GET, 0x64, 0, 1).general_status == 0x08
    assert call(device, GET_ALL, 0x64, cm).general_status == 0x08
    # "The setting cannot be written while the drive is operating": device state conflict.
    assert status_of_set(device, 0x29, 3, b"\x01") == 0
    assert status_of_set(device, 0x64, 24, u16(0), cm) == 0x10
    assert status_of_set(device, 0x29, 3, b"\x00") == 0
    device.advance(60.0)
    assert status_of_set(device, 0x64, 24, u16(0), cm) == 0


def test_cm94_gates_the_offered_instances(device: AcgDevice) -> None:
    def offered() -> tuple[set[int], set[int], set[tuple[int, int]]]:
        profile = device.io_profile()
        assert profile.pairs is not None
        return set(profile.consumed()), set(profile.produced()), profile.pairs()

    assert offered() == ({21}, {71}, {(21, 71)})                              # CM.23 = CM.24 = 1 by default
    cm = CLASS_64_INSTANCES["CM"]
    assert status_of_set(device, 0x64, 23, u16(6), cm) == 0                   # 143
    assert status_of_set(device, 0x64, 24, u16(3), cm) == 0                   # 101
    assert offered() == ({21}, {71}, {(21, 71)})                              # not before Comm Update
    assert device.drive.comm_update_pending
    assert status_of_set(device, 0x64, 94, u16(1), cm) == 0                   # CM.94 = 1: applied
    assert offered() == ({101}, {143}, {(101, 143)})
    assert get(device, 0x64, 30, cm) == u16(3)                                # CM.30 follows CM.23
    # Every instance stays reachable over explicit messaging (Assembly attribute 3).
    reply = call(device, GET, 0x04, 70, 3)
    assert reply.general_status == 0 and len(reply.data) == 4


def test_catalog_classes_decode_what_the_objects_serve(device: AcgDevice) -> None:
    for spec in CATALOG_CLASSES:
        assert device.router[spec.class_id].spec.class_id == spec.class_id
    assert device.catalog_classes() == CATALOG_CLASSES
    keypad = {s.class_id: s for s in CATALOG_CLASSES}[0x64]
    assert keypad.instance_attribute(23) is not None and keypad.max_instance == 12


# --- Emulator commands ------------------------------------------------------------------------------------

def test_inject_trip_accepts_codes_and_names(device: AcgDevice) -> None:
    assert device.inject_trip("0x4200") is Trip.OVER_HEAT
    device.drive.set_fault_reset(True, 0.0)
    assert device.inject_trip("ExternalTrip") is Trip.EXTERNAL_TRIP
    assert get(device, 0x29, 13) == u16(0x9000)
    with pytest.raises(ValueError):
        device.inject_trip("0x1234")
    with pytest.raises(ValueError):
        device.inject_trip("no such trip")


async def test_a_second_trip_is_refused_and_the_first_kept(device: AcgDevice) -> None:
    # 0x29 attribute 13 holds one Drive Fault Code; a trip is left by a Fault Reset only (ACG-ET2 manual).
    async with Adapter(AdapterSettings(host="127.0.0.1", port=0, io_port=0), device=device) as adapter:
        first = adapter.control({"command": "trip", "code": 0x4200})
        assert "OverHeat" in first["result"]
        with pytest.raises(StateRefused) as refused:                   # the device's state says no
            adapter.control({"command": "trip", "code": 0x5000})
        message = str(refused.value)
        assert "already tripped: OverHeat (fault code 0x4200)" in message and "\n" not in message
        assert device.drive.trip is Trip.OVER_HEAT and get(device, 0x29, 13) == u16(0x4200)
        assert "trip OverHeat (0x4200)" in adapter.control({"command": "status"})["status"]
        device.drive.set_fault_reset(True, device.now)                # reset: the next trip is taken
        assert "0x5000" in adapter.control({"command": "trip", "code": 0x5000})["result"]


def test_status_line(device: AcgDevice) -> None:
    assert device.status_line() == "READY      | --- | out   0.00 Hz | ref   0.00 Hz | io 0"
    device.drive.set_speed_reference(3000, 0.0)
    device.drive.set_run_command(True, False, 0.0)
    device.advance(1.25)
    assert device.status_line() == "ENABLED    | fwd | out  15.00 Hz | ref  30.00 Hz | io 0"
    device.inject_trip(Trip.OVER_HEAT)
    device.drive.write(addr("CM.23"), 0, 1.25)
    assert device.status_line() == ("FAULT_STOP | --- | out   0.00 Hz | ref  30.00 Hz | io 0 | trip OverHeat (0x4200)"
                                    " | CM.94 pending")


def test_state_file_is_the_drives_memory(tmp_path: Path) -> None:
    state = tmp_path / "acg.json"
    first = build_acg_device(state_path=state, now=0.0)
    first.drive.write(addr("dEC"), 42, 0.0)
    first.drive.write(0x03E0, 1, 0.0)
    assert first.flush_saves(5)                               # written off the caller's thread
    assert build_acg_device(state_path=state, now=0.0).drive.read(addr("dEC")) == 42
    state.write_text("{not json")
    with pytest.raises(StateFileError, match="not valid JSON"):
        build_acg_device(state_path=state)


def test_without_a_state_file_saved_values_last_the_process(device: AcgDevice) -> None:
    device.drive.write(addr("dEC"), 42, 0.0)
    device.drive.write(0x03E0, 1, 0.0)
    device.drive.write(addr("dEC"), 43, 0.0)
    device.reset(0)
    assert device.drive.read(addr("dEC")) == 42
