"""The inverter's ramps: acceleration and deceleration times, the frequency reference reached."""

from __future__ import annotations

from .states import (
    _EPSILON,
    _RS,
)


class Ramps:
    """The output frequency's ramps (part of ``Inverter``)."""

    def _rates(self) -> tuple[float, float]:
        """Acceleration and deceleration in 0.01 Hz per second: the times run from 0 to A004."""
        accel = self._values["F002"] * 0.01
        decel = self._values["F003"] * 0.01
        if self._cmd.net_ref:   # Table B-25: the REF bit selects the network times of assembly 110
            accel = self._cmd.accel_time if self._cmd.accel_time is not None else accel
            decel = self._cmd.decel_time if self._cmd.decel_time is not None else decel
        top = self._values["A004"] * 10.0
        return top / max(accel, 0.01), top / max(decel, 0.01)

    def _ramp_to(self, t: float) -> None:
        dt, self._t = t - self._t, t
        if self._trip or self._free_running():
            self._frequency = 0.0
        else:
            self._ramp(dt)
        self._settle(t)

    def _ramp(self, dt: float) -> None:
        target = self._target()
        accel, decel = self._rates()
        f = self._frequency
        while dt > 0 and abs(f - target) > _EPSILON:
            slowing = (f > 0 and target < f) or (f < 0 and target > f)
            if slowing:
                limit, rate = (max(target, 0.0) if f > 0 else min(target, 0.0)), decel
            else:
                limit, rate = target, accel
            distance = abs(limit - f)
            if rate * dt >= distance - _EPSILON:
                f = limit
                dt -= distance / rate
            else:
                f += rate * dt if limit > f else -rate * dt
                dt = 0.0
        self._frequency = f

    def _ramp_end(self) -> float | None:
        if self._trip or self._free_running():
            return None
        target, f = self._target(), self._frequency
        if abs(f - target) <= _EPSILON:
            return None
        accel, decel = self._rates()
        if f * target < 0:   # decelerate to 0, then accelerate the other way
            return self._t + abs(f) / decel + abs(target) / accel
        slowing = abs(target) < abs(f)
        return self._t + abs(target - f) / (decel if slowing else accel)

    def _settle(self, now: float) -> None:
        if self._pending_trip and abs(self._frequency) <= _EPSILON:
            self._raise_trip(self._pending_trip)
        running = self._output_active()
        if running and self._run_since is None:
            self._run_since = now
        elif not running:
            self._run_since = None

    def _evaluate(self, now: float) -> None:
        """Apply level-triggered inputs after any change."""
        if self._coils & _RS and self._trip:
            # Section 4-7-3: while RS stays set, new trips are cleared automatically.
            self._reset_trip(now)
        if self._trip or self._free_running():
            self._frequency = 0.0
        self._settle(now)

    def _output_active(self) -> bool:
        """The RUN state: the inverter drives the motor (a run command, or decelerating to a stop)."""
        if self._trip or self._free_running():
            return False
        return self._run_direction() != 0 or abs(self._frequency) > _EPSILON

    @property
    def output_frequency(self) -> float:
        """Signed output frequency in Hz (negative in reverse)."""
        return self._frequency / 100
