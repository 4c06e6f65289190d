"""The MX2/RX Digital Operator (``cipstack.devices.keypad``): function codes in the operator's unit.

The inverter's parameters are set on its Digital Operator by function code (F001, A001, A004, b049,
P044, P046...: CompoNet manual sections 3-2 and 4-1 set them there, "Set the desired parameters of the RX
Inverter with the Digital Operator Display", section 2-3-2-1). A value is entered in the unit of the
parameter's table (A004 in 0.1 Hz steps, F001 in 0.01 Hz, P044 in 0.1 s) and written with the
inverter's own rules (``Inverter.write_from_operator``): read-only monitors, the range, parameters
that are not run-mode editable while the output is on, torque-related ones outside d060 = 0. The
Function Code object's limit on F001 (section E-2-2) is the network's, not the operator's.

What is entered on the operator at start (``--param``) is kept: the manual sets the option board's
parameters on the operator and then has the system powered OFF and ON for them to take effect
(section 3-3 Step 3), and only what the network writes through the Function Code and Modbus Register
objects is temporary until the ENTER command (0900h) stores it (section E-2-2 note). The operator
does not change Identity attribute 9, which counts saves "through the Option Board interface" only
(Table C-2). A value set while the inverter runs (the HTTP API) is written as over the network, not
stored. b180 (the initialization) is not taken here: it stores every parameter as it runs, which the
emulator does only when the network asks for it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..keypad import Keypad, KeypadCodes
from ..registers import Register, RegisterError, RegisterRefusal
from .board import FUNCTION_CODE, MODBUS_REGISTER
from .models import Family
from .registers import function_code_from_path, modbus_address, register_set

if TYPE_CHECKING:
    from .device import OmronDevice

#: What the option board reads from the inverter when it starts, at power-on or after a reset
#: ("The Unit's configuration is read automatically when the power is turned ON or after a reset",
#: section 1-1-1): the node address P190, the default connection path P046, the flexible mapping
#: P160-P179, the terminal functions C001-C008.
BOARD_CONFIGURATION = frozenset({"P046", "P190", *(f"P{n}" for n in range(160, 180)),
                                  *(f"C{n:03d}" for n in range(1, 9))})
#: Written from the operator, these store to EEPROM (b180 initializes and saves, section 4-1 Step 1).
SAVING_CODES = frozenset({"b180"})


def operator_codes(family: Family) -> KeypadCodes:
    """The function codes of ``family``'s Digital Operator (Table E-3 spellings, any letter case)."""
    registers = register_set(family)
    # The monitor codes (d) first, then the function codes, group by group as the operator lists them.
    listed = sorted((r for r in registers.modbus.values() if r.code),
                    key=lambda r: ("dFAbCHP".find(r.code[0]) % 8, r.code))
    return KeypadCodes(f"the {family.value} Digital Operator", registers.by_code,
                       ("F001", "A001", "A004", "b049", "P044", "P046"), tuple(listed))


_CODES = {family: operator_codes(family) for family in Family}


class DigitalOperator(Keypad):
    """The Digital Operator of an ``OmronDevice``'s inverter."""

    def __init__(self, device: OmronDevice) -> None:
        self.device = device
        self.codes = _CODES[device.family]

    def read(self, register: Register) -> int:
        return self.device.inverter.read_code(register.code)

    def write(self, register: Register, raw: int, now: float) -> None:
        if register.code in SAVING_CODES:
            raise RegisterError(RegisterRefusal.READ_ONLY, register.address or 0,
                                f"{register.code} initializes and stores every parameter to EEPROM: write it "
                                "over the network (class 0x65)")
        device = self.device
        device.inverter.write_from_operator(register.code, raw, max(now, device.now))

    def register_at(self, class_id: int, instance: int, attribute: int) -> Register | None:
        registers = self.device.inverter.registers
        try:
            if class_id == MODBUS_REGISTER:     # section E-3-2: Modbus address XXYYh at instance XX, attribute YY
                return registers.at(modbus_address(instance, attribute))
            if class_id == FUNCTION_CODE:       # Table E-3: instance/attribute = the function code number
                return registers.by_code(function_code_from_path(instance, attribute))
        except (KeyError, ValueError):
            pass
        return None

    def keep(self, written: list[Register], now: float) -> None:
        self.device.inverter.keep_operator_entries([register.code for register in written])

    def started(self, written: list[Register], now: float) -> None:
        """Set on the operator before the network connects: the option board starts with them (it
        reads its configuration at start, section 1-1-1), as a board restarted after the setting."""
        if any(register.code in BOARD_CONFIGURATION for register in written):
            self.device.reset(0)
