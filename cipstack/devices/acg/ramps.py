"""Ramps: linear, from 0 to dr.20 Max Freq in ACC seconds and back in dEC seconds."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from .registers import (
    ACCEL_TIME,
    DECEL_TIME,
    MAX_FREQUENCY,
)

if TYPE_CHECKING:
    from .state import AcgState

#: A ramp that ends within this many seconds of a deadline ends at it (float rounding).
_TIME_TOLERANCE = 1e-9

_ACCEL_TIME = ACCEL_TIME.address
_DECEL_TIME = DECEL_TIME.address
_MAX_FREQUENCY = MAX_FREQUENCY.address


class Ramp:
    """The output frequency of one drive, along linear ramps over ACC/dEC from 0 to Max Freq."""

    def __init__(self, state: AcgState) -> None:
        self._state = state

    def _rate(self, accelerating: bool) -> float:
        values = self._state.values
        seconds = (values[_ACCEL_TIME] if accelerating else values[_DECEL_TIME]) / 10
        max_hz = values[_MAX_FREQUENCY] / 100
        return math.inf if seconds == 0 else max_hz / seconds

    def target_hz(self) -> float:
        """The signed output frequency the drive is heading for."""
        state = self._state
        if state.command is None or state.trip is not None:
            return 0.0
        return state.command * state.reference_hz()

    def segment(self) -> tuple[float, bool] | None:
        """The end of the present ramp segment (its frequency) and whether it accelerates."""
        state = self._state
        if not state.output_on:
            return None
        # ``target_hz``, inline: asked several times per request while the drive runs.
        command = state.command
        target = 0.0 if command is None or state.trip is not None else command * state.reference_hz()
        present = state.output_hz
        if present == target:
            return None
        if present != 0 and (target == 0 or (present > 0) != (target > 0)):
            return 0.0, False                       # slow down to 0 (stop or reversal)
        if abs(target) < abs(present):
            return target, False
        return target, True

    def run(self, elapsed: float) -> None:
        """Move the output along its ramp for ``elapsed`` seconds (0: apply instant steps)."""
        state = self._state
        remaining = elapsed
        while True:
            segment = self.segment()
            # Run time counts while the output is on; the heat sink fan is taken to run with it.
            if segment is None:
                if state.output_on:
                    state.run_seconds += remaining
                    state.fan_seconds += remaining
                return
            goal, accelerating = segment
            rate = self._rate(accelerating)
            needed = abs(goal - state.output_hz) / rate
            if needed > remaining + _TIME_TOLERANCE:
                step = rate * remaining
                state.output_hz += step if goal > state.output_hz else -step
                state.run_seconds += remaining
                state.fan_seconds += remaining
                return
            state.output_hz = goal
            ran = min(needed, remaining)
            state.run_seconds += ran
            state.fan_seconds += ran
            remaining = max(0.0, remaining - needed)
            self.settle()

    def settle(self) -> None:
        """At 0 Hz without a run command the output switches off: the stop is complete."""
        state = self._state
        if state.output_hz == 0 and (state.command is None or state.trip is not None):
            state.output_on = False

    def deadline(self) -> float | None:
        """When the present ramp segment ends, or None."""
        segment = self.segment()
        if segment is None:
            return None
        goal, accelerating = segment
        return self._state.time + abs(goal - self._state.output_hz) / self._rate(accelerating)

    def free_run(self) -> None:
        """Cut the output at once; the motor coasts (free-run stop)."""
        state = self._state
        state.command = None
        state.output_hz = 0.0
        state.output_on = False

    @property
    def accelerating(self) -> bool:
        segment = self.segment()
        return segment is not None and segment[1] and self._state.trip is None

    @property
    def decelerating(self) -> bool:
        segment = self.segment()
        return segment is not None and not segment[1]

    @property
    def at_reference(self) -> bool:
        """Running, and the output frequency has reached the reference."""
        state = self._state
        return (state.output_on and state.command is not None and state.trip is None
                and state.output_hz == self.target_hz())


__all__ = ["Ramp"]
