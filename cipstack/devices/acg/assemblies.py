"""The ACG-ET2 card's I/O assemblies (ACG-ET2 manual, "Implicit message": Input Instances, Output
Instances and the two bit tables that follow them).

* Outputs 20/21 and inputs 70/71 are the shared drive-profile layouts of ``drive_profile.py``
  with the speed words in rpm ("Speed Reference/Actual ... RPM unit").
* Outputs 100/101 and inputs 110/111 are the same bit layouts with the speed words in 0.01 Hz.
  The instance tables say only "Hz unit"; the count is the drive's own frequency word: the
  AC/DC Drive object gives Reference Hz/Actual Hz (0x2A attributes 101/100) as "0-400.00 Hz",
  and ACG RS-485 manual gives the frequency command 0x0380 and the output frequency 0x000A in 0.01 Hz,
  so 3000 is 30.00 Hz. The word's type, scale and unit are those of the register it carries
  (the frequency command for the reference, the output frequency for the actual speed), so the
  caller passes that register and the declaration says "Hz" with scale 0.01.
* Outputs 121-128 and inputs 141-148 ("smart scaling") are 1 to 8 words, "Control Parameter -
  n data" / "Status Parameter - n data": the drive registers whose addresses CM.51-CM.58 /
  CM.31-CM.38 hold. Their schemas are built from those registers, so the fields carry the
  registers' names, types and scales.

This module knows no drive: a word is described by anything with the attributes of
``ParameterWord`` (a drive ``Register`` has them).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Protocol

from ...assemblies.drive_profile import (
    basic_speed_control_input,
    basic_speed_control_output,
    extended_speed_control_input,
    extended_speed_control_output,
)
from ...assemblies.names import field_name, unique_field_names
from ...assemblies.schema import AssemblyField, AssemblySchema, word
from ...cip.types import UINT, CipType
from ...errors import UnknownKey

#: Output (O->T) instances, in CM.24 setting order (ACG-ET2 manual, "CIP Output Instance (CM.24)").
OUTPUT_INSTANCES: tuple[int, ...] = (20, 21, 100, 101, *range(121, 129))
#: Input (T->O) instances, in CM.23 setting order (ACG-ET2 manual, "CIP Input Instance (CM.23)").
INPUT_INSTANCES: tuple[int, ...] = (70, 71, 110, 111, *range(141, 149))
#: First smart-scaling instances: 121 carries one control word, 128 eight (likewise 141-148).
CONTROL_PARAMETER_BASE_INSTANCE = 120
STATUS_PARAMETER_BASE_INSTANCE = 140
MAX_PARAMETER_WORDS = 8

#: Instances whose speed word is the drive's frequency word (0.01 Hz) rather than rpm.
HZ_OUTPUTS = (100, 101)
HZ_INPUTS = (110, 111)


class ParameterWord(Protocol):
    """What a schema needs to know of a drive register."""

    @property
    def address(self) -> int: ...

    @property
    def code(self) -> str: ...

    @property
    def name(self) -> str: ...

    @property
    def type(self) -> CipType: ...

    @property
    def scale(self) -> float: ...

    @property
    def unit(self) -> str: ...


def parameter_words(instance: int) -> int:
    """How many words a smart-scaling instance carries (121/141: 1 ... 128/148: 8), 0 otherwise
    (the "Parameter Number" column of the CM.23/CM.24 tables)."""
    for base in (CONTROL_PARAMETER_BASE_INSTANCE, STATUS_PARAMETER_BASE_INSTANCE):
        if base < instance <= base + MAX_PARAMETER_WORDS:
            return instance - base
    return 0


def assembly_size(instance: int) -> int:
    """Data size in bytes (the "Data Size" column of the CM.23/CM.24 tables)."""
    words = parameter_words(instance)
    if words:
        return 2 * words
    if instance in OUTPUT_INSTANCES or instance in INPUT_INSTANCES:
        return 4
    raise UnknownKey(f"the ACG-ET2 has no assembly instance {instance}")


def _hz_speed(schema: AssemblySchema, name: str, register: ParameterWord) -> AssemblySchema:
    """``schema`` with its speed word ``name`` replaced by the drive's frequency word."""
    fields = [
        replace(f, type=register.type, unit=register.unit, scale=register.scale,
                help=f"{f.help} ({register.name}, 0x{register.address:04X})") if f.name == name else f
        for f in schema.fields
    ]
    return AssemblySchema(schema.instance, schema.name, schema.size, fields, schema.description)


def speed_output(instance: int, frequency_command: ParameterWord) -> AssemblySchema:
    """Output 20/100 (Run Fwd, Fault reset) or 21/101 (+ Run Rev, NetCtrl, NetRef); byte 1 is 0.
    NetRef and NetCtrl are "Not used" (note 2: reference and run control are set on the keypad)."""
    if instance == 20:
        return basic_speed_control_output(20, "rpm")
    if instance == 21:
        return extended_speed_control_output(21, "rpm")
    if instance == 100:
        return _hz_speed(basic_speed_control_output(100), "speed_reference", frequency_command)
    if instance == 101:
        return _hz_speed(extended_speed_control_output(101), "speed_reference", frequency_command)
    raise UnknownKey(f"{instance} is not a speed control output of the ACG-ET2")


#: ACG-ET2 manual disagrees with itself: the table after the input instances relates Ctrl From Net to 0x29
#: attribute 15, the Control Supervisor's own table serves "Control From Net." at 14. The object
#: table is what the device answers, so the bit links there.
CTRL_FROM_NET_ATTRIBUTE = 14


def speed_input(instance: int, output_frequency: ParameterWord) -> AssemblySchema:
    """Input 70/110 (Faulted, Running1) or 71/111 (all eight flags and Drive State). The Warning
    flag is "Not supported" (bit table after the input instances) and stays 0."""
    if instance == 70:
        return basic_speed_control_input(70, "rpm")
    if instance == 71:
        return extended_speed_control_input(71, "rpm", ctrl_from_net_attribute=CTRL_FROM_NET_ATTRIBUTE)
    if instance == 110:
        return _hz_speed(basic_speed_control_input(110), "speed_actual", output_frequency)
    if instance == 111:
        return _hz_speed(extended_speed_control_input(111, ctrl_from_net_attribute=CTRL_FROM_NET_ATTRIBUTE),
                         "speed_actual", output_frequency)
    raise UnknownKey(f"{instance} is not a speed control input of the ACG-ET2")


def _parameter_fields(kind: str, cm_first: int, words: Sequence[ParameterWord | None]) -> list[AssemblyField]:
    """One word per register, named by the field-name rule after its code or name; a register
    named twice gets its word number (``drive_model_4``: the register of CM.54 again)."""
    described: list[tuple[str, CipType, str, float, str]] = []
    for index, register in enumerate(words):
        number = index + 1
        where = f"{kind} Parameter - {number} data, the register named by CM.{cm_first + index}"
        if register is None:
            described.append((f"{kind.lower()}_parameter_{number}", UINT, "", 1.0, where))
        else:
            described.append((field_name(register.code or register.name) or f"{kind.lower()}_parameter_{number}",
                              register.type, register.unit, register.scale,
                              f"{register.name} (0x{register.address:04X}): {where}"))
    names = unique_field_names(name for name, *_ in described)
    return [word(name, 2 * index, cip_type, unit=unit, scale=scale, help=text)
            for index, (name, (_, cip_type, unit, scale, text)) in enumerate(zip(names, described, strict=True))]


def control_parameter_output(instance: int, words: Sequence[ParameterWord | None]) -> AssemblySchema:
    """Output 121-128: "Control Parameter - 1 ... n data", the registers CM.51-CM.5n name.
    ``words`` are those registers in order (None: the address names no register)."""
    count = parameter_words(instance)
    if not count or instance > CONTROL_PARAMETER_BASE_INSTANCE + MAX_PARAMETER_WORDS:
        raise UnknownKey(f"{instance} is not a control parameter output (121-128)")
    return AssemblySchema(instance, f"Control Parameter Output, {count} word(s)", 2 * count,
                          _parameter_fields("Control", 51, words[:count]))


def status_parameter_input(instance: int, words: Sequence[ParameterWord | None]) -> AssemblySchema:
    """Input 141-148: "Status Parameter - 1 ... n data", the registers CM.31-CM.3n name."""
    count = parameter_words(instance)
    if not count or instance <= STATUS_PARAMETER_BASE_INSTANCE:
        raise UnknownKey(f"{instance} is not a status parameter input (141-148)")
    return AssemblySchema(instance, f"Status Parameter Input, {count} word(s)", 2 * count,
                          _parameter_fields("Status", 31, words[:count]))


@dataclass(frozen=True)
class AcgAssemblies:
    """Every ACG-ET2 assembly schema for one set of smart-scaling addresses."""

    outputs: Mapping[int, AssemblySchema]
    inputs: Mapping[int, AssemblySchema]

    def __getitem__(self, instance: int) -> AssemblySchema:
        if instance in self.outputs:
            return self.outputs[instance]
        return self.inputs[instance]


def acg_assemblies(frequency_command: ParameterWord, output_frequency: ParameterWord,
                   control_words: Sequence[ParameterWord | None],
                   status_words: Sequence[ParameterWord | None]) -> AcgAssemblies:
    """All 24 schemas: ``frequency_command``/``output_frequency`` are the drive's Hz words,
    ``control_words``/``status_words`` the registers CM.51-CM.58 / CM.31-CM.38 name (8 each)."""
    outputs = {i: speed_output(i, frequency_command) for i in (20, 21, 100, 101)}
    outputs.update({i: control_parameter_output(i, control_words) for i in range(121, 129)})
    inputs = {i: speed_input(i, output_frequency) for i in (70, 71, 110, 111)}
    inputs.update({i: status_parameter_input(i, status_words) for i in range(141, 149)})
    return AcgAssemblies(outputs, inputs)


__all__ = [
    "HZ_INPUTS",
    "HZ_OUTPUTS",
    "INPUT_INSTANCES",
    "OUTPUT_INSTANCES",
    "AcgAssemblies",
    "ParameterWord",
    "acg_assemblies",
    "assembly_size",
    "control_parameter_output",
    "parameter_words",
    "speed_input",
    "speed_output",
    "status_parameter_input",
]
