"""The ACG drive simulation against ACG-ET2 manual (appendix B) and ACG RS-485 manual (chapter 5)."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cipstack.devices.acg.drive import (
    IO_BREAK_TIME,
    MODBUS_SILENCE_TIME,
    AcgDrive,
    Direction,
    DriveState,
    RunAction,
    Trip,
    drive_run_action,
)
from cipstack.devices.acg.registers import ACG_REGISTERS
from cipstack.devices.acg.status_words import LatchTrip1, LevelTrip, OperationStatus, WarningInformation
from cipstack.devices.registers import RegisterError, RegisterRefusal


def addr(code: str) -> int:
    return ACG_REGISTERS.by_code(code).address


ACC, DEC, DRV, FRQ, MAX_FREQ, POLES = addr("ACC"), addr("dEC"), addr("drv"), addr("Frq"), addr("dr.20"), addr("bA.11")
PR12, PR13, PR14 = addr("Pr.12"), addr("Pr.13"), addr("Pr.14")
FREQUENCY_COMMAND = 0x0380


@pytest.fixture
def drive() -> AcgDrive:
    """A drive run from the network: drv = 4 and Frq = 8 (Field Bus), ACC 5.0 s, dEC 10.0 s, 60 Hz max."""
    d = AcgDrive()
    d.write(DRV, 4, 0.0)
    d.write(FRQ, 8, 0.0)
    return d


def refusal(action) -> RegisterRefusal:
    with pytest.raises(RegisterError) as raised:
        action()
    return raised.value.refusal


# --- Control Supervisor "Drive Run" table (ACG-ET2 manual, class 0x29) ----------------------------

TABLE = [
    # Run1 before, Run2 before, Run1 after, Run2 after, Run Type
    ((0, 0), (0, 0), RunAction.STOP),
    ((0, 0), (1, 0), RunAction.RUN_FORWARD),
    ((0, 0), (0, 1), RunAction.RUN_REVERSE),
    ((0, 0), (1, 1), RunAction.NO_ACTION),
    ((1, 1), (1, 1), RunAction.NO_ACTION),
    ((1, 1), (0, 1), RunAction.RUN_REVERSE),
    ((1, 1), (1, 0), RunAction.RUN_FORWARD),
]


@pytest.mark.parametrize(("before", "after", "action"), TABLE)
def test_drive_run_table(before, after, action) -> None:
    assert drive_run_action(tuple(map(bool, before)), tuple(map(bool, after))) is action


def test_held_run_bit_commands_nothing() -> None:
    assert drive_run_action((True, False), (True, False)) is RunAction.NO_ACTION
    assert drive_run_action((False, True), (False, True)) is RunAction.NO_ACTION
    # One bit rising beside the other held at 1 leaves both at 1: the "1, 1" row, No Action.
    assert drive_run_action((True, False), (True, True)) is RunAction.NO_ACTION
    assert drive_run_action((False, True), (True, True)) is RunAction.NO_ACTION
    # Both dropping: "0, 0" is Stop.
    assert drive_run_action((True, True), (False, False)) is RunAction.STOP


def reach(drive: AcgDrive, hz: float, now: float) -> None:
    drive.write(FREQUENCY_COMMAND, round(hz * 100), now)


def test_row_stop(drive: AcgDrive) -> None:
    reach(drive, 60, 0)
    drive.set_run_command(True, False, 0)
    drive.advance(5)
    assert drive.output_frequency == 6000
    assert drive.set_run_command(False, False, 5) is RunAction.STOP
    assert drive.drive_state is DriveState.STOPPING
    drive.advance(15)                 # 60 Hz down at 60 Hz per 10 s
    assert drive.output_frequency == 0 and drive.drive_state is DriveState.READY and not drive.running


def test_row_run1(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    drive.set_run_command(True, False, 0)
    drive.advance(10)
    assert drive.running_forward and not drive.running_reverse
    assert drive.read(0x0311) == 3000


def test_row_run2(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    drive.set_run_command(False, True, 0)
    drive.advance(10)
    assert drive.running_reverse and not drive.running_forward
    assert drive.read(0x0313) == -900          # directional rpm: 30 Hz, 4 poles


def test_row_both_rising_is_no_action(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    assert drive.set_run_command(True, True, 0) is RunAction.NO_ACTION
    drive.advance(10)
    assert not drive.running and drive.drive_state is DriveState.READY


def test_row_both_held_is_no_action(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    drive.set_run_command(True, False, 0)
    drive.set_run_command(True, True, 1)     # Run2 rises beside a held Run1: no action
    assert drive.set_run_command(True, True, 2) is RunAction.NO_ACTION
    drive.advance(10)
    assert drive.running_forward


def test_row_run1_falls_with_run2_held(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    drive.set_run_command(True, False, 0)
    drive.set_run_command(True, True, 1)
    drive.advance(10)
    assert drive.running_forward
    assert drive.set_run_command(False, True, 10) is RunAction.RUN_REVERSE
    drive.advance(30)
    assert drive.running_reverse and drive.output_frequency == 3000


def test_row_run2_falls_with_run1_held(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    drive.set_run_command(False, True, 0)
    drive.set_run_command(True, True, 1)
    drive.advance(10)
    assert drive.running_reverse
    assert drive.set_run_command(True, False, 10) is RunAction.RUN_FORWARD
    drive.advance(30)
    assert drive.running_forward and drive.output_frequency == 3000


def test_single_attribute_writes_follow_the_table(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    assert drive.set_run_forward(True, 0) is RunAction.RUN_FORWARD
    assert drive.set_run_reverse(True, 1) is RunAction.NO_ACTION
    assert drive.set_run_forward(False, 2) is RunAction.RUN_REVERSE
    assert drive.set_run_reverse(False, 3) is RunAction.STOP
    assert (drive.control_supervisor.run_forward, drive.control_supervisor.run_reverse) == (False, False)


def test_run_bits_are_ignored_unless_drv_is_field_bus() -> None:
    d = AcgDrive()                              # drv = 1 (Fx/Rx-1) by default
    assert not d.control_from_net
    d.set_run_command(True, False, 0)
    d.advance(10)
    assert not d.running
    assert d.control_supervisor.run_forward     # the card keeps the value all the same


def test_held_run_bit_does_not_restart_after_a_trip(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    drive.set_run_command(True, False, 0)
    drive.advance(5)
    drive.inject_trip(Trip.OVER_CURRENT_1, 5)
    drive.set_fault_reset(True, 6)
    drive.set_run_command(True, False, 7)       # still 1: no 0 -> 1 change
    drive.advance(10)
    assert not drive.running and drive.drive_state is DriveState.READY
    drive.set_run_command(False, False, 10)
    drive.set_run_command(True, False, 11)
    drive.advance(20)
    assert drive.running_forward and drive.output_frequency == 3000


# --- Drive Fault Reset and fault codes --------------------------------------------------------

def test_fault_reset_on_zero_to_one_only(drive: AcgDrive) -> None:
    drive.inject_trip(Trip.OVER_VOLTAGE, 0)
    assert drive.faulted and drive.fault_code == 0x3210 and not drive.ready
    assert drive.set_fault_reset(True, 1)
    assert not drive.faulted and drive.fault_code == 0 and drive.ready
    drive.inject_trip(Trip.OVER_VOLTAGE, 2)
    assert not drive.set_fault_reset(True, 3)   # TRUE over TRUE: no reset
    assert drive.faulted
    assert not drive.set_fault_reset(False, 4)
    assert drive.faulted
    assert drive.set_fault_reset(True, 5)       # write 0 first, then 1
    assert not drive.faulted


FAULT_CODES = [
    (0x1000, Trip.ETHERMAL), (0x2200, Trip.OVER_LOAD), (0x2310, Trip.OVER_CURRENT_1), (0x2330, Trip.GFT),
    (0x2340, Trip.OVER_CURRENT_2), (0x3210, Trip.OVER_VOLTAGE), (0x3220, Trip.LOW_VOLTAGE),
    (0x4000, Trip.NTC_OPEN), (0x4200, Trip.OVER_HEAT), (0x5000, Trip.FUSE_OPEN), (0x7000, Trip.FAN_TRIP),
    (0x7120, Trip.NO_MOTOR_TRIP), (0x7300, Trip.ENCODER_TRIP), (0x8401, Trip.SPEED_DEV_TRIP),
    (0x8402, Trip.OVER_SPEED), (0x9000, Trip.EXTERNAL_TRIP),
]


@pytest.mark.parametrize(("fault_code", "trip"), FAULT_CODES)
def test_inject_trip_by_fault_code(drive: AcgDrive, fault_code: int, trip: Trip) -> None:
    assert drive.inject_trip(fault_code, 0) is trip
    assert drive.fault_code == fault_code
    assert drive.drive_state is DriveState.FAULT_STOP
    assert drive.read(0x000E) & OperationStatus.FAULT_TRIP
    assert drive.read(0x0305) >> 12 == 8        # B12-B15: fault occurred


def test_every_trip_of_the_table_has_its_code() -> None:
    codes = {t.fault_code for t in Trip}
    assert codes == {c for c, _ in FAULT_CODES}
    for label in ("Ethermal", "Out Phase Open", "InverterOLT", "InPhaseOpen", "ThermalTrip", "UnderLoad",
                  "ParaWriteTrip", "IOBoardTrip", "PrePIDFail", "OptionTrip1", "OptionTrip2", "OptionTrip3",
                  "LostCommand", "LostKeypad"):
        assert next(t for t in Trip if t.label == label).fault_code == 0x1000
    assert Trip.HW_DIAG.fault_code == 0x5000 and Trip.BX.fault_code == 0x9000
    assert Trip.GROUND_TRIP.fault_code == 0x2330


def test_unknown_fault_code_is_refused(drive: AcgDrive) -> None:
    with pytest.raises(ValueError, match="0x1234"):
        drive.inject_trip(0x1234, 0)
    with pytest.raises(ValueError):
        drive.inject_trip(0x0000, 0)


def test_trip_bits_in_the_monitoring_words(drive: AcgDrive) -> None:
    drive.inject_trip(Trip.OVER_CURRENT_1, 0)
    assert drive.read(0x0330) == LatchTrip1.OVERCURRENT
    assert drive.read(0x000F) == 0x0001          # latch type trip
    drive.set_fault_reset(True, 1)
    drive.inject_trip(Trip.LOW_VOLTAGE, 2)
    assert drive.read(0x0330) == 0 and drive.read(0x0332) == LevelTrip.LOW_VOLTAGE
    assert drive.read(0x000F) == 0x0008          # level type trip
    drive.set_fault_reset(False, 3)
    drive.set_fault_reset(True, 4)
    drive.inject_trip(Trip.HW_DIAG, 5)
    assert drive.read(0x000F) == 0x0400          # H/W-Diag


def test_trip_cuts_the_output(drive: AcgDrive) -> None:
    reach(drive, 60, 0)
    drive.set_run_command(True, False, 0)
    drive.advance(5)
    drive.inject_trip(Trip.EXTERNAL_TRIP, 5)
    assert drive.output_frequency == 0 and not drive.running
    assert drive.next_deadline() is None


# --- Drive State, At Reference, ramps, rpm ---------------------------------------------------

def test_drive_states(drive: AcgDrive) -> None:
    assert drive.drive_state is DriveState.READY == 3
    reach(drive, 60, 0)
    drive.set_run_command(True, False, 0)
    assert drive.drive_state is DriveState.ENABLED == 4
    drive.set_run_command(False, False, 5)
    assert drive.drive_state is DriveState.STOPPING == 5
    drive.inject_trip(Trip.FAN_TRIP, 6)
    assert drive.drive_state is DriveState.FAULT_STOP == 6


def test_ramp_times(drive: AcgDrive) -> None:
    # ACC 5.0 s is the time from 0 to Max Freq 60 Hz: 30 Hz takes 2.5 s.
    reach(drive, 30, 0)
    drive.set_run_command(True, False, 0)
    assert drive.next_deadline() == pytest.approx(2.5)
    drive.advance(1.0)
    assert drive.output_frequency == 1200
    assert drive.read(0x000E) & OperationStatus.ACCELERATING
    assert not drive.at_reference
    drive.advance(2.5)
    assert drive.output_frequency == 3000 and drive.at_reference
    assert drive.read(0x000E) & OperationStatus.SPEED_REACHED
    assert drive.next_deadline() is None
    # dEC 10.0 s from Max Freq to 0: 30 Hz takes 5 s.
    drive.set_run_command(False, False, 3.0)
    assert drive.next_deadline() == pytest.approx(8.0)
    drive.advance(4.0)
    assert drive.output_frequency == 2400
    assert drive.read(0x000E) & (OperationStatus.DECELERATING | OperationStatus.STOPPING)
    drive.advance(8.0)
    assert drive.output_frequency == 0 and not drive.running


def test_ramp_follows_acc_dec_and_max_frequency(drive: AcgDrive) -> None:
    drive.write(0x0007, 100, 0)                 # common area acceleration time: 10.0 s, same as ACC
    assert drive.read(ACC) == 100 and drive.read(0x0383) == 100
    drive.write(MAX_FREQ, 12000, 0)             # 120.00 Hz max: 12 Hz per second
    reach(drive, 60, 0)
    drive.set_run_command(True, False, 0)
    assert drive.next_deadline() == pytest.approx(5.0)
    drive.advance(2.0)
    assert drive.output_frequency == 2400


def test_zero_ramp_time_is_a_step(drive: AcgDrive) -> None:
    drive.write(ACC, 0, 0)
    reach(drive, 45, 0)
    drive.set_run_command(True, False, 0)
    assert drive.output_frequency == 4500 and drive.at_reference


def test_reversal_decelerates_through_zero(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    drive.set_run_command(True, False, 0)
    drive.advance(2.5)
    drive.set_run_command(False, True, 2.5)      # "1 -> 0, 0 -> 1": Run2
    assert drive.next_deadline() == pytest.approx(7.5)   # 30 Hz down at 6 Hz/s
    drive.advance(7.5)
    assert drive.output_frequency == 0 and drive.running
    drive.advance(10.0)                          # 30 Hz up at 12 Hz/s
    assert drive.running_reverse and drive.output_frequency == 3000 and drive.at_reference


def test_reference_change_while_running(drive: AcgDrive) -> None:
    reach(drive, 60, 0)
    drive.set_run_command(True, False, 0)
    drive.advance(5)
    reach(drive, 30, 5)                          # slow down, still running: Enabled, not Stopping
    assert drive.drive_state is DriveState.ENABLED and not drive.at_reference
    drive.advance(10)
    assert drive.output_frequency == 3000 and drive.at_reference


@pytest.mark.parametrize(("poles", "rpm"), [(2, 3600), (4, 1800), (6, 1200), (8, 900)])
def test_rpm_from_pole_count(drive: AcgDrive, poles: int, rpm: int) -> None:
    drive.write(POLES, poles, 0)
    reach(drive, 60, 0)
    drive.set_run_command(True, False, 0)
    drive.advance(5)
    assert drive.speed_actual_rpm == rpm
    assert drive.read(0x0312) == drive.read(0x0015) == drive.read(addr("RPM")) == rpm
    assert drive.read(0x031A) == drive.read(0x001B) == poles


def test_rpm_command(drive: AcgDrive) -> None:
    drive.write(0x0381, 1500, 0)                 # 1500 rpm, 4 poles: 50.00 Hz
    assert drive.read(FREQUENCY_COMMAND) == 5000 and drive.read(0x0005) == 5000
    drive.set_speed_reference_rpm(900, 0)
    assert drive.speed_reference == 3000 and drive.speed_reference_rpm == 900
    assert refusal(lambda: drive.set_speed_reference_rpm(24001, 0)) is RegisterRefusal.OUT_OF_RANGE


def test_reference_source() -> None:
    d = AcgDrive()
    d.write(FREQUENCY_COMMAND, 4000, 0)
    d.write(addr("0.00"), 2000, 0)
    assert not d.reference_from_net and d.speed_reference == 2000   # Frq = 0: keypad frequency
    d.write(FRQ, 8, 0)
    assert d.reference_from_net and d.speed_reference == 4000


def test_local_command_when_drv_is_not_field_bus() -> None:
    d = AcgDrive()
    d.write(addr("0.00"), 3000, 0)
    d.local_command(Direction.FORWARD, 0)
    d.advance(5)
    assert d.running_forward and d.output_frequency == 3000
    assert not d.read(0x000E) & OperationStatus.COMMAND_FROM_COMMUNICATION


@settings(max_examples=60, deadline=None)
@given(acc=st.integers(1, 600), dec=st.integers(1, 600), reference=st.integers(1, 6000),
       times=st.lists(st.floats(0, 200, allow_nan=False), min_size=2, max_size=12))
def test_ramp_is_monotonic_and_bounded(acc: int, dec: int, reference: int, times: list[float]) -> None:
    d = AcgDrive()
    d.write(DRV, 4, 0)
    d.write(FRQ, 8, 0)
    d.write(ACC, acc, 0)
    d.write(DEC, dec, 0)
    d.write(FREQUENCY_COMMAND, reference, 0)
    d.set_run_command(True, False, 0)
    end = reference / 6000 * acc / 10
    assert d.next_deadline() == pytest.approx(end)
    samples = []
    for t in sorted(times):
        d.advance(t)
        samples.append(d.output_frequency_signed)
        expected = min(reference / 100, 6000 / 100 / (acc / 10) * t)
        assert d.output_frequency_signed == pytest.approx(expected, abs=1e-6)
    assert samples == sorted(samples)
    assert all(0 <= s <= reference / 100 for s in samples)
    start = d.time
    level = d.output_frequency_signed
    d.set_run_command(False, False, start)
    previous = level
    for t in sorted(times):
        d.advance(start + t)
        assert d.output_frequency_signed <= previous
        previous = d.output_frequency_signed
    assert previous >= 0


# --- Register refusals -----------------------------------------------------------------------

def test_read_only_refusal(drive: AcgDrive) -> None:
    assert refusal(lambda: drive.write(0x0311, 1, 0)) is RegisterRefusal.READ_ONLY
    assert refusal(lambda: drive.write(addr("CM.6"), 1, 0)) is RegisterRefusal.READ_ONLY
    assert refusal(lambda: drive.write(0x0100, 1, 0)) is RegisterRefusal.READ_ONLY


def test_out_of_range_refusal(drive: AcgDrive) -> None:
    assert refusal(lambda: drive.write(addr("CM.7"), 221, 0)) is RegisterRefusal.OUT_OF_RANGE
    assert refusal(lambda: drive.write(PR13, 0, 0)) is RegisterRefusal.OUT_OF_RANGE
    assert refusal(lambda: drive.write(PR12, 6, 0)) is RegisterRefusal.OUT_OF_RANGE
    assert refusal(lambda: drive.write(addr("CM.94"), 2, 0)) is RegisterRefusal.OUT_OF_RANGE
    # Above dr.20 Max Freq (60.00 Hz) although within 0-400.00 Hz.
    assert refusal(lambda: drive.write(FREQUENCY_COMMAND, 6001, 0)) is RegisterRefusal.OUT_OF_RANGE
    assert refusal(lambda: drive.write(PR14, 6001, 0)) is RegisterRefusal.OUT_OF_RANGE
    drive.write(FREQUENCY_COMMAND, 6000, 0)
    assert drive.read(0x0005) == 6000


def test_not_while_running_refusal(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    drive.set_run_command(True, False, 0)
    assert refusal(lambda: drive.write(addr("CM.23"), 4, 1)) is RegisterRefusal.NOT_WHILE_RUNNING
    assert refusal(lambda: drive.write(addr("CM.24"), 4, 1)) is RegisterRefusal.NOT_WHILE_RUNNING
    assert refusal(lambda: drive.write(0x03E0, 1, 1)) is RegisterRefusal.NOT_WHILE_RUNNING
    drive.write(ACC, 30, 1)                      # a run-writable parameter
    drive.set_run_command(False, False, 2)
    drive.advance(60)
    drive.write(addr("CM.23"), 4, 60)


def test_no_such_register(drive: AcgDrive) -> None:
    assert refusal(lambda: drive.read(0x0400)) is RegisterRefusal.NO_SUCH_REGISTER
    assert refusal(lambda: drive.write(0x1C22, 0, 0)) is RegisterRefusal.NO_SUCH_REGISTER


def test_parameter_initialization_refused_during_a_trip(drive: AcgDrive) -> None:
    drive.inject_trip(Trip.OVER_HEAT, 0)
    assert refusal(lambda: drive.write(0x03E2, 14, 1)) is RegisterRefusal.NOT_WHILE_RUNNING


def test_time_cannot_go_backwards(drive: AcgDrive) -> None:
    drive.advance(5)
    with pytest.raises(ValueError, match="backwards"):
        drive.advance(4)


# --- Modbus command words (ACG RS-485 manual) ----------------------------------------------------------

def test_control_area_operation_command(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    drive.write(0x0382, 0x0003, 0)               # forward operation command
    drive.advance(5)
    assert drive.running_forward
    drive.write(0x0382, 0x0001, 5)               # reverse operation command
    drive.advance(20)
    assert drive.running_reverse and drive.output_frequency == 3000
    drive.write(0x0382, 0x0009, 20)              # B3 0 -> 1: free-run stop
    assert not drive.running and drive.output_frequency == 0
    drive.write(0x0382, 0x0000, 21)
    drive.inject_trip(Trip.OVER_LOAD, 22)
    drive.write(0x0382, 0x0004, 23)              # B2 0 -> 1: trip initialization
    assert not drive.faulted


def test_common_area_operation_command(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    drive.write(0x0006, 0x0002, 0)               # B1: forward
    drive.advance(5)
    assert drive.running_forward
    drive.write(0x0006, 0x0004, 5)               # B2: reverse
    drive.advance(20)
    assert drive.running_reverse
    drive.write(0x0006, 0x0001, 20)              # B0: stop
    assert drive.drive_state is DriveState.STOPPING
    # Read back: B6-B8 the command source (4 option), B9-B14 the frequency source (28 option).
    assert drive.read(0x0006) == 0x0001 | 4 << 6 | 28 << 9


def test_emergency_stop_is_a_level_trip(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    drive.write(0x0006, 0x0002, 0)
    drive.advance(5)
    drive.write(0x0006, 0x0010, 5)               # B4: emergency stop
    assert drive.trip is Trip.BX and drive.fault_code == 0x9000 and not drive.running
    assert drive.read(0x0332) == LevelTrip.BX
    drive.write(0x0006, 0x0018, 6)               # a reset does not clear it while B4 is set
    assert drive.faulted
    drive.write(0x0006, 0x0000, 7)               # BX released: the level trip clears
    assert not drive.faulted and not drive.running


def test_registered_parameters(drive: AcgDrive) -> None:
    # CM.31-CM.33 default to 0x000A (output frequency), 0x000E, 0x000F; CM.51/52 to 0x0005/0x0006.
    reach(drive, 30, 0)
    drive.write(0x0111, 0x0002, 0)               # Control Parameter-2 -> 0x0006: forward
    drive.advance(5)
    assert drive.read(0x0100) == 3000
    assert drive.read(0x0101) == drive.read(0x000E)
    drive.write(0x0110, 1500, 5)                 # Control Parameter-1 -> 0x0005: 15 Hz
    assert drive.read(0x0110) == 1500 and drive.speed_reference == 1500
    assert drive.status_parameter_addresses == (0x000A, 0x000E, 0x000F)
    assert drive.control_parameter_addresses == (0x0005, 0x0006)


def test_virtual_inputs_and_relays_are_monitored(drive: AcgDrive) -> None:
    drive.write(0x0385, 0x0005, 0)
    assert drive.read(0x0322) == drive.read(addr("CM.86")) == 0x0005
    drive.write(0x0386, 0x0002, 0)
    assert drive.read(0x0321) == drive.read(0x0011) == 0x0002


def test_operation_state_word(drive: AcgDrive) -> None:
    reach(drive, 30, 0)
    drive.set_run_command(False, True, 0)
    drive.advance(1)
    assert drive.read(0x0305) == 2 << 4 | 2       # accelerating, reverse
    drive.advance(10)
    assert drive.read(0x0305) == 3 << 4 | 2       # constant, reverse
    drive.set_run_command(False, False, 10)
    assert drive.read(0x0305) == 5 << 4 | 2       # decelerating to stop
    assert drive.read(0x0306) == 1 << 8 | 11      # communication option, both sources


# --- Lost command: Pr.12 / Pr.13 / Pr.14 -----------------------------------------------------

def test_lost_preset_range() -> None:
    # ACG-ET2 manual: Pr.14 0.05-60.00 Hz, default 0.00 (kept, so it can be written back).
    d = AcgDrive()
    d.write(addr("dr.20"), 40000, 0.0)                   # Max Freq 400.00 Hz: the table's 60.00 still bounds Pr.14
    for value in (0, 5, 6000):
        d.write(PR14, value, 0.0)
        assert d.read(PR14) == value
    for value in (1, 4, 6001):
        assert refusal(lambda v=value: d.write(PR14, v, 0.0)) is RegisterRefusal.OUT_OF_RANGE
    assert d.read(PR14) == 6000
    d.write(addr("dr.20"), 5000, 0.0)                    # and the present Max Freq does too
    assert refusal(lambda: d.write(PR14, 5500, 0.0)) is RegisterRefusal.OUT_OF_RANGE


def lost_setup(mode: int, lost_time: int = 20, acc: int = 600) -> AcgDrive:
    """Running forward towards 60 Hz at 1 Hz/s (ACC 60.0 s); Pr.13 = 2.0 s."""
    d = AcgDrive()
    d.write(DRV, 4, 0)
    d.write(FRQ, 8, 0)
    d.write(ACC, acc, 0)
    d.write(PR12, mode, 0)
    d.write(PR13, lost_time, 0)
    d.write(PR14, 2000, 0)
    d.write(FREQUENCY_COMMAND, 6000, 0)
    d.set_run_command(True, False, 0)
    return d


def test_io_loss_timing() -> None:
    d = lost_setup(1)
    d.on_io_connection_lost(10)
    # Lost command mode after the connection has been broken for 1 s, Pr.12 after Pr.13 more.
    assert d.next_deadline() == pytest.approx(10 + IO_BREAK_TIME)
    d.advance(11)
    assert d.command_lost and d.next_deadline() == pytest.approx(13)
    d.advance(12.999)
    assert not d.faulted and d.running
    d.advance(13)
    assert d.faulted


def test_pr12_none_keeps_running() -> None:
    d = lost_setup(0)
    d.on_io_connection_lost(10)
    d.advance(30)
    assert not d.faulted and not d.warning and d.output_frequency == 3000


def test_pr12_free_run() -> None:
    d = lost_setup(1)
    d.on_io_connection_lost(10)
    d.advance(13)
    assert d.trip is Trip.LOST_COMMAND and d.fault_code == 0x1000
    assert d.output_frequency == 0 and not d.running          # free-run: output cut at once
    assert d.read(0x0332) == LevelTrip.LOST_COMMAND
    assert not d.set_fault_reset(True, 14)                     # level type: holds while lost
    assert d.faulted


def test_pr12_dec() -> None:
    d = lost_setup(2)
    d.on_io_connection_lost(10)
    d.advance(13)
    assert d.trip is Trip.LOST_COMMAND
    assert d.output_frequency == 1300 and d.running            # 13 Hz, decelerating
    assert d.drive_state is DriveState.FAULT_STOP
    assert d.next_deadline() == pytest.approx(13 + 13 / 60 * 10.0)
    d.advance(20)
    assert d.output_frequency == 0 and not d.running


@pytest.mark.parametrize(("mode", "hz"), [(3, 60), (4, 13), (5, 20)])
def test_pr12_warning_modes(mode: int, hz: float) -> None:
    # Hold Input: the previous speed reference (60 Hz); Hold Output: the running speed at the
    # time (13 Hz after 13 s at 1 Hz/s); Lost Preset: Pr.14 (20.00 Hz).
    d = lost_setup(mode)
    d.on_io_connection_lost(10)
    d.advance(13)
    assert not d.faulted and d.warning
    assert d.warnings == WarningInformation.LOST_COMMAND
    assert d.read(0x0334) == WarningInformation.LOST_COMMAND
    assert d.read(0x0305) >> 12 == 4                            # warning occurred
    assert d.speed_reference == hz * 100
    d.advance(100)
    assert d.output_frequency == hz * 100 and d.running_forward
    d.on_io_connection_opened(100)                              # communication is back
    assert not d.warning and d.speed_reference == 6000


def test_free_run_trip_clears_when_communication_returns() -> None:
    d = lost_setup(1)
    d.on_io_connection_lost(10)
    d.advance(13)
    d.on_io_connection_opened(20)
    assert not d.faulted and not d.running
    d.set_run_command(True, False, 21)                          # still 1: no restart
    assert not d.running
    d.set_run_command(False, False, 22)
    d.set_run_command(True, False, 23)
    assert d.running_forward


def test_restored_before_pr13_elapses() -> None:
    d = lost_setup(1)
    d.on_io_connection_lost(10)
    d.advance(12)
    d.on_io_connection_opened(12.5)
    d.advance(30)
    assert not d.faulted and not d.command_lost and d.output_frequency == 3000


def test_io_reconnect_within_one_second() -> None:
    d = lost_setup(1)
    d.on_io_connection_lost(10)
    d.on_io_connection_opened(10.5)
    assert d.next_deadline() is None or d.next_deadline() > 10.5
    d.advance(30)
    assert not d.command_lost and not d.faulted


def test_modbus_silence() -> None:
    d = lost_setup(1, lost_time=10)
    d.advance(100)                                              # no Modbus client seen: no watch
    assert not d.faulted
    d.on_modbus_activity(100)
    d.on_modbus_activity(104)
    assert d.next_deadline() == pytest.approx(104 + MODBUS_SILENCE_TIME)
    d.advance(109)
    assert d.command_lost and not d.faulted
    d.advance(109.999)
    assert not d.faulted
    d.advance(110)
    assert d.trip is Trip.LOST_COMMAND
    d.on_modbus_activity(111)
    assert not d.faulted and not d.command_lost


def test_lost_command_applies_only_to_network_operation() -> None:
    d = AcgDrive()
    d.write(PR12, 1, 0)
    d.write(addr("0.00"), 3000, 0)
    d.local_command(Direction.FORWARD, 0)
    d.on_io_connection_lost(1)
    d.advance(10)
    assert not d.faulted and d.running


def test_pr13_timing() -> None:
    for tenths in (1, 10, 1200):
        d = lost_setup(1, lost_time=tenths)
        d.on_modbus_activity(0)
        d.advance(5 + tenths / 10 - 0.01)
        assert not d.faulted
        d.advance(5 + tenths / 10)
        assert d.faulted


# --- CM.94 Comm Update ------------------------------------------------------------------------

def test_comm_update_gates_network_parameters() -> None:
    d = AcgDrive()
    assert d.active_comm_settings.input_instance.instance == 71
    assert d.active_comm_settings.output_instance.instance == 21
    d.write(addr("CM.23"), 5, 0)                 # instance 142
    d.write(addr("CM.24"), 8, 0)                 # instance 125
    d.write(addr("CM.13"), 7, 0)
    assert d.read(addr("CM.30")) == 2 and d.read(addr("CM.50")) == 5   # set with the instances
    assert d.comm_update_pending
    assert d.active_comm_settings.input_instance.instance == 71
    assert d.active_comm_settings.ip_address == "192.168.1.101"
    assert d.pending_comm_settings.input_instance.instance == 142
    d.write(addr("CM.94"), 1, 1)
    assert d.read(addr("CM.94")) == 0 and not d.comm_update_pending
    active = d.active_comm_settings
    assert (active.input_instance.instance, active.output_instance.instance) == (142, 125)
    assert active.ip_address == "192.168.1.7" and active.subnet_mask == "255.255.255.0"
    assert active.gateway == "192.168.1.10" and active.station_id == 10


def test_comm_update_zero_does_nothing() -> None:
    d = AcgDrive()
    d.write(addr("CM.7"), 20, 0)
    d.write(addr("CM.94"), 0, 0)
    assert d.active_comm_settings.station_id == 10 and d.comm_update_pending


# --- Parameter lock (0x03E8) -------------------------------------------------------------------

def test_parameter_lock_password() -> None:
    d = AcgDrive(password=244)
    d.write(0x03E8, 244, 0)
    assert d.read(0x03E8) == 1
    assert refusal(lambda: d.write(ACC, 20, 0)) is RegisterRefusal.READ_ONLY
    d.write(0x03E8, 244, 0)                      # the same value again in a row: executed once
    assert d.read(0x03E8) == 1
    d.write(0x03E8, 0, 0)
    d.write(0x03E8, 244, 0)                      # 244 > 0 > 244
    assert d.read(0x03E8) == 0
    d.write(ACC, 20, 0)


# --- advance_to: the shell's call before every request, cheap for a drive at rest --------------

_STEPS = st.lists(st.tuples(
    st.sampled_from(["forward", "reverse", "stop", "io_lost", "io_opened", "modbus", "trip", "reset", "none"]),
    st.floats(min_value=0, max_value=8, allow_nan=False)), max_size=14)


def _snapshot(d: AcgDrive) -> dict[int, object]:
    seen: dict[int, object] = {}
    for register in ACG_REGISTERS.values():
        try:
            seen[register.address] = d.read(register.address)
        except RegisterError as exc:
            seen[register.address] = exc.refusal
    return seen


@given(_STEPS)
@settings(max_examples=60, deadline=None)
def test_advance_to_is_advance_then_next_deadline(steps) -> None:
    """Two drives given the same events: one moved by ``advance_to`` (which, at rest, only moves the
    clock), the other by ``advance`` and ``next_deadline``. They agree on every register and every
    deadline, at rest or not (stopped, ramping, running, watched for a command loss, tripped)."""
    fast, slow = lost_setup(2, lost_time=10, acc=50), lost_setup(2, lost_time=10, acc=50)
    for d in (fast, slow):
        d.set_run_command(False, False, 0)  # begin at rest: output off, nothing watched
    now = 0.0
    for action, dt in steps:
        now += dt
        deadline = fast.advance_to(now)
        slow.advance(now)
        assert deadline == slow.next_deadline()
        for d in (fast, slow):
            if action == "forward":
                d.set_run_command(True, False, now)
            elif action == "reverse":
                d.set_run_command(False, True, now)
            elif action == "stop":
                d.set_run_command(False, False, now)
            elif action == "io_lost":
                d.on_io_connection_lost(now)
            elif action == "io_opened":
                d.on_io_connection_opened(now)
            elif action == "modbus":
                d.on_modbus_activity(now)
            elif action == "trip":
                d.inject_trip(Trip.OVER_HEAT, now)
            elif action == "reset":
                d.set_fault_reset(False, now)
                d.set_fault_reset(True, now)
        assert fast.time == slow.time
        assert _snapshot(fast) == _snapshot(slow)


def test_advance_to_at_rest_moves_only_the_clock() -> None:
    d = AcgDrive()
    assert d.advance_to(1.0) is None and d.time == 1.0   # at rest: no deadline, the clock alone moves
    assert d.advance_to(0.5) is None and d.time == 1.0  # never backwards: it stays where it is
    d.write(DRV, 4, 1.0)
    d.write(FRQ, 8, 1.0)
    d.write(FREQUENCY_COMMAND, 6000, 1.0)
    d.set_run_command(True, False, 1.0)
    assert d.next_deadline() is not None                 # ramping: advance_to runs the ramp
    assert d.advance_to(2.0) == pytest.approx(1.0 + 5.0)  # ACC 5.0 s to 60 Hz
    assert d.output_frequency == 1200
