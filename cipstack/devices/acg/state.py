"""What the ACG drive is at one instant: the one state its components share.

Each rule of the drive is a component (``ramps.Ramp``, ``trips.TripLog``, ``run_command.RunControl``,
``lost_command.CommandLossWatches``, ``virtual_inputs.VirtualInputs``, ``register_effects``,
``computed.ComputedRegisters``) given this state at construction; ``AcgDrive`` composes them. The
state holds data and what follows from it alone (the reference in use, the direction of the output);
it changes only through the components.
"""

from __future__ import annotations

from .lost_command import IO_BREAK_TIME, MODBUS_SILENCE_TIME, CommandLossWatch
from .registers import (
    FREQ_REF_SOURCE,
    FREQ_REF_SOURCE_FIELDBUS,
    FREQ_REF_SOURCE_INT485,
    MAX_FREQUENCY,
    POLE_NUMBER,
    SPEED_REFERENCE,
    TARGET_FREQUENCY,
)
from .run_command import CommandPort, Direction
from .status_words import WarningInformation
from .trips import Trip

_MAX_FREQUENCY = MAX_FREQUENCY.address
_FREQ_REF_SOURCE = FREQ_REF_SOURCE.address
_SPEED_REFERENCE = SPEED_REFERENCE.address
_TARGET_FREQUENCY = TARGET_FREQUENCY.address
_POLE_NUMBER = POLE_NUMBER.address


class AcgState:
    """The drive's register values, output, run command, trip, warnings and command-loss watches."""

    # Read on every request and every class 1 datagram: slots keep each read one step.
    __slots__ = (
        "command",
        "command_port",
        "fan_seconds",
        "fault_history",
        "int485_watch",
        "io_watch",
        "level_causes",
        "lost_reference",
        "modbus_watch",
        "output_hz",
        "output_on",
        "run_seconds",
        "start_time",
        "time",
        "trip",
        "values",
        "warnings",
    )

    def __init__(self, values: dict[int, int], now: float) -> None:
        #: Register values by address (aliases resolved: ``registers.ALIASES``).
        self.values = values
        self.time = now
        #: The power-up instant: On Time (0x0340/0x0341) counts from it.
        self.start_time = now
        #: The run command the drive obeys (None: stop).
        self.command: Direction | None = None
        self.output_hz = 0.0            # signed: forward > 0, reverse < 0
        #: The output is on: running, or decelerating to a stop.
        self.output_on = False
        self.trip: Trip | None = None
        #: Level-type trips whose cause is present (they clear with it).
        self.level_causes: set[Trip] = set()
        self.warnings = WarningInformation(0)
        self.fault_history: list[Trip] = []
        #: Hz held by Hold Input / Hold Output / Lost Preset while a command is lost (Pr.12).
        self.lost_reference: float | None = None
        #: Accumulated run and heat-sink fan time (0x0342-0x0345), seconds.
        self.run_seconds = 0.0
        self.fan_seconds = 0.0
        #: The port the present write came in through (``AcgDrive.commands_from``); the card's by default.
        self.command_port = CommandPort.FIELDBUS
        #: The lost-command watches of the card's class 1 and Modbus TCP, and of the built-in RS-485.
        self.io_watch = CommandLossWatch(IO_BREAK_TIME)
        self.modbus_watch = CommandLossWatch(MODBUS_SILENCE_TIME)
        self.int485_watch = CommandLossWatch(None, CommandPort.INT485)

    @property
    def watches(self) -> tuple[CommandLossWatch, CommandLossWatch, CommandLossWatch]:
        return self.io_watch, self.modbus_watch, self.int485_watch

    def at_rest(self) -> bool:
        """Output off (nothing ramps, nothing counts) and no command-loss watch running (no timer): the
        stopped drive of most explicit traffic, which time moves on by the clock alone. A method, not a
        property: it is asked on every request, and a method call costs less."""
        return (not self.output_on and self.io_watch.silent_since is None and self.modbus_watch.silent_since is None
                and self.int485_watch.silent_since is None)

    # -- speeds --------------------------------------------------------------------------------
    def max_hz(self) -> float:
        return self.values[_MAX_FREQUENCY] / 100

    def reference_hz(self) -> float:
        """The speed reference in use, Hz: the lost-command one, else the source Frq names."""
        if self.lost_reference is not None:
            reference = self.lost_reference
        elif self.values[_FREQ_REF_SOURCE] in (FREQ_REF_SOURCE_FIELDBUS, FREQ_REF_SOURCE_INT485):
            # Both communication sources set the frequency command of 0x0005 / 0x0380 (ACG RS-485 manual).
            reference = self.values[_SPEED_REFERENCE] / 100
        else:
            reference = self.values[_TARGET_FREQUENCY] / 100
        return min(reference, self.values[_MAX_FREQUENCY] / 100)   # dr.20 Max Freq

    @property
    def poles(self) -> int:
        return self.values[_POLE_NUMBER]

    def hz_to_rpm(self, hz: float) -> int:
        """Synchronous speed: 120 * f / poles."""
        return round(120 * hz / self.values[_POLE_NUMBER])

    def rpm_to_centihertz(self, rpm: int) -> int:
        return round(rpm * self.values[_POLE_NUMBER] * 100 / 120)

    # -- status --------------------------------------------------------------------------------
    def direction(self) -> Direction | None:
        """The direction the output turns the motor (None: output off)."""
        if not self.output_on:
            return None
        if self.output_hz != 0:
            return Direction.FORWARD if self.output_hz > 0 else Direction.REVERSE
        return self.command

    def on_seconds(self) -> float:
        return self.time - self.start_time


__all__ = ["AcgState"]
