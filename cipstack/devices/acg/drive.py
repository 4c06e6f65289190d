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

Each rule lives in one component over one state (``state.AcgState``: values, output, command,
trip, watches), given at construction the state and the register map it needs: ``ramps.Ramp``,
``trips.TripLog``, ``run_command.RunControl`` (the run/stop commands; ``ControlSupervisor`` holds the
Drive Run table's inputs), ``lost_command.CommandLossWatches``, ``virtual_inputs.VirtualInputs``
(CM.70-CM.77), ``memory`` (saved parameters, password locks), ``comm_update.CommUpdate`` (CM.94),
``register_effects.RegisterEffects`` (what a write does beyond storing the value) and
``computed.ComputedRegisters`` (the monitors, and every register's read). ``AcgDrive`` composes them
and holds the drive's public interface: time, speeds, status and register access.

The simulation has no motor or load model: output current, power, torque, the inverter temperature
and the analog inputs read 0 (the registers say ``simulated=False``). The output voltage is a V/f line
and the DC link the rectified input (``computed``). The monitor rpm is the synchronous speed
120 * f / poles.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

from ...eip.target.limits import RateLimitedLog
from ...errors import WrongState
from ..registers import Register, RegisterAccess, RegisterError, RegisterMap, RegisterRefusal
from ..simulation import TimedSimulation
from ..state import ParameterStore
from . import registers as reg
from .comm_update import CommSettings, CommUpdate
from .computed import ComputedRegisters
from .lost_command import IO_BREAK_TIME, MODBUS_SILENCE_TIME, CommandLossWatches, LostCommandMode
from .memory import PasswordLocks, SavedParameters, SaveRequest
from .ramps import Ramp
from .register_effects import RegisterEffects
from .registers import (
    ACCEL_TIME,
    ACG_REGISTERS,
    ALIASES,
    CMD_SOURCE,
    CMD_SOURCE_FIELDBUS,
    CMD_SOURCE_INT485,
    DECEL_TIME,
    FREQ_REF_SOURCE,
    FREQ_REF_SOURCE_FIELDBUS,
    FREQ_REF_SOURCE_INT485,
    SAVE_PARAMETERS,
    SPEED_REFERENCE,
)
from .run_command import (
    CommandPort,
    ControlSupervisor,
    Direction,
    DriveState,
    RunAction,
    RunControl,
    drive_run_action,
)
from .state import AcgState
from .status_words import WarningInformation
from .trips import NO_FAULT, Trip, TripLog
from .virtual_inputs import VirtualInputs

log = logging.getLogger(__name__)

FAMILY = "acg"
MODEL = "ACG-ET2"

_CMD_SOURCE = CMD_SOURCE.address
_FREQ_REF_SOURCE = FREQ_REF_SOURCE.address
_SPEED_REFERENCE_ADDRESS = SPEED_REFERENCE.address


class AcgDrive(TimedSimulation):
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
        registers: RegisterMap = ACG_REGISTERS
        self.registers = registers
        #: Saves refused while the drive runs: a line at most once per 10 s, with a count.
        self._save_refused_log = RateLimitedLog(log)
        values = {a: r.default for a, r in registers.items() if a not in ALIASES}
        self._saving = SavedParameters(registers, on_save)
        if saved:
            self._saving.restore(saved, values, origin, self.model)
        state = self._state = AcgState(values, now)
        self._locks = PasswordLocks(password)
        self._comm = CommUpdate(registers, values, self._saving)
        self.control_supervisor = ControlSupervisor()
        ramp = self._ramp = Ramp(state)
        trips = self._trips = TripLog(state, ramp)
        run = self._run = RunControl(state, ramp)
        self._watches = CommandLossWatches(state, ramp, trips)
        self._virtual_inputs = VirtualInputs(state, registers, trips, run)
        self._effects = RegisterEffects(state, registers, trips=trips, run=run, virtual_inputs=self._virtual_inputs,
                                        saving=self._saving, comm=self._comm, locks=self._locks,
                                        write_through=self.write)
        self._computed = ComputedRegisters(state, registers, ramp, self._locks)
        #: Register writes tried so far, by any client (``write``): part of ``command_mark``.
        self._writes = 0

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

    @property
    def on_save(self) -> SaveRequest | None:
        """Where each save is handed (the shell: a state file, its writer); None: kept in memory."""
        return self._saving.on_save

    @property
    def saved_parameters(self) -> dict[int, int]:
        """What a power cycle comes back with (address -> raw value), beyond the defaults."""
        return dict(self._saving.saved)

    def forget_saved_parameters(self) -> None:
        """Identity Reset type 1: the saved values go, so the next power-up is at the factory values. A
        save the shell refuses (``StateFileError``) refuses this too, and nothing changes."""
        self._saving.forget()

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
        self.advance(max(now, self._state.time))
        drive = AcgDrive(self._saving.saved, now=now, password=self._locks.password, on_save=self._saving.on_save)
        before, after = self._state, drive._state
        after.start_time = now - before.on_seconds()
        after.run_seconds, after.fan_seconds = before.run_seconds, before.fan_seconds
        after.fault_history = list(before.fault_history)
        drive._locks.hide_locked, drive._locks.parameter_locked = self._locks.hide_locked, self._locks.parameter_locked
        return drive

    def keep_keypad_entries(self, addresses: list[int]) -> None:
        """The values at ``addresses`` were entered on the keypad: a power cycle keeps them
        (``memory.SavedParameters.keep``)."""
        values = self._state.values
        self._saving.keep({address: values[address] for address in addresses if address in values})

    def save_parameters(self) -> None:
        """Save every keypad parameter as it is now (what 0x03E0 0 -> 1 does)."""
        self._saving.save_all(self._state.values)

    # -----------------------------------------------------------------------------------------
    # Time
    # -----------------------------------------------------------------------------------------

    @property
    def time(self) -> float:
        return self._state.time

    def power_up_at(self, now: float) -> None:
        """Place the power-up instant of a drive built before its shell's clock was known; only
        before anything has moved it."""
        state = self._state
        if state.time != state.start_time:
            raise WrongState("the drive has already run: its power-up time is fixed")
        state.time = state.start_time = now

    @property
    def password(self) -> int | None:
        """The password of 0x03E7/0x03E8 registered from the keypad (None: none)."""
        return self._locks.password

    def _timer_deadline(self) -> float | None:
        return self._watches.deadline()

    def _fire_timers(self, moment: float) -> None:
        self._watches.fire(moment)

    def _run_until(self, moment: float) -> None:
        state = self._state
        if state.output_on:  # off, nothing ramps and nothing counts (``Ramp.run``)
            self._ramp.run(max(0.0, moment - state.time))
        state.time = moment

    def _ramp_deadline(self) -> float | None:
        return self._ramp.deadline()

    def advance(self, now: float) -> None:
        # At rest (``_at_rest``) moving on is the clock alone: called several times per request and
        # per O->T datagram, it skips the timer and ramp steps that would find nothing to do.
        state = self._state
        if state.output_on or now < state.time or not state.at_rest():
            TimedSimulation.advance(self, now)   # ramps, timers; or the error for a time gone backwards
        else:
            state.time = now

    def advance_to(self, now: float) -> float | None:
        # The shell's call before every request. At rest (the stopped drive of most explicit
        # traffic) nothing ramps, counts or times out: moving on is the clock alone, which is all
        # ``_run_until`` does with the output off, and there is no deadline.
        state = self._state
        if state.at_rest():
            if now > state.time:
                state.time = now
            return None
        return super().advance_to(now)

    def _at_rest(self) -> bool:
        # Output off: no ramp and no run-time counting (``_run_until``); no command-loss watch
        # running: no timer (``_timer_deadline``). The stopped drive of most explicit traffic.
        return self._state.at_rest()

    # -----------------------------------------------------------------------------------------
    # Commands
    # -----------------------------------------------------------------------------------------

    @property
    def command_port(self) -> CommandPort:
        """The port the present write came in through (``commands_from``); the card's by default."""
        return self._state.command_port

    @command_port.setter
    def command_port(self, port: CommandPort) -> None:
        self._state.command_port = port

    @contextmanager
    def commands_from(self, port: CommandPort) -> Iterator[None]:
        """Writes made inside come in through ``port``: a run command in them is obeyed when drv is
        that port's command source (``CommandPort``). Outside, writes are the card's. (A request path
        may set ``command_port`` itself and put the previous one back, as ``commands_from`` does.)"""
        state = self._state
        previous, state.command_port = state.command_port, port
        try:
            yield
        finally:
            state.command_port = previous

    @property
    def control_from_int485(self) -> bool:
        """drv is 3 (Int485): the built-in RS-485 port commands run and stop."""
        return self._state.values[_CMD_SOURCE] == CMD_SOURCE_INT485

    @property
    def reference_from_int485(self) -> bool:
        """Frq is 6 (Int485): the built-in RS-485 port sets the speed reference."""
        return self._state.values[_FREQ_REF_SOURCE] == FREQ_REF_SOURCE_INT485

    @property
    def control_from_net(self) -> bool:
        """Class 0x29 attribute 14: drv is 4 (Field Bus)."""
        return self._state.values[_CMD_SOURCE] == CMD_SOURCE_FIELDBUS

    @property
    def reference_from_net(self) -> bool:
        """Class 0x2A attribute 29: Frq is 8 (Field Bus)."""
        return self._state.values[_FREQ_REF_SOURCE] == FREQ_REF_SOURCE_FIELDBUS

    def set_run_command(self, forward: bool, reverse: bool, now: float) -> RunAction:
        """Forward and Reverse Run Cmd (class 0x29 attributes 3 and 4) written together, as an
        output assembly does; returns what the Drive Run table made of it. The card keeps the
        values whatever the command source; the drive acts on them only when drv is Field Bus."""
        self.advance(now)
        action = self.control_supervisor.update_run(bool(forward), bool(reverse))
        if self._state.values[_CMD_SOURCE] == CMD_SOURCE_FIELDBUS:
            self._run.apply(action)
            self._ramp.run(0.0)
        return action

    def command_mark(self) -> tuple[object, ...]:
        """What applying an output assembly's commands again would read or change: the card's command
        values (Forward/Reverse Run Cmd, Drive Fault Reset), the command source, the command the drive
        obeys, its trip, the speed reference, and the count of register writes (a write of any register
        may change what a speed reference converts to or whether it is accepted). While the mark and
        the data are what they were right after the last application, applying the same data again
        changes nothing: a held run bit is No Action, a held fault reset no edge, a stop with no command
        nothing, the same reference the same value. Time alone moves none of these but to stop the
        drive (a trip, the end of a stop), which a repeated stop or a held run leaves as it is."""
        supervisor, state = self.control_supervisor, self._state
        values = state.values
        return (self._writes, supervisor.run_forward, supervisor.run_reverse, supervisor.fault_reset,
                values[_CMD_SOURCE], state.command, state.trip, values[_SPEED_REFERENCE_ADDRESS])

    def status_mark(self) -> tuple[object, ...]:
        """What the speed input assemblies (70/71/110/111) are made of: ``command_mark``, the output
        (on, frequency), a lost-command reference and the reference source. Equal marks, equal inputs."""
        state = self._state
        return (self.command_mark(), state.output_on, state.output_hz, state.lost_reference,
                state.values[_FREQ_REF_SOURCE])

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
            return self._trips.reset()
        return False

    def local_command(self, direction: Direction | None, now: float) -> None:
        """Run or stop from the keypad or terminals, which the drive obeys when drv is not Field Bus."""
        self.advance(now)
        if self.control_from_net:
            return
        if direction is None:
            self._run.stop()
        else:
            self._run.run(direction)
        self._ramp.run(0.0)

    def fault_reset(self, now: float) -> bool:
        """A fault reset at ``now`` from outside the network (the test rig's): what a rising edge of
        Drive Fault Reset does. Whether a trip was cleared."""
        self.advance(now)
        return self._trips.reset()

    def set_speed_reference_rpm(self, rpm: int, now: float) -> None:
        """Class 0x2A attribute 8 SpeedRef (0-24000 rpm): the network reference, in rpm."""
        if not 0 <= rpm <= 24000:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, 0x0381, f"{rpm} rpm not in 0..24000")
        self.write(0x0381, rpm, now)

    def set_speed_reference(self, centihertz: int, now: float) -> None:
        """Class 0x2A attribute 101 Reference Hz: the network reference, in 0.01 Hz."""
        self.write(SPEED_REFERENCE.address, centihertz, now)

    # -----------------------------------------------------------------------------------------
    # Trips and lost command
    # -----------------------------------------------------------------------------------------

    def inject_trip(self, trip: Trip | int, now: float) -> Trip:
        """Trip the drive as if ``trip`` occurred (a Trip, or a fault code of the table: the
        first trip listed under it). The output is cut (free-run); a Fault Reset clears it."""
        self.advance(now)
        if not isinstance(trip, Trip):
            trip = Trip.from_fault_code(trip)
        self._trips.trip(trip)
        return trip

    @property
    def trip(self) -> Trip | None:
        return self._state.trip

    @property
    def faulted(self) -> bool:
        """Class 0x29 attribute 10."""
        return self._state.trip is not None

    @property
    def fault_code(self) -> int:
        """Class 0x29 attribute 13: the Drive Fault Codes table value of the present trip."""
        trip = self._state.trip
        return NO_FAULT if trip is None else trip.fault_code

    @property
    def fault_history(self) -> list[Trip]:
        """Every trip that occurred, oldest first (0x03E5 deletes it)."""
        return self._state.fault_history

    @property
    def warnings(self) -> WarningInformation:
        return self._state.warnings

    @property
    def warning(self) -> bool:
        """A warning is active (0x0305 B12-B15 = 4). Class 0x29 attribute 11 is "Not supported"."""
        return bool(self._state.warnings)

    def on_io_connection_lost(self, now: float) -> None:
        """The class 1 connection broke (timed out or closed)."""
        self.advance(now)
        self._watches.connection_lost(now)

    def on_io_connection_opened(self, now: float) -> None:
        """A class 1 connection is open and producing again: communication has returned."""
        self.advance(now)
        self._watches.connection_opened()

    def on_modbus_activity(self, now: float, port: CommandPort = CommandPort.FIELDBUS) -> None:
        """A Modbus request arrived: on the card (Modbus TCP; from the first one on, 5 s of silence
        is a command loss) or, ``port`` INT485, on the built-in RS-485 (Pr.13 of silence is)."""
        self.advance(now)
        self._watches.activity(now, port)

    @property
    def command_lost(self) -> bool:
        """The drive is in lost command mode on some protocol."""
        return self._watches.lost

    # -----------------------------------------------------------------------------------------
    # Speeds
    # -----------------------------------------------------------------------------------------

    @property
    def poles(self) -> int:
        return self._state.poles

    def hz_to_rpm(self, hz: float) -> int:
        """Synchronous speed: 120 * f / poles."""
        return self._state.hz_to_rpm(hz)

    def rpm_to_centihertz(self, rpm: int) -> int:
        return self._state.rpm_to_centihertz(rpm)

    @property
    def output_frequency(self) -> int:
        """Output frequency in 0.01 Hz (class 0x2A attribute 100, 0x000A, 0x0311)."""
        return round(abs(self._state.output_hz) * 100)

    @property
    def output_frequency_signed(self) -> float:
        return self._state.output_hz

    @property
    def speed_reference(self) -> int:
        """The speed reference in use, 0.01 Hz."""
        return round(self._state.reference_hz() * 100)

    @property
    def speed_actual_rpm(self) -> int:
        """Class 0x2A attribute 7: the output speed in rpm."""
        return self._state.hz_to_rpm(abs(self._state.output_hz))

    @property
    def speed_reference_rpm(self) -> int:
        """Class 0x2A attribute 8: the reference in rpm."""
        return self._state.hz_to_rpm(self._state.reference_hz())

    @property
    def accel_time(self) -> int:
        """ACC in 0.1 s (class 0x2A attribute 102)."""
        return self._state.values[ACCEL_TIME.address]

    @property
    def decel_time(self) -> int:
        """dEC in 0.1 s (class 0x2A attribute 103)."""
        return self._state.values[DECEL_TIME.address]

    # -----------------------------------------------------------------------------------------
    # Status
    # -----------------------------------------------------------------------------------------

    @property
    def running(self) -> bool:
        """The output is on: running, or decelerating to a stop."""
        return self._state.output_on

    @property
    def running_forward(self) -> bool:
        """Class 0x29 attribute 7."""
        return self._state.direction() is Direction.FORWARD

    @property
    def running_reverse(self) -> bool:
        """Class 0x29 attribute 8."""
        return self._state.direction() is Direction.REVERSE

    @property
    def ready(self) -> bool:
        """Class 0x29 attribute 9: 0 while a trip is active."""
        return self._state.trip is None

    @property
    def drive_state(self) -> DriveState:
        """Class 0x29 attribute 6. Startup and Not Ready (resetting) pass in no time here."""
        state = self._state
        if state.trip is not None:
            return DriveState.FAULT_STOP
        if state.output_on and state.command is not None:
            return DriveState.ENABLED
        if state.output_on:
            return DriveState.STOPPING
        return DriveState.READY

    @property
    def at_reference(self) -> bool:
        """Class 0x2A attribute 3: running, and the output frequency has reached the reference."""
        return self._ramp.at_reference

    @property
    def accelerating(self) -> bool:
        return self._ramp.accelerating

    @property
    def decelerating(self) -> bool:
        return self._ramp.decelerating

    # -----------------------------------------------------------------------------------------
    # CM.94 Comm Update: pending and active communication settings
    # -----------------------------------------------------------------------------------------

    def _value(self, code: str) -> int:
        return self._state.values[self.registers.by_code(code).address]

    @property
    def active_comm_settings(self) -> CommSettings:
        """The settings the card runs with: those of the last CM.94 update (or of power-up)."""
        return self._comm.active

    @property
    def pending_comm_settings(self) -> CommSettings:
        """The CM parameters as written, which CM.94 = 1 would make active."""
        return self._comm.pending

    @property
    def comm_update_pending(self) -> bool:
        """CM parameters changed without CM.94: the card's error LED flashes red every 2 s."""
        return self._comm.update_pending

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
        return self._computed.read(address)

    def write(self, address: int, value: int, now: float) -> None:
        """Write one register as a network client does, or raise ``RegisterError``."""
        self._writes += 1   # tried, even if refused: ``command_mark`` moves on
        register = self.register(address)
        self.advance(now)
        if register.access is RegisterAccess.READ:
            raise RegisterError(RegisterRefusal.READ_ONLY, address)
        register.check(value)
        if register.access is RegisterAccess.WRITE_STOPPED and self._state.output_on:
            if address == SAVE_PARAMETERS.address and value == 1:
                # The writer gets an error status; whoever runs the emulator should see it too.
                self._save_refused_log("parameter save refused (0x03E0 = 1 while the drive runs): nothing saved",
                                       now=now)
            raise RegisterError(RegisterRefusal.NOT_WHILE_RUNNING, address)
        if self._locks.parameter_locked and register.group in reg.KEYPAD_GROUPS:
            raise RegisterError(RegisterRefusal.READ_ONLY, address, "parameters are locked (0x03E8)")
        self._effects.write(ALIASES.get(address, address), value, now)
        self._ramp.run(0.0)  # a 0 s ramp time takes effect at once


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
    "SaveRequest",
    "Trip",
    "drive_run_action",
]
