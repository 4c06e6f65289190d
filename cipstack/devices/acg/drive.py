"""The ACG drive with its ACG-ET2 card, simulated without I/O.

Time is an argument: every method that can change the drive takes ``now`` (seconds, from any
monotonic origin); nothing here reads a clock, sleeps or opens a socket. ``advance(now)``
moves the simulation to ``now`` and ``next_deadline()`` says when it next changes on its own
(the end of a ramp segment, a lost-command timer), so an event loop can sleep until then.

Behaviour, with the table it comes from:

* Registers: ``read``/``write`` over the map of ``registers.py``; a refused write raises
  ``RegisterError`` (read-only, out of range, not writable in run).
* Command and frequency source: drv = 4 "Field Bus" takes the run command from the network,
  Frq = 8 "Field Bus" the speed reference (seed 000, Keypad Parameters Related to ACG-ET2).
* Run/stop: the Control Supervisor "Drive Run" table (seed 000, class 0x29), the common area
  operation command 0x0006 and the control area command 0x0382 (seed 001).
* Ramps: linear, from 0 to dr.20 Max Freq in ACC seconds and back in dEC seconds.
* Trips: the "Drive Fault Codes" table (class 0x29 attribute 13) with the trip bits of the
  monitoring words 0x0330-0x0335; Drive Fault Reset acts on a 0 -> 1 change only.
* Lost command: Pr.12/Pr.13/Pr.14 (seed 000, PR Group (Lost Command); seed 001, Command Loss
  Protective Operation).
* Parameter save: 0x03E0 from 0 to 1 (seed 001, Saving Parameters Defined by Communication).
* CM.94 Comm Update: CM.7 and CM.10-CM.24 take effect on the card only when it is set to 1.

The simulation has no motor or load model: output current, voltage, power, torque and the
analog inputs read 0. The monitor rpm is the synchronous speed 120 * f / poles.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import Enum, IntEnum

from ..registers import Register, RegisterAccess, RegisterError, RegisterMap, RegisterRefusal
from ..simulation import TimedSimulation
from ..state import ParameterStore, StateFileError
from . import registers as reg
from .registers import (
    ACCEL_TIME,
    ACG_REGISTERS,
    ALIASES,
    CMD_SOURCE,
    CMD_SOURCE_FIELDBUS,
    COMM_UPDATE,
    COMM_UPDATE_CODES,
    DECEL_TIME,
    FREQ_REF_SOURCE,
    FREQ_REF_SOURCE_FIELDBUS,
    LOST_CMD_MODE,
    LOST_CMD_TIME,
    LOST_PRESET_FREQ,
    MAX_FREQUENCY,
    POLE_NUMBER,
    SAVE_PARAMETERS,
    SPEED_REFERENCE,
    TARGET_FREQUENCY,
    ControlCommand,
    FaultTripInformation,
    InstanceSelection,
    LatchTrip1,
    LatchTrip2,
    LevelTrip,
    OperationCommand,
    OperationDirection,
    OperationHealth,
    OperationPhase,
    OperationStatus,
    WarningInformation,
)

FAMILY = "acg"
MODEL = "ACG-ET2"

#: What the drive hands a save to: every saved value (address -> raw). It may refuse the save
#: by raising ``StateFileError`` (the state file is known not to be writable).
SaveRequest = Callable[[dict[int, int]], None]

#: Seed 000, "Lost command conditions by protocol": a class 1 connection that stays broken for
#: longer than one second, or a Modbus TCP server that receives nothing for five seconds, puts
#: the card in lost command mode; Pr.12 then acts after Pr.13 seconds.
IO_BREAK_TIME = 1.0
MODBUS_SILENCE_TIME = 5.0

#: A ramp that ends within this many seconds of a deadline ends at it (float rounding).
_TIME_TOLERANCE = 1e-9
_SECONDS_PER_MINUTE = 60
_SECONDS_PER_DAY = 86400


class Direction(IntEnum):
    FORWARD = 1
    REVERSE = -1


class DriveState(IntEnum):
    """Class 0x29 attribute 6 "Drive State" (seed 000)."""

    VENDOR_SPECIFIC = 0
    STARTUP = 1
    NOT_READY = 2
    READY = 3
    ENABLED = 4
    STOPPING = 5
    FAULT_STOP = 6


class LostCommandMode(IntEnum):
    """Pr.12 Lost Cmd Mode (seed 000)."""

    NONE = 0
    FREE_RUN = 1
    DEC = 2
    HOLD_INPUT = 3
    HOLD_OUTPUT = 4
    LOST_PRESET = 5


class RunAction(Enum):
    STOP = "Stop"
    RUN_FORWARD = "Run1"
    RUN_REVERSE = "Run2"
    NO_ACTION = "No Action"


def drive_run_action(previous: tuple[bool, bool], present: tuple[bool, bool]) -> RunAction:
    """The Control Supervisor "Drive Run" table (seed 000, class 0x29): what a change of the
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
    and Drive Fault Reset (12), as the card holds them (seed 000). "The Forward Run Cmd. value
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


class Trip(Enum):
    """The trips of the "Drive Fault Codes" table (seed 000, class 0x29 attribute 13).

    Each value: display name, fault code, the monitoring word that shows it and its bit there
    (seed 001, 0x0330-0x0335; None where that table has no bit for it), and whether it is a
    level-type trip (0x0332), which clears by itself once its cause is gone.
    The table lists 0x2330 twice (GFT and GroundTrip, both the ground fault of 0x0330 B4) and an
    "UNDEFINED" entry under 0x1000, which is no trip and is left out.
    """

    ETHERMAL = ("Ethermal", 0x1000, 0x0330, LatchTrip1.E_THERMAL)
    OUT_PHASE_OPEN = ("Out Phase Open", 0x1000, 0x0330, LatchTrip1.OUTPUT_OPEN_PHASE)
    INVERTER_OLT = ("InverterOLT", 0x1000, 0x0330, LatchTrip1.DRIVE_OVERLOAD)
    IN_PHASE_OPEN = ("InPhaseOpen", 0x1000, 0x0330, LatchTrip1.INPUT_OPEN_PHASE)
    THERMAL_TRIP = ("ThermalTrip", 0x1000, None, 0)
    UNDER_LOAD = ("UnderLoad", 0x1000, 0x0330, LatchTrip1.UNDERLOAD)
    PARA_WRITE_TRIP = ("ParaWriteTrip", 0x1000, None, 0)
    IO_BOARD_TRIP = ("IOBoardTrip", 0x1000, 0x0331, LatchTrip2.BAD_CONTACT_IO_BOARD)
    PRE_PID_FAIL = ("PrePIDFail", 0x1000, 0x0331, LatchTrip2.PRE_PID_FAIL)
    OPTION_TRIP_1 = ("OptionTrip1", 0x1000, 0x0331, LatchTrip2.BAD_OPTION_CARD)
    OPTION_TRIP_2 = ("OptionTrip2", 0x1000, None, 0)
    OPTION_TRIP_3 = ("OptionTrip3", 0x1000, None, 0)
    LOST_COMMAND = ("LostCommand", 0x1000, 0x0332, LevelTrip.LOST_COMMAND, True)
    LOST_KEYPAD = ("LostKeypad", 0x1000, 0x0332, LevelTrip.KEYPAD_LOST_COMMAND, True)
    OVER_LOAD = ("OverLoad", 0x2200, 0x0330, LatchTrip1.OVERLOAD)
    OVER_CURRENT_1 = ("OverCurrent1", 0x2310, 0x0330, LatchTrip1.OVERCURRENT)
    GFT = ("GFT", 0x2330, 0x0330, LatchTrip1.GROUND_FAULT)
    OVER_CURRENT_2 = ("OverCurrent2", 0x2340, 0x0330, LatchTrip1.ARM_SHORT)
    OVER_VOLTAGE = ("OverVoltage", 0x3210, 0x0330, LatchTrip1.OVERVOLTAGE)
    LOW_VOLTAGE = ("LowVoltage", 0x3220, 0x0332, LevelTrip.LOW_VOLTAGE, True)
    GROUND_TRIP = ("GroundTrip", 0x2330, 0x0330, LatchTrip1.GROUND_FAULT)
    NTC_OPEN = ("NTCOpen", 0x4000, 0x0330, LatchTrip1.NTC)
    OVER_HEAT = ("OverHeat", 0x4200, 0x0330, LatchTrip1.OVER_HEAT)
    FUSE_OPEN = ("FuseOpen", 0x5000, 0x0330, LatchTrip1.FUSE_OPEN)
    HW_DIAG = ("HWDiag", 0x5000, None, 0)
    FAN_TRIP = ("FanTrip", 0x7000, 0x0331, LatchTrip2.FAN_TRIP)
    NO_MOTOR_TRIP = ("No Motor Trip", 0x7120, 0x0331, LatchTrip2.NO_MOTOR)
    ENCODER_TRIP = ("EncoderTrip", 0x7300, None, 0)
    SPEED_DEV_TRIP = ("SpeedDevTrip", 0x8401, None, 0)
    OVER_SPEED = ("OverSpeed", 0x8402, None, 0)
    EXTERNAL_TRIP = ("ExternalTrip", 0x9000, 0x0330, LatchTrip1.EXTERNAL_TRIP)
    BX = ("BX", 0x9000, 0x0332, LevelTrip.BX, True)

    def __init__(self, label: str, fault_code: int, info_address: int | None, bit: int, level: bool = False) -> None:
        self.label = label
        self.fault_code = fault_code
        self.info_address = info_address
        self.bit = int(bit)
        self.level = level

    @classmethod
    def from_fault_code(cls, code: int) -> Trip:
        """The first trip the table lists under ``code`` (0x1000 -> Ethermal)."""
        for trip in cls:
            if trip.fault_code == code:
                return trip
        raise ValueError(f"0x{code:04X} is not a trip of the Drive Fault Codes table")


NO_FAULT = 0x0000

# Where the sources read in 0x0006 (B6-B8, B9-B14) and 0x0306 (B8-B15, B0-B7) come from.
# drv codes equal the 0x0006 command-source codes (both lists read 0 keypad ... 4 option).
_MONITOR_COMMAND_SOURCE = {0: 0, 1: 4, 2: 4, 3: 3, 4: 1}  # drv -> 0x0306 B8-B15
# Frq settings the seeds name; an unnamed local source acts as the keypad frequency here (the
# emulated drive has no analog inputs), so it is shown as the keypad.
_COMMON_FREQUENCY_SOURCE = {0: 0, 6: 27, 8: 28}  # Frq -> 0x0006 B9-B14
_MONITOR_FREQUENCY_SOURCE = {0: 0, 6: 10, 8: 11}  # Frq -> 0x0306 B0-B7
_COMMAND_SOURCES_BY_COMMUNICATION = (3, 4)  # drv Int485 or Field Bus: 0x000E B13
_FREQUENCY_SOURCES_BY_COMMUNICATION = (6, 8)  # Frq Int485 or Field Bus: 0x000E B14


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


@dataclass
class _CommandLossWatch:
    """One protocol's lost-command timers (seed 000, "Lost command conditions by protocol")."""

    detect_after: float
    #: Since when nothing has arrived (class 1: the break; Modbus: the last request), or None.
    silent_since: float | None = None
    #: When lost command mode was entered (Pr.13 counts from here), or None.
    lost_since: float | None = None
    #: Pr.12 has acted for this loss.
    acted: bool = False

    def deadline(self, lost_time: float) -> float | None:
        if self.silent_since is None or self.acted:
            return None
        if self.lost_since is None:
            return self.silent_since + self.detect_after
        return self.lost_since + lost_time

    def clear(self) -> None:
        self.silent_since = None
        self.lost_since = None
        self.acted = False


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
        self.registers: RegisterMap = ACG_REGISTERS
        self.on_save = on_save
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
        self._lost_reference: float | None = None  # Hz held by Hold Input/Hold Output/Lost Preset
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
        self._ramp(max(0.0, moment - self._time))
        self._time = moment

    # -----------------------------------------------------------------------------------------
    # Ramps: linear over ACC/dEC from 0 to Max Freq (the drive's definition of the ramp times)
    # -----------------------------------------------------------------------------------------

    def _rate(self, accelerating: bool) -> float:
        seconds = (self._values[ACCEL_TIME.address] if accelerating else self._values[DECEL_TIME.address]) / 10
        max_hz = self._values[MAX_FREQUENCY.address] / 100
        return math.inf if seconds == 0 else max_hz / seconds

    def _target_hz(self) -> float:
        """The signed output frequency the drive is heading for."""
        if self._command is None or self._trip is not None:
            return 0.0
        return self._command * self._reference_hz()

    def _segment(self) -> tuple[float, bool] | None:
        """The end of the present ramp segment (its frequency) and whether it accelerates."""
        if not self._output_on:
            return None
        present, target = self._output_hz, self._target_hz()
        if present == target:
            return None
        if present != 0 and (target == 0 or (present > 0) != (target > 0)):
            return 0.0, False                       # slow down to 0 (stop or reversal)
        if abs(target) < abs(present):
            return target, False
        return target, True

    def _ramp(self, elapsed: float) -> None:
        """Move the output along its ramp for ``elapsed`` seconds (0: apply instant steps)."""
        remaining = elapsed
        while True:
            segment = self._segment()
            if segment is None:
                if self._output_on:
                    self._count_run_time(remaining)
                return
            goal, accelerating = segment
            rate = self._rate(accelerating)
            needed = abs(goal - self._output_hz) / rate
            if needed > remaining + _TIME_TOLERANCE:
                step = rate * remaining
                self._output_hz += step if goal > self._output_hz else -step
                self._count_run_time(remaining)
                return
            self._output_hz = goal
            self._count_run_time(min(needed, remaining))
            remaining = max(0.0, remaining - needed)
            self._settle()

    def _count_run_time(self, seconds: float) -> None:
        # The heat sink fan is taken to run while the drive runs.
        self._run_seconds += seconds
        self._fan_seconds += seconds

    def _settle(self) -> None:
        """At 0 Hz without a run command the output switches off: the stop is complete."""
        if self._output_hz == 0 and (self._command is None or self._trip is not None):
            self._output_on = False

    def _ramp_deadline(self) -> float | None:
        segment = self._segment()
        if segment is None:
            return None
        goal, accelerating = segment
        return self._time + abs(goal - self._output_hz) / self._rate(accelerating)

    def _free_run(self) -> None:
        """Cut the output at once; the motor coasts (free-run stop)."""
        self._command = None
        self._output_hz = 0.0
        self._output_on = False

    # -----------------------------------------------------------------------------------------
    # Commands
    # -----------------------------------------------------------------------------------------

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
        over TRUE does nothing (seed 000, "Drive Fault Reset"). Returns whether a reset was made."""
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

    def _fault_reset(self) -> bool:
        if self._trip is None or self._trip in self._level_causes:
            return False                            # a level-type trip holds while its cause lasts
        self._trip = None
        return True

    # -----------------------------------------------------------------------------------------
    # Trips
    # -----------------------------------------------------------------------------------------

    def inject_trip(self, trip: Trip | int, now: float) -> Trip:
        """Trip the drive as if ``trip`` occurred (a Trip, or a fault code of the table: the
        first trip listed under it). The output is cut (free-run); a Fault Reset clears it."""
        self.advance(now)
        if not isinstance(trip, Trip):
            trip = Trip.from_fault_code(trip)
        self._trip_drive(trip)
        return trip

    def _trip_drive(self, trip: Trip, free_run: bool = True) -> None:
        self.fault_history.append(trip)
        if self._trip is not None:
            return
        self._trip = trip
        self._command = None
        if free_run:
            self._free_run()

    def _set_level_cause(self, trip: Trip, active: bool, free_run: bool = True) -> None:
        if active and trip not in self._level_causes:
            self._level_causes.add(trip)
            self._trip_drive(trip, free_run)
        elif not active and trip in self._level_causes:
            self._level_causes.discard(trip)
            if self._trip is trip:
                self._trip = None                   # level type: clears with its cause
                self._settle()

    @property
    def trip(self) -> Trip | None:
        return self._trip

    @property
    def faulted(self) -> bool:
        """Class 0x29 attribute 10."""
        return self._trip is not None

    @property
    def fault_code(self) -> int:
        """Class 0x29 attribute 13: the Drive Fault Codes table value of the present trip."""
        return NO_FAULT if self._trip is None else self._trip.fault_code

    @property
    def warnings(self) -> WarningInformation:
        return self._warnings

    @property
    def warning(self) -> bool:
        """A warning is active (0x0305 B12-B15 = 4). Class 0x29 attribute 11 is "Not supported"."""
        return bool(self._warnings)

    # -----------------------------------------------------------------------------------------
    # Lost command (Pr.12 / Pr.13 / Pr.14)
    # -----------------------------------------------------------------------------------------

    def on_io_connection_lost(self, now: float) -> None:
        """The class 1 connection broke (timed out or closed)."""
        self.advance(now)
        if self._io_watch.silent_since is None:
            self._io_watch.silent_since = now

    def on_io_connection_opened(self, now: float) -> None:
        """A class 1 connection is open and producing again: communication has returned."""
        self.advance(now)
        self._io_watch.clear()
        self._restore_after_loss()
        self._ramp(0.0)

    def on_modbus_activity(self, now: float) -> None:
        """A Modbus TCP request arrived; from the first one on, 5 s of silence is a command loss."""
        self.advance(now)
        self._modbus_watch.clear()
        self._modbus_watch.silent_since = now
        self._restore_after_loss()
        self._ramp(0.0)

    def _lost_time(self) -> float:
        return self._values[LOST_CMD_TIME.address] / 10

    def _timer_deadline(self) -> float | None:
        lost_time = self._lost_time()
        deadlines = [d for d in (self._io_watch.deadline(lost_time), self._modbus_watch.deadline(lost_time))
                     if d is not None]
        return min(deadlines) if deadlines else None

    def _fire_timers(self, moment: float) -> None:
        lost_time = self._lost_time()
        for watch in (self._io_watch, self._modbus_watch):
            deadline = watch.deadline(lost_time)
            if deadline is None or deadline > moment:
                continue
            if watch.lost_since is None:
                watch.lost_since = moment            # lost command mode entered; Pr.13 starts
            else:
                watch.acted = True
                self._lost_command_action()

    @property
    def command_lost(self) -> bool:
        """The card is in lost command mode on some protocol."""
        return any(w.lost_since is not None for w in (self._io_watch, self._modbus_watch))

    def _lost_command_action(self) -> None:
        """Pr.12 after Pr.13 (seed 000, PR Group (Lost Command)), for a drive operated via the
        network ("while the drive is operated via network communication")."""
        if not (self.control_from_net or self.reference_from_net):
            return
        mode = LostCommandMode(self._values[LOST_CMD_MODE.address])
        if mode is LostCommandMode.NONE:
            return                                  # "Maintains the previous status."
        if mode is LostCommandMode.FREE_RUN:        # Lost Command Trip, free-run stop
            self._set_level_cause(Trip.LOST_COMMAND, True, free_run=True)
        elif mode is LostCommandMode.DEC:           # Lost Command Trip, deceleration stop
            self._set_level_cause(Trip.LOST_COMMAND, True, free_run=False)
            self._settle()
        else:
            self._warnings |= WarningInformation.LOST_COMMAND
            if mode is LostCommandMode.HOLD_INPUT:    # the speed reference before the loss
                self._lost_reference = self._reference_hz()
            elif mode is LostCommandMode.HOLD_OUTPUT:  # the running speed before the loss
                self._lost_reference = abs(self._output_hz)
            else:                                      # Lost Preset: Pr.14
                self._lost_reference = self._values[LOST_PRESET_FREQ.address] / 100

    def _restore_after_loss(self) -> None:
        """Communication is back. The Lost Command warning clears and the reference is the
        network's again; the Lost Command trip is a level-type trip (0x0332 B2) and clears
        with its cause, leaving the drive stopped until a run command's next 0 -> 1 change."""
        if any(w.acted for w in (self._io_watch, self._modbus_watch)):
            return                                  # another protocol is still lost
        self._warnings &= ~WarningInformation.LOST_COMMAND
        self._lost_reference = None
        self._set_level_cause(Trip.LOST_COMMAND, False)

    # -----------------------------------------------------------------------------------------
    # Speeds
    # -----------------------------------------------------------------------------------------

    def _max_hz(self) -> float:
        return self._values[MAX_FREQUENCY.address] / 100

    def _reference_hz(self) -> float:
        if self._lost_reference is not None:
            reference = self._lost_reference
        elif self.reference_from_net:
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

    # Write side effects, by the address that holds the value.

    def _write_frequency(self, address: int, value: int, now: float) -> None:
        self._check_frequency(address, value)
        self._values[address] = value

    def _write_lost_preset(self, address: int, value: int, now: float) -> None:
        # Pr.14: 0.05-60.00, or the table's default 0.00 (seed 000:214; registers.LOST_PRESET_FREQ).
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
        # Common area 0x0006 (seed 001): B0 stop, B1 forward, B2 reverse, B3 trip reset on 0 -> 1,
        # B4 emergency stop (the BX level trip while it is set).
        previous = OperationCommand(self._values[address] & 0x1F)
        bits = OperationCommand(value & 0x1F)
        self._values[address] = int(bits)
        if OperationCommand.TRIP_RESET in bits and OperationCommand.TRIP_RESET not in previous:
            self._fault_reset()
        self._set_level_cause(Trip.BX, OperationCommand.EMERGENCY_STOP in bits)
        if not self.control_from_net:
            return
        run_bits = bits & (OperationCommand.STOP | OperationCommand.FORWARD | OperationCommand.REVERSE)
        if OperationCommand.STOP in run_bits:
            self._stop()
        elif run_bits == OperationCommand.FORWARD:
            self._run(Direction.FORWARD)
        elif run_bits == OperationCommand.REVERSE:
            self._run(Direction.REVERSE)

    def _write_control_command(self, address: int, value: int, now: float) -> None:
        # Control area 0x0382 (seed 001): B0 run/stop, B1 forward/reverse, B2 trip reset on
        # 0 -> 1, B3 free-run stop on 0 -> 1. Forward run is 0x0003, reverse run 0x0001.
        previous = ControlCommand(self._values[address] & 0x0F)
        bits = ControlCommand(value & 0x0F)
        self._values[address] = value
        rising = bits & ~previous
        if ControlCommand.TRIP_RESET in rising:
            self._fault_reset()
        if not self.control_from_net:
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
        # does not carry out the same function." (seed 001)
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
        # in a row executes once only (seed 001).
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
        # CM.94 = 1 applies CM.7 and CM.10-CM.24 and restarts the card's communication (seed 000);
        # it reads back 0 (NO), ready for the next update.
        if value == 1:
            self._comm_update()
        self._values[address] = 0

    def _write_instance_setting(self, address: int, value: int, now: float) -> None:
        # CM.30/CM.50 are "automatically set according to the CIP Input/Output Instance": the
        # Parameter Number column of the CM.23/CM.24 tables (seed 000).
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

    _write_handlers: Mapping[int, Callable[[AcgDrive, int, int, float], None]] = {
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
    }

    # -----------------------------------------------------------------------------------------
    # Computed registers (monitors)
    # -----------------------------------------------------------------------------------------

    def _operation_status(self) -> int:
        """Common area 0x000E (seed 001)."""
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
        """Common area 0x000F (seed 001)."""
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
        """Monitoring 0x0305 (seed 001)."""
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
        """Monitoring 0x0306 (seed 001)."""
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

        def virtual_inputs() -> int:   # 0x0385 as written, monitored at 0x0322 and CM.86
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
            # The second motor's pole number is an M2 parameter the seeds do not describe.
            0x031B: lambda: self.poles,
            0x031C: lambda: self.poles,
            0x0321: relays,
            0x0322: virtual_inputs,
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


__all__ = [
    "FAMILY",
    "IO_BREAK_TIME",
    "MODBUS_SILENCE_TIME",
    "MODEL",
    "NO_FAULT",
    "AcgDrive",
    "CommSettings",
    "ControlSupervisor",
    "Direction",
    "DriveState",
    "LostCommandMode",
    "RunAction",
    "Trip",
    "drive_run_action",
]
