"""Register side effects: run and frequency commands, parameter save and initialization, password,
counters, CM.94 and the smart-scaling words (ACG RS-485 manual control and memory control areas; ACG-ET2 manual)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from ..registers import RegisterError, RegisterRefusal
from . import registers as reg
from .registers import (
    ACG_REGISTERS,
    COMM_UPDATE,
    LOST_PRESET_FREQ,
    SAVE_PARAMETERS,
    SPEED_REFERENCE,
    TARGET_FREQUENCY,
    ControlCommand,
    OperationCommand,
)
from .run_command import Direction
from .trips import Trip
from .virtual_inputs import (
    TERMINAL_FUNCTION_ADDRESSES,
    VIRTUAL_FUNCTION_ADDRESSES,
    VIRTUAL_INPUT_CONTROL,
    VirtualInputs,
)


class RegisterEffects:
    """What writing a register does beyond storing it, by the address that holds the value (part of
    ``AcgDrive``)."""

    def _write_frequency(self, address: int, value: int, now: float) -> None:
        self._check_frequency(address, value)
        self._values[address] = value

    def _write_lost_preset(self, address: int, value: int, now: float) -> None:
        # Pr.14: 0.05-60.00, or the table's default 0.00 (ACG-ET2 manual; registers.LOST_PRESET_FREQ).
        if 0 < value < reg.LOST_PRESET_MINIMUM:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, address,
                                f"{value / 100:.2f} Hz below the lowest Lost Preset F, 0.05 Hz (0.00: none)")
        self._write_frequency(address, value, now)

    def _write_rpm_command(self, address: int, value: int, now: float) -> None:
        centihertz = self.rpm_to_centihertz(value)
        if centihertz > SPEED_REFERENCE.raw_maximum:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, address, f"{value} rpm above 400.00 Hz")
        self._check_frequency(address, centihertz)
        self._values[SPEED_REFERENCE.address] = centihertz

    def set_speed_reference_rpm(self, rpm: int, now: float) -> None:
        """Class 0x2A attribute 8 SpeedRef (0-24000 rpm): the network reference, in rpm."""
        if not 0 <= rpm <= 24000:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, 0x0381, f"{rpm} rpm not in 0..24000")
        self.write(0x0381, rpm, now)

    def set_speed_reference(self, centihertz: int, now: float) -> None:
        """Class 0x2A attribute 101 Reference Hz: the network reference, in 0.01 Hz."""
        self.write(SPEED_REFERENCE.address, centihertz, now)

    def _write_operation_command(self, address: int, value: int, now: float) -> None:
        # Common area 0x0006 (ACG RS-485 manual): B0 stop, B1 forward, B2 reverse, B3 trip reset on 0 -> 1,
        # B4 emergency stop (the BX level trip while it is set).
        previous = OperationCommand(self._values[address] & 0x1F)
        bits = OperationCommand(value & 0x1F)
        self._values[address] = int(bits)
        if OperationCommand.TRIP_RESET in bits and OperationCommand.TRIP_RESET not in previous:
            self._fault_reset()
        self._set_level_cause(Trip.BX, self._emergency_stop())   # B4, or a closed virtual BX input
        if not self._port_commands():
            return
        run_bits = bits & (OperationCommand.STOP | OperationCommand.FORWARD | OperationCommand.REVERSE)
        if OperationCommand.STOP in run_bits:
            self._stop()
        elif run_bits == OperationCommand.FORWARD:
            self._run(Direction.FORWARD)
        elif run_bits == OperationCommand.REVERSE:
            self._run(Direction.REVERSE)

    def _write_control_command(self, address: int, value: int, now: float) -> None:
        # Control area 0x0382 (ACG RS-485 manual): B0 run/stop, B1 forward/reverse, B2 trip reset on
        # 0 -> 1, B3 free-run stop on 0 -> 1. Forward run is 0x0003, reverse run 0x0001.
        previous = ControlCommand(self._values[address] & 0x0F)
        bits = ControlCommand(value & 0x0F)
        self._values[address] = value
        rising = bits & ~previous
        if ControlCommand.TRIP_RESET in rising:
            self._fault_reset()
        if not self._port_commands():
            return
        if ControlCommand.FREE_RUN_STOP in rising:
            self._free_run()
        elif ControlCommand.RUN in bits:
            self._run(Direction.FORWARD if ControlCommand.FORWARD in bits else Direction.REVERSE)
        else:
            self._stop()

    def _write_save(self, address: int, value: int, now: float) -> None:
        # "Setting address 0h03E0 to 0 and then setting it again to 1 ... allows the existing
        # parameter settings to be saved. However, setting 0h03E0 to 1 and then setting it to 0
        # does not carry out the same function." (ACG RS-485 manual)
        # A refused save (the state file cannot be written) leaves 0x03E0 as it was.
        if self._values[address] == 0 and value == 1:
            self.save_parameters()
        self._values[address] = value

    def _write_parameter_initialization(self, address: int, value: int, now: float) -> None:
        if self._trip is not None:
            raise RegisterError(RegisterRefusal.NOT_WHILE_RUNNING, address,
                                "parameter initialization is prohibited during a fault trip")
        groups = reg.PARAMETER_INITIALIZATION_TARGETS.get(value, ())
        initialized = {r.address: r.default for r in self.registers.values() if r.group in groups and r.saved}
        # Memory-control settings "are reflected to the drive operation and saved".
        if initialized:
            self._save_some(initialized)
        self._values[address] = value
        self._values.update(initialized)

    def _write_fault_history(self, address: int, value: int, now: float) -> None:
        self._values[address] = value
        if value:
            self.fault_history.clear()

    def _write_password(self, address: int, value: int, now: float) -> None:
        # 0x03E7/0x03E8: entering the password toggles Lock/Unlock; the same value entered again
        # in a row executes once only (ACG RS-485 manual).
        previous = self._values[address]
        self._values[address] = value
        if value == previous or self._password is None or value != self._password:
            return
        if address == 0x03E7:
            self._hide_locked = not self._hide_locked
        else:
            self._parameter_locked = not self._parameter_locked

    def _write_counter_reset(self, address: int, value: int, now: float) -> None:
        self._values[address] = value
        if value and address == 0x03EB:
            self._run_seconds = 0.0
        elif value and address == 0x03EC:
            self._fan_seconds = 0.0
        # 0x03EA: power consumption is not simulated and reads 0 anyway.

    def _write_comm_update(self, address: int, value: int, now: float) -> None:
        # CM.94 = 1 applies CM.7 and CM.10-CM.24 and restarts the card's communication (ACG-ET2 manual);
        # it reads back 0 (NO), ready for the next update.
        if value == 1:
            self._comm_update()
        self._values[address] = 0

    def _write_instance_setting(self, address: int, value: int, now: float) -> None:
        # CM.30/CM.50 are "automatically set according to the CIP Input/Output Instance": the
        # Parameter Number column of the CM.23/CM.24 tables (ACG-ET2 manual).
        self._values[address] = value
        if address == self.registers.by_code("CM.23").address:
            count, target = reg.input_instance(value).parameters, "CM.30"
        else:
            count, target = reg.output_instance(value).parameters, "CM.50"
        if count is not None:
            self._values[self.registers.by_code(target).address] = count

    def _write_control_parameter(self, address: int, value: int, now: float) -> None:
        # 0x0110-0x0117: the word at the address registered in CM.51-CM.58.
        target = self._value(f"CM.{51 + address - reg.CONTROL_PARAMETER_BASE}")
        if self.registers.get(target) is None or reg.STATUS_PARAMETER_BASE <= target <= 0x01FF:
            raise RegisterError(RegisterRefusal.NO_SUCH_REGISTER, address,
                                f"CM.{51 + address - reg.CONTROL_PARAMETER_BASE} holds 0x{target:04X}")
        self.write(target, value, now)

    _write_handlers: Mapping[int, Callable[[Any, int, int, float], None]] = {
        SPEED_REFERENCE.address: _write_frequency,
        TARGET_FREQUENCY.address: _write_frequency,
        LOST_PRESET_FREQ.address: _write_lost_preset,
        0x0381: _write_rpm_command,
        0x0006: _write_operation_command,
        0x0382: _write_control_command,
        SAVE_PARAMETERS.address: _write_save,
        0x03E2: _write_parameter_initialization,
        0x03E5: _write_fault_history,
        0x03E7: _write_password,
        0x03E8: _write_password,
        0x03EA: _write_counter_reset,
        0x03EB: _write_counter_reset,
        0x03EC: _write_counter_reset,
        COMM_UPDATE.address: _write_comm_update,
        ACG_REGISTERS.by_code("CM.23").address: _write_instance_setting,
        ACG_REGISTERS.by_code("CM.24").address: _write_instance_setting,
        **dict.fromkeys(range(reg.CONTROL_PARAMETER_BASE, reg.CONTROL_PARAMETER_BASE + 8), _write_control_parameter),
        VIRTUAL_INPUT_CONTROL: VirtualInputs._write_virtual_inputs,
        **dict.fromkeys((*VIRTUAL_FUNCTION_ADDRESSES, *TERMINAL_FUNCTION_ADDRESSES),
                        VirtualInputs._write_input_function),
    }
