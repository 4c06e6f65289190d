"""Computed registers: the monitors of the common and monitoring areas (ACG RS-485 manual) that the
simulation produces rather than stores."""

from __future__ import annotations

from collections.abc import Callable

from . import registers as reg
from .registers import (
    CMD_SOURCE,
    FREQ_REF_SOURCE,
    SPEED_REFERENCE,
    FaultTripInformation,
    OperationDirection,
    OperationHealth,
    OperationPhase,
    OperationStatus,
)
from .run_command import Direction
from .trips import Trip

_SECONDS_PER_MINUTE = 60
_SECONDS_PER_DAY = 86400

# Where the sources read in 0x0006 (B6-B8, B9-B14) and 0x0306 (B8-B15, B0-B7) come from.
# drv codes equal the 0x0006 command-source codes (both lists read 0 keypad ... 4 option).
_MONITOR_COMMAND_SOURCE = {0: 0, 1: 4, 2: 4, 3: 3, 4: 1}  # drv -> 0x0306 B8-B15
# Frq settings the ACG manuals name; an unnamed local source acts as the keypad frequency here (the
# emulated drive has no analog inputs), so it is shown as the keypad.
_COMMON_FREQUENCY_SOURCE = {0: 0, 6: 27, 8: 28}  # Frq -> 0x0006 B9-B14
_MONITOR_FREQUENCY_SOURCE = {0: 0, 6: 10, 8: 11}  # Frq -> 0x0306 B0-B7
_COMMAND_SOURCES_BY_COMMUNICATION = (3, 4)  # drv Int485 or Field Bus: 0x000E B13
_FREQUENCY_SOURCES_BY_COMMUNICATION = (6, 8)  # Frq Int485 or Field Bus: 0x000E B14



class ComputedRegisters:
    """Registers whose value the simulation produces (part of ``AcgDrive``)."""


    def _operation_status(self) -> int:
        """Common area 0x000E (ACG RS-485 manual)."""
        status = OperationStatus(0)
        direction = self._direction()
        if not self._output_on:
            status |= OperationStatus.STOPPED
        if direction is Direction.FORWARD:
            status |= OperationStatus.FORWARD
        if direction is Direction.REVERSE:
            status |= OperationStatus.REVERSE
        if self._trip is not None:
            status |= OperationStatus.FAULT_TRIP
        if self.accelerating:
            status |= OperationStatus.ACCELERATING
        if self.decelerating:
            status |= OperationStatus.DECELERATING
        if self.at_reference:
            status |= OperationStatus.SPEED_REACHED
        if self._output_on and self._command is None:
            status |= OperationStatus.STOPPING
        if self._command is Direction.FORWARD:
            status |= OperationStatus.FORWARD_COMMAND
        if self._command is Direction.REVERSE:
            status |= OperationStatus.REVERSE_COMMAND
        if self._values[CMD_SOURCE.address] in _COMMAND_SOURCES_BY_COMMUNICATION:
            status |= OperationStatus.COMMAND_FROM_COMMUNICATION
        if self._values[FREQ_REF_SOURCE.address] in _FREQUENCY_SOURCES_BY_COMMUNICATION:
            status |= OperationStatus.FREQUENCY_FROM_COMMUNICATION
        return int(status)

    def _fault_trip_information(self) -> int:
        """Common area 0x000F (ACG RS-485 manual)."""
        info = FaultTripInformation(0)
        if self._trip is Trip.HW_DIAG:
            info |= FaultTripInformation.HW_DIAG
        elif self._trip is not None:
            info |= FaultTripInformation.LEVEL_TYPE_TRIP if self._trip.level else FaultTripInformation.LATCH_TYPE_TRIP
        return int(info)

    def _trip_bits(self, address: int) -> int:
        trip = self._trip
        return trip.bit if trip is not None and trip.info_address == address else 0

    def _operation_command_word(self) -> int:
        """Common area 0x0006 read: command bits as written, command and frequency sources."""
        frequency_source = _COMMON_FREQUENCY_SOURCE.get(self._values[FREQ_REF_SOURCE.address], 0)
        return (self._values[0x0006] & 0x1F
                | (self._values[CMD_SOURCE.address] & reg.OPERATION_COMMAND_SOURCE_MASK)
                << reg.OPERATION_COMMAND_SOURCE_SHIFT
                | (frequency_source & reg.OPERATION_FREQUENCY_SOURCE_MASK) << reg.OPERATION_FREQUENCY_SOURCE_SHIFT)

    def _operation_state(self) -> int:
        """Monitoring 0x0305 (ACG RS-485 manual)."""
        if self._trip is not None:
            health = OperationHealth.FAULT
        elif self._warnings:
            health = OperationHealth.WARNING
        else:
            health = OperationHealth.NORMAL
        if self.accelerating:
            phase = OperationPhase.ACCELERATING
        elif self.decelerating:
            phase = OperationPhase.DECELERATING if self._command is not None else OperationPhase.DECELERATING_TO_STOP
        elif self._output_on:
            phase = OperationPhase.CONSTANT_SPEED
        else:
            phase = OperationPhase.NONE
        direction = {Direction.FORWARD: OperationDirection.FORWARD, Direction.REVERSE: OperationDirection.REVERSE,
                     None: OperationDirection.STOPPED}[self._direction()]
        return health << reg.OPERATION_HEALTH_SHIFT | phase << reg.OPERATION_PHASE_SHIFT | direction

    def _source_word(self) -> int:
        """Monitoring 0x0306 (ACG RS-485 manual)."""
        command = _MONITOR_COMMAND_SOURCE[self._values[CMD_SOURCE.address]]
        frequency = _MONITOR_FREQUENCY_SOURCE.get(self._values[FREQ_REF_SOURCE.address], 0)
        return command << reg.MONITOR_COMMAND_SOURCE_SHIFT | frequency

    def _status_parameter(self, index: int) -> int:
        target = self._value(f"CM.{31 + index}")
        if self.registers.get(target) is None or reg.STATUS_PARAMETER_BASE <= target <= 0x01FF:
            return 0
        return self.read(target) & 0xFFFF

    def _on_seconds(self) -> float:
        return self._time - self._start_time

    def _computed_registers(self) -> dict[int, Callable[[], int]]:
        def days(seconds: Callable[[], float]) -> Callable[[], int]:
            return lambda: int(seconds() // _SECONDS_PER_DAY)

        def minutes(seconds: Callable[[], float]) -> Callable[[], int]:
            return lambda: int(seconds() % _SECONDS_PER_DAY // _SECONDS_PER_MINUTE)

        def virtual_inputs() -> int:   # 0x0385 as written, monitored at CM.86 (and 0x0322, an alias)
            return self._values[0x0385]

        def relays() -> int:           # 0x0386 as written, monitored at 0x0011 and 0x0321
            return self._values[0x0386]

        def rpm() -> int:
            return self.speed_actual_rpm

        computed: dict[int, Callable[[], int]] = {
            0x0006: self._operation_command_word,
            0x000A: lambda: self.output_frequency,
            0x000E: self._operation_status,
            0x000F: self._fault_trip_information,
            0x0011: relays,
            0x0015: rpm,
            0x0381: lambda: self.hz_to_rpm(self._values[SPEED_REFERENCE.address] / 100),
            0x001B: lambda: self.poles,
            0x0305: self._operation_state,
            0x0306: self._source_word,
            0x0311: lambda: self.output_frequency,
            0x0312: rpm,
            0x0313: lambda: self.hz_to_rpm(self._output_hz),
            0x031A: lambda: self.poles,
            # The second motor's pole number is an M2 parameter the ACG manuals do not describe.
            0x031B: lambda: self.poles,
            0x031C: lambda: self.poles,
            0x0321: relays,
            0x0334: lambda: int(self._warnings),
            0x0340: days(self._on_seconds),
            0x0341: minutes(self._on_seconds),
            0x0342: days(lambda: self._run_seconds),
            0x0343: minutes(lambda: self._run_seconds),
            0x0344: days(lambda: self._fan_seconds),
            0x0345: minutes(lambda: self._fan_seconds),
            0x03E7: lambda: int(self._hide_locked),
            0x03E8: lambda: int(self._parameter_locked),
            0x1F09: rpm,
            self.registers.by_code("CM.86").address: virtual_inputs,
            **{address: (lambda a=address: self._trip_bits(a)) for address in (0x0330, 0x0331, 0x0332, 0x0333,
                                                                                 0x0335)},
            **{reg.STATUS_PARAMETER_BASE + i: (lambda i=i: self._status_parameter(i)) for i in range(8)},
            **{reg.CONTROL_PARAMETER_BASE + i: (lambda i=i: self._control_parameter(i)) for i in range(8)},
        }
        return computed

    def _control_parameter(self, index: int) -> int:
        target = self._value(f"CM.{51 + index}")
        if self.registers.get(target) is None or reg.STATUS_PARAMETER_BASE <= target <= 0x01FF:
            return 0
        return self.read(target) & 0xFFFF
