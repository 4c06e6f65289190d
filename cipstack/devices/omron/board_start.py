"""The option board's start, at power-on and at each reset: it reads its configuration from the
inverter (section 1-1-1 "Simplified Start-up") and waits for fresh rising edges (Table B-2 note)."""

from __future__ import annotations

from .flexible import FlexibleMappingError, validate_flexible
from .registers import FLEXIBLE_FORMAT, TERMINAL_FRS, TORQUE_PATHS, FamilyTraits, RegisterSet
from .states import InverterState


class BoardStartup:
    """Starts the option board of one inverter; counts its restarts (power-on excluded)."""

    def __init__(self, state: InverterState, registers: RegisterSet, traits: FamilyTraits) -> None:
        self._state = state
        self._registers = registers
        self._traits = traits
        #: Times the option board restarted (power-on excluded): Identity reset, trip clear with C102 != 3.
        self.resets = 0

    def start(self) -> None:
        """What the board does at power-on and reset: read the terminal functions, the connection path
        and the flexible mapping; an illegal mapping or torque path trips."""
        state = self._state
        values = state.values
        state.terminal_functions = tuple(values[f"C{n:03d}"] for n in range(1, self._traits.input_terminals + 1))
        state.free_run_inputs = sum(1 << n for n, function in enumerate(state.terminal_functions)
                                    if function == TERMINAL_FRS)
        state.connection_path = values["P046"]
        state.armed_fwd = state.armed_rev = state.armed_rst = False
        state.flexible = None
        state.flexible_error = None
        mode = values["d060"]
        if state.connection_path == FLEXIBLE_FORMAT:
            try:
                state.flexible = validate_flexible(values, self._registers, mode)
            except FlexibleMappingError as exc:
                # Appendix F Note 5: Major Recoverable Fault and trip E64 (MX2) / E74 (RX).
                state.flexible_error = exc
                state.raise_trip(self._traits.trip_flexible_mapping)
        elif state.connection_path in TORQUE_PATHS and mode != 0:
            # Tables 22/23 note: torque-related data in the process area without torque control.
            state.raise_trip(self._traits.trip_flexible_mapping)

    def restart(self) -> None:
        """A reset of the board (not a power-on): counted, then started again."""
        self.resets += 1
        self.start()


__all__ = ["BoardStartup"]
