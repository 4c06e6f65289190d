"""What every object of the option board shares: the class ids, the ``OptionBoard`` the objects
belong to, the errors of Table E-5 and the base classes that bind attributes to the inverter."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from types import MappingProxyType
from typing import Any, Protocol

from ...cip.messages import Service
from ...cip.model import AttributeSpec, Binding, CipObject, ClassSpec
from ...cip.status import CipError, GeneralStatus
from ..registers import RegisterError, RegisterRefusal
from .inverter import Inverter, InverterModeError

_GET_SET = frozenset({Service.GET_ATTRIBUTE_SINGLE, Service.SET_ATTRIBUTE_SINGLE})
_GET = frozenset({Service.GET_ATTRIBUTE_SINGLE})

IDENTITY = 0x01
CONNECTION = 0x05
DISCRETE_INPUT_POINT = 0x08
DISCRETE_OUTPUT_POINT = 0x09
MOTOR_DATA = 0x28
CONTROL_SUPERVISOR = 0x29
AC_DC_DRIVE = 0x2A
MODBUS_REGISTER = 0x64
FUNCTION_CODE = 0x65
UNIT_PARAMETER = 0x94
COMPONET_LINK = 0xF7


class OptionBoard(Protocol):
    """What the objects need from the device they belong to."""

    inverter: Inverter

    @property
    def now(self) -> float: ...

    @property
    def inverter_link_ok(self) -> bool: ...

    def command(self, **fields: Any) -> None: ...

    def motor_type_changed(self) -> None: ...


# -- Table E-5 -----------------------------------------------------------------------------------

_REFUSALS: Mapping[RegisterRefusal, GeneralStatus] = MappingProxyType({
    RegisterRefusal.NO_SUCH_REGISTER: GeneralStatus.ATTRIBUTE_NOT_SUPPORTED,
    RegisterRefusal.READ_ONLY: GeneralStatus.ATTRIBUTE_NOT_SETTABLE,
    RegisterRefusal.OUT_OF_RANGE: GeneralStatus.INVALID_ATTRIBUTE_VALUE,
    RegisterRefusal.NOT_WHILE_RUNNING: GeneralStatus.DEVICE_STATE_CONFLICT,
    RegisterRefusal.SAVE_FAILED: GeneralStatus.STORE_OPERATION_FAILURE,   # the state file took no write
})


def refusal_status(error: RegisterError) -> GeneralStatus:
    """The Table E-5 status of an inverter refusal: "10 Device state conflict: cannot be executed in
    this inverter mode" covers both the run-mode lock and the torque registers outside d060 = 0."""
    if isinstance(error, InverterModeError):
        return GeneralStatus.DEVICE_STATE_CONFLICT
    return _REFUSALS[error.refusal]


@contextmanager
def inverter_access(board: OptionBoard) -> Iterator[None]:
    """Run an inverter access; refusals become the statuses of Table E-5."""
    if not board.inverter_link_ok:
        # Table E-5: "02 Resource unavailable: an internal communication error between Option Board and Inverter".
        raise CipError(GeneralStatus.RESOURCE_UNAVAILABLE, message="no communication with the inverter")
    try:
        yield
    except RegisterError as exc:
        raise CipError(refusal_status(exc), message=str(exc)) from None


#: Table E-5 (CompoNet manual): "16 Object does not exist: The specified Instance ID is not supported",
#: the board's answer to an instance it does not have, in every object (CIP's own is 0x05).
MISSING_INSTANCE = GeneralStatus.OBJECT_DOES_NOT_EXIST


class OptionBoardObject(CipObject):
    """An object of appendices C/D: an unknown instance answers 0x16 (Table E-5, "Object does not exist")."""

    missing_instance_status = MISSING_INSTANCE


class BoundObject(OptionBoardObject):
    """A declared class whose attributes are ``Binding`` entries onto the option board."""

    def __init__(self, spec: ClassSpec, board: OptionBoard) -> None:
        super().__init__(spec)
        self.board = board

    def bound(self, get: Callable[[], Any], set: Callable[[Any], None] | None = None) -> Binding:
        board = self.board

        def guarded_get() -> Any:
            with inverter_access(board):
                return get()

        guarded_set = None
        if set is not None:
            def guarded_set(value: Any) -> None:
                with inverter_access(board):
                    set(value)
        return Binding(guarded_get, guarded_set)


def _spec(class_id: int, name: str, attributes: tuple[AttributeSpec, ...], revision: int = 1) -> ClassSpec:
    return ClassSpec(class_id, name, revision=revision, instance_attributes=attributes, class_services=_GET,
                     instance_services=_GET_SET)
