"""The ACG drive with its ACG-ET2 card, simulated without I/O.

Time is an argument: every method that can change the drive takes ``now`` (seconds, from any
monotonic origin); nothing here reads a clock, sleeps or opens a socket. ``advance(now)``
moves the simulation to ``now`` and ``next_deadline()`` says when it next changes on its own
(the end of a ramp segment, a lost-command timer), so an event loop can sleep until then.

Behaviour, with the table it comes from:

* Registers: ``read``/``write`` over the map of ``registers.py``; a refused write raises
  ``RegisterError`` (read-only, out of range, not writable in run).
* Command and frequency source: drv = 4 "Field Bus" takes the run command from the network,
  Frq = 8 "Field Bus" the speed reference (ACG-ET2 manual, Keypad Parameters Related to ACG-ET2).
* Run/stop: the Control Supervisor "Drive Run" table (ACG-ET2 manual, class 0x29), the common area
  operation command 0x0006 and the control area command 0x0382 (ACG RS-485 manual).
* Ramps: linear, from 0 to dr.20 Max Freq in ACC seconds and back in dEC seconds.
* Trips: the "Drive Fault Codes" table (class 0x29 attribute 13) with the trip bits of the
  monitoring words 0x0330-0x0335; Drive Fault Reset acts on a 0 -> 1 change only.
* Lost command: Pr.12/Pr.13/Pr.14 (ACG-ET2 manual, PR Group (Lost Command); ACG RS-485 manual, Command Loss
  Protective Operation).
* Parameter save: 0x03E0 from 0 to 1 (ACG RS-485 manual, Saving Parameters Defined by Communication).
* CM.94 Comm Update: CM.7 and CM.10-CM.24 take effect on the card only when it is set to 1.
* Virtual multi-function inputs: CM.70-CM.77 and 0x0385 (ACG RS-485 manual, ``virtual_inputs``).
* Command ports: a run command is obeyed when it comes in through the port drv names (4 Field
  Bus: the card; 3 Int485: the RS-485 port, ``commands_from``; 1/2 Fx/Rx: the terminals' FX/RX).

Each rule lives in one module, ``AcgDrive`` combines them: ``run_command`` (the Drive Run table,
the run/stop commands), ``ramps``, ``trips``, ``lost_command``, ``register_effects`` (what a write
does beyond storing the value: save, initialization, password, CM.94, ...), ``virtual_inputs``
(CM.70-CM.77) and ``computed`` (the monitors); this module holds the drive's state, its saved
parameters, speeds, status and register access.

The simulation has no motor or load model: output current, voltage, power, torque and the
analog inputs read 0. The monitor rpm is the synchronous speed 120 * f / poles.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from ...eip.target.limits import RateLimitedLog
from ..registers import Register, RegisterAccess, RegisterError, RegisterMap, RegisterRefusal
from ..simulation import TimedSimulation
from ..state import ParameterStore, StateFileError
from . import registers as reg
from .computed import ComputedRegisters
from .lost_command import IO_BREAK_TIME, MODBUS_SILENCE_TIME, LostCommand, LostCommandMode, _CommandLossWatch
from .ramps import Ramps
from .register_effects import RegisterEffects
from .registers import (
    ACCEL_TIME,
    ACG_REGISTERS,
    ALIASES,
    COMM_UPDATE_CODES,
    DECEL_TIME,
    MAX_FREQUENCY,
    POLE_NUMBER,
    SAVE_PARAMETERS,
    SPEED_REFERENCE,
    TARGET_FREQUENCY,
    InstanceSelection,
    WarningInformation,
)
from .run_command import (
    CommandPort,
    ControlSupervisor,
    Direction,
    DriveState,
    RunAction,
    RunCommands,
    drive_run_action,
)
from .trips import NO_FAULT, Trip, Trips
from .virtual_inputs import VirtualInputs

log = logging.getLogger(__name__)

FAMILY = "acg"
MODEL = "ACG-ET2"

#: What the drive hands a save to: every saved value (address -> raw). It may refuse the save
#: by raising ``StateFileError`` (the state file is known not to be writable).
SaveRequest = Callable[[dict[int, int]], None]

@dataclass(frozen=True)
class CommSettings:
    """The CM parameters gated by CM.94 (CM.7, CM.10-CM.24), as one consistent set."""

    station_id: int
    ip_address: str
    subnet_mask: str
    gateway: str
    speed: int
    input_setting: int
    output_setting: int

    @property
    def input_instance(self) -> InstanceSelection:
        return reg.input_instance(self.input_setting)

    @property
    def output_instance(self) -> InstanceSelection:
        return reg.output_instance(self.output_setting)

    @classmethod
    def from_values(cls, value: Callable[[str], int]) -> CommSettings:
        def dotted(first: int) -> str:
            return ".".join(str(value(f"CM.{n}")) for n in range(first, first + 4))

        return cls(value("CM.7"), dotted(10), dotted(14), dotted(18), value("CM.22"), value("CM.23"), value("CM.24"))


class AcgDrive(RunCommands, Ramps, Trips, LostCommand, RegisterEffects, VirtualInputs, ComputedRegisters,
               TimedSimulation):
    """The ACG drive behind its ACG-ET2 card, sans I/O. ``advance``/``next_deadline``: ``TimedSimulation``
    (ramps; the lost-command timers)."""

    family = FAMILY
    model = MODEL

    def __init__(self, saved: Mapping[int, int] | None = None, *, now: float = 0.0, password: int | None = None,
                 on_save: SaveRequest | None = None, origin: str = "saved parameters") -> None:
        """Power the drive up at ``now``: factory values, then the ``saved`` ones (a
        ``StateFileError`` naming ``origin`` if one is no saved parameter of this drive or out of
        range). Each save (0x03E0, CM.94, a parameter initialization) is handed to ``on_save``
        with every saved value: the drive does no file I/O itself. ``on_save`` refuses a save by
        raising ``StateFileError``; the write is then refused and nothing is saved."""
        self.registers: RegisterMap = ACG_REGISTERS
        self.on_save = on_save
        #: Saves refused while the drive runs: a line at most once per 10 s, with a count.
        self._save_refused_log = RateLimitedLog(log)
        self._time = now
        self._start_time = now
        #: Password of 0x03E7/0x03E8 (registered from the keypad; None: none registered).
        self._password = password
        self._values: dict[int, int] = {a: r.default for a, r in self.registers.items() if a not in ALIASES}
        self._saved: dict[int, int] = {}
        if saved:
            self._restore(saved, origin)
        self._active_comm = {code: self._value(code) for code in COMM_UPDATE_CODES}
        self.control_supervisor = ControlSupervisor()
        # Run state.
        self._command: Direction | None = None
        self._output_hz = 0.0           # signed: forward > 0, reverse < 0
        self._output_on = False
        self._trip: Trip | None = None
        self._level_causes: set[Trip] = set()
        self._warnings = WarningInformation(0)
        self.fault_history: list[Trip] = []
        # Lost command.
        self._io_watch = _CommandLossWatch(IO_BREAK_TIME)
        self._modbus_watch = _CommandLossWatch(MODBUS_SILENCE_TIME)
        self._int485_watch = _CommandLossWatch(None, CommandPort.INT485)
        #: The port the present write came in through (``commands_from``); the card's by default.
        self.command_port = CommandPort.FIELDBUS
        self._lost_reference: float | None = None  # Hz held by Hold Input/Hold Output/Lost Preset
        # Virtual multi-function inputs: the functions closed, and what FX/RX last commanded.
        self._closed_functions: frozenset[int] = frozenset()
        self._virtual_command: Direction | None = None
        # Memory control.
        self._hide_locked = False
        self._parameter_locked = False
        self._run_seconds = 0.0
        self._fan_seconds = 0.0
        self._computed = self._computed_registers()

    @classmethod
    def with_state_file(cls, path: str | os.PathLike[str], *, now: float = 0.0,
                        password: int | None = None) -> AcgDrive:
        """A drive that keeps its saved parameters in ``path`` (see ``state.default_state_path``),
        writing each save at once on the caller's thread: for scripts and tests. An emulator
        writes them off its event loop (``build_acg_device``, ``state.StateWriter``)."""
        store = ParameterStore(path, FAMILY, MODEL)
        return cls(store.load(), now=now, password=password, on_save=store.save, origin=str(store.path))

    # -----------------------------------------------------------------------------------------
    # Saved parameters
    # -----------------------------------------------------------------------------------------

    def _restore(self, saved: Mapping[int, int], origin: str) -> None:
        for address, value in saved.items():
            register = self.registers.get(address)
            if register is None or not register.saved or address in ALIASES:
                raise StateFileError(f"{origin}: 0x{address:04X} is not a saved parameter of the {self.model}")
            try:
                register.check(value)
            except RegisterError as exc:
                raise StateFileError(f"{origin}: {exc}") from None
            self._values[address] = value
        self._saved = dict(saved)

    @property
    def saved_parameters(self) -> dict[int, int]:
        """What a power cycle comes back with (address -> raw value), beyond the defaults."""
        return dict(self._saved)

    def forget_saved_parameters(self) -> None:
        """Identity Reset type 1: the saved values go, so the next power-up is at the factory values. A
        save the shell refuses (``StateFileError``) refuses this too, and nothing changes."""
        if self.on_save is not None:
            self.on_save({})
        self._saved = {}

    def power_cycled(self, now: float) -> AcgDrive:
        """The drive as it comes back from a power loss at ``now``.

        Kept: the saved parameters (ACG RS-485 manual, "Saving Parameters Defined by Communication": "Parameter
        SET via Communications + SAVED + Power Cycle = Parameters holds saved value"), and what the
        drive memory control area sets, since "when setting parameters in the drive memory control
        area, the values are reflected to the drive operation and saved" (ACG RS-485 manual, 0x03E0-0x03EC):
        the accumulated times it initializes (0x03EB run time, 0x03EC fan time; the On Time of
        0x0340/0x0341 is the "total number of days the drive has been powered on", so it goes on
        from where it was), the fault history it deletes (0x03E5) and the locks of the password
        (0x03E7/0x03E8); the keypad's password itself.

        Lost: every value written and not saved ("NOT Saved + Power Cycle = Parameters reverts back
        to previous setting"; the frequency of 0x0380 even when saved, ACG RS-485 manual), the run command
        and the output (0 Hz: the motor coasts), the trip present (the ACG manuals say nothing of a trip
        across a power cycle: the drive starts without it, and the fault history keeps it), the
        lost-command watches and the virtual inputs (0x0385) and CM.94's pending settings."""
        self.advance(max(now, self._time))
        drive = AcgDrive(self._saved, now=now, password=self._password, on_save=self.on_save)
        drive._start_time = now - self._on_seconds()
        drive._run_seconds, drive._fan_seconds = self._run_seconds, self._fan_seconds
        drive.fault_history = list(self.fault_history)
        drive._hide_locked, drive._parameter_locked = self._hide_locked, self._parameter_locked
        return drive

    def save_parameters(self) -> None:
        """Save every keypad parameter as it is now (what 0x03E0 0 -> 1 does)."""
        self._persist({a: self._values[a] for a, r in self.registers.items() if r.saved and a not in ALIASES})

    def _save_some(self, values: Mapping[int, int]) -> None:
        """Save these values (address -> raw) on top of the saved ones."""
        self._persist({**self._saved, **values})

    def _persist(self, saved: dict[int, int]) -> None:
        """Hand a save to the shell; refused (``RegisterError`` SAVE_FAILED), nothing is saved."""
        if self.on_save is not None:
            try:
                self.on_save(dict(saved))
            except StateFileError as exc:
                raise RegisterError(RegisterRefusal.SAVE_FAILED, SAVE_PARAMETERS.address, str(exc)) from None
        self._saved = saved

    # -----------------------------------------------------------------------------------------
    # Time
    # -----------------------------------------------------------------------------------------

    @property
    def time(self) -> float:
        return self._time

    def power_up_at(self, now: float) -> None:
        """Place the power-up instant of a drive built before its shell's clock was known; only
        before anything has moved it."""
        if self._time != self._start_time:
            raise RuntimeError("the drive has already run: its power-up time is fixed")
        self._time = self._start_time = now

    @property
    def password(self) -> int | None:
        """The password of 0x03E7/0x03E8 registered from the keypad (None: none)."""
        return self._password

    def _run_until(self, moment: float) -> None:
        if self._output_on:  # off, nothing ramps and nothing counts (``_segment``, ``_ramp``)
            self._ramp(max(0.0, moment - self._time))
        self._time = moment

    def advance_to(self, now: float) -> float | None:
        # The shell's call before every request. At rest (the stopped drive of most explicit
        # traffic) nothing ramps, counts or times out: moving on is the clock alone, which is all
        # ``_run_until`` does with the output off, and there is no deadline.
        if self._at_rest():
            if now > self._time:
                self._time = now
            return None
        return super().advance_to(now)

    def _at_rest(self) -> bool:
        # Output off: no ramp and no run-time counting (``_run_until``); no command-loss watch
        # running: no timer (``_timer_deadline``). The stopped drive of most explicit traffic.
        return (not self._output_on and self._io_watch.silent_since is None
                and self._modbus_watch.silent_since is None and self._int485_watch.silent_since is None)

    # -----------------------------------------------------------------------------------------
    # Speeds
    # -----------------------------------------------------------------------------------------

    def _max_hz(self) -> float:
        return self._values[MAX_FREQUENCY.address] / 100

    def _reference_hz(self) -> float:
        if self._lost_reference is not None:
            reference = self._lost_reference
        elif self.reference_from_net or self.reference_from_int485:
            # Both communication sources set the frequency command of 0x0005 / 0x0380 (ACG RS-485 manual).
            reference = self._values[SPEED_REFERENCE.address] / 100
        else:
            reference = self._values[TARGET_FREQUENCY.address] / 100
        return min(reference, self._max_hz())

    @property
    def poles(self) -> int:
        return self._values[POLE_NUMBER.address]

    def hz_to_rpm(self, hz: float) -> int:
        """Synchronous speed: 120 * f / poles."""
        return round(120 * hz / self.poles)

    def rpm_to_centihertz(self, rpm: int) -> int:
        return round(rpm * self.poles * 100 / 120)

    @property
    def output_frequency(self) -> int:
        """Output frequency in 0.01 Hz (class 0x2A attribute 100, 0x000A, 0x0311)."""
        return round(abs(self._output_hz) * 100)

    @property
    def output_frequency_signed(self) -> float:
        return self._output_hz

    @property
    def speed_reference(self) -> int:
        """The speed reference in use, 0.01 Hz."""
        return round(self._reference_hz() * 100)

    @property
    def speed_actual_rpm(self) -> int:
        """Class 0x2A attribute 7: the output speed in rpm."""
        return self.hz_to_rpm(abs(self._output_hz))

    @property
    def speed_reference_rpm(self) -> int:
        """Class 0x2A attribute 8: the reference in rpm."""
        return self.hz_to_rpm(self._reference_hz())

    @property
    def accel_time(self) -> int:
        """ACC in 0.1 s (class 0x2A attribute 102)."""
        return self._values[ACCEL_TIME.address]

    @property
    def decel_time(self) -> int:
        """dEC in 0.1 s (class 0x2A attribute 103)."""
        return self._values[DECEL_TIME.address]

    # -----------------------------------------------------------------------------------------
    # Status
    # -----------------------------------------------------------------------------------------

    @property
    def running(self) -> bool:
        """The output is on: running, or decelerating to a stop."""
        return self._output_on

    def _direction(self) -> Direction | None:
        if not self._output_on:
            return None
        if self._output_hz != 0:
            return Direction.FORWARD if self._output_hz > 0 else Direction.REVERSE
        return self._command

    @property
    def running_forward(self) -> bool:
        """Class 0x29 attribute 7."""
        return self._direction() is Direction.FORWARD

    @property
    def running_reverse(self) -> bool:
        """Class 0x29 attribute 8."""
        return self._direction() is Direction.REVERSE

    @property
    def ready(self) -> bool:
        """Class 0x29 attribute 9: 0 while a trip is active."""
        return self._trip is None

    @property
    def drive_state(self) -> DriveState:
        """Class 0x29 attribute 6. Startup and Not Ready (resetting) pass in no time here."""
        if self._trip is not None:
            return DriveState.FAULT_STOP
        if self._output_on and self._command is not None:
            return DriveState.ENABLED
        if self._output_on:
            return DriveState.STOPPING
        return DriveState.READY

    @property
    def at_reference(self) -> bool:
        """Class 0x2A attribute 3: running, and the output frequency has reached the reference."""
        return (self._output_on and self._command is not None and self._trip is None
                and self._output_hz == self._target_hz())

    @property
    def accelerating(self) -> bool:
        segment = self._segment()
        return segment is not None and segment[1] and self._trip is None

    @property
    def decelerating(self) -> bool:
        segment = self._segment()
        return segment is not None and not segment[1]

    # -----------------------------------------------------------------------------------------
    # CM.94 Comm Update: pending and active communication settings
    # -----------------------------------------------------------------------------------------

    def _value(self, code: str) -> int:
        return self._values[self.registers.by_code(code).address]

    @property
    def active_comm_settings(self) -> CommSettings:
        """The settings the card runs with: those of the last CM.94 update (or of power-up)."""
        return CommSettings.from_values(self._active_comm.__getitem__)

    @property
    def pending_comm_settings(self) -> CommSettings:
        """The CM parameters as written, which CM.94 = 1 would make active."""
        return CommSettings.from_values(self._value)

    @property
    def comm_update_pending(self) -> bool:
        """CM parameters changed without CM.94: the card's error LED flashes red every 2 s."""
        return any(self._value(code) != self._active_comm[code] for code in COMM_UPDATE_CODES)

    @property
    def status_parameter_addresses(self) -> tuple[int, ...]:
        """CM.31.. up to CM.30 of them: what assemblies 141-148 carry."""
        count = self._value("CM.30")
        return tuple(self._value(f"CM.{31 + i}") for i in range(count))

    @property
    def control_parameter_addresses(self) -> tuple[int, ...]:
        """CM.51.. up to CM.50 of them: what assemblies 121-128 carry."""
        count = self._value("CM.50")
        return tuple(self._value(f"CM.{51 + i}") for i in range(count))

    def _comm_update(self) -> None:
        # "This action will prevent any data loss from a drive power loss": the CM group is saved.
        self._save_some({r.address: self._values[r.address] for r in self.registers.group("CM") if r.saved})
        self._active_comm = {code: self._value(code) for code in COMM_UPDATE_CODES}

    # -----------------------------------------------------------------------------------------
    # Register access
    # -----------------------------------------------------------------------------------------

    def register(self, address: int) -> Register:
        try:
            return self.registers[address]
        except KeyError:
            raise RegisterError(RegisterRefusal.NO_SUCH_REGISTER, address) from None

    def read(self, address: int) -> int:
        """The raw value of one register (signed for INT registers), as of the last ``advance``."""
        self.register(address)
        address = ALIASES.get(address, address)
        compute = self._computed.get(address)
        return compute() if compute is not None else self._values[address]

    def write(self, address: int, value: int, now: float) -> None:
        """Write one register as a network client does, or raise ``RegisterError``."""
        register = self.register(address)
        self.advance(now)
        if register.access is RegisterAccess.READ:
            raise RegisterError(RegisterRefusal.READ_ONLY, address)
        register.check(value)
        if register.access is RegisterAccess.WRITE_STOPPED and self._output_on:
            if address == SAVE_PARAMETERS.address and value == 1:
                # The writer gets an error status; whoever runs the emulator should see it too.
                self._save_refused_log("parameter save refused (0x03E0 = 1 while the drive runs): nothing saved",
                                       now=now)
            raise RegisterError(RegisterRefusal.NOT_WHILE_RUNNING, address)
        if self._parameter_locked and register.group in reg.KEYPAD_GROUPS:
            raise RegisterError(RegisterRefusal.READ_ONLY, address, "parameters are locked (0x03E8)")
        target = ALIASES.get(address, address)
        handler = self._write_handlers.get(target)
        if handler is not None:
            handler(self, target, value, now)
        else:
            self._values[target] = value
        self._ramp(0.0)  # a 0 s ramp time takes effect at once

    def _check_frequency(self, address: int, value: int) -> None:
        if value > self._values[MAX_FREQUENCY.address]:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, address,
                                f"{value / 100:.2f} Hz above dr.20 Max Freq "
                                f"{self._values[MAX_FREQUENCY.address] / 100:.2f} Hz")

__all__ = [
    "FAMILY",
    "IO_BREAK_TIME",
    "MODBUS_SILENCE_TIME",
    "MODEL",
    "NO_FAULT",
    "AcgDrive",
    "CommSettings",
    "CommandPort",
    "ControlSupervisor",
    "Direction",
    "DriveState",
    "LostCommandMode",
    "RunAction",
    "Trip",
    "drive_run_action",
]
