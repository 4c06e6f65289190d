"""The Modbus Register object (0x64, section E-3) and the Function Code object (0x65, section E-2):
the inverter's registers by instance (high byte) and attribute (low byte); errors of Table E-5."""

from __future__ import annotations

from collections.abc import Iterator

from ...cip.epath import ApplicationPath
from ...cip.messages import MessageRouterRequest, Service
from ...cip.model import Access, AttributeSpec, CipObject, ClassSpec
from ...cip.router import RequestContext
from ...cip.status import CipError, GeneralStatus
from ...cip.types import DINT, INT, UDINT, UINT, CipType
from .board import _GET_SET, FUNCTION_CODE, MODBUS_REGISTER, OptionBoard, inverter_access
from .registers import Parameter, RegisterSet, function_code_from_number

# -- Modbus Register (section E-3) and Function Code (section E-2) ---------------------------------

def _value_type(parameter: Parameter, words: int) -> CipType:
    if words == 2:
        return DINT if parameter.signed else UDINT
    return INT if parameter.signed and parameter.words == 1 else UINT


class RegisterObject(CipObject):
    """Instance = high byte, attribute = low byte of a number naming one inverter register.

    The manual's mapping makes instance 0 address numbers 0001h-00FFh (F001 at Modbus 0001h,
    A001-A255 by function code), so instance 0 is not the class level here.
    """

    def __init__(self, spec: ClassSpec, board: OptionBoard, registers: RegisterSet) -> None:
        super().__init__(spec)
        self.board = board
        self.registers = registers
        self.instance_ids = frozenset(number >> 8 for number in self.numbers())

    def numbers(self) -> Iterator[int]:
        raise NotImplementedError

    def handle(self, path: ApplicationPath, request: MessageRouterRequest, context: RequestContext) -> bytes:
        if request.service not in _GET_SET:
            raise CipError(GeneralStatus.SERVICE_NOT_SUPPORTED, message=f"service 0x{request.service:02X}")
        instance = path.instance or 0
        if instance > 0xFF or instance not in self.instance_ids:
            raise CipError(GeneralStatus.OBJECT_DOES_NOT_EXIST, message=f"{self.spec.name} has no instance {instance}")
        if path.attribute is None or path.attribute > 0xFF:
            raise CipError(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED, message="attribute must be one byte")
        number = instance << 8 | path.attribute
        with inverter_access(self.board):
            if request.service == Service.GET_ATTRIBUTE_SINGLE:
                if request.data:
                    raise CipError(GeneralStatus.TOO_MUCH_DATA)
                return self.read(number)
            self.write(number, request.data)
            return b""

    def read(self, number: int) -> bytes:
        raise NotImplementedError

    def write(self, number: int, data: bytes) -> None:
        raise NotImplementedError


def _decode_sized(cip_type: CipType, data: bytes) -> int:
    """Table E-5: data smaller than the register 0x13, larger 0x15."""
    assert cip_type.size is not None
    if len(data) < cip_type.size:
        raise CipError(GeneralStatus.NOT_ENOUGH_DATA, message=f"the register takes {cip_type.size} bytes")
    if len(data) > cip_type.size:
        raise CipError(GeneralStatus.TOO_MUCH_DATA, message=f"the register takes {cip_type.size} bytes")
    return int(cip_type.decode(data))


#: Table E-3: the decimal base of each function group (A 0, b 1000, C 2000, d 3000, F 5000, H 7000,
#: P 15000, U 20000); a group's codes are base + 1 to base + 999.
FUNCTION_CODE_GROUP_BASES = (0, 1000, 2000, 3000, 5000, 7000, 15000, 20000)

MODBUS_REGISTER_SPEC = ClassSpec(MODBUS_REGISTER, "Modbus Register", class_services=_GET_SET,
                                 instance_services=_GET_SET, max_instance=0xFF)
FUNCTION_CODE_SPEC = ClassSpec(FUNCTION_CODE, "Function Code", class_services=_GET_SET,
                               instance_services=_GET_SET, max_instance=0xFF)


class ModbusRegisterObject(RegisterObject):
    """Class 0x64: Modbus address XXYYh at instance XXh, attribute YYh (section E-3-2). A double
    word is 4 bytes at its first (high) word; its second word alone is one word."""

    def __init__(self, board: OptionBoard, registers: RegisterSet) -> None:
        super().__init__(MODBUS_REGISTER_SPEC, board, registers)

    def numbers(self) -> Iterator[int]:
        for register in self.registers.modbus.values():
            yield from range(register.address, register.address + register.words)

    def _register(self, address: int) -> tuple[Parameter, CipType]:
        found = self.registers.word(address)
        if found is None:
            raise CipError(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED, message=f"no register {address:04X}h")
        parameter, index = found
        words = parameter.words if index == 0 else 1
        return parameter, _value_type(parameter, words) if index == 0 else UINT

    def read(self, number: int) -> bytes:
        _, cip_type = self._register(number)
        return cip_type.encode(self.board.inverter.read(number))

    def write(self, number: int, data: bytes) -> None:
        _, cip_type = self._register(number)
        self.board.inverter.write(number, _decode_sized(cip_type, data), self.board.now)


class FunctionCodeObject(RegisterObject):
    """Class 0x65: group base x 1000 + code (Table E-3) split into instance (high byte) and attribute
    (low byte): d005 = 3005 = 0BBDh, P060 = 15060 = 3AD4h. F001 is read only here; b127 is two words."""

    def __init__(self, board: OptionBoard, registers: RegisterSet) -> None:
        super().__init__(FUNCTION_CODE_SPEC, board, registers)
        # Table E-3 (CompoNet manual) gives each group's number range, e.g. A001-A999 = 0001-03E7h: an
        # instance inside one is supported, and a number in it that names no parameter of this
        # inverter is Table E-5's 14h "the attribute or inverter parameter does not exist"
        # (CompoNet manual); 16h is for an instance outside every range.
        self.instance_ids = frozenset(instance for base in FUNCTION_CODE_GROUP_BASES
                                      for instance in range((base + 1) >> 8, ((base + 999) >> 8) + 1))

    def numbers(self) -> Iterator[int]:
        yield from self.registers.by_number

    def _parameter(self, number: int) -> tuple[Parameter, CipType]:
        parameter = self.registers.by_number.get(number)
        if parameter is None:
            try:
                code = function_code_from_number(number)
            except ValueError:
                code = f"{number}"
            raise CipError(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED, message=f"no function code {code}")
        return parameter, _value_type(parameter, parameter.function_code_words or parameter.words)

    def read(self, number: int) -> bytes:
        _, cip_type = self._parameter(number)
        return cip_type.encode(self.board.inverter.read_function_code(number))

    def write(self, number: int, data: bytes) -> None:
        parameter, cip_type = self._parameter(number)
        if not parameter.function_code_writable:
            raise CipError(GeneralStatus.ATTRIBUTE_NOT_SETTABLE, message=f"{parameter.key} (section E-2-2)")
        self.board.inverter.write_function_code(number, _decode_sized(cip_type, data), self.board.now)


def register_attribute(registers: RegisterSet, class_id: int, instance: int, attribute: int) -> AttributeSpec | None:
    """What class 0x64 or 0x65 holds at ``instance``/``attribute`` (instance 0 included: F001 is 0x64/0/1),
    by the same rules the objects above serve it: its register's name and CIP type, for a scanner."""
    if not (0 <= instance <= 0xFF and 0 <= attribute <= 0xFF):
        return None
    number = instance << 8 | attribute
    index = 0
    if class_id == MODBUS_REGISTER:
        found = registers.word(number)
        if found is None:
            return None
        parameter, index = found
        cip_type = _value_type(parameter, parameter.words) if index == 0 else UINT
        name = f"{parameter.key} {parameter.name}" + (" (second word)" if index else "")
    elif class_id == FUNCTION_CODE:
        found_code = registers.by_number.get(number)
        if found_code is None:
            return None
        parameter = found_code
        cip_type = _value_type(parameter, parameter.function_code_words or parameter.words)
        name = f"{parameter.key} {parameter.name}"
    else:
        return None
    if index:
        return AttributeSpec(attribute, name, cip_type, Access.GET_SET)
    # The register's unit, scale and meanings (the tables of the CompoNet manual and the inverter manuals).
    return AttributeSpec(attribute, name, cip_type, Access.GET_SET, unit=parameter.unit, scale=parameter.scale,
                         enum=parameter.enum)
