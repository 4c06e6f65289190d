"""Network events of the option board: the P044 network error timer and its P045 action, the
idle action P048 (Table 12, Table 26)."""

from __future__ import annotations

import dataclasses

from .states import (
    _EPSILON,
    _OPR,
    NetworkAction,
    Source,
)


class NetworkEvents:
    """Network error, idle and recovery (part of ``Inverter``)."""

    def on_network_ok(self, now: float) -> None:
        """Valid I/O data arrived: restarts the P044 timer and ends an idle or error condition."""
        self.advance(now)
        self._last_ok = now
        self._net_error = False
        self._idle = False

    def on_network_error(self, now: float) -> None:
        """The connection was lost (timed out or closed): the P045 action (Table 12)."""
        self.advance(now)
        if not self._net_error:
            self._net_error = True
            self._lost_command(NetworkAction(self._values["P045"]), now)

    def on_idle(self, now: float) -> None:
        """The master entered idle mode: the P048 action (Table 12) if the inverter is running;
        Table 26 names "communication idle or communication timeout during RUN mode"."""
        self.advance(now)
        if not self._idle:
            self._idle = True
            if self._output_active():
                self._lost_command(NetworkAction(self._values["P048"]), now)

    def _lost_command(self, action: NetworkAction, now: float) -> None:
        if action is NetworkAction.NONE:
            return
        if action is NetworkAction.TRIP:
            self._raise_trip(self.traits.trip_network)
            self._evaluate(now)
            return
        network_run = self.run_source in (Source.OPTION_BOARD, Source.MODBUS)
        # The option board drops the run command it holds; a later FWD/Opr from the master runs again.
        self._cmd = dataclasses.replace(self._cmd, fwd=False, rev=False)
        self._armed_fwd = self._armed_rev = True
        self._coils &= ~_OPR
        if action is NetworkAction.FREE_RUN and network_run:
            self._frequency = 0.0
        elif action is NetworkAction.DECELERATE_AND_TRIP:
            if abs(self._frequency) < _EPSILON:
                self._raise_trip(self.traits.trip_network)
            else:
                self._pending_trip = self.traits.trip_network
        self._evaluate(now)
