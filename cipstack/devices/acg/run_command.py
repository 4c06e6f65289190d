"""The Control Supervisor's run commands: the "Drive Run" edge table (ACG-ET2 manual, class 0x29),
Drive State, and the commands of the common and control areas (ACG RS-485 manual)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from enum import Enum, IntEnum

from .registers import (
    CMD_SOURCE,
    CMD_SOURCE_FIELDBUS,
    CMD_SOURCE_INT485,
    FREQ_REF_SOURCE,
    FREQ_REF_SOURCE_FIELDBUS,
    FREQ_REF_SOURCE_INT485,
)


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


class DriveState(IntEnum):
    """Class 0x29 attribute 6 "Drive State" (ACG-ET2 manual)."""

    VENDOR_SPECIFIC = 0
    STARTUP = 1
    NOT_READY = 2
    READY = 3
    ENABLED = 4
    STOPPING = 5
    FAULT_STOP = 6


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



class RunCommands:
    """Run, stop and fault reset as the network and the keypad command them (part of ``AcgDrive``)."""


    def _apply_run_action(self, action: RunAction) -> None:
        if action is RunAction.STOP:
            self._stop()
        elif action is RunAction.RUN_FORWARD:
            self._run(Direction.FORWARD)
        elif action is RunAction.RUN_REVERSE:
            self._run(Direction.REVERSE)

    def _run(self, direction: Direction) -> None:
        if self._trip is not None:
            return                                  # a tripped drive ignores run commands
        self._command = direction
        self._output_on = True

    def _stop(self) -> None:
        self._command = None
        self._settle()

    @contextmanager
    def commands_from(self, port: CommandPort) -> Iterator[None]:
        """Writes made inside come in through ``port``: a run command in them is obeyed when drv is
        that port's command source (``CommandPort``). Outside, writes are the card's. (A request path
        may set ``command_port`` itself and put the previous one back, as ``commands_from`` does.)"""
        previous, self.command_port = self.command_port, port
        try:
            yield
        finally:
            self.command_port = previous

    def _port_commands(self) -> bool:
        """The drive obeys run commands of the port the present write came in through."""
        return self._values[CMD_SOURCE.address] == self.command_port.command_source

    @property
    def control_from_int485(self) -> bool:
        """drv is 3 (Int485): the built-in RS-485 port commands run and stop."""
        return self._values[CMD_SOURCE.address] == CMD_SOURCE_INT485

    @property
    def reference_from_int485(self) -> bool:
        """Frq is 6 (Int485): the built-in RS-485 port sets the speed reference."""
        return self._values[FREQ_REF_SOURCE.address] == FREQ_REF_SOURCE_INT485

    @property
    def control_from_net(self) -> bool:
        """Class 0x29 attribute 14: drv is 4 (Field Bus)."""
        return self._values[CMD_SOURCE.address] == CMD_SOURCE_FIELDBUS

    @property
    def reference_from_net(self) -> bool:
        """Class 0x2A attribute 29: Frq is 8 (Field Bus)."""
        return self._values[FREQ_REF_SOURCE.address] == FREQ_REF_SOURCE_FIELDBUS

    def set_run_command(self, forward: bool, reverse: bool, now: float) -> RunAction:
        """Forward and Reverse Run Cmd (class 0x29 attributes 3 and 4) written together, as an
        output assembly does; returns what the Drive Run table made of it. The card keeps the
        values whatever the command source; the drive acts on them only when drv is Field Bus."""
        self.advance(now)
        action = self.control_supervisor.update_run(bool(forward), bool(reverse))
        if self.control_from_net:
            self._apply_run_action(action)
            self._ramp(0.0)
        return action

    def set_run_forward(self, value: bool, now: float) -> RunAction:
        """Class 0x29 attribute 3 alone."""
        return self.set_run_command(bool(value), self.control_supervisor.run_reverse, now)

    def set_run_reverse(self, value: bool, now: float) -> RunAction:
        """Class 0x29 attribute 4 alone."""
        return self.set_run_command(self.control_supervisor.run_forward, bool(value), now)

    def set_fault_reset(self, value: bool, now: float) -> bool:
        """Class 0x29 attribute 12 Drive Fault Reset: resets on FALSE -> TRUE only; writing TRUE
        over TRUE does nothing (ACG-ET2 manual, "Drive Fault Reset"). Returns whether a reset was made."""
        self.advance(now)
        if self.control_supervisor.update_fault_reset(bool(value)):
            return self._fault_reset()
        return False

    def local_command(self, direction: Direction | None, now: float) -> None:
        """Run or stop from the keypad or terminals, which the drive obeys when drv is not Field Bus."""
        self.advance(now)
        if self.control_from_net:
            return
        if direction is None:
            self._stop()
        else:
            self._run(direction)
        self._ramp(0.0)

    def fault_reset(self, now: float) -> bool:
        """A fault reset at ``now`` from outside the network (the test rig's): what a rising edge of
        Drive Fault Reset does. Whether a trip was cleared."""
        self.advance(now)
        return self._fault_reset()

    def _fault_reset(self) -> bool:
        if self._trip is None or self._trip in self._level_causes:
            return False                            # a level-type trip holds while its cause lasts
        self._trip = None
        return True
