"""Ramps: linear, from 0 to dr.20 Max Freq in ACC seconds and back in dEC seconds."""

from __future__ import annotations

import math

from .registers import (
    ACCEL_TIME,
    DECEL_TIME,
    MAX_FREQUENCY,
)

#: A ramp that ends within this many seconds of a deadline ends at it (float rounding).
_TIME_TOLERANCE = 1e-9


class Ramps:
    """Linear ramps over ACC/dEC from 0 to Max Freq (part of ``AcgDrive``)."""


    def _rate(self, accelerating: bool) -> float:
        seconds = (self._values[ACCEL_TIME.address] if accelerating else self._values[DECEL_TIME.address]) / 10
        max_hz = self._values[MAX_FREQUENCY.address] / 100
        return math.inf if seconds == 0 else max_hz / seconds

    def _target_hz(self) -> float:
        """The signed output frequency the drive is heading for."""
        if self._command is None or self._trip is not None:
            return 0.0
        return self._command * self._reference_hz()

    def _segment(self) -> tuple[float, bool] | None:
        """The end of the present ramp segment (its frequency) and whether it accelerates."""
        if not self._output_on:
            return None
        present, target = self._output_hz, self._target_hz()
        if present == target:
            return None
        if present != 0 and (target == 0 or (present > 0) != (target > 0)):
            return 0.0, False                       # slow down to 0 (stop or reversal)
        if abs(target) < abs(present):
            return target, False
        return target, True

    def _ramp(self, elapsed: float) -> None:
        """Move the output along its ramp for ``elapsed`` seconds (0: apply instant steps)."""
        remaining = elapsed
        while True:
            segment = self._segment()
            if segment is None:
                if self._output_on:
                    self._count_run_time(remaining)
                return
            goal, accelerating = segment
            rate = self._rate(accelerating)
            needed = abs(goal - self._output_hz) / rate
            if needed > remaining + _TIME_TOLERANCE:
                step = rate * remaining
                self._output_hz += step if goal > self._output_hz else -step
                self._count_run_time(remaining)
                return
            self._output_hz = goal
            self._count_run_time(min(needed, remaining))
            remaining = max(0.0, remaining - needed)
            self._settle()

    def _count_run_time(self, seconds: float) -> None:
        # The heat sink fan is taken to run while the drive runs.
        self._run_seconds += seconds
        self._fan_seconds += seconds

    def _settle(self) -> None:
        """At 0 Hz without a run command the output switches off: the stop is complete."""
        if self._output_hz == 0 and (self._command is None or self._trip is not None):
            self._output_on = False

    def _ramp_deadline(self) -> float | None:
        segment = self._segment()
        if segment is None:
            return None
        goal, accelerating = segment
        return self._time + abs(goal - self._output_hz) / self._rate(accelerating)

    def _free_run(self) -> None:
        """Cut the output at once; the motor coasts (free-run stop)."""
        self._command = None
        self._output_hz = 0.0
        self._output_on = False
