"""The flexible format (appendix F): P160-P179 map up to eight Modbus registers into assemblies
139/159; ``validate_flexible`` applies the rules of appendix F and Table 25."""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from enum import Enum

from ...errors import BadRequest
from ..registers import RegisterAccess
from .registers import (
    Parameter,
    RegisterSet,
)

# -- flexible format (appendix F) -------------------------------------------------------------------

FLEXIBLE_WORDS = 8
OUTPUT_PARAMETERS = tuple(f"P16{n}" for n in range(FLEXIBLE_WORDS))
INPUT_PARAMETERS = tuple(f"P17{n}" for n in range(FLEXIBLE_WORDS))
#: "Be sure to keep parameters P168, P169, P178 and P179 always to zero" (appendix F Note 6).
RESERVED_PARAMETERS = ("P168", "P169", "P178", "P179")


class FlexibleRule(Enum):
    """The flexible-format rules of appendix F and Table 25 (Step I)."""

    RESERVED_NOT_ZERO = "P168, P169, P178 and P179 must be zero (Note 6)"
    EMPTY_AREA = "input and output each need at least one word (Note 1)"
    NO_SUCH_REGISTER = "the Modbus register does not exist (Table 25)"
    DOUBLE_WORD_SPLIT = "a double word needs its high word followed by its low word in two consecutive " \
                        "parameters; only the output area may take the low word alone (Note 3)"
    DUPLICATE_OUTPUT = "a register may be mapped only once in the output area (Note 4)"
    READ_ONLY_OUTPUT = "an output register must be writable (Table 25)"
    NOT_RUN_MODE_EDITABLE = "an output register must be editable in run mode (Table 25)"
    TORQUE_NOT_AVAILABLE = "torque-related registers need the constant-torque IM mode, d060 = 0 (Tables 22/23)"


@dataclass(frozen=True)
class FlexibleProblem:
    rule: FlexibleRule
    parameter: str
    address: int

    def __str__(self) -> str:
        return f"{self.parameter} = {self.address:04X}h: {self.rule.value}"


class FlexibleMappingError(BadRequest):
    """P160-P179 break a rule of appendix F; ``problems`` lists every broken rule."""

    def __init__(self, problems: Sequence[FlexibleProblem]) -> None:
        self.problems = tuple(problems)
        super().__init__("illegal flexible mapping: " + "; ".join(str(p) for p in self.problems))

    @property
    def rule(self) -> FlexibleRule:
        return self.problems[0].rule


@dataclass(frozen=True)
class FlexibleMapping:
    """Word addresses of the flexible output (master to inverter) and input areas; 0 reserves a word."""

    outputs: tuple[int, ...]
    inputs: tuple[int, ...]


def _area(values: Mapping[str, int], codes: Sequence[str]) -> tuple[int, ...]:
    entries = [values.get(code, 0) for code in codes]
    # Note 1: the size is set by the highest non-zero parameter.
    size = max((i + 1 for i, address in enumerate(entries) if address), default=0)
    return tuple(entries[:size])


def validate_flexible(values: Mapping[str, int], registers: RegisterSet, inverter_mode: int = 0) -> FlexibleMapping:
    """Check P160-P179 (``values`` by function code; missing ones are zero) against appendix F.

    Returns the word addresses of both areas, or raises ``FlexibleMappingError`` listing
    every rule broken (appendix F Notes 1-6, Table 25 Step I, the note of Tables 22/23).
    """
    problems: list[FlexibleProblem] = [FlexibleProblem(FlexibleRule.RESERVED_NOT_ZERO, code, values.get(code, 0))
                                       for code in RESERVED_PARAMETERS if values.get(code, 0)]
    outputs, inputs = _area(values, OUTPUT_PARAMETERS), _area(values, INPUT_PARAMETERS)
    for is_output, codes, entries in ((True, OUTPUT_PARAMETERS, outputs), (False, INPUT_PARAMETERS, inputs)):
        if not entries:
            problems.append(FlexibleProblem(FlexibleRule.EMPTY_AREA, f"{codes[0]}-{codes[-1]}", 0))
        seen: set[int] = set()
        for i, address in enumerate(entries):
            if not address:
                continue  # Note 2: a reserved word
            code = codes[i]
            found = registers.word(address)
            if found is None:
                problems.append(FlexibleProblem(FlexibleRule.NO_SUCH_REGISTER, code, address))
                continue
            parameter, index = found
            if parameter.words == 2:
                following = entries[i + 1] if i + 1 < len(entries) else 0
                preceding = entries[i - 1] if i > 0 else 0
                if (index == 0 and following != address + 1) or (
                        index == 1 and not is_output and preceding != address - 1):
                    problems.append(FlexibleProblem(FlexibleRule.DOUBLE_WORD_SPLIT, code, address))
            if is_output:
                if address in seen:
                    problems.append(FlexibleProblem(FlexibleRule.DUPLICATE_OUTPUT, code, address))
                seen.add(address)
                if not parameter.access.writable:
                    problems.append(FlexibleProblem(FlexibleRule.READ_ONLY_OUTPUT, code, address))
                elif parameter.access is RegisterAccess.WRITE_STOPPED:
                    problems.append(FlexibleProblem(FlexibleRule.NOT_RUN_MODE_EDITABLE, code, address))
            if parameter.torque_related and inverter_mode != 0:
                problems.append(FlexibleProblem(FlexibleRule.TORQUE_NOT_AVAILABLE, code, address))
    if problems:
        raise FlexibleMappingError(problems)
    return FlexibleMapping(outputs, inputs)


def flexible_writes(mapping: FlexibleMapping, registers: RegisterSet,
                    words: Sequence[int]) -> Iterator[tuple[Parameter, int]]:
    """The register writes the output words of assembly 139 make, in order (appendix F): each mapped
    register and its value (a double word from two words, signed types signed)."""
    outputs = mapping.outputs
    i = 0
    while i < len(outputs):
        address, word = outputs[i], words[i] & 0xFFFF
        i += 1
        if not address:
            continue   # Note 2: a reserved word is ignored
        found = registers.word(address)
        if found is None:   # validate_flexible let no such address through
            raise AssertionError(f"{address:04X}h is not a register")
        parameter, index = found
        value = word
        if parameter.words == 2 and index == 0:
            value = word << 16 | (words[i] & 0xFFFF)
            i += 1
        if parameter.signed and parameter.words == 1 and value >= 0x8000:
            value -= 0x10000
        elif parameter.signed and parameter.words == 2 and index == 0 and value >= 0x80000000:
            value -= 1 << 32
        yield parameter, value
