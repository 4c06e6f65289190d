"""The drive memory control area (ACG RS-485 manual, 0x03E0-0x03EC): the saved parameters and the
password locks, what a power cycle keeps."""

from __future__ import annotations

from collections.abc import Callable, Mapping

from ..registers import RegisterError, RegisterMap, RegisterRefusal
from ..state import StateFileError
from .registers import ALIASES, SAVE_PARAMETERS

#: What the drive hands a save to: every saved value (address -> raw). It may refuse the save
#: by raising ``StateFileError`` (the state file is known not to be writable); what it returns (a
#: writer's future) is the shell's.
SaveRequest = Callable[[dict[int, int]], object]


class SavedParameters:
    """The values a power cycle comes back with, and the shell's ``on_save`` each save is handed to:
    the drive does no file I/O itself."""

    def __init__(self, registers: RegisterMap, on_save: SaveRequest | None) -> None:
        self._registers = registers
        self.on_save = on_save
        #: Address -> raw value, beyond the defaults.
        self.saved: dict[int, int] = {}

    def restore(self, saved: Mapping[int, int], values: dict[int, int], origin: str, model: str) -> None:
        """Put ``saved`` into ``values`` at power-up; a ``StateFileError`` naming ``origin`` if one is
        no saved parameter of this drive or out of range."""
        for address, value in saved.items():
            register = self._registers.get(address)
            if register is None or not register.saved or address in ALIASES:
                raise StateFileError(f"{origin}: 0x{address:04X} is not a saved parameter of the {model}")
            try:
                register.check(value)
            except RegisterError as exc:
                raise StateFileError(f"{origin}: {exc}") from None
            values[address] = value
        self.saved = dict(saved)

    def save_all(self, values: Mapping[int, int]) -> None:
        """Save every keypad parameter as it is in ``values`` (what 0x03E0 0 -> 1 does)."""
        self.persist({a: values[a] for a, r in self._registers.items() if r.saved and a not in ALIASES})

    def save_some(self, values: Mapping[int, int]) -> None:
        """Save these values (address -> raw) on top of the saved ones."""
        self.persist({**self.saved, **values})

    def keep(self, values: Mapping[int, int]) -> None:
        """Keypad entries (address -> raw): a drive keeps what its keypad enters, where communication
        writes are lost unless saved (ACG RS-485 manual, "Saving Parameters Defined by Communication"),
        so a power cycle comes back with them. Kept in memory, not handed to the shell: the next save
        writes them with the rest, and the emulator's command line enters them again at its next start."""
        kept = {a: v for a, v in values.items() if (r := self._registers.get(a)) is not None and r.saved
                and a not in ALIASES}
        self.saved = {**self.saved, **kept}

    def persist(self, saved: dict[int, int]) -> None:
        """Hand a save to the shell; refused (``RegisterError`` SAVE_FAILED), nothing is saved."""
        if self.on_save is not None:
            try:
                self.on_save(dict(saved))
            except StateFileError as exc:
                raise RegisterError(RegisterRefusal.SAVE_FAILED, SAVE_PARAMETERS.address, str(exc)) from None
        self.saved = saved

    def forget(self) -> None:
        """The saved values go (a save the shell refuses, ``StateFileError``, changes nothing)."""
        if self.on_save is not None:
            self.on_save({})
        self.saved = {}


class PasswordLocks:
    """0x03E7 Hide parameter mode and 0x03E8 Lock parameter mode, with the keypad's password."""

    def __init__(self, password: int | None) -> None:
        #: The password registered from the keypad (None: none registered).
        self.password = password
        self.hide_locked = False
        self.parameter_locked = False

    def enter(self, address: int, value: int, previous: int) -> None:
        """``value`` written at 0x03E7/0x03E8 over ``previous``: entering the password toggles Lock/Unlock;
        the same value entered again in a row executes once only (ACG RS-485 manual)."""
        if value == previous or self.password is None or value != self.password:
            return
        if address == 0x03E7:
            self.hide_locked = not self.hide_locked
        else:
            self.parameter_locked = not self.parameter_locked


__all__ = ["PasswordLocks", "SaveRequest", "SavedParameters"]
