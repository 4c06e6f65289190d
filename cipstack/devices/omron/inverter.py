"""An MX2 or RX inverter with its CompoNet option board, simulated without I/O.

Everything is driven by the caller's clock: each method that can change the drive takes
``now`` (seconds, monotonic) and first brings the simulation up to that instant. Nothing here
reads a clock, sleeps or touches a socket; ``next_deadline()`` tells the shell when the state
will next change by itself (a ramp reaching its reference, the network error timer P044).

What the master commands through the option board (the assemblies of appendix B, the Control
Supervisor, AC/DC Drive and Discrete Point objects) goes through ``command()``; the inverter's
registers through ``read``/``write`` (Modbus address, class 0x64) and ``read_code``/``write_code``
(function code, class 0x65); the flexible format (assemblies 139/159) through
``flexible_output``/``flexible_input`` once ``validate_flexible`` accepted P160-P179.

``Inverter`` combines the modules of each concern: ``states`` (Drive State, sources, the command
fields), ``network`` (P044/P045/P048), ``ramps``, ``monitors`` and ``flexible``; this module holds
power-on, the option board's commands, trips, sources and register access.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping

from ..registers import RegisterAccess, RegisterError, RegisterRefusal
from ..simulation import TimedSimulation
from ..state import StateFileError
from .flexible import (
    FlexibleFormat,
    FlexibleMapping,
    FlexibleMappingError,
    FlexibleProblem,
    FlexibleRule,
    validate_flexible,
)
from .models import Family, Model, model
from .monitors import Monitors
from .network import NetworkEvents
from .ramps import Ramps
from .registers import (
    COIL_DATA_0,
    COIL_DATA_1,
    EEPROM_SAVE,
    FLEXIBLE_FORMAT,
    STATUS_C_ADDRESS,
    TERMINAL_FRS,
    TORQUE_PATHS,
    FamilyTraits,
    Parameter,
    RegisterSet,
    SpeedUnit,
    function_code_from_number,
    register_set,
    speed_to_centihertz,
    trip_code,
)
from .states import (
    _DIR,
    _EXT,
    _OPR,
    DriveState,
    DriveStateDetail,
    InverterModeError,
    NetworkAction,
    OptionCommand,
    Source,
    Status,
)


class Inverter(NetworkEvents, Ramps, Monitors, FlexibleFormat, TimedSimulation):
    """One MX2 or RX inverter with its option board, from power-on onwards."""

    def __init__(self, inverter_model: Model | str, *, now: float = 0.0, saved: Mapping[int, int] | None = None,
                 on_save: Callable[[dict[int, int]], None] | None = None, consistency_value: int = 0) -> None:
        """``saved`` holds the values in EEPROM, by Table E-3 function code number (P044 -> 15044);
        ``on_save`` receives them all when the EEPROM save register (0900h) is written."""
        self.model = model(inverter_model) if isinstance(inverter_model, str) else inverter_model
        self.family: Family = self.model.family
        self.registers: RegisterSet = register_set(self.family)
        self.traits: FamilyTraits = self.registers.traits
        self._eeprom: dict[int, int] = self._checked_saved(saved or {})
        self._on_save = on_save
        #: Identity attribute 9: saves through the option board (Table C-2), a UINT.
        self.consistency_value = consistency_value & 0xFFFF
        #: Times the option board restarted (power-on excluded): Identity reset, trip clear with C102 != 3.
        self.option_board_resets = 0
        #: Cyclic flexible-format writes the inverter refused (out of range, wrong mode).
        self.flexible_write_errors = 0
        #: Physical intelligent input terminals, bit n-1 = terminal [n] (the test rig's wiring).
        self.terminals = 0
        self._local_run = 0
        #: Frequency reference of the local sources (terminal analog input), 0.01 Hz.
        self.local_reference = 0
        self._last_trip = 0
        self._producers = self._computed()
        self._power_on(now)

    # -- power, option board start ---------------------------------------------------------------
    def _checked_saved(self, saved: Mapping[int, int]) -> dict[int, int]:
        checked: dict[int, int] = {}
        for number, value in saved.items():
            parameter = self.registers.by_number.get(number)
            if parameter is None or not parameter.saved:
                raise ValueError(f"saved value for {number}: not a saved {self.family.value} parameter")
            try:
                checked[number] = parameter.check(value)
            except RegisterError as exc:
                raise ValueError(f"saved value for {parameter.key}: {exc}") from None
        return checked

    def _power_on(self, now: float) -> None:
        self._t = now
        self._values: dict[str, int] = {p.key: p.default for p in self.registers.parameters}
        for number, value in self._eeprom.items():
            self._values[self.registers.by_number[number].key] = value
        self._frequency = 0.0           # signed output frequency, 0.01 Hz (negative: reverse)
        self._trip = 0
        self._pending_trip = 0          # trip to raise once a "deceleration and trip" stop ends
        self._force_status = False
        self._cmd = OptionCommand()
        self._coils = 0
        self._last_ok: float | None = None
        self._run_since: float | None = None
        self._net_error = False
        self._idle = False
        self._start_option_board(now)

    def _start_option_board(self, now: float) -> None:
        """What the board does at power-on and reset: read its configuration from the inverter
        (section 1-1-1 "Simplified Start-up") and wait for fresh rising edges (Table B-2 note)."""
        self._terminal_functions = tuple(self._values[f"C{n:03d}"] for n in range(1, self.traits.input_terminals + 1))
        self.connection_path = self._values["P046"]
        # Note to Tables B-2/B-6/B-10/B-19/B-25: FWD, REV and RST act only after a 0 -> 1 transition
        # following power-on or a trip reset; "armed" means the bit has been seen at 0 since.
        self._armed_fwd = self._armed_rev = self._armed_rst = False
        self.flexible: FlexibleMapping | None = None
        self.flexible_error: FlexibleMappingError | None = None
        mode = self._values["d060"]
        if self.connection_path == FLEXIBLE_FORMAT:
            try:
                self.flexible = validate_flexible(self._values, self.registers, mode)
            except FlexibleMappingError as exc:
                # Appendix F Note 5: Major Recoverable Fault and trip E64 (MX2) / E74 (RX).
                self.flexible_error = exc
                self._raise_trip(self.traits.trip_flexible_mapping)
        elif self.connection_path in TORQUE_PATHS and mode != 0:
            # Tables 22/23 note: torque-related data in the process area without torque control.
            self._raise_trip(self.traits.trip_flexible_mapping)

    def power_cycle(self, now: float) -> None:
        """Switch off and on at ``now``, the option board with the inverter.

        Lost: what was written and not saved ("All data written by Function Code or Modbus Register
        object are stored temporary in the memory of the inverter. Be sure to execute the ENTER
        command ... to store the value in EEPROM", section E-2-2 note); the output (0 Hz, the run
        stopped) and everything the network commanded (run bits, Net Ctrl/Net Ref, coils); the trip
        present: Table 25 Step II names "Power OFF and ON" among the ways to restart after a trip,
        beside the STOP key and the RS terminal.

        Kept: the EEPROM (the saved parameters, and the configuration consistency value of Identity
        attribute 9 that counts its saves, Table C-2); the trip history: d081 still names the last trip
        (section 5-1-1 Tip, "Checking data in trip history is still an option"); the option board's
        reset count (power-on is no reset); and what is wired to the terminals.

        At power-on the board reads its configuration again (section 1-1-1, "read automatically when
        the power is turned ON or after a reset"): an illegal flexible mapping or torque path still
        saved trips again (appendix F Note 5, Tables 22/23 note), and FWD, REV and RST wait for a
        rising edge (note under Table B-2)."""
        if now < self._t:
            raise ValueError(f"time went backwards: {now} < {self._t}")
        self._power_on(now)
        self._evaluate(now)

    def reset_option_board(self, now: float) -> None:
        """Identity Reset of the option board, "return to initial status" (Table C-1): the board keeps
        nothing the network commanded (run bits, Net Ctrl, Net Ref, references, overrides: as at
        power-on) and re-reads its configuration; an option-board trip (E60-E69 / E70-E79) is cleared
        first and raised again if its cause remains (appendix F Note 5)."""
        self.advance(now)
        self._cmd = OptionCommand()
        base = self.traits.option_trip_base
        if base <= self._trip < base + 10:
            self._clear_trip()
        self._restart_option_board(now)
        self._evaluate(now)

    def _restart_option_board(self, now: float) -> None:
        self.option_board_resets += 1
        self._start_option_board(now)
        self._settle(now)

    # -- time --------------------------------------------------------------------------------------
    # ``advance``/``next_deadline`` (``TimedSimulation``): the ramps and the P044 timer.
    def _timer_deadline(self) -> float | None:
        return self._watchdog_deadline()

    def _fire_timers(self, moment: float) -> None:
        due = self._watchdog_deadline()
        if due is not None and due <= moment:
            # Table 12 / Table 26: no communication for P044 while running: P045 action.
            self._net_error = True
            self._lost_command(NetworkAction(self._values["P045"]), moment)

    def _run_until(self, moment: float) -> None:
        self._ramp_to(moment)

    def _ramp_deadline(self) -> float | None:
        return self._ramp_end()

    def _watchdog_deadline(self) -> float | None:
        timer = self._values["P044"]
        if not timer or self._net_error or self._trip or self._run_since is None:
            return None
        start = self._run_since if self._last_ok is None else max(self._last_ok, self._run_since)
        return start + timer * 0.1

    # -- option board commands -----------------------------------------------------------------
    @property
    def option_command(self) -> OptionCommand:
        return self._cmd

    def command(self, now: float, **changes: object) -> None:
        """Apply the master's option-board command fields (see ``OptionCommand``) at ``now``."""
        self.advance(now)
        old = self._cmd
        new = dataclasses.replace(old, **changes)  # type: ignore[arg-type]
        self._cmd = new
        if new.fault_reset and not old.fault_reset and self._armed_rst:
            self._reset_trip(now)
        if new.force_fault and not old.force_fault:
            # Table D-4 attribute 0x11: external fault on the rising edge; E62 / E72 (section E-1 Example 2).
            if not self._trip:
                self._force_status = True
            self._raise_trip(self.traits.trip_force_fault)
        # After the reset above, so that a board restarted by it counts the bits of this very message.
        self._armed_fwd |= not new.fwd
        self._armed_rev |= not new.rev
        self._armed_rst |= not new.fault_reset
        self._evaluate(now)

    def write_fault_reset(self, now: float, value: bool) -> None:
        """Control Supervisor attribute 0Ch Fault Rst written: "Reset fault / trip state of inverter
        when written to 1" (Table D-4, CompoNet manual). Each write of 1 resets: the same table says
        "on rising edge" for Force Fault (11h) and not here, and the rising-edge rule of the notes
        under Tables B-2 and after (004:1992) is for the RST bit of the I/O data, repeated each cycle."""
        self.command(now, fault_reset=value)
        if value:
            self._reset_trip(now)
            self._evaluate(now)

    def set_terminals(self, now: float, mask: int) -> None:
        """Physical state of the intelligent input terminals, bit n-1 = terminal [n]."""
        self.advance(now)
        self.terminals = mask & ((1 << self.traits.input_terminals) - 1)
        self._evaluate(now)

    def set_local_run(self, now: float, direction: int) -> None:
        """Run command of the local sources (FW/RV terminals, operator): +1, -1 or 0."""
        self.advance(now)
        self._local_run = (direction > 0) - (direction < 0)
        self._evaluate(now)

    @property
    def time(self) -> float:
        """The instant the simulation has reached (the latest ``now`` it was given)."""
        return self._t

    @property
    def local_run(self) -> int:
        """Run command of the local sources: +1 (FW terminal), -1 (RV) or 0 (Table C-10 instance 9 on the RX)."""
        return self._local_run

    def press_stop_reset(self, now: float) -> None:
        """The operator's STOP/RESET key: clears a trip (section 4-5-2 warning, Table 25 Step II)."""
        self.advance(now)
        self._reset_trip(now)
        self._evaluate(now)

    # -- trips ------------------------------------------------------------------------------------
    @property
    def trip(self) -> int:
        """Current trip as n of En, 0 when not tripped."""
        return self._trip

    def raise_trip(self, now: float, number: int) -> None:
        """Trip the inverter with En (an inverter-side fault of Table D-5, for test rigs)."""
        trip_code(self.family, number)
        self.advance(now)
        self._raise_trip(number)
        self._evaluate(now)

    def _raise_trip(self, number: int) -> None:
        if self._trip:
            return
        self._trip = self._last_trip = number
        self._pending_trip = 0
        self._frequency = 0.0   # the output is cut; the speed monitor reads 0

    def _clear_trip(self) -> int:
        cleared, self._trip = self._trip, 0
        self._force_status = False
        # Trip reset is the second moment the rising-edge rule names (Table B-2 note).
        self._armed_fwd = not self._cmd.fwd
        self._armed_rev = not self._cmd.rev
        return cleared

    def _reset_trip(self, now: float) -> None:
        if not self._trip:
            return
        cleared = self._clear_trip()
        if self._values["C102"] != 3:
            # Table 11 / section 3-2 Step 4: with C102 other than 3 clearing a trip resets the board.
            self._restart_option_board(now)
        elif cleared == self.traits.trip_flexible_mapping:
            # Table 25 Step II: resetting the trip restarts the check of the mapping.
            self._start_option_board(now)

    # -- sources and references ------------------------------------------------------------------
    @property
    def run_source(self) -> Source:
        a002 = self._values["A002"]
        # Section 4-2-1 note: CTR has the effect of temporarily setting A002 to the option board.
        if self._cmd.net_ctrl or a002 == self.traits.option_source:
            return Source.OPTION_BOARD
        return Source.MODBUS if a002 == self.traits.modbus_source else Source.LOCAL

    @property
    def reference_source(self) -> Source:
        a001 = self._values["A001"]
        if self._cmd.net_ref or a001 == self.traits.option_source:
            return Source.OPTION_BOARD
        if a001 == self.traits.modbus_source:
            return Source.MODBUS
        return Source.OPERATOR if a001 == self.traits.operator_source else Source.LOCAL

    @property
    def speed_unit(self) -> SpeedUnit:
        return self.traits.speed_unit(self._values["P049"], self._values["d060"])

    def _run_direction(self) -> int:
        if self._trip or self._pending_trip:
            return 0
        source = self.run_source
        if source is Source.OPTION_BOARD:
            forward = self._cmd.fwd and self._armed_fwd
            reverse = self._cmd.rev and self._armed_rev
            return 1 if forward and not reverse else -1 if reverse and not forward else 0
        if source is Source.MODBUS:
            # Coil data 0 Opr/Dir: level commands, no rising-edge rule (section 4-7-3 warning).
            return 0 if not self._coils & _OPR else -1 if self._coils & _DIR else 1
        return self._local_run

    def _reference(self) -> float:
        """Frequency reference in 0.01 Hz, limited to the maximum frequency A004."""
        source = self.reference_source
        if source is Source.OPTION_BOARD:
            reference = speed_to_centihertz(self._cmd.speed_reference, self.speed_unit, self._values["P049"])
        elif source in (Source.MODBUS, Source.OPERATOR):
            reference = self._values["F001"]
        else:
            reference = self.local_reference
        return min(max(reference, 0.0), self._values["A004"] * 10.0)

    def _free_running(self) -> bool:
        if self._cmd.free_run:
            return True
        inputs = self._inputs()
        return any(function == TERMINAL_FRS and inputs >> n & 1 for n, function in enumerate(self._terminal_functions))

    def _target(self) -> float:
        return self._run_direction() * self._reference()

    # -- registers ----------------------------------------------------------------------------------
    def _computed(self) -> dict[str, Callable[[], int]]:
        """Registers whose value the simulation produces rather than stores."""
        return {
            f"{COIL_DATA_0:04X}h": lambda: self._coils | (0x8000 if self._output_active() else 0),
            f"{COIL_DATA_1:04X}h": self._coil_data_1,
            f"{STATUS_C_ADDRESS:04X}h": self._status_c,
            f"{EEPROM_SAVE:04X}h": lambda: 0,
            "d001": lambda: round(abs(self._frequency)),
            "d005": self._inputs,
            "d006": self._outputs,
            "d012": lambda: 0,      # no torque model: the output torque reads 0 %
            "d081": lambda: self._last_trip,
            "b180": lambda: 0,      # the trigger reads back 0 once the initialization is done
        }

    def _value(self, parameter: Parameter) -> int:
        computed = self._producers.get(parameter.key)
        return computed() if computed is not None else self._values[parameter.key]

    def read(self, address: int) -> int:
        """The register whose first word is at ``address`` (double words whole, signed types signed);
        the second word of a double word alone when ``address`` points at it."""
        found = self.registers.word(address)
        if found is None:
            raise RegisterError(RegisterRefusal.NO_SUCH_REGISTER, address)
        parameter, index = found
        value = self._value(parameter)
        if index == 0:
            return value
        return value & 0xFFFF

    def read_word(self, address: int) -> int:
        """The 16-bit word at ``address`` as it travels in Modbus and in the flexible format."""
        found = self.registers.word(address)
        if found is None:
            raise RegisterError(RegisterRefusal.NO_SUCH_REGISTER, address)
        parameter, index = found
        return (self._value(parameter) >> (16 * (parameter.words - 1 - index))) & 0xFFFF

    def read_code(self, code: str) -> int:
        """The value of function code ``code`` (class 0x65)."""
        return self._value(self._by_code(code))

    def write(self, address: int, value: int, now: float) -> None:
        """Write the register whose first word is at ``address``; at the low word of a double word,
        write that word with a zero high word (appendix F Note 3)."""
        self.advance(now)
        found = self.registers.word(address)
        if found is None:
            raise RegisterError(RegisterRefusal.NO_SUCH_REGISTER, address)
        parameter, index = found
        if index and not 0 <= value <= 0xFFFF:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, address, f"{value} is not a word")
        self._write(parameter, value, now)

    def write_code(self, code: str, value: int, now: float) -> None:
        """Write function code ``code`` through the Function Code object (class 0x65)."""
        self.advance(now)
        parameter = self._by_code(code)
        if not parameter.function_code_writable:
            raise RegisterError(RegisterRefusal.READ_ONLY, parameter.function_code_number or 0,
                                f"{parameter.key} cannot be written by function code (section E-2-2)")
        self._write(parameter, value, now)

    def write_from_operator(self, code: str, value: int, now: float) -> None:
        """Write function code ``code`` as the Digital Operator does: the inverter's own rules (read
        only, range, not run-mode editable while running, torque-related outside d060 = 0) and not the
        Function Code object's: "F001 can not be written using the Function code object" (section
        E-2-2) is that object's limit, while the operator sets F001 itself (A001 = 2 takes the
        frequency from "digital operator (F001)", Tables 13/14)."""
        self.advance(now)
        self._write(self._by_code(code), value, now)

    def read_function_code(self, number: int) -> int:
        """Class 0x65 by instance/attribute number (Table E-3)."""
        return self.read_code(self._code_of(number))

    def write_function_code(self, number: int, value: int, now: float) -> None:
        self.write_code(self._code_of(number), value, now)

    def _code_of(self, number: int) -> str:
        try:
            code = function_code_from_number(number)
        except ValueError:
            raise RegisterError(RegisterRefusal.NO_SUCH_REGISTER, number) from None
        if code not in self.registers.by_key:
            raise RegisterError(RegisterRefusal.NO_SUCH_REGISTER, number, f"{self.family.value} has no {code}")
        return code

    def _by_code(self, code: str) -> Parameter:
        try:
            return self.registers.by_code(code)
        except KeyError:
            raise RegisterError(RegisterRefusal.NO_SUCH_REGISTER, 0, f"{self.family.value} has no {code!r}") from None

    def _write(self, parameter: Parameter, value: int, now: float) -> None:
        where = parameter.address if parameter.address is not None else (parameter.function_code_number or 0)
        if not parameter.access.writable:
            raise RegisterError(RegisterRefusal.READ_ONLY, where, parameter.key)
        parameter.check(value)
        # Table 27 says a trip "may" prevent downloads, but Table 25 has P160-P179 corrected while E64/E74
        # is shown, so a trip alone refuses nothing; running refuses what is not run-mode editable.
        if parameter.access is RegisterAccess.WRITE_STOPPED and self._output_active():
            raise RegisterError(RegisterRefusal.NOT_WHILE_RUNNING, where, f"{parameter.key} is not run-mode editable")
        if parameter.torque_related and self._values["d060"] != 0:
            raise InverterModeError(RegisterRefusal.NOT_WHILE_RUNNING, where,
                                    f"{parameter.key} needs the constant-torque IM mode (d060 = 0)")
        if parameter.address == EEPROM_SAVE:
            self._save()
        elif parameter.address == COIL_DATA_0:
            self._write_coils(value & parameter.writable_bits, now)
            return
        elif parameter.key == "b180":
            self._initialize()
        else:
            self._values[parameter.key] = value
        self._evaluate(now)

    def _write_coils(self, value: int, now: float) -> None:
        old, self._coils = self._coils, value
        if value & _EXT and not old & _EXT:
            # Section 4-7-3: user trips from the EXT coil (external trip E12, Table D-5).
            self._raise_trip(12)
        self._evaluate(now)

    def _save(self) -> None:
        """EEPROM save (0900h): every parameter, and Identity attribute 9 counts it (Table C-2)."""
        eeprom = {number: self._values[p.key] for number, p in self.registers.by_number.items() if p.saved}
        before = self.consistency_value
        self.consistency_value = (before + 1) & 0xFFFF
        if self._on_save is not None:
            try:
                self._on_save(dict(eeprom))
            except StateFileError as exc:   # refused by the shell: nothing saved, nothing counted
                self.consistency_value = before
                raise RegisterError(RegisterRefusal.SAVE_FAILED, EEPROM_SAVE, str(exc)) from None
        self._eeprom = eeprom

    def _initialize(self) -> None:
        """b180 = 1: initialize the inverter mode from b171 (MX2) and b049 (section 4-1 Step 1),
        and store it like the inverter does (which counts as a save through the option board)."""
        rating = self._values["b049"]
        mode = self._values.get("b171", 1)
        self._values["d060"] = {2: 2, 3: 3}.get(mode, rating)
        self._save()

    @property
    def saved_values(self) -> dict[int, int]:
        """The values in EEPROM, by function code number."""
        return dict(self._eeprom)


__all__ = [
    "DriveState", "DriveStateDetail", "FlexibleMapping", "FlexibleMappingError", "FlexibleProblem", "FlexibleRule",
    "Inverter", "InverterModeError", "NetworkAction", "OptionCommand", "Source", "Status", "validate_flexible",
]
