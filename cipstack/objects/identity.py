"""Identity object (class 0x01): who the device is, its status word, and Reset."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum, IntFlag

from ..cip.messages import Service
from ..cip.model import Access, AttributeSpec, CipObject, ClassSpec, Instance
from ..cip.router import RequestContext
from ..cip.status import CipError, GeneralStatus
from ..cip.types import REVISION, SHORT_STRING, UDINT, UINT, USINT, WORD

CLASS_ID = 0x01


class IdentityStatus(IntFlag):
    """Identity attribute 5 bits (CIP Vol. 1 5-2.2.1.5)."""

    OWNED = 0x0001
    CONFIGURED = 0x0004
    MINOR_RECOVERABLE_FAULT = 0x0100
    MINOR_UNRECOVERABLE_FAULT = 0x0200
    MAJOR_RECOVERABLE_FAULT = 0x0400
    MAJOR_UNRECOVERABLE_FAULT = 0x0800


class ExtendedDeviceStatus(IntEnum):
    """Bits 4-7 of the status word."""

    UNKNOWN = 0
    FIRMWARE_UPDATE = 1
    IO_CONNECTION_FAULTED = 2
    NO_IO_CONNECTION = 3
    NON_VOLATILE_CONFIG_BAD = 4
    MAJOR_FAULT = 5
    IO_CONNECTION_RUNNING = 6
    IO_CONNECTION_IDLE = 7


class DeviceState(IntEnum):
    """Identity attribute 8, also carried in the ListIdentity reply."""

    NONEXISTENT = 0
    SELF_TESTING = 1
    STANDBY = 2
    OPERATIONAL = 3
    MAJOR_RECOVERABLE_FAULT = 4
    MAJOR_UNRECOVERABLE_FAULT = 5
    DEFAULT = 0xFF


@dataclass(frozen=True)
class IdentityInfo:
    vendor_id: int
    device_type: int
    product_code: int
    revision: tuple[int, int]
    serial_number: int
    product_name: str


def identity_spec(*, extra: tuple[AttributeSpec, ...] = (),
                  instance_services: frozenset[int] | None = None,
                  class_services: frozenset[int] | None = None) -> ClassSpec:
    """Identity class declaration; device families may add attributes (e.g. 9, 0x65)."""
    attributes = (
        AttributeSpec(1, "Vendor ID", UINT),
        AttributeSpec(2, "Device Type", UINT),
        AttributeSpec(3, "Product Code", UINT),
        AttributeSpec(4, "Revision", REVISION),
        AttributeSpec(5, "Status", WORD),
        AttributeSpec(6, "Serial Number", UDINT),
        AttributeSpec(7, "Product Name", SHORT_STRING),
        AttributeSpec(8, "State", USINT, in_get_all=False),
        *extra,
    )
    return ClassSpec(
        CLASS_ID, "Identity", revision=1,
        instance_attributes=tuple(sorted(attributes, key=lambda a: a.id)),
        class_services=class_services if class_services is not None else frozenset(
            {Service.GET_ATTRIBUTE_SINGLE, Service.GET_ATTRIBUTES_ALL}),
        instance_services=instance_services if instance_services is not None else frozenset(
            {Service.GET_ATTRIBUTES_ALL, Service.GET_ATTRIBUTE_SINGLE, Service.GET_ATTRIBUTE_LIST,
             Service.RESET}),
    )


ResetHandler = Callable[[int], None]


class IdentityObject(CipObject):
    """Identity with Reset types 0 (power cycle) and 1 (out-of-box defaults, then power cycle).

    The reset itself is the device's business: ``on_reset`` is called after the reply has
    been built, and the device schedules the restart so the reply still goes out.
    """

    def __init__(self, info: IdentityInfo, spec: ClassSpec | None = None,
                 on_reset: ResetHandler | None = None) -> None:
        super().__init__(spec or identity_spec())
        self.info = info
        self.on_reset = on_reset
        # Attribute 8 is optional in CIP; a device whose table leaves it out (the Omron board's
        # Table C-2) still has a state for ListIdentity (``state``).
        state = {"state": DeviceState.OPERATIONAL} if self.spec.instance_attribute(8) is not None else {}
        self.add_instance(
            1,
            vendor_id=info.vendor_id,
            device_type=info.device_type,
            product_code=info.product_code,
            revision={"major": info.revision[0], "minor": info.revision[1]},
            status=0,
            serial_number=info.serial_number,
            product_name=info.product_name,
            **state,
        )

    @property
    def status(self) -> int:
        return int(self.get(1, 5))

    @property
    def state(self) -> int:
        """Attribute 8, or, where it is not served, the state the status word's fault bits say."""
        if self.spec.instance_attribute(8) is not None:
            return int(self.get(1, 8))
        status = self.status
        if status & IdentityStatus.MAJOR_UNRECOVERABLE_FAULT:
            return DeviceState.MAJOR_UNRECOVERABLE_FAULT
        if status & IdentityStatus.MAJOR_RECOVERABLE_FAULT:
            return DeviceState.MAJOR_RECOVERABLE_FAULT
        return DeviceState.OPERATIONAL

    def perform_reset(self, instance: Instance | None, reset_type: int, context: RequestContext) -> None:
        if instance is None:
            raise CipError(GeneralStatus.SERVICE_NOT_SUPPORTED)
        if reset_type not in (0, 1):
            raise CipError(GeneralStatus.INVALID_PARAMETER_VALUE, message=f"reset type {reset_type}")
        if self.on_reset is not None:
            self.on_reset(reset_type)


__all__ = ["CLASS_ID", "Access", "DeviceState", "ExtendedDeviceStatus", "IdentityInfo", "IdentityObject",
           "IdentityStatus", "identity_spec"]
