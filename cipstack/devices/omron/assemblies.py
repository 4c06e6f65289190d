"""The I/O assemblies of the Omron MX2/RX CompoNet option board (appendix B, Table C-6).

20/70 and 21/71 are the AC drive profile layouts the ACG shares (``drive_profile``); every
other instance is the option board's own and its name says so (``omron_...``): in particular
110/111 here are Extended Speed and Acceleration Control (Tables B-24 to B-27), not the ACG's
110/111. The Rotational Speed words are in RPM, 0.1 Hz or 0.01 Hz depending on P049 and d060
(section 4-2-5), so each schema is built for a ``SpeedUnit``. The flexible format 139/159 has
one UINT per mapped word, as many words as P160-P167 / P170-P177 give (appendix F Note 1).

``pair_sizes`` gives the bytes of the pair P046 selects (Table 10) and ``componet_io_words`` the
``[CompoNet_IO]`` lengths of section 3-4 Step 7 (in words) from the same declarations.
"""

from __future__ import annotations

from collections.abc import Mapping
from functools import cache
from types import MappingProxyType

from ...assemblies.drive_profile import (
    AC_DC_DRIVE,
    CONTROL_SUPERVISOR,
    basic_speed_control_input,
    basic_speed_control_output,
    extended_speed_control_input,
    extended_speed_control_output,
)
from ...assemblies.schema import AssemblyField, AssemblySchema, bit, word
from ...cip.types import INT, UINT, USINT
from ...errors import BadRequest

#: Output (consumed) and input (produced) instances of Table C-6 (173 from Table B-11, see below).
OUTPUT_INSTANCES = (20, 21, 100, 101, 110, 123, 139)
INPUT_INSTANCES = (70, 71, 111, 150, 151, 153, 159, 173)
FLEXIBLE_OUTPUT = 139
FLEXIBLE_INPUT = 159
#: Table C-6 "BYTE x 16 max": eight words (appendix F Note 1).
FLEXIBLE_MAX_WORDS = 8

#: Table C-6 sizes in bytes. Table C-6 has no row for input 173; Table B-11 gives it three words.
SIZES: Mapping[int, int] = MappingProxyType({
    20: 4, 21: 4, 70: 4, 71: 4, 100: 8, 101: 8, 110: 8, 111: 8, 123: 6, 150: 8, 151: 8, 153: 10, 173: 6,
})

#: Engineering unit and scale of the Rotational Speed words (section 4-2-5): 0.01 Hz, 0.1 Hz or RPM.
CENTIHERTZ = ("Hz", 0.01)
DECIHERTZ = ("Hz", 0.1)
RPM = ("rpm", 1.0)

# Special I/O function codes (Table B-14) and fault codes (Table B-17).
SPECIAL_READ_WORD = 0x03
SPECIAL_WRITE_WORD = 0x10
SPECIAL_READ_DOUBLE = 0x43
SPECIAL_WRITE_DOUBLE = 0x50
SPECIAL_FUNCTION_CODES = frozenset({SPECIAL_READ_WORD, SPECIAL_WRITE_WORD, SPECIAL_READ_DOUBLE, SPECIAL_WRITE_DOUBLE})
#: Table B-16: a failed request answers its function code OR'ed with 80h.
SPECIAL_FAILURE = 0x80
FAULT_FUNCTION_CODE = 0x01
FAULT_REGISTER_NUMBER = 0x02
FAULT_SLAVE_DEVICE = 0x04
FAULT_DATA_SETTING = 0x21
FAULT_WRITING_MODE = 0x22
FAULT_REGISTER_SIZE = 0x23
SPECIAL_FAULTS: Mapping[int, str] = MappingProxyType({
    FAULT_FUNCTION_CODE: "Function code error", FAULT_REGISTER_NUMBER: "Register number error",
    FAULT_SLAVE_DEVICE: "Slave device failure", FAULT_DATA_SETTING: "Data setting error",
    FAULT_WRITING_MODE: "Writing mode error", FAULT_REGISTER_SIZE: "Register size error"})


def _speed(name: str, unit: tuple[str, float], attribute: int, text: str) -> AssemblyField:
    label, scale = unit
    return word(name, 2, INT, unit=label, scale=scale, help=text, link=(AC_DC_DRIVE, 1, attribute))


def _torque(name: str, offset: int, attribute: int, text: str) -> AssemblyField:
    return word(name, offset, INT, unit="%", help=text, link=(AC_DC_DRIVE, 1, attribute))


def _current(offset: int) -> AssemblyField:
    return word("output_current", offset, INT, unit="A", scale=0.1, help="Output current monitor",
                link=(AC_DC_DRIVE, 1, 9))


def _status_byte0_extended() -> list[AssemblyField]:
    """Byte 0 of inputs 151/153 (Tables B-20, B-22)."""
    return [
        bit("running_forward", 0, 0, help="DFR: during forward run", link=(CONTROL_SUPERVISOR, 1, 7)),
        bit("zero_speed", 0, 1, help="DZS: during zero speed", link=(AC_DC_DRIVE, 1, 0x7A)),
        bit("running_reverse", 0, 2, help="DRR: during reverse run", link=(CONTROL_SUPERVISOR, 1, 8)),
        bit("at_reference", 0, 4, help="ARF: at reference", link=(AC_DC_DRIVE, 1, 3)),
        bit("ready", 0, 5, help="RDY: inverter ready", link=(CONTROL_SUPERVISOR, 1, 9)),
        bit("warning", 0, 6, help="WR: warning", link=(CONTROL_SUPERVISOR, 1, 11)),
        bit("faulted", 0, 7, help="FLT: fault/trip", link=(CONTROL_SUPERVISOR, 1, 10)),
        bit("ctrl_from_net", 1, 2, help="CFN: run command from the network", link=(CONTROL_SUPERVISOR, 1, 15)),
        bit("relay_output", 1, 3, help="MR: monitor relay output"),
        *(bit(f"output_{n}", 1, 3 + n, help=f"MO{n}: monitor output [{n}]" + (" (RX)" if n > 2 else ""))
          for n in range(1, 5)),
    ]


@cache
def omron_schemas(unit: tuple[str, float] = CENTIHERTZ) -> Mapping[int, AssemblySchema]:
    """Every fixed-size assembly of the option board, by instance, with speed words in ``unit``
    (``CENTIHERTZ``, ``DECIHERTZ`` or ``RPM``)."""
    label, scale = unit
    schemas = [
        # B-1, B-2: the AC drive profile layouts shared with the ACG.
        basic_speed_control_output(20, label, scale),
        basic_speed_control_input(70, label, scale),
        extended_speed_control_output(21, label, scale),
        extended_speed_control_input(71, label, scale),
        # B-3: Extended Speed and Torque Control (Tables B-9, B-11).
        AssemblySchema(123, "Omron Extended Speed and Torque Control Output", 6, [
            *extended_speed_control_output(21, label, scale).fields,
            _torque("torque_reference", 4, 0x78, "Reference torque")]),
        AssemblySchema(173, "Omron Extended Speed and Torque Control Input", 6, [
            *extended_speed_control_input(71, label, scale).fields,
            _torque("torque_actual", 4, 0x77, "Actual torque monitor")]),
        # B-4: Special I/O (Tables B-13, B-15).
        AssemblySchema(100, "Omron Special Output", 8, _special_fields()),
        AssemblySchema(150, "Omron Special Input", 8, _special_fields()),
        # B-5: Extended Control I/O (Tables B-18, B-20, B-22).
        AssemblySchema(101, "Omron Extended Control Output", 8, [
            bit("run_forward", 0, 0, help="FWD: forward run", link=(CONTROL_SUPERVISOR, 1, 3)),
            bit("run_reverse", 0, 1, help="REV: reverse run", link=(CONTROL_SUPERVISOR, 1, 4)),
            *(bit(f"override_input_{n}", 0, n - 1, help=f"CI{n}: override input terminal [{n}]"
                  + (" (RX)" if n == 8 else ""), link=(0x08, n, 0x69)) for n in range(3, 9)),
            bit("force_fault", 1, 0, help="FFL: force external fault/trip on 0 to 1", link=(CONTROL_SUPERVISOR, 1, 17)),
            bit("fault_reset", 1, 1, help="RST: fault reset on 0 to 1", link=(CONTROL_SUPERVISOR, 1, 12)),
            *(bit(f"set_output_{n}", 1, n - 1, help=f"CO{n}: set output [{n}] (RX)") for n in range(3, 6)),
            bit("set_relay", 1, 5, help="CR: set relay output"),
            bit("set_output_1", 1, 6, help="CO1: set output [1]"),
            bit("set_output_2", 1, 7, help="CO2: set output [2]"),
            _speed("speed_reference", unit, 8, "Rotational speed reference"),
            _torque("torque_reference", 4, 0x78, "Reference torque"),
            _torque("torque_bias", 6, 0x79, "Torque compensation bias"),
        ]),
        AssemblySchema(151, "Omron Extended Control Input", 8, [
            *_status_byte0_extended(),
            _speed("speed_actual", unit, 7, "Rotational speed monitor"),
            _torque("torque_actual", 4, 0x77, "Actual torque monitor"),
            _current(6),
        ]),
        AssemblySchema(153, "Omron Extended Control and Multi Function Input", 10, [
            *_status_byte0_extended(),
            _speed("speed_actual", unit, 7, "Rotational speed monitor"),
            _torque("torque_actual", 4, 0x77, "Actual torque monitor"),
            _current(6),
            *(bit(f"input_{n}", 8, n - 1, help=f"MI{n}: monitor input terminal [{n}]" + (" (RX)" if n == 8 else ""),
                  link=(0x08, n, 3)) for n in range(1, 9)),
        ]),
        # B-6: Extended Speed and Acceleration Control (Tables B-24, B-26); not the ACG's 110/111.
        AssemblySchema(110, "Omron Extended Speed and Acceleration Control Output", 8, [
            bit("run_forward", 0, 0, help="FWD: forward run", link=(CONTROL_SUPERVISOR, 1, 3)),
            bit("run_reverse", 0, 1, help="REV: reverse run", link=(CONTROL_SUPERVISOR, 1, 4)),
            bit("fault_reset", 0, 2, help="RST: fault reset on 0 to 1", link=(CONTROL_SUPERVISOR, 1, 12)),
            bit("free_run", 0, 3, help="FRS: free run stop", link=(CONTROL_SUPERVISOR, 1, 0x66)),
            bit("net_ctrl", 0, 5, help="CTR: run command from the network", link=(CONTROL_SUPERVISOR, 1, 5)),
            bit("net_ref", 0, 6, help="REF: speed and ramp times from the network", link=(AC_DC_DRIVE, 1, 4)),
            _speed("speed_reference", unit, 8, "Rotational speed reference"),
            word("accel_time", 4, UINT, unit="s", scale=0.1, help="Acceleration time (0.1 to 3600.0 s)"),
            word("decel_time", 6, UINT, unit="s", scale=0.1, help="Deceleration time (0.1 to 3600.0 s)"),
        ]),
        AssemblySchema(111, "Omron Extended Speed and Acceleration Control Input", 8, [
            bit("running_forward", 0, 0, help="DFR: during forward run", link=(CONTROL_SUPERVISOR, 1, 7)),
            bit("running_reverse", 0, 1, help="DRR: during reverse run", link=(CONTROL_SUPERVISOR, 1, 8)),
            bit("faulted", 0, 2, help="FLT: fault/trip", link=(CONTROL_SUPERVISOR, 1, 10)),
            bit("at_reference", 0, 4, help="ARF: at reference", link=(AC_DC_DRIVE, 1, 3)),
            *(bit(f"input_{n}", 0, 4 + n, help=f"MI{n}: monitor input terminal [{n}]") for n in range(1, 4)),
            AssemblyField("drive_state_detail", 1, USINT, help="Drive status detail",
                          link=(CONTROL_SUPERVISOR, 1, 0x64)),
            _speed("speed_actual", unit, 7, "Rotational speed monitor"),
            _current(4),
            AssemblyField("trip_cause", 6, USINT, help="Trip cause: n of En", link=(CONTROL_SUPERVISOR, 1, 0x65)),
            *(bit(f"input_{n}", 7, n - 4, help=f"MI{n}: monitor input terminal [{n}]" + (" (RX)" if n == 8 else ""))
              for n in range(4, 9)),
            bit("forward_terminal", 7, 5, help="FWT: forward terminal state (RX)", link=(0x08, 9, 3)),
            bit("ctrl_from_net", 7, 6, help="CFN: run command from the network", link=(CONTROL_SUPERVISOR, 1, 15)),
            bit("ref_from_net", 7, 7, help="RFN: speed reference from the network", link=(AC_DC_DRIVE, 1, 29)),
        ]),
    ]
    for schema in schemas:
        assert schema.size == SIZES[schema.instance], schema
    return MappingProxyType({s.instance: s for s in schemas})


def _special_fields() -> list[AssemblyField]:
    return [
        AssemblyField("function_code", 0, USINT, help="03/10/43/50h; a failure answers it OR'ed with 80h"),
        word("register_number", 2, UINT, help="Modbus register number"),
        word("data_word_0", 4, UINT, help="Least significant word (on failure: the fault code of Table B-17)"),
        word("data_word_1", 6, UINT, help="Most significant word"),
    ]


@cache
def flexible_schema(instance: int, words: int) -> AssemblySchema:
    """Flexible output 139 or input 159 with ``words`` words (1 to 8): word n is the register of P16n / P17n."""
    if instance not in (FLEXIBLE_OUTPUT, FLEXIBLE_INPUT) or not 1 <= words <= FLEXIBLE_MAX_WORDS:
        raise BadRequest(f"no flexible assembly {instance} of {words} words")
    area, first = ("Output", "P16") if instance == FLEXIBLE_OUTPUT else ("Input", "P17")
    return AssemblySchema(instance, f"Omron Flexible {area}", 2 * words, [
        word(f"word_{n}", 2 * n, UINT, help=f"Modbus register set by {first}{n}") for n in range(words)])


def pair_sizes(output: int, input_: int, flexible: tuple[int, int] | None = None) -> tuple[int, int]:
    """(output bytes, input bytes) of an assembly pair of Table 10 (the pair P046 selects). The
    flexible pair 139/159 needs its word counts (output, input) from the mapping (appendix F Note 1)."""
    if output == FLEXIBLE_OUTPUT:
        if flexible is None:
            raise BadRequest("the flexible format's size depends on P160-P177: give the word counts")
        return 2 * flexible[0], 2 * flexible[1]
    return SIZES[output], SIZES[input_]


def componet_io_words(output: int, input_: int, flexible: tuple[int, int] | None = None) -> tuple[int, int]:
    """(input words, output words) of a pair for ``[CompoNet_IO]`` (section 3-4 Step 7: lengths in words)."""
    out_bytes, in_bytes = pair_sizes(output, input_, flexible)
    return (in_bytes + 1) // 2, (out_bytes + 1) // 2


__all__ = [
    "CENTIHERTZ", "DECIHERTZ", "FLEXIBLE_INPUT", "FLEXIBLE_MAX_WORDS", "FLEXIBLE_OUTPUT", "INPUT_INSTANCES",
    "OUTPUT_INSTANCES", "RPM", "SIZES", "SPECIAL_FAULTS", "SPECIAL_FUNCTION_CODES", "componet_io_words",
    "flexible_schema", "omron_schemas", "pair_sizes",
]
