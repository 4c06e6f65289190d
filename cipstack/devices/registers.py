"""Drive registers, declared once.

A drive (the ACG, an MX2 or RX inverter) is at heart a table of 16-bit registers: the
keypad parameters and the monitoring/control words that Modbus addresses directly and that
the CIP objects (0x28, 0x29, 0x2A, 0x64, 0x65) and the assemblies map onto. Each register is
declared here once, with its address, keypad code, name, data type, scale, unit, access,
default and range; the CIP attributes, the Modbus server, the EDS parameters and the docs
all derive from that one declaration.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from enum import Enum

from ..cip.types import INT, UINT, CipType
from ..errors import BadRequest, StateRefused


class RegisterAccess(Enum):
    READ = "R"
    READ_WRITE = "R/W"
    #: Writable only while the drive is stopped (the manuals mark these "not editable in run").
    WRITE_STOPPED = "R/W (stopped)"
    WRITE = "W"

    @property
    def writable(self) -> bool:
        return self is not RegisterAccess.READ


class RegisterRefusal(Enum):
    """Why a register write is refused; each transport maps it to its own error code."""

    NO_SUCH_REGISTER = "no such register"
    READ_ONLY = "read-only register"
    OUT_OF_RANGE = "value out of range"
    NOT_WHILE_RUNNING = "not writable while running"
    #: A save the state file could not take (read-only directory, full disk): nothing saved.
    SAVE_FAILED = "parameters not saved"


class RegisterError(StateRefused):
    def __init__(self, refusal: RegisterRefusal, address: int, detail: str = "") -> None:
        self.refusal = refusal
        self.address = address
        text = f"register 0x{address:04X}: {refusal.value}"
        super().__init__(f"{text} ({detail})" if detail else text)


@dataclass(frozen=True)
class Register:
    #: Protocol address of the (first) register as the manual writes it, e.g. 0x1117.
    address: int
    #: Keypad code, e.g. "CM.23", "dr.3", "F001"; empty for registers that have none.
    code: str
    name: str
    type: CipType = UINT
    access: RegisterAccess = RegisterAccess.READ_WRITE
    default: int = 0
    minimum: int | None = None
    maximum: int | None = None
    #: Engineering value = raw x scale (0.01 for a frequency in 0.01 Hz).
    scale: float = 1.0
    unit: str = ""
    enum: Mapping[int, str] | None = None
    help: str = ""
    #: Parameter group (keypad group name, e.g. "CM", "Pr", or an area such as "monitor").
    group: str = ""
    #: 1 for a word, 2 for a double word (high word at ``address``, low word next, unless
    #: ``low_word_first``).
    words: int = 1
    low_word_first: bool = False
    #: A parameter that the save command persists (keypad parameters are; monitor words not).
    saved: bool = True
    #: Where the value is declared in the manual, e.g. "ACG-ET2 manual table CM".
    source: str = ""
    #: False for a parameter its manual's address table prints without an address ("-"): it is
    #: reached by its keypad code alone (CIP class 0x64), and ``address`` is only the key the
    #: device holds it under, never served at that address (Modbus, smart-scaling words).
    addressed: bool = True
    #: False for a monitor the simulation has no model for (an output current needs a motor and a
    #: load): it reads 0, and the front panel, ``record`` and the docs say "not simulated".
    simulated: bool = True

    @property
    def signed(self) -> bool:
        return self.type is INT or getattr(self.type, "signed", False)

    @property
    def raw_minimum(self) -> int:
        if self.minimum is not None:
            return self.minimum
        bits = 16 * self.words
        return -(1 << (bits - 1)) if self.signed else 0

    @property
    def raw_maximum(self) -> int:
        if self.maximum is not None:
            return self.maximum
        bits = 16 * self.words
        return (1 << (bits - 1)) - 1 if self.signed else (1 << bits) - 1

    def check(self, value: int) -> int:
        """Return ``value`` if it is within range, else raise ``RegisterError``."""
        if not self.raw_minimum <= value <= self.raw_maximum:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, self.address,
                                f"{value} not in {self.raw_minimum}..{self.raw_maximum}")
        if self.enum is not None and self.minimum is None and value not in self.enum:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, self.address, f"{value} not enumerated")
        return value

    def to_words(self, value: int) -> list[int]:
        """Split a value into its 16-bit register words as they appear on the wire."""
        raw = value & ((1 << (16 * self.words)) - 1)
        words = [(raw >> (16 * i)) & 0xFFFF for i in reversed(range(self.words))]
        return list(reversed(words)) if self.low_word_first else words

    def from_words(self, words: Iterable[int]) -> int:
        ordered = list(words)
        if self.low_word_first:
            ordered.reverse()
        raw = 0
        for word in ordered:
            raw = (raw << 16) | (word & 0xFFFF)
        if self.signed and raw >= 1 << (16 * self.words - 1):
            raw -= 1 << (16 * self.words)
        return raw


class RegisterMap(Mapping[int, Register]):
    """All registers of a drive, by address, with lookup by keypad code."""

    def __init__(self, registers: Iterable[Register]) -> None:
        self._by_address: dict[int, Register] = {}
        self._by_code: dict[str, Register] = {}
        #: Every word address -> (register, word index) including the second word of a double.
        self._words: dict[int, tuple[Register, int]] = {}
        for register in registers:
            for index in range(register.words):
                address = register.address + index
                if address in self._words:
                    other = self._words[address][0]
                    raise BadRequest(f"register 0x{address:04X} declared twice ({other.code or other.name}"
                                     f" and {register.code or register.name})")
                self._words[address] = (register, index)
            self._by_address[register.address] = register
            if register.code:
                if register.code in self._by_code:
                    raise BadRequest(f"keypad code {register.code} declared twice")
                self._by_code[register.code] = register

    def __getitem__(self, address: int) -> Register:
        return self._by_address[address]

    def __iter__(self) -> Iterator[int]:
        return iter(sorted(self._by_address))

    def __len__(self) -> int:
        return len(self._by_address)

    def by_code(self, code: str) -> Register:
        return self._by_code[code]

    def word(self, address: int) -> tuple[Register, int] | None:
        """The register that holds word ``address`` and which of its words it is."""
        return self._words.get(address)

    def group(self, name: str) -> list[Register]:
        return [r for r in (self._by_address[a] for a in self) if r.group == name]
