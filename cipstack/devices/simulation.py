"""How time moves a drive simulation, shared by every drive family.

A drive changes continuously between events (a ramp moves the output frequency) and at discrete
instants of its own (a lost-command or network-error timer expires). ``advance(now)`` runs the
continuous part up to each timer that falls due before ``now``, fires it, and goes on to
``now``; ``next_deadline()`` tells the shell when to call it next. The simulation itself never
reads a clock: ``now`` is always given.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

from ..errors import BadRequest


class TimedSimulation(ABC):
    """The ``advance`` loop of a simulation with ramps and timers; families supply the four steps."""

    @property
    @abstractmethod
    def time(self) -> float:
        """The instant the simulation has reached."""

    @abstractmethod
    def _timer_deadline(self) -> float | None:
        """When the earliest pending timer falls due, or None."""

    @abstractmethod
    def _fire_timers(self, moment: float) -> None:
        """Act on the timers due at ``moment`` (the simulation has been run up to it)."""

    @abstractmethod
    def _run_until(self, moment: float) -> None:
        """Run the continuous change (ramps, counters) up to ``moment``."""

    @abstractmethod
    def _ramp_deadline(self) -> float | None:
        """When the present ramp segment ends, or None."""

    def advance(self, now: float) -> None:
        """Move the simulation to ``now``: ramps, then each timer that falls due on the way."""
        if now < self.time:
            raise BadRequest(f"time went backwards: {now} < {self.time}")
        while True:
            deadline = self._timer_deadline()
            if deadline is None or deadline > now:
                break
            self._run_until(deadline)
            self._fire_timers(deadline)
        self._run_until(now)

    def advance_to(self, now: float) -> float | None:
        """``advance`` to ``now`` (or stay, if the simulation is already later), then
        ``next_deadline()``: the shell's call before every request. Families with a cheap way to
        tell that nothing moves by itself override it (``AcgDrive``)."""
        self.advance(max(now, self.time))
        return self.next_deadline()

    def next_deadline(self) -> float | None:
        """When the simulation next changes by itself: the end of a ramp segment or a timer."""
        timer, ramp = self._timer_deadline(), self._ramp_deadline()
        if timer is None or (ramp is not None and ramp < timer):
            return ramp
        return timer
