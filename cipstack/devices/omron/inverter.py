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

``Inverter`` composes one component per concern over one state (``states.InverterState``), each
given at construction the state and what it needs of the register set: ``sources.Sources`` (run and
reference sources), ``board_start.BoardStartup`` (the option board's start), ``ramps.Ramp``,
``trips.Trips`` (trip reset and the level-triggered inputs), ``network.NetworkWatch``
(P044/P045/P048) and ``monitors.Monitors``; ``flexible`` checks and maps the flexible format. This
module holds power-on, the option board's commands and register access.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence

from ...errors import BadRequest, WrongState
from ..registers import RegisterAccess, RegisterError, RegisterRefusal
from ..simulation import TimedSimulation
from ..state import StateFileError
from .board_start import BoardStartup
from .flexible import (
    FlexibleMapping,
    FlexibleMappingError,
    FlexibleProblem,
    FlexibleRule,
    flexible_writes,
    validate_flexible,
)
from .models import Family, Model, model
from .monitors import Monitors
from .network import NetworkWatch
from .ramps import Ramp
from .registers import (
    COIL_DATA_0,
    EEPROM_SAVE,
    FamilyTraits,
    Parameter,
    RegisterSet,
    SpeedUnit,
    function_code_from_number,
    register_set,
    trip_code,
)
from .sources import Sources
from .states import (
    _EXT,
    DriveState,
    DriveStateDetail,
    InverterModeError,
    InverterState,
    NetworkAction,
    OptionCommand,
    Source,
    Status,
)
from .trips import Trips


class Inverter(TimedSimulation):
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
        #: Cyclic flexible-format writes the inverter refused (out of range, wrong mode).
        self.flexible_write_errors = 0
        traits = self.traits
        state = self._state = InverterState(self._power_on_values(), now)
        sources = self._sources = Sources(state, traits)
        self._startup = BoardStartup(state, self.registers, traits)
        ramp = self._ramp = Ramp(state, sources)
        trips = self._trips = Trips(state, self._startup, sources, ramp, traits.trip_flexible_mapping)
        self._network = NetworkWatch(state, sources, trips, traits.trip_network)
        self._monitors = Monitors(state, self.family, traits, sources)
        self._producers = self._monitors.producers()
        self._startup.start()

    # -- power, option board start ---------------------------------------------------------------
    def _checked_saved(self, saved: Mapping[int, int]) -> dict[int, int]:
        checked: dict[int, int] = {}
        for number, value in saved.items():
            parameter = self.registers.by_number.get(number)
            if parameter is None or not parameter.saved:
                raise BadRequest(f"saved value for {number}: not a saved {self.family.value} parameter")
            try:
                checked[number] = parameter.check(value)
            except RegisterError as exc:
                raise BadRequest(f"saved value for {parameter.key}: {exc}") from None
        return checked

    def _power_on_values(self) -> dict[str, int]:
        """The defaults, then what the EEPROM holds."""
        values = {p.key: p.default for p in self.registers.parameters}
        for number, value in self._eeprom.items():
            values[self.registers.by_number[number].key] = value
        return values

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
        if now < self._state.t:
            raise BadRequest(f"time went backwards: {now} < {self._state.t}")
        self._state.power_on(self._power_on_values(), now)
        self._startup.start()
        self._trips.evaluate(now)

    def reset_option_board(self, now: float) -> None:
        """Identity Reset of the option board, "return to initial status" (Table C-1): the board keeps
        nothing the network commanded (run bits, Net Ctrl, Net Ref, references, overrides: as at
        power-on) and re-reads its configuration; an option-board trip (E60-E69 / E70-E79) is cleared
        first and raised again if its cause remains (appendix F Note 5)."""
        self.advance(now)
        state = self._state
        state.cmd = OptionCommand()
        base = self.traits.option_trip_base
        if base <= state.trip < base + 10:
            self._trips.clear()
        self._trips.restart_board(now)
        self._trips.evaluate(now)

    @property
    def option_board_resets(self) -> int:
        """Times the option board restarted (power-on excluded): Identity reset, trip clear with C102 != 3."""
        return self._startup.resets

    @property
    def connection_path(self) -> int:
        """P046 as the option board read it at its start: the default connection path (Table 10)."""
        return self._state.connection_path

    @property
    def flexible(self) -> FlexibleMapping | None:
        """The flexible mapping the board accepted at its start (None: not the flexible format)."""
        return self._state.flexible

    @property
    def flexible_error(self) -> FlexibleMappingError | None:
        """Why the board refused the flexible mapping at its start, or None."""
        return self._state.flexible_error

    # -- time --------------------------------------------------------------------------------------
    # ``advance``/``next_deadline`` (``TimedSimulation``): the ramps and the P044 timer.
    def _timer_deadline(self) -> float | None:
        return self._network.deadline()

    def _fire_timers(self, moment: float) -> None:
        self._network.fire(moment)

    def _run_until(self, moment: float) -> None:
        self._ramp.ramp_to(moment)

    def _ramp_deadline(self) -> float | None:
        return self._ramp.end()

    # -- option board commands -----------------------------------------------------------------
    @property
    def option_command(self) -> OptionCommand:
        return self._state.cmd

    def command(self, now: float, **changes: object) -> None:
        """Apply the master's option-board command fields (see ``OptionCommand``) at ``now``."""
        self.advance(now)
        state = self._state
        old = state.cmd
        new = dataclasses.replace(old, **changes)  # type: ignore[arg-type]  # any field by name: replace checks it
        state.cmd = new
        if new.fault_reset and not old.fault_reset and state.armed_rst:
            self._trips.reset(now)
        if new.force_fault and not old.force_fault:
            # Table D-4 attribute 0x11: external fault on the rising edge; E62 / E72 (section E-1 Example 2).
            if not state.trip:
                state.force_status = True
            state.raise_trip(self.traits.trip_force_fault)
        # After the reset above, so that a board restarted by it counts the bits of this very message.
        state.armed_fwd |= not new.fwd
        state.armed_rev |= not new.rev
        state.armed_rst |= not new.fault_reset
        self._trips.evaluate(now)

    def write_fault_reset(self, now: float, value: bool) -> None:
        """Control Supervisor attribute 0Ch Fault Rst written: "Reset fault / trip state of inverter
        when written to 1" (Table D-4, CompoNet manual). Each write of 1 resets: the same table says
        "on rising edge" for Force Fault (11h) and not here, and the rising-edge rule of the notes
        under Tables B-2 and after (004:1992) is for the RST bit of the I/O data, repeated each cycle."""
        self.command(now, fault_reset=value)
        if value:
            self._trips.reset(now)
            self._trips.evaluate(now)

    def set_terminals(self, now: float, mask: int) -> None:
        """Physical state of the intelligent input terminals, bit n-1 = terminal [n]."""
        self.advance(now)
        self._state.terminals = mask & ((1 << self.traits.input_terminals) - 1)
        self._trips.evaluate(now)

    @property
    def terminals(self) -> int:
        """Physical intelligent input terminals, bit n-1 = terminal [n] (the test rig's wiring)."""
        return self._state.terminals

    def set_local_run(self, now: float, direction: int) -> None:
        """Run command of the local sources (FW/RV terminals, operator): +1, -1 or 0."""
        self.advance(now)
        self._state.local_run = (direction > 0) - (direction < 0)
        self._trips.evaluate(now)

    @property
    def local_reference(self) -> int:
        """Frequency reference of the local sources (terminal analog input), 0.01 Hz."""
        return self._state.local_reference

    @local_reference.setter
    def local_reference(self, centihertz: int) -> None:
        self._state.local_reference = centihertz

    @property
    def time(self) -> float:
        """The instant the simulation has reached (the latest ``now`` it was given)."""
        return self._state.t

    @property
    def local_run(self) -> int:
        """Run command of the local sources: +1 (FW terminal), -1 (RV) or 0 (Table C-10 instance 9 on the RX)."""
        return self._state.local_run

    def press_stop_reset(self, now: float) -> None:
        """The operator's STOP/RESET key: clears a trip (section 4-5-2 warning, Table 25 Step II)."""
        self.advance(now)
        self._trips.reset(now)
        self._trips.evaluate(now)

    # -- network events ------------------------------------------------------------------------------
    def on_network_ok(self, now: float) -> None:
        """Valid I/O data arrived: restarts the P044 timer and ends an idle or error condition."""
        self.advance(now)
        self._network.ok(now)

    def on_network_error(self, now: float) -> None:
        """The connection was lost (timed out or closed): the P045 action (Table 12)."""
        self.advance(now)
        self._network.error(now)

    def on_idle(self, now: float) -> None:
        """The master entered idle mode: the P048 action (Table 12) if the inverter is running."""
        self.advance(now)
        self._network.idle(now)

    # -- trips ------------------------------------------------------------------------------------
    @property
    def trip(self) -> int:
        """Current trip as n of En, 0 when not tripped."""
        return self._state.trip

    def raise_trip(self, now: float, number: int) -> None:
        """Trip the inverter with En (an inverter-side fault of Table D-5, for test rigs)."""
        trip_code(self.family, number)
        self.advance(now)
        self._state.raise_trip(number)
        self._trips.evaluate(now)

    # -- sources, output and status ------------------------------------------------------------------
    @property
    def run_source(self) -> Source:
        return self._sources.run_source

    @property
    def reference_source(self) -> Source:
        return self._sources.reference_source

    @property
    def speed_unit(self) -> SpeedUnit:
        return self._sources.speed_unit

    @property
    def output_frequency(self) -> float:
        """Signed output frequency in Hz (negative in reverse)."""
        return self._state.frequency / 100

    def status(self) -> Status:
        """A snapshot of everything the input assemblies and the status attributes report."""
        return self._monitors.status()

    # -- flexible format (appendix F) ----------------------------------------------------------------
    def flexible_output(self, words: Sequence[int], now: float) -> None:
        """The output words of assembly 139, written to the mapped registers in order (appendix F)."""
        mapping = self._state.flexible
        if mapping is None:
            raise WrongState("the flexible format is not active (P046 = 6 and a valid P160-P179 at start-up)")
        if len(words) != len(mapping.outputs):
            raise BadRequest(f"flexible output is {len(mapping.outputs)} words, got {len(words)}")
        self.advance(now)
        for parameter, value in flexible_writes(mapping, self.registers, words):
            try:
                self._write(parameter, value, now)
            except RegisterError:
                self.flexible_write_errors += 1

    def flexible_input(self) -> list[int]:
        """The input words of assembly 159: each mapped register's word, 0 for a reserved word."""
        mapping = self._state.flexible
        if mapping is None:
            raise WrongState("the flexible format is not active (P046 = 6 and a valid P160-P179 at start-up)")
        return [self.read_word(address) if address else 0 for address in mapping.inputs]

    # -- registers ----------------------------------------------------------------------------------
    def _value(self, parameter: Parameter) -> int:
        computed = self._producers.get(parameter.key)
        return computed() if computed is not None else self._state.values[parameter.key]

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

    def keep_operator_entries(self, codes: list[str]) -> None:
        """The values of ``codes`` were entered on the Digital Operator: the EEPROM holds them, and a
        power cycle comes back with them. The CompoNet manual sets the option board's parameters on the
        operator and then has the system powered OFF and ON for them to take effect (section 3-3 Step 3),
        and leaves out only what the network writes (section E-2-2 note: Function Code and Modbus Register
        object writes are temporary until the ENTER command). Not a save through the option board:
        Identity attribute 9 does not count it ("changes using the other Inverter interfaces (Serial,
        Digital operator) will not influence this attribute", Table C-2). Kept in memory: the next EEPROM
        save hands them to the shell with the rest."""
        values = self._state.values
        for code in codes:
            parameter = self._by_code(code)
            number = parameter.function_code_number
            if parameter.saved and number is not None:
                self._eeprom[number] = values[parameter.key]

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
        if parameter.access is RegisterAccess.WRITE_STOPPED and self._sources.output_active():
            raise RegisterError(RegisterRefusal.NOT_WHILE_RUNNING, where, f"{parameter.key} is not run-mode editable")
        if parameter.torque_related and self._state.values["d060"] != 0:
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
            self._state.values[parameter.key] = value
        self._trips.evaluate(now)

    def _write_coils(self, value: int, now: float) -> None:
        state = self._state
        old, state.coils = state.coils, value
        if value & _EXT and not old & _EXT:
            # Section 4-7-3: user trips from the EXT coil (external trip E12, Table D-5).
            state.raise_trip(12)
        self._trips.evaluate(now)

    def _save(self) -> None:
        """EEPROM save (0900h): every parameter, and Identity attribute 9 counts it (Table C-2)."""
        values = self._state.values
        eeprom = {number: values[p.key] for number, p in self.registers.by_number.items() if p.saved}
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
        values = self._state.values
        rating = values["b049"]
        mode = values.get("b171", 1)
        values["d060"] = {2: 2, 3: 3}.get(mode, rating)
        self._save()

    @property
    def saved_values(self) -> dict[int, int]:
        """The values in EEPROM, by function code number."""
        return dict(self._eeprom)


__all__ = [
    "DriveState", "DriveStateDetail", "FlexibleMapping", "FlexibleMappingError", "FlexibleProblem", "FlexibleRule",
    "Inverter", "InverterModeError", "NetworkAction", "OptionCommand", "Source", "Status", "validate_flexible",
]
