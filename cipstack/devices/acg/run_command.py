"""The Control Supervisor's run commands: the "Drive Run" edge table (ACG-ET2 manual, class 0x29),
Drive State, and the commands of the common and control areas (ACG RS-485 manual)."""

from __future__ import annotations

from enum import Enum, IntEnum
from typing import TYPE_CHECKING

from ...assemblies.drive_profile import DriveState
from .registers import (
    CMD_SOURCE,
    CMD_SOURCE_FIELDBUS,
    CMD_SOURCE_INT485,
    FREQ_REF_SOURCE_FIELDBUS,
    FREQ_REF_SOURCE_INT485,
)

if TYPE_CHECKING:
    from .ramps import Ramp
    from .state import AcgState

_CMD_SOURCE = CMD_SOURCE.address


class CommandPort(Enum):
    """Where a command written to the drive came in, and the drv / Frq settings that make the drive
    obey it: the communication option (the ACG-ET2 card: EtherNet/IP, Modbus TCP) at drv 4 / Frq 8
    "Field Bus" (ACG-ET2 manual), the built-in RS-485 at drv 3 / Frq 6 "Int485" (ACG RS-485 manual, Setting
    Operation Command and Frequency)."""

    FIELDBUS = (CMD_SOURCE_FIELDBUS, FREQ_REF_SOURCE_FIELDBUS)
    INT485 = (CMD_SOURCE_INT485, FREQ_REF_SOURCE_INT485)

    def __init__(self, command_source: int, frequency_source: int) -> None:
        self.command_source = command_source
        self.frequency_source = frequency_source


class Direction(IntEnum):
    FORWARD = 1
    REVERSE = -1


class RunAction(Enum):
    STOP = "Stop"
    RUN_FORWARD = "Run1"
    RUN_REVERSE = "Run2"
    NO_ACTION = "No Action"


def drive_run_action(previous: tuple[bool, bool], present: tuple[bool, bool]) -> RunAction:
    """The Control Supervisor "Drive Run" table (ACG-ET2 manual, class 0x29): what a change of the
    Forward Run Cmd (Run1, attribute 3) and Reverse Run Cmd (Run2, attribute 4) commands.

    ==========  ==========  ===========  ========
    Run1        Run2        Trigger      Run Type
    ==========  ==========  ===========  ========
    0           0           Stop         NA
    0 -> 1      0           Run          Run1
    0           0 -> 1      Run          Run2
    0 -> 1      0 -> 1      No Action    NA
    1           1           No Action    NA
    1 -> 0      1           Run          Run2
    1           1 -> 0      Run          Run1
    ==========  ==========  ===========  ========

    A command is made when a value changes from 0 to 1 (or when the other one drops and leaves
    it alone); a value held at 1 commands nothing, so a drive stopped by a trip, a free-run stop
    or a lost command does not restart until its run bit goes 0 -> 1 again.
    """
    forward_before, reverse_before = previous
    forward, reverse = present
    if not forward and not reverse:
        return RunAction.STOP                       # row "0, 0: Stop"
    if forward and reverse:
        return RunAction.NO_ACTION                  # rows "0->1, 0->1" and "1, 1": No Action
    if forward:
        if not forward_before:
            return RunAction.RUN_FORWARD            # row "0->1, 0: Run1"
        if reverse_before:
            return RunAction.RUN_FORWARD            # row "1, 1->0: Run1"
        return RunAction.NO_ACTION                  # held at 1: no new command
    if not reverse_before:
        return RunAction.RUN_REVERSE                # row "0, 0->1: Run2"
    if forward_before:
        return RunAction.RUN_REVERSE                # row "1->0, 1: Run2"
    return RunAction.NO_ACTION


class ControlSupervisor:
    """The command attributes of class 0x29 instance 1: Forward Run Cmd (3), Reverse Run Cmd (4)
    and Drive Fault Reset (12), as the card holds them (ACG-ET2 manual). "The Forward Run Cmd. value
    does not indicate the present operation status of the drive; it indicates the operation
    command value on the Ethernet communication board."
    """

    def __init__(self) -> None:
        self.run_forward = False
        self.run_reverse = False
        self.fault_reset = False

    def update_run(self, forward: bool, reverse: bool) -> RunAction:
        action = drive_run_action((self.run_forward, self.run_reverse), (forward, reverse))
        self.run_forward, self.run_reverse = forward, reverse
        return action

    def update_fault_reset(self, value: bool) -> bool:
        """Store attribute 12; True on its FALSE -> TRUE change, the only one that resets."""
        edge = value and not self.fault_reset
        self.fault_reset = value
        return edge



class RunControl:
    """Run and stop as the drive obeys them, whoever commands (the Control Supervisor, the common
    and control areas, the keypad, the virtual inputs)."""

    def __init__(self, state: AcgState, ramp: Ramp) -> None:
        self._state = state
        self._ramp = ramp

    def apply(self, action: RunAction) -> None:
        """What a row of the Drive Run table commands."""
        if action is RunAction.STOP:
            self.stop()
        elif action is RunAction.RUN_FORWARD:
            self.run(Direction.FORWARD)
        elif action is RunAction.RUN_REVERSE:
            self.run(Direction.REVERSE)

    def run(self, direction: Direction) -> None:
        state = self._state
        if state.trip is not None:
            return                                  # a tripped drive ignores run commands
        state.command = direction
        state.output_on = True

    def stop(self) -> None:
        self._state.command = None
        self._ramp.settle()

    def free_run(self) -> None:
        """A free-run stop: the output is cut at once."""
        self._ramp.free_run()

    def port_commands(self) -> bool:
        """The drive obeys run commands of the port the present write came in through."""
        return self._state.values[_CMD_SOURCE] == self._state.command_port.command_source


__all__ = ["CommandPort", "ControlSupervisor", "Direction", "DriveState", "RunAction", "RunControl", "drive_run_action"]
