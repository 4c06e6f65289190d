"""The MX2/RX inverter simulation: sections 4-2 to 4-7, appendices B, D, E and F of the option board manual."""

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cipstack.devices.omron.inverter import (
    DriveState,
    DriveStateDetail,
    FlexibleMappingError,
    FlexibleRule,
    Inverter,
    InverterModeError,
    Source,
    validate_flexible,
)
from cipstack.devices.omron.models import Family
from cipstack.devices.omron.registers import SpeedUnit, register_set
from cipstack.devices.registers import RegisterError, RegisterRefusal

MX2_MODEL = "MX2-A2015-E"
RX_MODEL = "RX-A4055-E"
MX2 = register_set(Family.MX2)
RX = register_set(Family.RX)


def configured(name: str = MX2_MODEL, now: float = 0.0, **codes: int) -> Inverter:
    """An inverter with parameters written by function code and its option board restarted."""
    inverter = Inverter(name, now=now)
    for code, value in codes.items():
        if code == "F001":      # Modbus only: the Function Code object cannot write F001 (section E-2-2)
            inverter.write(0x0001, value, now)
        else:
            inverter.write_code(code, value, now)
    inverter.reset_option_board(now)
    return inverter


def option_source(name: str = MX2_MODEL, **codes: int) -> Inverter:
    """Section 4-2-1 Step 1: A001 = A002 = 4 (MX2) or 5 (RX), the option board as source."""
    source = 4 if name.startswith("MX2") else 5
    return configured(name, A001=source, A002=source, **codes)


def running(inverter: Inverter, now: float, hz: float = 10.0) -> None:
    """Start forward through the option board with a fresh rising edge and wait until at reference."""
    inverter.command(now, fwd=False, speed_reference=round(hz * 100))
    inverter.command(now, fwd=True)
    end = inverter.next_deadline()
    assert end is not None
    inverter.advance(end)
    assert inverter.status().at_reference


# -- the rising-edge rule (note to Tables B-2, B-6, B-10, B-19, B-25) -------------------------------

@pytest.mark.parametrize("name", [MX2_MODEL, RX_MODEL])
def test_fwd_set_at_power_on_needs_a_rising_edge(name):
    inverter = option_source(name)
    inverter.command(0.0, fwd=True, speed_reference=1000)
    inverter.advance(5.0)
    assert not inverter.status().running and inverter.output_frequency == 0
    inverter.command(5.0, fwd=False)
    inverter.command(5.0, fwd=True)
    inverter.advance(6.0)
    assert inverter.status().running and inverter.status().forward
    assert inverter.output_frequency == pytest.approx(5.0)   # F002 = 10 s from 0 to A004 = 50 Hz


def test_rev_needs_its_own_rising_edge_too():
    inverter = option_source()
    inverter.command(0.0, rev=True, speed_reference=1000)
    inverter.advance(1.0)
    assert not inverter.status().running
    inverter.command(1.0, rev=False)
    inverter.command(1.0, rev=True)
    inverter.advance(2.0)
    assert inverter.status().reverse and inverter.output_frequency == pytest.approx(-5.0)


def test_fwd_held_through_a_trip_reset_does_not_restart():
    inverter = option_source(C102=3)
    running(inverter, 0.0)
    inverter.raise_trip(3.0, 12)
    assert inverter.status().faulted and inverter.output_frequency == 0
    inverter.command(4.0, fault_reset=True)          # RST 0 -> 1
    assert inverter.trip == 0
    inverter.advance(6.0)
    assert not inverter.status().running             # FWD stayed 1 through the reset
    inverter.command(6.0, fwd=False)
    inverter.command(6.5, fwd=True)
    inverter.advance(7.5)
    assert inverter.output_frequency == pytest.approx(5.0)


def test_fwd_cleared_with_the_reset_runs_on_the_next_message():
    # Section 4-5-2: clear FWD/REV on FLT, then set RST; with C102 = 0 the board restarts on the reset.
    inverter = option_source()
    running(inverter, 0.0)
    inverter.command(3.0, force_fault=True)
    inverter.command(3.1, fwd=False, force_fault=False)
    inverter.command(3.2, fault_reset=True)
    assert inverter.trip == 0 and inverter.option_board_resets == 2
    inverter.command(3.3, fault_reset=False, fwd=True)
    inverter.advance(4.3)
    assert inverter.output_frequency == pytest.approx(5.0)


def test_rst_held_from_power_on_is_not_a_reset():
    inverter = option_source()
    inverter.raise_trip(0.0, 12)
    inverter.command(0.0, fault_reset=True)
    assert inverter.status().faulted
    inverter.command(0.1, fault_reset=False)
    inverter.command(0.2, fault_reset=True)
    assert not inverter.status().faulted


def test_opr_coil_restarts_as_soon_as_the_trip_clears():
    # Section 4-7-3: "If the Opr bit is set when the trip condition is cleared, the Inverter will
    # immediately start running!" - the Modbus coils have no rising-edge rule.
    inverter = configured(A001=3, A002=3, F001=1000, C102=3)
    inverter.write(0x1F01, 0x0002, 0.0)
    inverter.advance(2.0)
    assert inverter.status().at_reference
    inverter.write(0x1F01, 0x0002 | 0x0008, 2.0)     # EXT: external trip E12
    assert inverter.trip == 12
    assert inverter.read(0x1E01) & (1 << 8)          # AL
    inverter.write(0x1F01, 0x0002 | 0x0010, 3.0)     # RS with Opr still set
    assert inverter.trip == 0
    inverter.advance(4.0)
    assert inverter.output_frequency == pytest.approx(5.0)


def test_rs_coil_held_clears_new_trips():
    # Section 4-7-3 warning: "Not doing so will result in new trip conditions automatically being cleared."
    inverter = configured(A001=3, A002=3)
    inverter.write(0x1F01, 0x0010, 0.0)
    inverter.raise_trip(1.0, 12)
    assert inverter.trip == 0
    assert inverter.read_code("d081") == 12          # the trip monitor keeps it


# -- force fault (section 4-5-1, Table D-4 attributes 0x11/0x12, section E-1 Example 2) ---------------

@pytest.mark.parametrize(("name", "code"), [(MX2_MODEL, 62), (RX_MODEL, 72)])
def test_force_fault_trips_on_the_rising_edge(name, code):
    inverter = option_source(name)
    running(inverter, 0.0)
    inverter.command(3.0, force_fault=True)
    status = inverter.status()
    assert status.faulted and status.trip_cause == code and status.force_status
    assert status.fault_code == 0x7510 and status.drive_state is DriveState.FAULTED
    assert status.drive_state_detail is DriveStateDetail.TRIP
    assert status.output_frequency == 0 and not status.ready
    assert inverter.read_code("d081") == code
    inverter.command(4.0, force_fault=False)         # Table 24: clear FFL, then reset the trip
    inverter.command(4.0, fault_reset=False)
    inverter.command(4.5, fault_reset=True)
    assert not inverter.status().faulted and not inverter.status().force_status


def test_force_fault_held_does_not_trip_again_after_the_reset():
    inverter = option_source()
    inverter.command(0.0, force_fault=True)
    inverter.command(0.0, fault_reset=False)
    inverter.command(0.1, fault_reset=True)
    assert inverter.trip == 0
    inverter.command(0.2, speed_reference=500)
    assert inverter.trip == 0


# -- NetCtrl and NetRef (section 4-2-1 note, Table B-6) ----------------------------------------------

def test_netctrl_and_netref_override_a001_a002():
    inverter = configured(A001=1, A002=1)             # control terminal as source
    inverter.local_reference = 2000
    inverter.command(0.0, fwd=False, speed_reference=1000)
    inverter.command(0.0, fwd=True)
    inverter.advance(1.0)
    status = inverter.status()
    assert not status.running and not status.ctrl_from_net and not status.ref_from_net
    assert inverter.run_source is Source.LOCAL

    inverter.command(1.0, net_ctrl=True)              # CTR: run command from the network
    assert inverter.run_source is Source.OPTION_BOARD and inverter.status().ctrl_from_net
    inverter.advance(2.0)
    assert inverter.output_frequency == pytest.approx(5.0)
    inverter.advance(6.0)
    assert inverter.output_frequency == pytest.approx(20.0)      # the local reference, 20 Hz

    inverter.command(6.0, net_ref=True)               # REF: speed reference from the network
    assert inverter.reference_source is Source.OPTION_BOARD and inverter.status().ref_from_net
    inverter.advance(9.0)
    assert inverter.output_frequency == pytest.approx(10.0)

    inverter.command(9.0, net_ctrl=False)             # back to A002: no local run command, so it stops
    assert inverter.status().drive_state is DriveState.STOPPING
    inverter.advance(11.0)
    assert inverter.output_frequency == 0 and inverter.status().drive_state is DriveState.READY


def test_netref_selects_the_network_ramp_times():
    # Table B-25: with REF set, assembly 110's times replace F002/F003.
    inverter = option_source()
    inverter.command(0.0, net_ref=True, accel_time=2.0, decel_time=1.0, speed_reference=2500)
    inverter.command(0.0, fwd=True)
    inverter.advance(0.5)
    assert inverter.output_frequency == pytest.approx(12.5)      # 50 Hz in 2 s
    inverter.advance(1.0)
    inverter.command(1.0, fwd=False)
    inverter.advance(1.25)
    assert inverter.output_frequency == pytest.approx(12.5)      # 50 Hz in 1 s down


# -- ramps, direction change, stop (section 4-2) -------------------------------------------------------

def test_acceleration_reference_and_deceleration():
    inverter = option_source(F002=500, F003=250)      # 5 s and 2.5 s from 0 to 50 Hz
    inverter.command(0.0, speed_reference=2000)
    inverter.command(0.0, fwd=True)
    assert inverter.next_deadline() == pytest.approx(2.0)
    inverter.advance(1.0)
    status = inverter.status()
    assert status.output_frequency == 1000 and not status.at_reference and status.status_c == 4
    inverter.advance(2.0)
    status = inverter.status()
    assert status.at_reference and status.status_c == 3 and status.drive_state is DriveState.ENABLED
    assert inverter.read(0x1001) == 2000 and inverter.read_word(0x1002) == 2000
    inverter.command(3.0, fwd=False)                  # section 4-2-3: decelerated stop, ARF clears
    assert not inverter.status().at_reference and inverter.status().drive_state is DriveState.STOPPING
    inverter.advance(3.5)
    assert inverter.output_frequency == pytest.approx(10.0) and inverter.status().status_c == 2
    inverter.advance(4.0)
    assert inverter.output_frequency == 0 and not inverter.status().running
    assert inverter.next_deadline() is None


def test_changing_direction_decelerates_through_zero():
    inverter = option_source()
    running(inverter, 0.0, hz=10.0)                  # 2 s at 5 Hz/s
    inverter.command(2.0, fwd=False, rev=True)
    assert inverter.next_deadline() == pytest.approx(6.0)
    inverter.advance(3.0)
    assert inverter.output_frequency == pytest.approx(5.0) and inverter.status().forward
    inverter.advance(5.0)
    assert inverter.output_frequency == pytest.approx(-5.0) and inverter.status().reverse
    inverter.advance(6.0)
    assert inverter.status().at_reference and inverter.status().reverse


def test_zero_reference_keeps_run_mode():
    # Section 4-2-3 note: with the run bit left set at 0 Hz the inverter stays in run mode.
    inverter = option_source()
    running(inverter, 0.0)
    inverter.command(2.0, speed_reference=0)
    inverter.advance(10.0)
    status = inverter.status()
    assert status.output_frequency == 0 and status.running and status.zero_speed
    assert status.drive_state is DriveState.ENABLED


def test_reference_is_limited_to_the_maximum_frequency():
    inverter = option_source()
    inverter.command(0.0, speed_reference=9000)
    inverter.command(0.0, fwd=True)
    inverter.advance(20.0)
    assert inverter.output_frequency == pytest.approx(50.0)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 360000), st.integers(1, 360000), st.integers(0, 5000), st.booleans())
def test_ramps_end_at_the_reference(accel, decel, reference, reverse):
    inverter = option_source(F002=accel, F003=decel)
    inverter.command(0.0, speed_reference=reference)
    inverter.command(0.0, rev=reverse, fwd=not reverse)
    previous = 0.0
    end = inverter.next_deadline() or 0.0
    for step in range(1, 5):
        inverter.advance(end * step / 4)
        assert abs(inverter.output_frequency) >= previous - 1e-9
        previous = abs(inverter.output_frequency)
    assert inverter.status().at_reference
    assert inverter.status().output_frequency == reference
    assert end == pytest.approx(reference / 5000 * accel * 0.01)


def test_time_may_not_run_backwards():
    inverter = Inverter(MX2_MODEL, now=10.0)
    with pytest.raises(ValueError):
        inverter.advance(9.0)


# -- free-run stop (sections 4-2-4, 4-3, Table B-25) -------------------------------------------------

def test_free_run_terminal_takes_effect_after_an_option_board_reset():
    inverter = option_source()
    running(inverter, 0.0)
    with pytest.raises(RegisterError):
        inverter.write_code("C001", 11, 2.0)         # not run-mode editable
    inverter.command(2.0, fwd=False)
    inverter.advance(5.0)
    inverter.write_code("C001", 11, 5.0)
    inverter.set_terminals(5.0, 0b1)
    inverter.command(5.0, fwd=True)                   # the new C001 is not in effect yet
    inverter.advance(5.5)
    assert inverter.output_frequency == pytest.approx(2.5)
    inverter.command(5.5, fwd=False)
    inverter.advance(6.0)
    inverter.reset_option_board(6.0)                  # "Restart the Inverter or reset the Option Board"
    inverter.command(6.0, fwd=False, speed_reference=1000)   # the reset board holds no reference: sent again
    inverter.command(6.0, fwd=True)
    inverter.advance(7.0)
    status = inverter.status()
    assert status.output_frequency == 0 and not status.at_reference
    assert status.drive_state_detail is DriveStateDetail.FREE_RUNNING
    inverter.set_terminals(7.0, 0)
    inverter.advance(8.0)
    assert inverter.output_frequency == pytest.approx(5.0)      # restarts from 0 Hz


def test_free_run_drops_the_speed_monitor_at_once():
    inverter = option_source(C003=11)
    running(inverter, 0.0)
    inverter.command(2.0, input_overrides=0b100)      # CI3 overrides terminal 3 (section 4-3)
    status = inverter.status()
    assert status.output_frequency == 0 and status.speed_actual == 0 and not status.at_reference
    assert status.inputs == 0b100 and inverter.read_code("d005") == 0b100
    inverter.command(2.0, input_overrides=0, free_run=True)   # FRS of assembly 110
    assert inverter.output_frequency == 0


def test_intelligent_input_coils_drive_the_terminals():
    inverter = configured(A001=3, A002=3, C001=11, F001=1000)
    inverter.write(0x1F01, 0x0002, 0.0)
    inverter.advance(2.0)
    assert inverter.output_frequency == pytest.approx(10.0)
    inverter.write(0x1F01, 0x0002 | 1 << 7, 2.0)     # In1 (Table 18 bit 7)
    assert inverter.output_frequency == 0
    assert inverter.read_code("d005") == 1


# -- network error timer P044 and actions P045, idle action P048 (Table 12) --------------------------

def start_with_timer(action_code: str, action: int, timer: int = 30) -> Inverter:
    """At reference at t = 2 s with the network error timer at 3.0 s, last traffic at t = 2 s."""
    inverter = option_source(P044=timer, **{action_code: action})
    inverter.on_network_ok(0.0)
    running(inverter, 0.0)                            # at 10 Hz at t = 2 s
    inverter.on_network_ok(2.0)
    return inverter


def test_p044_timer_runs_only_while_running_and_is_kicked_by_traffic():
    inverter = start_with_timer("P045", 0)
    assert inverter.next_deadline() == pytest.approx(5.0)
    inverter.advance(4.9)
    inverter.on_network_ok(4.9)
    inverter.advance(7.8)
    assert inverter.trip == 0
    inverter.advance(7.9)
    assert inverter.trip == 63                        # E63: communication lost (Table D-5)
    stopped = option_source(P044=10)
    stopped.advance(100.0)
    assert stopped.trip == 0 and stopped.next_deadline() is None


def test_p044_zero_disables_the_timer():
    inverter = start_with_timer("P045", 0, timer=0)
    inverter.advance(1000.0)
    assert inverter.trip == 0 and inverter.status().at_reference


def test_p045_0_trips():
    inverter = start_with_timer("P045", 0)
    inverter.advance(10.0)
    status = inverter.status()
    assert status.trip_cause == 63 and status.fault_code == 0x7510 and status.output_frequency == 0


def test_p045_1_decelerates_then_trips():
    inverter = start_with_timer("P045", 1)
    inverter.advance(5.0)
    status = inverter.status()
    assert not status.faulted and status.drive_state is DriveState.FAULT_STOP
    inverter.advance(5.5)
    assert inverter.output_frequency == pytest.approx(7.5)
    inverter.advance(7.0)
    assert inverter.trip == 63 and inverter.status().drive_state is DriveState.FAULTED


def test_p045_2_does_nothing():
    inverter = start_with_timer("P045", 2)
    inverter.advance(30.0)
    assert inverter.trip == 0 and inverter.status().at_reference


def test_p045_3_free_runs():
    inverter = start_with_timer("P045", 3)
    inverter.advance(5.0)
    status = inverter.status()
    assert status.output_frequency == 0 and not status.faulted and not status.running


def test_p045_4_decelerates_and_stops_then_runs_again_on_a_new_command():
    inverter = start_with_timer("P045", 4)
    inverter.advance(5.5)
    assert inverter.output_frequency == pytest.approx(7.5) and inverter.status().drive_state is DriveState.STOPPING
    inverter.advance(8.0)
    assert inverter.output_frequency == 0 and inverter.trip == 0
    inverter.on_network_ok(8.0)                       # the master is back and still sends FWD = 1
    inverter.command(8.0, fwd=True)
    inverter.advance(9.0)
    assert inverter.output_frequency == pytest.approx(5.0)


def test_connection_loss_applies_p045_at_once():
    inverter = option_source(P045=0)
    running(inverter, 0.0)
    inverter.on_network_error(2.5)
    assert inverter.trip == 63


@pytest.mark.parametrize(("name", "code"), [(MX2_MODEL, 63), (RX_MODEL, 73)])
def test_p048_idle_trip(name, code):
    inverter = option_source(name, P048=0)
    running(inverter, 0.0)
    inverter.on_idle(2.0)
    assert inverter.trip == code


def test_idle_while_stopped_does_nothing():
    inverter = option_source(P048=0)
    inverter.on_idle(1.0)
    assert inverter.trip == 0
    inverter.on_network_ok(2.0)
    running(inverter, 2.0)
    inverter.on_idle(4.0)
    assert inverter.trip == 63


def test_p048_idle_actions():
    decelerate = option_source(P048=4)
    running(decelerate, 0.0)
    decelerate.on_idle(2.0)
    decelerate.advance(3.0)
    assert decelerate.output_frequency == pytest.approx(5.0) and decelerate.trip == 0
    ignore = option_source(P048=2)
    running(ignore, 0.0)
    ignore.on_idle(2.0)
    ignore.advance(9.0)
    assert ignore.status().at_reference
    coast = option_source(P048=3)
    running(coast, 0.0)
    coast.on_idle(2.0)
    assert coast.output_frequency == 0 and coast.trip == 0
    decel_trip = option_source(P048=1)
    running(decel_trip, 0.0)
    decel_trip.on_idle(2.0)
    decel_trip.advance(4.0)
    assert decel_trip.trip == 63


# -- register access and refusals ----------------------------------------------------------------------

def test_refusals():
    inverter = option_source()
    with pytest.raises(RegisterError) as caught:
        inverter.write(0x9999, 1, 0.0)
    assert caught.value.refusal is RegisterRefusal.NO_SUCH_REGISTER
    with pytest.raises(RegisterError) as caught:
        inverter.write(0x1001, 5, 0.0)                # d001 is a monitor
    assert caught.value.refusal is RegisterRefusal.READ_ONLY
    with pytest.raises(RegisterError) as caught:
        inverter.write_code("P046", 8, 0.0)           # Table 25: P046 in 0..7
    assert caught.value.refusal is RegisterRefusal.OUT_OF_RANGE
    with pytest.raises(RegisterError) as caught:
        inverter.write_code("F001", 1000, 0.0)        # section E-2-2
    assert caught.value.refusal is RegisterRefusal.READ_ONLY
    with pytest.raises(RegisterError) as caught:
        inverter.write(0x0900, 0, 0.0)                # the ENTER command is 01h
    assert caught.value.refusal is RegisterRefusal.OUT_OF_RANGE
    running(inverter, 0.0)
    with pytest.raises(RegisterError) as caught:
        inverter.write_code("A001", 3, 2.0)           # not run-mode editable
    assert caught.value.refusal is RegisterRefusal.NOT_WHILE_RUNNING
    inverter.write_code("F002", 2000, 2.0)            # run-mode editable
    assert inverter.read(0x1103) == 2000


def test_function_code_object_access():
    inverter = Inverter(MX2_MODEL)
    inverter.write_function_code(15060, 128000, 0.0)  # section E-2-2 Example 2
    assert inverter.read_function_code(0x3AD4) == 128000
    assert inverter.read_word(0x163E) == 0x0001 and inverter.read_word(0x163F) == 0xF400
    inverter.write_function_code(15060, -5, 0.0)
    assert inverter.read(0x163E) == -5 and inverter.read(0x163F) == 0xFFFB
    with pytest.raises(RegisterError) as caught:
        inverter.read_function_code(15999)
    assert caught.value.refusal is RegisterRefusal.NO_SUCH_REGISTER
    rx = Inverter(RX_MODEL)
    rx.write_code("P044", 50, 0.0)                    # the RX parameter has no Modbus address here
    assert rx.read_code("p044") == 50


def test_torque_registers_need_constant_torque_mode():
    inverter = Inverter(MX2_MODEL)
    inverter.write_code("P034", 20, 0.0)
    inverter.write_code("b049", 1, 0.0)               # VT rating
    inverter.write_code("b171", 1, 0.0)
    inverter.write_code("b180", 1, 0.0)               # initialize (section 4-1 Step 1)
    assert inverter.read_code("d060") == 1 and inverter.read_code("b180") == 0
    with pytest.raises(InverterModeError) as caught:
        inverter.write_code("P034", 20, 0.0)
    assert caught.value.refusal is RegisterRefusal.NOT_WHILE_RUNNING


def test_high_frequency_mode_and_rpm_scaling():
    inverter = option_source(b171=2, b180=1)          # MX2 high-frequency mode: 0.1 Hz (Table 22)
    assert inverter.read_code("d060") == 2 and inverter.speed_unit is SpeedUnit.DECIHERTZ
    inverter.command(0.0, speed_reference=100)
    inverter.command(0.0, fwd=True)
    inverter.advance(10.0)
    assert inverter.output_frequency == pytest.approx(10.0) and inverter.status().speed_actual == 100
    rpm = option_source(P049=4)                       # section 4-2-5: P049 non-zero, RPM
    rpm.command(0.0, speed_reference=600)
    rpm.command(0.0, fwd=True)
    rpm.advance(10.0)
    assert rpm.output_frequency == pytest.approx(20.0) and rpm.status().speed_actual == 600
    rx = option_source(RX_MODEL, b049=1, b180=1)      # the RX has no high-frequency mode (Table 23)
    assert rx.read_code("d060") == 1 and rx.speed_unit is SpeedUnit.CENTIHERTZ


def test_output_terminals_follow_the_option_board_when_sourced_from_it():
    inverter = configured(C021=63, C026=63)
    inverter.command(0.0, outputs=0b111)
    assert inverter.status().outputs == 0b101        # C022 is not set to 63
    assert inverter.read_code("d006") == 0b101


# -- EEPROM save, restart, configuration consistency value (Table C-2) ---------------------------------

def test_written_values_survive_a_restart_only_when_saved():
    saves: list[dict[int, int]] = []
    inverter = Inverter(MX2_MODEL, on_save=saves.append)
    inverter.write_code("P044", 25, 0.0)
    inverter.power_cycle(1.0)
    assert inverter.read_code("P044") == 0 and inverter.consistency_value == 0
    inverter.write_code("P044", 25, 1.0)
    inverter.write(0x0900, 1, 1.0)                    # ENTER (sections E-2-2, E-3-2)
    assert inverter.consistency_value == 1 and len(saves) == 1
    assert saves[0][15044] == 25 and saves[0][5002] == 1000 and 3001 not in saves[0]
    inverter.write(0x0900, 1, 2.0)                    # every save counts, changed or not
    assert inverter.consistency_value == 2
    inverter.power_cycle(3.0)
    assert inverter.read_code("P044") == 25
    restored = Inverter(MX2_MODEL, saved=saves[-1], consistency_value=inverter.consistency_value)
    assert restored.read(0x162E) == 25 and restored.consistency_value == 2


def test_consistency_value_wraps_as_a_uint():
    inverter = Inverter(RX_MODEL, consistency_value=0xFFFF)
    inverter.write(0x0900, 1, 0.0)
    assert inverter.consistency_value == 0


def test_saved_values_are_checked():
    with pytest.raises(ValueError):
        Inverter(MX2_MODEL, saved={15046: 9})         # P046 out of range
    with pytest.raises(ValueError):
        Inverter(MX2_MODEL, saved={3001: 5})          # d001 is not saved
    with pytest.raises(ValueError):
        Inverter(MX2_MODEL, saved={2008: 11})         # the MX2 has no C008
    assert Inverter(RX_MODEL, saved={2008: 11}).read_code("C008") == 11


def test_option_board_reset_on_trip_clear_depends_on_c102():
    # Section 3-2 Step 4: with C102 other than 3, clearing a trip resets the option board.
    inverter = option_source()
    before = inverter.option_board_resets
    inverter.raise_trip(0.0, 12)
    inverter.press_stop_reset(0.0)
    assert inverter.trip == 0 and inverter.option_board_resets == before + 1
    inverter.write_code("C102", 3, 0.0)
    inverter.raise_trip(0.0, 12)
    inverter.press_stop_reset(0.0)
    assert inverter.trip == 0 and inverter.option_board_resets == before + 1


# -- flexible format (section 4-7, appendix F) ------------------------------------------------------

TYPICAL = dict(P160=0x1F01, P161=0x0001, P162=0x0002, P170=0x0005, P171=0x1E01, P172=0x1001, P173=0x1002)


@pytest.mark.parametrize("name", [MX2_MODEL, RX_MODEL])
def test_typical_configuration_tables_18_to_21(name):
    inverter = configured(name, P046=6, A001=3, A002=3, **TYPICAL)   # section 4-7-1 Steps 1-7, 4-7-2 Step 8
    assert inverter.trip == 0 and inverter.flexible is not None
    # "the Output has a data size of 3 words and the Input has 4 words".
    assert inverter.flexible.outputs == (0x1F01, 0x0001, 0x0002)
    assert inverter.flexible.inputs == (0x0005, 0x1E01, 0x1001, 0x1002)
    assert inverter.flexible_input() == [0x0001, 0x0002, 0x0000, 0x0000]            # Table 19
    inverter.flexible_output([0x0002, 0x0000, 0x03E8], 1.0)                          # Table 20
    end = inverter.next_deadline()
    assert end == pytest.approx(3.0)
    inverter.advance(end)
    assert inverter.flexible_input() == [0x0003, 0x001A, 0x0000, 0x03E8]            # Table 21
    inverter.flexible_output([0x0002 | 0x0004, 0x0000, 0x03E8], 3.0)                # Step 11: Dir
    assert not inverter.flexible_input()[1] & 0x10                                    # FA1 clears
    inverter.advance(7.0)
    words = inverter.flexible_input()
    assert words[1] == 0x001B and words[3] == 0x03E8                                  # Dir, Rdy, RUN, FA1
    inverter.flexible_output([0x0004, 0x0000, 0x03E8], 7.0)                          # Step 12: clear Opr
    inverter.advance(9.0)
    assert inverter.flexible_input() == [0x0001, 0x0002, 0x0000, 0x0000]


def test_low_word_only_frequency_reference():
    # Appendix F tip: P160 = 1F01h, P161 = 0002h; Note 3: the high word is written as zero.
    inverter = configured(P046=6, A001=3, A002=3, P160=0x1F01, P161=0x0002, P170=0x1E01)
    inverter.write(0x0001, 30000, 0.0)
    assert inverter.read_word(0x0001) == 0 and inverter.read_word(0x0002) == 30000
    inverter.write(0x0002, 0x1234, 0.0)               # the low word alone, by Modbus address
    assert inverter.read(0x0001) == 0x1234
    inverter.flexible_output([0x0000, 0x07D0], 0.0)
    assert inverter.read(0x0001) == 2000 and inverter.read_word(0x0001) == 0


def test_refused_cyclic_writes_are_counted():
    inverter = configured(P046=6, A001=3, A002=3, P160=0x0002, P170=0x1E01)
    inverter.flexible_output([0xFFFF], 0.0)           # 655.35 Hz is above 400.00 Hz
    assert inverter.flexible_write_errors == 1 and inverter.read_code("F001") == 0


@pytest.mark.parametrize(("values", "rule"), [
    ({**TYPICAL, "P168": 0x0005}, FlexibleRule.RESERVED_NOT_ZERO),
    ({**TYPICAL, "P179": 0x0005}, FlexibleRule.RESERVED_NOT_ZERO),
    ({"P170": 0x1E01}, FlexibleRule.EMPTY_AREA),
    ({"P160": 0x1F01}, FlexibleRule.EMPTY_AREA),
    ({"P160": 0x1F01, "P170": 0x4321}, FlexibleRule.NO_SUCH_REGISTER),
    ({"P160": 0x0001, "P170": 0x1E01}, FlexibleRule.DOUBLE_WORD_SPLIT),                   # high word alone
    ({"P160": 0x0002, "P161": 0x0001, "P170": 0x1E01}, FlexibleRule.DOUBLE_WORD_SPLIT),   # reversed
    ({"P160": 0x1F01, "P170": 0x1002}, FlexibleRule.DOUBLE_WORD_SPLIT),                   # input low word alone
    ({"P160": 0x1F01, "P170": 0x1001, "P172": 0x1002}, FlexibleRule.DOUBLE_WORD_SPLIT),   # not consecutive
    ({"P160": 0x1F01, "P161": 0x1F01, "P170": 0x1E01}, FlexibleRule.DUPLICATE_OUTPUT),
    ({"P160": 0x1E01, "P170": 0x1E01}, FlexibleRule.READ_ONLY_OUTPUT),
    ({"P160": 0x1001, "P161": 0x1002, "P170": 0x1E01}, FlexibleRule.READ_ONLY_OUTPUT),
])
def test_each_flexible_rule(values, rule):
    for registers in (MX2, RX):
        with pytest.raises(FlexibleMappingError) as caught:
            validate_flexible(values, registers)
        assert caught.value.rule is rule
        assert rule in {p.rule for p in caught.value.problems}


def test_not_run_mode_editable_outputs_are_refused():
    with pytest.raises(FlexibleMappingError) as caught:
        validate_flexible({"P160": 0x162E, "P170": 0x1E01}, MX2)      # P044
    assert caught.value.rule is FlexibleRule.NOT_RUN_MODE_EDITABLE
    assert validate_flexible({"P160": 0x1103, "P161": 0x1104, "P170": 0x162E}, MX2).outputs == (0x1103, 0x1104)


def test_torque_registers_need_constant_torque_mode_in_the_mapping():
    values = {"P160": 0x1F01, "P170": 0x1010}                        # d012 output torque
    assert validate_flexible(values, MX2, inverter_mode=0).inputs == (0x1010,)
    with pytest.raises(FlexibleMappingError) as caught:
        validate_flexible(values, MX2, inverter_mode=1)
    assert caught.value.rule is FlexibleRule.TORQUE_NOT_AVAILABLE


def test_every_broken_rule_is_reported():
    with pytest.raises(FlexibleMappingError) as caught:
        validate_flexible({"P169": 1, "P160": 0x1E01, "P161": 0x1E01, "P170": 0x1002}, MX2)
    rules = [p.rule for p in caught.value.problems]
    assert rules[0] is FlexibleRule.RESERVED_NOT_ZERO
    assert {FlexibleRule.READ_ONLY_OUTPUT, FlexibleRule.DUPLICATE_OUTPUT, FlexibleRule.DOUBLE_WORD_SPLIT} <= set(rules)
    assert "P161 = 1E01h" in str(caught.value)


def test_reserved_words_keep_their_place():
    mapping = validate_flexible({"P160": 0x1F01, "P162": 0x0002, "P170": 0x0005, "P173": 0x1E01}, MX2)
    assert mapping.outputs == (0x1F01, 0, 0x0002) and mapping.inputs == (0x0005, 0, 0, 0x1E01)
    inverter = configured(P046=6, P160=0x1F01, P162=0x0002, P170=0x0005, P173=0x1E01)
    assert inverter.flexible_input() == [1, 0, 0, 2]


_PAIRS = [(0x0001, 0x0002), (0x1001, 0x1002), (0x1103, 0x1104), (0x1105, 0x1106)]
_HIGH_WORDS = {high for high, _ in _PAIRS}


@given(st.lists(st.sampled_from([(0x1F01,), (0x0005,), (0x1E01,), (0x1007,), (0,), *_PAIRS]), max_size=6))
def test_inputs_built_from_whole_registers_are_accepted(pieces):
    # Any sequence of single words, reserved words and high/low pairs is a legal input area, unless
    # the 8-word limit cuts a pair in two or nothing but reserved words remain (Notes 1-3).
    words = [w for piece in pieces for w in piece][:8]
    while words and not words[-1]:
        words.pop()
    values = {"P160": 0x1F01, **{f"P17{i}": w for i, w in enumerate(words)}}
    cut_pair = bool(words) and words[-1] in _HIGH_WORDS
    if not words or cut_pair:
        with pytest.raises(FlexibleMappingError) as caught:
            validate_flexible(values, MX2)
        expected = FlexibleRule.DOUBLE_WORD_SPLIT if words else FlexibleRule.EMPTY_AREA
        assert caught.value.rule is expected
    else:
        assert validate_flexible(values, MX2).inputs == tuple(words)


@pytest.mark.parametrize(("name", "code"), [(MX2_MODEL, 64), (RX_MODEL, 74)])
def test_illegal_mapping_trips_at_start_up_not_when_written(name, code):
    inverter = Inverter(name)
    inverter.write_code("P046", 6, 0.0)
    inverter.write_code("P160", 0x1E01, 0.0)          # read-only register as an output
    inverter.write_code("P170", 0x1E01, 0.0)
    assert inverter.trip == 0                         # the check happens when the board starts
    inverter.reset_option_board(1.0)
    assert inverter.trip == code and inverter.status().fault_code == 0x6320
    assert inverter.flexible is None and inverter.flexible_error.rule is FlexibleRule.READ_ONLY_OUTPUT
    # Table 25 Step II: resetting the trip restarts the check, which fails again ...
    inverter.write(0x1F01, 0x0010, 2.0)
    assert inverter.trip == code
    inverter.write(0x1F01, 0x0000, 2.0)
    # ... until the mapping is corrected.
    inverter.write_code("P160", 0x1F01, 3.0)
    inverter.write(0x1F01, 0x0010, 3.0)
    assert inverter.trip == 0 and inverter.flexible is not None


def test_illegal_mapping_after_power_cycle_from_saved_values():
    inverter = Inverter(MX2_MODEL, saved={15046: 6, 15160: 0x1F01, 15170: 0x1E01, 15168: 1})
    assert inverter.trip == 64
    assert inverter.flexible_error.rule is FlexibleRule.RESERVED_NOT_ZERO


def test_flexible_mapping_is_only_checked_for_path_6():
    inverter = Inverter(MX2_MODEL, saved={15160: 0x1E01})
    assert inverter.trip == 0 and inverter.flexible is None
    with pytest.raises(RuntimeError):
        inverter.flexible_input()


def test_torque_assemblies_trip_outside_constant_torque_mode():
    # Tables 22/23 note: torque-related registers in the process area without torque control.
    inverter = configured(b049=1, b171=1, b180=1, P046=4)
    assert inverter.trip == 64
    assert configured(P046=4).trip == 0
