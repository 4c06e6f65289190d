"""An EDS-emulated device's parameters as a keypad: each ``ParamN`` that links an attribute the device
serves (an integer one: the keypad's values are whole raw numbers on a scale), by its keyword
(``Param3``) or its name, in the parameter's own unit and scaling. What the front panel, ``cipstack
drive parameter`` and the HTTP API read and write for a device that has no keypad of its own; a write
goes through the attribute's own checks, as a Set_Attribute_Single would."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from ..cip.status import CipError
from ..cip.types import IntegerType
from ..devices.keypad import Keypad, KeypadCodes
from ..devices.registers import Register, RegisterAccess, RegisterError, RegisterRefusal
from ..errors import UnknownKey
from .interpret import ParamInfo

if TYPE_CHECKING:
    from .emulated_device import EdsDevice, EdsObject

#: The group the parameters are shown in (an EDS's own [Groups] are not read here).
GROUP = "Params"


def _register(number: int, param: ParamInfo) -> Register:
    assert isinstance(param.type, IntegerType) and param.type.size is not None
    return Register(address=number, code=param.keyword, name=param.name, type=param.type,
                    access=RegisterAccess.READ_WRITE if param.settable else RegisterAccess.READ,
                    default=int(param.default or 0),
                    minimum=int(param.minimum) if isinstance(param.minimum, int) else None,
                    maximum=int(param.maximum) if isinstance(param.maximum, int) else None,
                    # An offset cannot be shown exactly on the keypad's scale: such a parameter is raw.
                    scale=param.scale if param.offset == 0 else 1.0, unit=param.unit if param.offset == 0 else "",
                    enum=param.enum, help=param.help, group=GROUP, words=max(1, param.type.size // 2),
                    saved=False, source="its EDS file", addressed=False)


class EdsParameters(Keypad):
    """The ``params`` of ``device`` (those it serves, in the file's order) as a keypad."""

    def __init__(self, device: EdsDevice, params: Sequence[ParamInfo]) -> None:
        self.device = device
        self._links: dict[str, tuple[EdsObject, int, int]] = {}
        registers: list[Register] = []
        for param in params:
            served = device.eds_object(param.link) if param.link is not None else None
            if served is None or not isinstance(param.type, IntegerType) or param.type.size is None:
                continue
            register = _register(int(param.keyword[5:]), param)
            registers.append(register)
            self._links[register.code] = served
        by_name = {r.name.strip().lower(): r for r in registers}
        by_code = {r.code.lower(): r for r in registers}

        def lookup(text: str) -> Register:
            wanted = text.strip().lower()
            found = by_code.get(wanted) or by_code.get(f"param{wanted}") or by_name.get(wanted)
            if found is None:
                raise UnknownKey(text)
            return found

        examples = tuple(r.code for r in registers[:3]) or ("Param1",)
        self.codes = KeypadCodes(f"the parameters of its EDS ({device.identity_info.product_name})", lookup,
                                 examples, tuple(registers))

    def read(self, register: Register) -> int:
        obj, instance, attribute = self._links[register.code]
        return int(obj.get(instance, attribute))

    def write(self, register: Register, raw: int, now: float) -> None:
        if not register.access.writable:
            raise RegisterError(RegisterRefusal.READ_ONLY, register.address, f"{register.code} is not settable")
        obj, instance, attribute = self._links[register.code]
        try:
            obj.set(instance, attribute, raw)
        except CipError as exc:
            raise RegisterError(RegisterRefusal.OUT_OF_RANGE, register.address, str(exc)) from None


__all__ = ["GROUP", "EdsParameters"]
