"""Virtual multi-function inputs (ACG RS-485 manual, "Setting Virtual Multi-Function Input").

"Set codes CM.70-CM.77 to the functions to operate, and then set the BIT relevant to the function
to 1 at 0h0322 [0h0385] to operate it": bit n of 0x0385 (also written at 0x0322, ``registers``)
closes virtual input n + 1, whose function is CM.(70 + n); CM.86 Virt DI Status shows the bits.

* Functions modelled (``registers.MULTI_FUNCTIONS``): FX and RX run the drive as the terminals'
  run commands do, RST resets a trip when it closes, External Trip trips the drive (latch type,
  0x0330 B12) when it closes, BX is the emergency stop (level type, 0x0332 B0) while it is closed.
  Other settings of 0-49 are taken and do nothing.
* "Before you configure the virtual multi-function inputs, set the parameter code drv according to
  the command source": FX and RX are the terminals' run commands, which the drive obeys at drv 1
  Fx/Rx-1 (FX forward, RX reverse, both or neither stop) and drv 2 Fx/Rx-2 (FX runs, RX selects
  reverse). The chapter's table for the written word (0h0001 Forward operation, 0h0003 Reverse
  operation, 0h0000 Stop; CM.70 = FX, CM.71 = RX) is the Fx/Rx-2 reading: FX and RX together run
  in reverse. At any other drv the inputs are held and command nothing.
* A run command acts when the inputs' command changes, as a terminal's edge: a drive stopped by a
  trip does not restart while FX stays closed, only when it opens and closes again.
* "Virtual multi-function operates independently from In.65-In.69 ... and cannot be set
  redundantly": a function already set at another CM.70-CM.77 or In.65-In.69 is refused (out of
  range).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..registers import RegisterError, RegisterMap, RegisterRefusal
from .registers import (
    ACG_REGISTERS,
    CMD_SOURCE,
    CMD_SOURCE_FX_RX_1,
    CMD_SOURCE_FX_RX_2,
)
from .run_command import Direction
from .trips import Trip

if TYPE_CHECKING:
    from .run_command import RunControl
    from .state import AcgState
    from .trips import TripLog

_CMD_SOURCE = CMD_SOURCE.address

VIRTUAL_INPUT_CONTROL = 0x0385
FX, RX, RST, EXTERNAL_TRIP, BX = 1, 2, 3, 4, 5
#: CM.70-CM.77: the function of virtual input 1-8 (bit 0-7 of 0x0385).
VIRTUAL_FUNCTION_ADDRESSES = tuple(ACG_REGISTERS.by_code(f"CM.{70 + n}").address for n in range(8))
#: In.65-In.69: the functions of the terminals P1-P5.
TERMINAL_FUNCTION_ADDRESSES = tuple(ACG_REGISTERS.by_code(f"In.{65 + n}").address for n in range(5))


class VirtualInputs:
    """CM.70-CM.77 and 0x0385: the functions of the closed inputs, and what FX/RX last commanded."""

    def __init__(self, state: AcgState, registers: RegisterMap, trips: TripLog, run: RunControl) -> None:
        self._state = state
        self._registers = registers
        self._trips = trips
        self._run = run
        #: The functions of the inputs closed now.
        self._closed_functions: frozenset[int] = frozenset()
        #: What FX and RX last commanded (None: stop).
        self._virtual_command: Direction | None = None

    def _virtual_functions(self) -> frozenset[int]:
        """The functions of the closed virtual inputs."""
        values = self._state.values
        bits = values[VIRTUAL_INPUT_CONTROL]
        return frozenset(values[a] for n, a in enumerate(VIRTUAL_FUNCTION_ADDRESSES) if bits >> n & 1)

    def write_inputs(self, address: int, value: int, now: float) -> None:
        """0x0385 (0x0322) written: the inputs open and close."""
        self._state.values[VIRTUAL_INPUT_CONTROL] = value
        self._apply()

    def write_function(self, address: int, value: int, now: float) -> None:
        """A function set at CM.70-CM.77 or In.65-In.69: refused when another input has it."""
        values = self._state.values
        if value:
            for other in (*VIRTUAL_FUNCTION_ADDRESSES, *TERMINAL_FUNCTION_ADDRESSES):
                if other != address and values[other] == value:
                    raise RegisterError(RegisterRefusal.OUT_OF_RANGE, address,
                                        f"function {value} is already set at {self._registers[other].code} "
                                        f"(a function cannot be set redundantly)")
        values[address] = value
        if address in VIRTUAL_FUNCTION_ADDRESSES:
            self._apply()

    def _virtual_run_command(self, closed: frozenset[int]) -> Direction | None:
        """What FX and RX command at the present drv (None: stop)."""
        forward, reverse = FX in closed, RX in closed
        if self._state.values[_CMD_SOURCE] == CMD_SOURCE_FX_RX_2:
            return (Direction.REVERSE if reverse else Direction.FORWARD) if forward else None
        if forward != reverse:
            return Direction.FORWARD if forward else Direction.REVERSE
        return None

    def _apply(self) -> None:
        closed = self._virtual_functions()
        rising = closed - self._closed_functions
        self._closed_functions = closed
        if RST in rising:
            self._trips.reset()
        if EXTERNAL_TRIP in rising:
            self._trips.trip(Trip.EXTERNAL_TRIP)
        self._trips.set_level_cause(Trip.BX, self.emergency_stop())
        command = self._virtual_run_command(closed)
        previous, self._virtual_command = self._virtual_command, command
        if self._state.values[_CMD_SOURCE] not in (CMD_SOURCE_FX_RX_1, CMD_SOURCE_FX_RX_2) or command == previous:
            return
        if command is None:
            self._run.stop()
        else:
            self._run.run(command)

    def emergency_stop(self) -> bool:
        """BX: the common area's emergency stop bit (0x0006 B4) or a closed virtual BX input."""
        return bool(self._state.values[0x0006] & 0x10) or BX in self._closed_functions


__all__ = ["TERMINAL_FUNCTION_ADDRESSES", "VIRTUAL_FUNCTION_ADDRESSES", "VIRTUAL_INPUT_CONTROL", "VirtualInputs"]
