"""Lost command: Pr.12/Pr.13/Pr.14 (ACG-ET2 manual, PR Group (Lost Command) and "Lost command conditions
by protocol"; ACG RS-485 manual, Command Loss Protective Operation)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import TYPE_CHECKING

from .registers import CMD_SOURCE, FREQ_REF_SOURCE, LOST_CMD_MODE, LOST_CMD_TIME, LOST_PRESET_FREQ
from .run_command import CommandPort
from .status_words import WarningInformation
from .trips import Trip

if TYPE_CHECKING:
    from .ramps import Ramp
    from .state import AcgState
    from .trips import TripLog

_CMD_SOURCE = CMD_SOURCE.address
_FREQ_REF_SOURCE = FREQ_REF_SOURCE.address
_LOST_CMD_MODE = LOST_CMD_MODE.address
_LOST_CMD_TIME = LOST_CMD_TIME.address
_LOST_PRESET_FREQ = LOST_PRESET_FREQ.address

#: ACG-ET2 manual, "Lost command conditions by protocol": a class 1 connection that stays broken for
#: longer than one second, or a Modbus TCP server that receives nothing for five seconds, puts
#: the card in lost command mode; Pr.12 then acts after Pr.13 seconds.
IO_BREAK_TIME = 1.0
MODBUS_SILENCE_TIME = 5.0


class LostCommandMode(IntEnum):
    """Pr.12 Lost Cmd Mode (ACG-ET2 manual)."""

    NONE = 0
    FREE_RUN = 1
    DEC = 2
    HOLD_INPUT = 3
    HOLD_OUTPUT = 4
    LOST_PRESET = 5



@dataclass
class CommandLossWatch:
    """One protocol's lost-command timers (ACG-ET2 manual, "Lost command conditions by protocol").

    ``detect_after``: the silence that puts the port in lost command mode, after which Pr.12 acts
    when Pr.13 has passed (the card's protocols). None: the built-in RS-485, where Pr.13 is the
    silence itself: "the drive function that will occur after the communication loss time is
    expired (set in Pr.13)" (ACG RS-485 manual, Command Loss Protective Operation), so Pr.12 acts at once."""

    detect_after: float | None
    #: The command source whose commands the watch guards (drv / Frq of that port).
    port: CommandPort = CommandPort.FIELDBUS
    #: Since when nothing has arrived (class 1: the break; Modbus: the last request), or None.
    silent_since: float | None = None
    #: When lost command mode was entered (Pr.13 counts from here), or None.
    lost_since: float | None = None
    #: Pr.12 has acted for this loss.
    acted: bool = False

    def deadline(self, lost_time: float) -> float | None:
        if self.silent_since is None or self.acted:
            return None
        if self.lost_since is None:
            return self.silent_since + (lost_time if self.detect_after is None else self.detect_after)
        return self.lost_since + (0.0 if self.detect_after is None else lost_time)

    def clear(self) -> None:
        self.silent_since = None
        self.lost_since = None
        self.acted = False



class CommandLossWatches:
    """Pr.12/Pr.13/Pr.14 over the state's three watches: what silence on a port does to a drive
    operated through it, and what the return of communication undoes."""

    def __init__(self, state: AcgState, ramp: Ramp, trips: TripLog) -> None:
        self._state = state
        self._ramp = ramp
        self._trips = trips

    def connection_lost(self, now: float) -> None:
        """The class 1 connection broke (timed out or closed)."""
        watch = self._state.io_watch
        if watch.silent_since is None:
            watch.silent_since = now

    def connection_opened(self) -> None:
        """A class 1 connection is open and producing again: communication has returned."""
        self._state.io_watch.clear()
        self._restore_after_loss()
        self._ramp.run(0.0)

    def activity(self, now: float, port: CommandPort) -> None:
        """A Modbus request arrived on the card (``port`` FIELDBUS) or on the built-in RS-485 (INT485)."""
        watch = self._state.int485_watch if port is CommandPort.INT485 else self._state.modbus_watch
        watch.clear()
        watch.silent_since = now
        self._restore_after_loss()
        self._ramp.run(0.0)

    def _lost_time(self) -> float:
        return self._state.values[_LOST_CMD_TIME] / 10

    def deadline(self) -> float | None:
        """When the earliest watch falls due, or None."""
        state = self._state
        if (state.io_watch.silent_since is None and state.modbus_watch.silent_since is None
                and state.int485_watch.silent_since is None):
            return None  # nothing is silent: the common case, asked several times per O->T datagram
        lost_time = self._lost_time()
        earliest = None
        for watch in (state.io_watch, state.modbus_watch, state.int485_watch):   # on every request: no genexpr
            deadline = watch.deadline(lost_time)
            if deadline is not None and (earliest is None or deadline < earliest):
                earliest = deadline
        return earliest

    def fire(self, moment: float) -> None:
        """Act on the watches due at ``moment``: lost command mode entered, or Pr.12 acting."""
        lost_time = self._lost_time()
        for watch in self._state.watches:
            deadline = watch.deadline(lost_time)
            if deadline is None or deadline > moment:
                continue
            if watch.lost_since is None:
                if watch.detect_after is None and not self._operated_from(watch.port):
                    watch.clear()                    # RS-485 silence matters to a drive run from RS-485
                    continue
                watch.lost_since = moment            # lost command mode entered; Pr.13 starts
            else:
                watch.acted = True
                self._lost_command_action(watch.port)

    @property
    def lost(self) -> bool:
        """The drive is in lost command mode on some protocol."""
        return any(w.lost_since is not None for w in self._state.watches)

    def _operated_from(self, port: CommandPort) -> bool:
        """drv or Frq is ``port``'s source."""
        values = self._state.values
        return values[_CMD_SOURCE] == port.command_source or values[_FREQ_REF_SOURCE] == port.frequency_source

    def _lost_command_action(self, port: CommandPort) -> None:
        """Pr.12 after Pr.13 (ACG-ET2 manual, PR Group (Lost Command)), for a drive operated via the
        port that went silent ("while the drive is operated via network communication"): drv or
        Frq is that port's source."""
        if not self._operated_from(port):
            return
        state = self._state
        mode = LostCommandMode(state.values[_LOST_CMD_MODE])
        if mode is LostCommandMode.NONE:
            return                                  # "Maintains the previous status."
        if mode is LostCommandMode.FREE_RUN:        # Lost Command Trip, free-run stop
            self._trips.set_level_cause(Trip.LOST_COMMAND, True, free_run=True)
        elif mode is LostCommandMode.DEC:           # Lost Command Trip, deceleration stop
            self._trips.set_level_cause(Trip.LOST_COMMAND, True, free_run=False)
            self._ramp.settle()
        else:
            state.warnings |= WarningInformation.LOST_COMMAND
            if mode is LostCommandMode.HOLD_INPUT:    # the speed reference before the loss
                state.lost_reference = state.reference_hz()
            elif mode is LostCommandMode.HOLD_OUTPUT:  # the running speed before the loss
                state.lost_reference = abs(state.output_hz)
            else:                                      # Lost Preset: Pr.14
                state.lost_reference = state.values[_LOST_PRESET_FREQ] / 100

    def _restore_after_loss(self) -> None:
        """Communication is back. The Lost Command warning clears and the reference is the
        network's again; the Lost Command trip is a level-type trip (0x0332 B2) and clears
        with its cause, leaving the drive stopped until a run command's next 0 -> 1 change."""
        state = self._state
        if state.io_watch.acted or state.modbus_watch.acted or state.int485_watch.acted:
            return                                  # another protocol is still lost
        state.warnings &= ~WarningInformation.LOST_COMMAND
        state.lost_reference = None
        self._trips.set_level_cause(Trip.LOST_COMMAND, False)


__all__ = ["IO_BREAK_TIME", "MODBUS_SILENCE_TIME", "CommandLossWatch", "CommandLossWatches", "LostCommandMode"]
