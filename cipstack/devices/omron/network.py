"""Network events of the option board: the P044 network error timer and its P045 action, the
idle action P048 (Table 12, Table 26)."""

from __future__ import annotations

import dataclasses

from .sources import Sources
from .states import (
    _EPSILON,
    _OPR,
    InverterState,
    NetworkAction,
    Source,
)
from .trips import Trips


class NetworkWatch:
    """Network error, idle and recovery of one inverter's option board."""

    def __init__(self, state: InverterState, sources: Sources, trips: Trips, trip_network: int) -> None:
        self._state = state
        self._sources = sources
        self._trips = trips
        self._trip_network = trip_network

    def ok(self, now: float) -> None:
        """Valid I/O data arrived: restarts the P044 timer and ends an idle or error condition."""
        state = self._state
        state.last_ok = now
        state.net_error = False
        state.idle = False

    def error(self, now: float) -> None:
        """The connection was lost (timed out or closed): the P045 action (Table 12)."""
        state = self._state
        if not state.net_error:
            state.net_error = True
            self._lost_command(NetworkAction(state.values["P045"]), now)

    def idle(self, now: float) -> None:
        """The master entered idle mode: the P048 action (Table 12) if the inverter is running;
        Table 26 names "communication idle or communication timeout during RUN mode"."""
        state = self._state
        if not state.idle:
            state.idle = True
            if self._sources.output_active():
                self._lost_command(NetworkAction(state.values["P048"]), now)

    def deadline(self) -> float | None:
        """When the P044 timer expires: no communication for P044 while running, or None."""
        state = self._state
        timer = state.values["P044"]
        if not timer or state.net_error or state.trip or state.run_since is None:
            return None
        start = state.run_since if state.last_ok is None else max(state.last_ok, state.run_since)
        return start + timer * 0.1

    def fire(self, moment: float) -> None:
        due = self.deadline()
        if due is not None and due <= moment:
            # Table 12 / Table 26: no communication for P044 while running: P045 action.
            self._state.net_error = True
            self._lost_command(NetworkAction(self._state.values["P045"]), moment)

    def _lost_command(self, action: NetworkAction, now: float) -> None:
        if action is NetworkAction.NONE:
            return
        state = self._state
        if action is NetworkAction.TRIP:
            state.raise_trip(self._trip_network)
            self._trips.evaluate(now)
            return
        network_run = self._sources.run_source in (Source.OPTION_BOARD, Source.MODBUS)
        # The option board drops the run command it holds; a later FWD/Opr from the master runs again.
        state.cmd = dataclasses.replace(state.cmd, fwd=False, rev=False)
        state.armed_fwd = state.armed_rev = True
        state.coils &= ~_OPR
        if action is NetworkAction.FREE_RUN and network_run:
            state.frequency = 0.0
        elif action is NetworkAction.DECELERATE_AND_TRIP:
            if abs(state.frequency) < _EPSILON:
                state.raise_trip(self._trip_network)
            else:
                state.pending_trip = self._trip_network
        self._trips.evaluate(now)


__all__ = ["NetworkWatch"]
