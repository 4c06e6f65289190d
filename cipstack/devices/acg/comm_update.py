"""CM.94 Comm Update: CM.7 and CM.10-CM.24 take effect on the ACG-ET2 card only when it is set to 1
(ACG-ET2 manual); until then they are pending."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ..registers import RegisterMap
from . import registers as reg
from .memory import SavedParameters
from .registers import COMM_UPDATE_CODES, InstanceSelection


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


class CommUpdate:
    """The card's communication settings: those of the last CM.94 update (or of power-up), and the
    CM parameters as written."""

    def __init__(self, registers: RegisterMap, values: dict[int, int], saving: SavedParameters) -> None:
        self._registers = registers
        self._values = values
        self._saving = saving
        self._active = {code: self._value(code) for code in COMM_UPDATE_CODES}

    def _value(self, code: str) -> int:
        return self._values[self._registers.by_code(code).address]

    @property
    def active(self) -> CommSettings:
        return CommSettings.from_values(self._active.__getitem__)

    @property
    def pending(self) -> CommSettings:
        return CommSettings.from_values(self._value)

    @property
    def update_pending(self) -> bool:
        """CM parameters changed without CM.94."""
        return any(self._value(code) != self._active[code] for code in COMM_UPDATE_CODES)

    def apply(self) -> None:
        """CM.94 = 1: the written settings become the card's."""
        # "This action will prevent any data loss from a drive power loss": the CM group is saved.
        self._saving.save_some({r.address: self._values[r.address] for r in self._registers.group("CM") if r.saved})
        self._active = {code: self._value(code) for code in COMM_UPDATE_CODES}


__all__ = ["CommSettings", "CommUpdate"]
