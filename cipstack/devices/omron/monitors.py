"""Registers the simulation produces rather than stores: the monitors (d-group) and status words."""

from __future__ import annotations

from .registers import (
    OUTPUT_FROM_OPTION,
    centihertz_to_speed,
    trip_code,
)
from .states import (
    _EPSILON,
    _IN_SHIFT,
    DriveState,
    DriveStateDetail,
    Source,
    Status,
)


class Monitors:
    """The inverter's monitors (part of ``Inverter``)."""

    def _inputs(self) -> int:
        mask = (1 << self.traits.input_terminals) - 1
        return (self.terminals | self._coils >> _IN_SHIFT | self._cmd.input_overrides) & mask

    def _outputs(self) -> int:
        mask = 0
        for i, code in enumerate(self.traits.output_sources):
            if self._values[code] == OUTPUT_FROM_OPTION and self._cmd.outputs >> i & 1:
                mask |= 1 << i
        return mask

    def _at_reference(self) -> bool:
        return self._output_active() and self._run_direction() != 0 and abs(self._frequency - self._target()) <= 0.5

    def _status_c(self) -> int:
        if not self._output_active():
            return 1
        target, f = self._target(), self._frequency
        if abs(f - target) <= 0.5:
            return 3
        return 4 if (target > f >= 0) or (target < f <= 0) else 2

    def _coil_data_1(self) -> int:
        f = self._frequency
        reverse = f < -_EPSILON or (abs(f) <= _EPSILON and self._run_direction() < 0)
        bits = {0: reverse, 1: not self._trip, 3: self._output_active(), 4: self._at_reference(), 8: bool(self._trip)}
        return sum(1 << index for index, on in bits.items() if on)

    def status(self) -> Status:
        f = self._frequency
        running = self._output_active()
        direction = self._run_direction()
        forward = running and (f > _EPSILON or (abs(f) <= _EPSILON and direction > 0))
        reverse = running and (f < -_EPSILON or (abs(f) <= _EPSILON and direction < 0))
        if self._trip:
            state, detail = DriveState.FAULTED, DriveStateDetail.TRIP
        elif self._pending_trip:
            state, detail = DriveState.FAULT_STOP, DriveStateDetail.RUNNING
        elif direction:
            state, detail = DriveState.ENABLED, DriveStateDetail.RUNNING
        elif running:
            state, detail = DriveState.STOPPING, DriveStateDetail.RUNNING
        else:
            state, detail = DriveState.READY, DriveStateDetail.STOPPING
        if not self._trip and self._free_running() and (self._run_direction() or self._cmd.free_run):
            detail = DriveStateDetail.FREE_RUNNING
        unit = self.speed_unit
        magnitude = round(abs(f))
        return Status(
            faulted=bool(self._trip), warning=False, forward=forward, reverse=reverse, ready=not self._trip,
            running=running, ctrl_from_net=self.run_source is Source.OPTION_BOARD,
            ref_from_net=self.reference_source is Source.OPTION_BOARD, at_reference=self._at_reference(),
            zero_speed=abs(f) <= _EPSILON, drive_state=state, drive_state_detail=detail, trip_cause=self._trip,
            fault_code=trip_code(self.family, self._trip).cip_code if self._trip else 0,
            force_status=self._force_status, output_frequency=magnitude, speed_unit=unit,
            speed_actual=centihertz_to_speed(magnitude, unit, self._values["P049"]),
            inputs=self._inputs(), outputs=self._outputs(), status_c=self._status_c())
