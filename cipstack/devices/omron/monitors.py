"""Registers the simulation produces rather than stores: the monitors (d-group) and status words."""

from __future__ import annotations

from collections.abc import Callable

from .models import Family
from .registers import (
    COIL_DATA_0,
    COIL_DATA_1,
    EEPROM_SAVE,
    OUTPUT_FROM_OPTION,
    STATUS_C_ADDRESS,
    FamilyTraits,
    centihertz_to_speed,
    trip_code,
)
from .sources import Sources
from .states import (
    _EPSILON,
    DriveState,
    DriveStateDetail,
    InverterState,
    Source,
    Status,
)


class Monitors:
    """The monitors and status of one inverter, read from its state."""

    def __init__(self, state: InverterState, family: Family, traits: FamilyTraits, sources: Sources) -> None:
        self._state = state
        self._family = family
        self._traits = traits
        self._sources = sources

    def outputs(self) -> int:
        """The output terminals the option board sets, in ``traits.output_terminals`` order."""
        state = self._state
        mask = 0
        for i, code in enumerate(self._traits.output_sources):
            if state.values[code] == OUTPUT_FROM_OPTION and state.cmd.outputs >> i & 1:
                mask |= 1 << i
        return mask

    def at_reference(self) -> bool:
        sources = self._sources
        return (sources.output_active() and sources.run_direction() != 0
                and abs(self._state.frequency - sources.target()) <= 0.5)

    def status_c(self) -> int:
        if not self._sources.output_active():
            return 1
        target, f = self._sources.target(), self._state.frequency
        if abs(f - target) <= 0.5:
            return 3
        return 4 if (target > f >= 0) or (target < f <= 0) else 2

    def coil_data_1(self) -> int:
        state = self._state
        f = state.frequency
        reverse = f < -_EPSILON or (abs(f) <= _EPSILON and self._sources.run_direction() < 0)
        bits = {0: reverse, 1: not state.trip, 3: self._sources.output_active(), 4: self.at_reference(),
                8: bool(state.trip)}
        return sum(1 << index for index, on in bits.items() if on)

    def producers(self) -> dict[str, Callable[[], int]]:
        """Registers whose value the simulation produces rather than stores, by key."""
        state, sources = self._state, self._sources
        return {
            f"{COIL_DATA_0:04X}h": lambda: state.coils | (0x8000 if sources.output_active() else 0),
            f"{COIL_DATA_1:04X}h": self.coil_data_1,
            f"{STATUS_C_ADDRESS:04X}h": self.status_c,
            f"{EEPROM_SAVE:04X}h": lambda: 0,
            "d001": lambda: round(abs(state.frequency)),
            "d005": sources.inputs,
            "d006": self.outputs,
            "d012": lambda: 0,      # no torque model: the output torque reads 0 %
            "d081": lambda: state.last_trip,
            "b180": lambda: 0,      # the trigger reads back 0 once the initialization is done
        }

    def status(self) -> Status:
        state, sources = self._state, self._sources
        f = state.frequency
        trip = state.trip
        running = sources.output_active()
        direction = sources.run_direction()
        forward = running and (f > _EPSILON or (abs(f) <= _EPSILON and direction > 0))
        reverse = running and (f < -_EPSILON or (abs(f) <= _EPSILON and direction < 0))
        if trip:
            drive_state, detail = DriveState.FAULTED, DriveStateDetail.TRIP
        elif state.pending_trip:
            drive_state, detail = DriveState.FAULT_STOP, DriveStateDetail.RUNNING
        elif direction:
            drive_state, detail = DriveState.ENABLED, DriveStateDetail.RUNNING
        elif running:
            drive_state, detail = DriveState.STOPPING, DriveStateDetail.RUNNING
        else:
            drive_state, detail = DriveState.READY, DriveStateDetail.STOPPING
        if not trip and sources.free_running() and (direction or state.cmd.free_run):
            detail = DriveStateDetail.FREE_RUNNING
        unit = sources.speed_unit
        magnitude = round(abs(f))
        return Status(
            faulted=bool(trip), warning=False, forward=forward, reverse=reverse, ready=not trip,
            running=running, ctrl_from_net=sources.run_source is Source.OPTION_BOARD,
            ref_from_net=sources.reference_source is Source.OPTION_BOARD, at_reference=self.at_reference(),
            zero_speed=abs(f) <= _EPSILON, drive_state=drive_state, drive_state_detail=detail, trip_cause=trip,
            fault_code=trip_code(self._family, trip).cip_code if trip else 0,
            force_status=state.force_status, output_frequency=magnitude, speed_unit=unit,
            speed_actual=centihertz_to_speed(magnitude, unit, state.values["P049"]),
            inputs=sources.inputs(), outputs=self.outputs(), status_c=self.status_c())


__all__ = ["Monitors"]
