"""The drives as compositions: one state, components given it at construction, one Drive State."""

import pytest

from cipstack.assemblies.drive_profile import DriveState
from cipstack.devices.acg import drive as acg_drive
from cipstack.devices.acg.ramps import Ramp
from cipstack.devices.acg.registers import (
    ACCEL_TIME,
    ACG_REGISTERS,
    ALIASES,
    MAX_FREQUENCY,
    TARGET_FREQUENCY,
)
from cipstack.devices.acg.run_command import Direction
from cipstack.devices.acg.state import AcgState
from cipstack.devices.acg.trips import Trip, TripLog
from cipstack.devices.omron import inverter as omron_inverter
from cipstack.devices.simulation import TimedSimulation


def test_both_families_report_one_drive_state() -> None:
    # Control Supervisor attribute 6: 0-6 in the ACG-ET2 manual, 1-7 in the CompoNet manual (Table D-4).
    assert acg_drive.DriveState is DriveState and omron_inverter.DriveState is DriveState
    assert [(s.name, int(s)) for s in DriveState] == [
        ("VENDOR_SPECIFIC", 0), ("STARTUP", 1), ("NOT_READY", 2), ("READY", 3), ("ENABLED", 4), ("STOPPING", 5),
        ("FAULT_STOP", 6), ("FAULTED", 7)]


def test_the_drives_derive_from_the_timed_simulation_alone() -> None:
    assert acg_drive.AcgDrive.__bases__ == (TimedSimulation,)
    assert omron_inverter.Inverter.__bases__ == (TimedSimulation,)


def _acg_state() -> AcgState:
    values = {a: r.default for a, r in ACG_REGISTERS.items() if a not in ALIASES}
    values[MAX_FREQUENCY.address] = 6000        # 60.00 Hz
    values[ACCEL_TIME.address] = 50             # 5.0 s from 0 to Max Freq: 12 Hz/s
    values[TARGET_FREQUENCY.address] = 3000     # 30.00 Hz, the keypad's reference (Frq 0)
    return AcgState(values, 0.0)


def test_a_ramp_moves_the_output_of_the_state_it_was_given() -> None:
    state = _acg_state()
    ramp = Ramp(state)
    state.command, state.output_on = Direction.FORWARD, True
    assert ramp.segment() == (30.0, True) and ramp.deadline() == pytest.approx(2.5)
    ramp.run(1.0)
    assert state.output_hz == pytest.approx(12.0) and state.run_seconds == pytest.approx(1.0)
    assert ramp.accelerating and not ramp.at_reference
    ramp.run(2.0)                                # reaches 30 Hz at 2.5 s and holds it
    assert state.output_hz == 30.0 and ramp.at_reference and ramp.deadline() is None
    assert state.run_seconds == pytest.approx(3.0)


def test_a_level_trip_of_the_trip_log_holds_while_its_cause_lasts() -> None:
    state = _acg_state()
    trips = TripLog(state, Ramp(state))
    state.command, state.output_on, state.output_hz = Direction.FORWARD, True, 20.0
    trips.set_level_cause(Trip.BX, True)
    assert state.trip is Trip.BX and state.fault_history == [Trip.BX]
    assert (state.output_on, state.output_hz, state.command) == (False, 0.0, None)   # free-run stop
    assert not trips.reset() and state.trip is Trip.BX
    trips.set_level_cause(Trip.BX, False)
    assert state.trip is None and state.fault_history == [Trip.BX]
