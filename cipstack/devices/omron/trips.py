"""The inverter's trips as the option board clears them: the reset (the RST bit, Fault Rst, the STOP/RESET
key, the RS coil) and what it restarts (Table 11, Table 25)."""

from __future__ import annotations

from .board_start import BoardStartup
from .ramps import Ramp
from .sources import Sources
from .states import _RS, InverterState


class Trips:
    """Clearing the trips of one inverter, and the level-triggered inputs applied after any change."""

    def __init__(self, state: InverterState, startup: BoardStartup, sources: Sources, ramp: Ramp,
                 trip_flexible_mapping: int) -> None:
        self._state = state
        self._startup = startup
        self._sources = sources
        self._ramp = ramp
        self._trip_flexible_mapping = trip_flexible_mapping

    def clear(self) -> int:
        """Clear the trip present; which one it was."""
        state = self._state
        cleared, state.trip = state.trip, 0
        state.force_status = False
        # Trip reset is the second moment the rising-edge rule names (Table B-2 note).
        state.armed_fwd = not state.cmd.fwd
        state.armed_rev = not state.cmd.rev
        return cleared

    def restart_board(self, now: float) -> None:
        self._startup.restart()
        self._ramp.settle(now)

    def reset(self, now: float) -> None:
        """A trip reset: the trip clears, and the board restarts as C102 says."""
        state = self._state
        if not state.trip:
            return
        cleared = self.clear()
        if state.values["C102"] != 3:
            # Table 11 / section 3-2 Step 4: with C102 other than 3 clearing a trip resets the board.
            self.restart_board(now)
        elif cleared == self._trip_flexible_mapping:
            # Table 25 Step II: resetting the trip restarts the check of the mapping.
            self._startup.start()

    def evaluate(self, now: float) -> None:
        """Apply level-triggered inputs after any change."""
        state = self._state
        if state.coils & _RS and state.trip:
            # Section 4-7-3: while RS stays set, new trips are cleared automatically.
            self.reset(now)
        if state.trip or self._sources.free_running():
            state.frequency = 0.0
        self._ramp.settle(now)


__all__ = ["Trips"]
