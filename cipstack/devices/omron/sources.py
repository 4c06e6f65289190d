"""Where the inverter's run command and frequency reference come from (A001/A002, the NetCtrl/NetRef
overrides), and what follows: the direction commanded, the target frequency, the RUN state."""

from __future__ import annotations

from .registers import FamilyTraits, SpeedUnit, speed_to_centihertz
from .states import _DIR, _EPSILON, _IN_SHIFT, _OPR, InverterState, Source


class Sources:
    """The run and reference sources of one inverter, read from its state."""

    def __init__(self, state: InverterState, traits: FamilyTraits) -> None:
        self._state = state
        self._traits = traits
        self._input_mask = (1 << traits.input_terminals) - 1

    @property
    def run_source(self) -> Source:
        state = self._state
        a002 = state.values["A002"]
        # Section 4-2-1 note: CTR has the effect of temporarily setting A002 to the option board.
        if state.cmd.net_ctrl or a002 == self._traits.option_source:
            return Source.OPTION_BOARD
        return Source.MODBUS if a002 == self._traits.modbus_source else Source.LOCAL

    @property
    def reference_source(self) -> Source:
        state = self._state
        a001 = state.values["A001"]
        if state.cmd.net_ref or a001 == self._traits.option_source:
            return Source.OPTION_BOARD
        if a001 == self._traits.modbus_source:
            return Source.MODBUS
        return Source.OPERATOR if a001 == self._traits.operator_source else Source.LOCAL

    @property
    def speed_unit(self) -> SpeedUnit:
        values = self._state.values
        return self._traits.speed_unit(values["P049"], values["d060"])

    def run_direction(self) -> int:
        """The direction commanded: +1, -1 or 0."""
        state = self._state
        if state.trip or state.pending_trip:
            return 0
        source = self.run_source
        if source is Source.OPTION_BOARD:
            cmd = state.cmd
            forward = cmd.fwd and state.armed_fwd
            reverse = cmd.rev and state.armed_rev
            return 1 if forward and not reverse else -1 if reverse and not forward else 0
        if source is Source.MODBUS:
            # Coil data 0 Opr/Dir: level commands, no rising-edge rule (section 4-7-3 warning).
            coils = state.coils
            return 0 if not coils & _OPR else -1 if coils & _DIR else 1
        return state.local_run

    def reference(self) -> float:
        """Frequency reference in 0.01 Hz, limited to the maximum frequency A004."""
        state = self._state
        source = self.reference_source
        if source is Source.OPTION_BOARD:
            reference = speed_to_centihertz(state.cmd.speed_reference, self.speed_unit, state.values["P049"])
        elif source in (Source.MODBUS, Source.OPERATOR):
            reference = state.values["F001"]
        else:
            reference = state.local_reference
        return min(max(reference, 0.0), state.values["A004"] * 10.0)

    def inputs(self) -> int:
        """The intelligent input terminals as the inverter sees them: wired, coils, overrides."""
        state = self._state
        return (state.terminals | state.coils >> _IN_SHIFT | state.cmd.input_overrides) & self._input_mask

    def free_running(self) -> bool:
        """Free Run commanded, or an input terminal set to FRS is on (asked many times per datagram:
        the FRS terminals are a mask the board's start computes)."""
        state = self._state
        if state.cmd.free_run:
            return True
        return bool(state.free_run_inputs) and bool(self.inputs() & state.free_run_inputs)

    def target(self) -> float:
        """The signed output frequency the inverter is heading for, 0.01 Hz."""
        return self.run_direction() * self.reference()

    def output_active(self) -> bool:
        """The RUN state: the inverter drives the motor (a run command, or decelerating to a stop)."""
        if self._state.trip or self.free_running():
            return False
        return self.run_direction() != 0 or abs(self._state.frequency) > _EPSILON


__all__ = ["Sources"]
