"""Register side effects: run and frequency commands, parameter save and initialization, password,
counters, CM.94 and the smart-scaling words (ACG RS-485 manual control and memory control areas; ACG-ET2 manual)."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from ..registers import RegisterError, RegisterMap, RegisterRefusal
from . import registers as reg
from .registers import COMM_UPDATE, LOST_PRESET_FREQ, MAX_FREQUENCY, SAVE_PARAMETERS, SPEED_REFERENCE, TARGET_FREQUENCY
from .run_command import Direction
from .status_words import ControlCommand, OperationCommand
from .trips import Trip
from .virtual_inputs import (
    TERMINAL_FUNCTION_ADDRESSES,
    VIRTUAL_FUNCTION_ADDRESSES,
    VIRTUAL_INPUT_CONTROL,
)

if TYPE_CHECKING:
    from .comm_update import CommUpdate
    from .memory import PasswordLocks, SavedParameters
    from .run_command import RunControl
    from .state import AcgState
    from .trips import TripLog
    from .virtual_inputs import VirtualInputs

#: A write's effect: (address, raw value, now).
WriteHandler = Callable[[int, int, float], None]

_MAX_FREQUENCY = MAX_FREQUENCY.address
_SPEED_REFERENCE = SPEED_REFERENCE.address


class RegisterEffects:
    """What writing a register does beyond storing it, by the address that holds the value.
    ``write_through``: the drive's own write, which a control parameter word (0x0110-0x0117) is
    passed on to at the address its CM.51-CM.58 names."""

    def __init__(self, state: AcgState, registers: RegisterMap, *, trips: TripLog, run: RunControl,
                 virtual_inputs: VirtualInputs, saving: SavedParameters, comm: CommUpdate, locks: PasswordLocks,
                 write_through: WriteHandler) -> None:
        self._state = state
        self._registers = registers
        self._trips = trips
        self._run = run
        self._virtual_inputs = virtual_inputs
        self._saving = saving
        self._comm = comm
        self._locks = locks
        self._write_through = write_through
        self._cm23 = registers.by_code("CM.23").address
        self._cm30 = registers.by_code("CM.30").address
        self._cm50 = registers.by_code("CM.50").address
        self._control_targets = tuple(registers.by_code(f"CM.{51 + i}").address for i in range(8))
        self._handlers: dict[int, WriteHandler] = {
            SPEED_REFERENCE.address: self._write_frequency,
            TARGET_FREQUENCY.address: self._write_frequency,
            LOST_PRESET_FREQ.address: self._write_lost_preset,
            0x0381: self._write_rpm_command,
            0x0006: self._write_operation_command,
            0x0382: self._write_control_command,
            SAVE_PARAMETERS.address: self._write_save,
            0x03E2: self._write_parameter_initialization,
            0x03E5: self._write_fault_history,
            0x03E7: self._write_password,
            0x03E8: self._write_password,
            0x03EA: self._write_counter_reset,
            0x03EB: self._write_counter_reset,
            0x03EC: self._write_counter_reset,
            COMM_UPDATE.address: self._write_comm_update,
            self._cm23: self._write_instance_setting,
            registers.by_code("CM.24").address: self._write_instance_setting,
            **dict.fromkeys(range(reg.CONTROL_PARAMETER_BASE, reg.CONTROL_PARAMETER_BASE + 8),
                            self._write_control_parameter),
            VIRTUAL_INPUT_CONTROL: virtual_inputs.write_inputs,
            **dict.fromkeys((*VIRTUAL_FUNCTION_ADDRESSES, *TERMINAL_FUNCTION_ADDRESSES),
                            virtual_inputs.write_function),
        }

    def write(self, address: int, value: int, now: float) -> None:
        """Store ``value`` (checked against the register's range) at ``address``, with its effect."""
        handler = self._handlers.get(address)
        if handler is not None:
            handler(address, value, now)
        else:
            self._state.values[address] = value

    def _check_frequency(self, address: int, value: int) -> None:
        maximum = self._state.values[_MAX_FREQUENCY]
        if value > maximum:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, address,
                                f"{value / 100:.2f} Hz above dr.20 Max Freq {maximum / 100:.2f} Hz")

    def _write_frequency(self, address: int, value: int, now: float) -> None:
        self._check_frequency(address, value)
        self._state.values[address] = value

    def _write_lost_preset(self, address: int, value: int, now: float) -> None:
        # Pr.14: 0.05-60.00, or the table's default 0.00 (ACG-ET2 manual; registers.LOST_PRESET_FREQ).
        if 0 < value < reg.LOST_PRESET_MINIMUM:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, address,
                                f"{value / 100:.2f} Hz below the lowest Lost Preset F, 0.05 Hz (0.00: none)")
        self._write_frequency(address, value, now)

    def _write_rpm_command(self, address: int, value: int, now: float) -> None:
        centihertz = self._state.rpm_to_centihertz(value)
        if centihertz > SPEED_REFERENCE.raw_maximum:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, address, f"{value} rpm above 400.00 Hz")
        self._check_frequency(address, centihertz)
        self._state.values[_SPEED_REFERENCE] = centihertz

    def _write_operation_command(self, address: int, value: int, now: float) -> None:
        # Common area 0x0006 (ACG RS-485 manual): B0 stop, B1 forward, B2 reverse, B3 trip reset on 0 -> 1,
        # B4 emergency stop (the BX level trip while it is set).
        values = self._state.values
        previous = OperationCommand(values[address] & 0x1F)
        bits = OperationCommand(value & 0x1F)
        values[address] = int(bits)
        if OperationCommand.TRIP_RESET in bits and OperationCommand.TRIP_RESET not in previous:
            self._trips.reset()
        self._trips.set_level_cause(Trip.BX, self._virtual_inputs.emergency_stop())   # B4, or a closed BX input
        if not self._run.port_commands():
            return
        run_bits = bits & (OperationCommand.STOP | OperationCommand.FORWARD | OperationCommand.REVERSE)
        if OperationCommand.STOP in run_bits:
            self._run.stop()
        elif run_bits == OperationCommand.FORWARD:
            self._run.run(Direction.FORWARD)
        elif run_bits == OperationCommand.REVERSE:
            self._run.run(Direction.REVERSE)

    def _write_control_command(self, address: int, value: int, now: float) -> None:
        # Control area 0x0382 (ACG RS-485 manual): B0 run/stop, B1 forward/reverse, B2 trip reset on
        # 0 -> 1, B3 free-run stop on 0 -> 1. Forward run is 0x0003, reverse run 0x0001.
        values = self._state.values
        previous = ControlCommand(values[address] & 0x0F)
        bits = ControlCommand(value & 0x0F)
        values[address] = value
        rising = bits & ~previous
        if ControlCommand.TRIP_RESET in rising:
            self._trips.reset()
        if not self._run.port_commands():
            return
        if ControlCommand.FREE_RUN_STOP in rising:
            self._run.free_run()
        elif ControlCommand.RUN in bits:
            self._run.run(Direction.FORWARD if ControlCommand.FORWARD in bits else Direction.REVERSE)
        else:
            self._run.stop()

    def _write_save(self, address: int, value: int, now: float) -> None:
        # "Setting address 0h03E0 to 0 and then setting it again to 1 ... allows the existing
        # parameter settings to be saved. However, setting 0h03E0 to 1 and then setting it to 0
        # does not carry out the same function." (ACG RS-485 manual)
        # A refused save (the state file cannot be written) leaves 0x03E0 as it was.
        values = self._state.values
        if values[address] == 0 and value == 1:
            self._saving.save_all(values)
        values[address] = value

    def _write_parameter_initialization(self, address: int, value: int, now: float) -> None:
        if self._state.trip is not None:
            raise RegisterError(RegisterRefusal.NOT_WHILE_RUNNING, address,
                                "parameter initialization is prohibited during a fault trip")
        groups = reg.PARAMETER_INITIALIZATION_TARGETS.get(value, ())
        initialized = {r.address: r.default for r in self._registers.values() if r.group in groups and r.saved}
        # Memory-control settings "are reflected to the drive operation and saved".
        if initialized:
            self._saving.save_some(initialized)
        self._state.values[address] = value
        self._state.values.update(initialized)

    def _write_fault_history(self, address: int, value: int, now: float) -> None:
        self._state.values[address] = value
        if value:
            self._state.fault_history.clear()

    def _write_password(self, address: int, value: int, now: float) -> None:
        values = self._state.values
        previous = values[address]
        values[address] = value
        self._locks.enter(address, value, previous)

    def _write_counter_reset(self, address: int, value: int, now: float) -> None:
        self._state.values[address] = value
        if value and address == 0x03EB:
            self._state.run_seconds = 0.0
        elif value and address == 0x03EC:
            self._state.fan_seconds = 0.0
        # 0x03EA: power consumption is not simulated and reads 0 anyway.

    def _write_comm_update(self, address: int, value: int, now: float) -> None:
        # CM.94 = 1 applies CM.7 and CM.10-CM.24 and restarts the card's communication (ACG-ET2 manual);
        # it reads back 0 (NO), ready for the next update.
        if value == 1:
            self._comm.apply()
        self._state.values[address] = 0

    def _write_instance_setting(self, address: int, value: int, now: float) -> None:
        # CM.30/CM.50 are "automatically set according to the CIP Input/Output Instance": the
        # Parameter Number column of the CM.23/CM.24 tables (ACG-ET2 manual).
        values = self._state.values
        values[address] = value
        if address == self._cm23:
            count, target = reg.input_instance(value).parameters, self._cm30
        else:
            count, target = reg.output_instance(value).parameters, self._cm50
        if count is not None:
            values[target] = count

    def _write_control_parameter(self, address: int, value: int, now: float) -> None:
        # 0x0110-0x0117: the word at the address registered in CM.51-CM.58.
        index = address - reg.CONTROL_PARAMETER_BASE
        target = self._state.values[self._control_targets[index]]
        if self._registers.get(target) is None or reg.STATUS_PARAMETER_BASE <= target <= 0x01FF:
            raise RegisterError(RegisterRefusal.NO_SUCH_REGISTER, address, f"CM.{51 + index} holds 0x{target:04X}")
        self._write_through(target, value, now)


__all__ = ["RegisterEffects", "WriteHandler"]
