"""The inverter's ramps: acceleration and deceleration times, the frequency reference reached."""

from __future__ import annotations

from .sources import Sources
from .states import _EPSILON, InverterState


class Ramp:
    """The output frequency of one inverter along its ramps (F002/F003, or assembly 110's times)."""

    def __init__(self, state: InverterState, sources: Sources) -> None:
        self._state = state
        self._sources = sources

    def _rates(self) -> tuple[float, float]:
        """Acceleration and deceleration in 0.01 Hz per second: the times run from 0 to A004."""
        state = self._state
        accel = state.values["F002"] * 0.01
        decel = state.values["F003"] * 0.01
        cmd = state.cmd
        if cmd.net_ref:   # Table B-25: the REF bit selects the network times of assembly 110
            accel = cmd.accel_time if cmd.accel_time is not None else accel
            decel = cmd.decel_time if cmd.decel_time is not None else decel
        top = state.values["A004"] * 10.0
        return top / max(accel, 0.01), top / max(decel, 0.01)

    def ramp_to(self, t: float) -> None:
        """Move the output along its ramps up to ``t``."""
        state = self._state
        dt, state.t = t - state.t, t
        if state.trip or self._sources.free_running():
            state.frequency = 0.0
        else:
            self._ramp(dt)
        self.settle(t)

    def _ramp(self, dt: float) -> None:
        target = self._sources.target()
        accel, decel = self._rates()
        f = self._state.frequency
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
        self._state.frequency = f

    def end(self) -> float | None:
        """When the output reaches its target, or None."""
        state = self._state
        if state.trip or self._sources.free_running():
            return None
        target, f = self._sources.target(), state.frequency
        if abs(f - target) <= _EPSILON:
            return None
        accel, decel = self._rates()
        if f * target < 0:   # decelerate to 0, then accelerate the other way
            return state.t + abs(f) / decel + abs(target) / accel
        slowing = abs(target) < abs(f)
        return state.t + abs(target - f) / (decel if slowing else accel)

    def settle(self, now: float) -> None:
        """A "deceleration and trip" stop that reached 0 trips; the RUN state's start is noted (P044)."""
        state = self._state
        if state.pending_trip and abs(state.frequency) <= _EPSILON:
            state.raise_trip(state.pending_trip)
        running = self._sources.output_active()
        if running and state.run_since is None:
            state.run_since = now
        elif not running:
            state.run_since = None


__all__ = ["Ramp"]
