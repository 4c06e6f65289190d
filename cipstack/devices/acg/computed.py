"""Computed registers: the monitors of the common and monitoring areas (ACG RS-485 manual) that the
simulation produces rather than stores.

The voltages follow from the running state (there is no motor model, so not the current, power or
torque: those registers are declared ``simulated=False`` and read 0):

* DC link voltage (0x000C, 0x0315, dCL): the rectified input, sqrt(2) x the input voltage while the
  drive is powered, running or not. The input is the drive's class, 0x0002 "Drive input voltage"
  (0 "230V level", 1 "460V level"; the emulated drive is 230 V 3-phase, 0x0302 = 0x0230).
* Output voltage (0x000B, 0x0314, vOL): a linear V/f, the rated voltage bA.15 (Motor Data attribute 7;
  0, its factory value here, takes the input voltage) times the output frequency over dr.20 Max Freq,
  at most the rated voltage, 0 while the output is off. The ACG manuals name no base frequency (dr.18
  is listed without a description), so the V/f line ends at the maximum frequency.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from ..registers import RegisterError, RegisterMap, RegisterRefusal
from . import registers as reg
from . import status_words as words
from .registers import ALIASES, CMD_SOURCE, FREQ_REF_SOURCE, MAX_FREQUENCY, RATED_VOLTAGE, SPEED_REFERENCE
from .run_command import Direction
from .status_words import FaultTripInformation, OperationDirection, OperationHealth, OperationPhase, OperationStatus
from .trips import Trip

if TYPE_CHECKING:
    from .memory import PasswordLocks
    from .ramps import Ramp
    from .state import AcgState

_CMD_SOURCE = CMD_SOURCE.address
_FREQ_REF_SOURCE = FREQ_REF_SOURCE.address
_SPEED_REFERENCE = SPEED_REFERENCE.address

_MAX_FREQUENCY = MAX_FREQUENCY.address
_RATED_VOLTAGE = RATED_VOLTAGE.address
#: 0x0002 Drive input voltage (ACG RS-485 manual, Compatible Common Area): its levels in volts.
_INPUT_VOLTAGE = {0: 230, 1: 460}
_INPUT_VOLTAGE_LEVEL = 0x0002

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
    """Registers whose value the simulation produces: ``read`` gives any register's value, computed
    or stored."""

    def __init__(self, state: AcgState, registers: RegisterMap, ramp: Ramp, locks: PasswordLocks) -> None:
        self._state = state
        self._registers = registers
        self._ramp = ramp
        self._locks = locks
        self._addresses = frozenset(registers)
        self._computed = self._computed_registers()
        self._cm_address = {code: registers.by_code(code).address
                            for code in (*(f"CM.{31 + i}" for i in range(8)), *(f"CM.{51 + i}" for i in range(8)))}

    def read(self, address: int) -> int:
        """The raw value of the register at ``address`` (an alias reads its target), or ``RegisterError``."""
        if address not in self._addresses:
            raise RegisterError(RegisterRefusal.NO_SUCH_REGISTER, address)
        address = ALIASES.get(address, address)
        compute = self._computed.get(address)
        return compute() if compute is not None else self._state.values[address]

    def _output_frequency(self) -> int:
        return round(abs(self._state.output_hz) * 100)

    def _input_voltage(self) -> int:
        return _INPUT_VOLTAGE.get(self._state.values[_INPUT_VOLTAGE_LEVEL], _INPUT_VOLTAGE[0])

    def _dc_link_voltage(self) -> int:
        """0x000C / 0x0315: sqrt(2) x the input voltage (325 V on the 230 V class), while powered."""
        return round(math.sqrt(2) * self._input_voltage())

    def _output_voltage(self) -> int:
        """0x000B / 0x0314: V/f from 0 V at 0 Hz to the rated voltage at dr.20 Max Freq (module docstring)."""
        state = self._state
        if not state.output_on:
            return 0
        values = state.values
        rated = values[_RATED_VOLTAGE] or self._input_voltage()
        maximum = values[_MAX_FREQUENCY] / 100
        return round(rated * min(1.0, abs(state.output_hz) / maximum)) if maximum > 0 else rated

    def _operation_status(self) -> int:
        """Common area 0x000E (ACG RS-485 manual)."""
        state, ramp = self._state, self._ramp
        status = OperationStatus(0)
        direction = state.direction()
        if not state.output_on:
            status |= OperationStatus.STOPPED
        if direction is Direction.FORWARD:
            status |= OperationStatus.FORWARD
        if direction is Direction.REVERSE:
            status |= OperationStatus.REVERSE
        if state.trip is not None:
            status |= OperationStatus.FAULT_TRIP
        if ramp.accelerating:
            status |= OperationStatus.ACCELERATING
        if ramp.decelerating:
            status |= OperationStatus.DECELERATING
        if ramp.at_reference:
            status |= OperationStatus.SPEED_REACHED
        if state.output_on and state.command is None:
            status |= OperationStatus.STOPPING
        if state.command is Direction.FORWARD:
            status |= OperationStatus.FORWARD_COMMAND
        if state.command is Direction.REVERSE:
            status |= OperationStatus.REVERSE_COMMAND
        if state.values[_CMD_SOURCE] in _COMMAND_SOURCES_BY_COMMUNICATION:
            status |= OperationStatus.COMMAND_FROM_COMMUNICATION
        if state.values[_FREQ_REF_SOURCE] in _FREQUENCY_SOURCES_BY_COMMUNICATION:
            status |= OperationStatus.FREQUENCY_FROM_COMMUNICATION
        return int(status)

    def _fault_trip_information(self) -> int:
        """Common area 0x000F (ACG RS-485 manual)."""
        info = FaultTripInformation(0)
        trip = self._state.trip
        if trip is Trip.HW_DIAG:
            info |= FaultTripInformation.HW_DIAG
        elif trip is not None:
            info |= FaultTripInformation.LEVEL_TYPE_TRIP if trip.level else FaultTripInformation.LATCH_TYPE_TRIP
        return int(info)

    def _trip_bits(self, address: int) -> int:
        trip = self._state.trip
        return trip.bit if trip is not None and trip.info_address == address else 0

    def _operation_command_word(self) -> int:
        """Common area 0x0006 read: command bits as written, command and frequency sources."""
        values = self._state.values
        frequency_source = _COMMON_FREQUENCY_SOURCE.get(values[_FREQ_REF_SOURCE], 0)
        return (values[0x0006] & 0x1F
                | (values[_CMD_SOURCE] & words.OPERATION_COMMAND_SOURCE_MASK) << words.OPERATION_COMMAND_SOURCE_SHIFT
                | (frequency_source & words.OPERATION_FREQUENCY_SOURCE_MASK) << words.OPERATION_FREQUENCY_SOURCE_SHIFT)

    def _operation_state(self) -> int:
        """Monitoring 0x0305 (ACG RS-485 manual)."""
        state, ramp = self._state, self._ramp
        if state.trip is not None:
            health = OperationHealth.FAULT
        elif state.warnings:
            health = OperationHealth.WARNING
        else:
            health = OperationHealth.NORMAL
        if ramp.accelerating:
            phase = OperationPhase.ACCELERATING
        elif ramp.decelerating:
            phase = OperationPhase.DECELERATING if state.command is not None else OperationPhase.DECELERATING_TO_STOP
        elif state.output_on:
            phase = OperationPhase.CONSTANT_SPEED
        else:
            phase = OperationPhase.NONE
        direction = {Direction.FORWARD: OperationDirection.FORWARD, Direction.REVERSE: OperationDirection.REVERSE,
                     None: OperationDirection.STOPPED}[state.direction()]
        return int(health << words.OPERATION_HEALTH_SHIFT | phase << words.OPERATION_PHASE_SHIFT | direction)

    def _source_word(self) -> int:
        """Monitoring 0x0306 (ACG RS-485 manual)."""
        values = self._state.values
        command = _MONITOR_COMMAND_SOURCE[values[_CMD_SOURCE]]
        frequency = _MONITOR_FREQUENCY_SOURCE.get(values[_FREQ_REF_SOURCE], 0)
        return command << words.MONITOR_COMMAND_SOURCE_SHIFT | frequency

    def _parameter_word(self, code: str) -> int:
        """0x0100-0x0107 / 0x0110-0x0117 read: the word at the address ``code`` (CM.31.. / CM.51..) holds."""
        target = self._state.values[self._cm_address[code]]
        if self._registers.get(target) is None or reg.STATUS_PARAMETER_BASE <= target <= 0x01FF:
            return 0
        return self.read(target) & 0xFFFF

    def _computed_registers(self) -> dict[int, Callable[[], int]]:
        state, locks = self._state, self._locks

        def days(seconds: Callable[[], float]) -> Callable[[], int]:
            return lambda: int(seconds() // _SECONDS_PER_DAY)

        def minutes(seconds: Callable[[], float]) -> Callable[[], int]:
            return lambda: int(seconds() % _SECONDS_PER_DAY // _SECONDS_PER_MINUTE)

        def virtual_inputs() -> int:   # 0x0385 as written, monitored at CM.86 (and 0x0322, an alias)
            return state.values[0x0385]

        def relays() -> int:           # 0x0386 as written, monitored at 0x0011 and 0x0321
            return state.values[0x0386]

        def rpm() -> int:
            return state.hz_to_rpm(abs(state.output_hz))

        def poles() -> int:
            return state.poles

        def trip_bits(address: int) -> Callable[[], int]:
            return lambda: self._trip_bits(address)

        def parameter_word(code: str) -> Callable[[], int]:
            return lambda: self._parameter_word(code)

        computed: dict[int, Callable[[], int]] = {
            0x0006: self._operation_command_word,
            0x000A: self._output_frequency,
            0x000B: self._output_voltage,
            0x000C: self._dc_link_voltage,
            0x000E: self._operation_status,
            0x000F: self._fault_trip_information,
            0x0011: relays,
            0x0015: rpm,
            0x0381: lambda: state.hz_to_rpm(state.values[_SPEED_REFERENCE] / 100),
            0x001B: poles,
            0x0305: self._operation_state,
            0x0306: self._source_word,
            0x0311: self._output_frequency,
            0x0312: rpm,
            0x0313: lambda: state.hz_to_rpm(state.output_hz),
            0x0314: self._output_voltage,
            0x0315: self._dc_link_voltage,
            0x031A: poles,
            # The second motor's pole number is an M2 parameter the ACG manuals do not describe.
            0x031B: poles,
            0x031C: poles,
            0x0321: relays,
            0x0334: lambda: int(state.warnings),
            0x0340: days(state.on_seconds),
            0x0341: minutes(state.on_seconds),
            0x0342: days(lambda: state.run_seconds),
            0x0343: minutes(lambda: state.run_seconds),
            0x0344: days(lambda: state.fan_seconds),
            0x0345: minutes(lambda: state.fan_seconds),
            0x03E7: lambda: int(locks.hide_locked),
            0x03E8: lambda: int(locks.parameter_locked),
            0x1F09: rpm,
            0x1F0A: self._dc_link_voltage,
            0x1F0B: self._output_voltage,
            self._registers.by_code("CM.86").address: virtual_inputs,
            **{address: trip_bits(address) for address in (0x0330, 0x0331, 0x0332, 0x0333, 0x0335)},
            **{reg.STATUS_PARAMETER_BASE + i: parameter_word(f"CM.{31 + i}") for i in range(8)},
            **{reg.CONTROL_PARAMETER_BASE + i: parameter_word(f"CM.{51 + i}") for i in range(8)},
        }
        return computed


__all__ = ["ComputedRegisters"]
