"""The CIP objects of the ACG-ET2 card (ACG-ET2 manual, "Explicit Messages", "Supported Objects").

Each object has exactly the attributes, access and services of its table in the ACG-ET2 manual:

* Identity 0x01 instance 1: attributes 1-7; instance services 0x0E, 0x05, 0x01; no class services.
* Motor Data 0x28, Control Supervisor 0x29, AC/DC Drive 0x2A instance 1 and class 0x64: instance
  services 0x0E and 0x10 only; no class services ("Support for Class: No").

Attributes that stand for a drive register are declared from the ``Register`` (type, range,
scale, unit); the others read or command the drive through its API. A register refusal becomes
the CIP status a scanner expects: read-only 0x0E, out of range 0x09, not writable while the drive
runs 0x10 (device state conflict), no such register 0x14.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from ...cip.epath import ApplicationPath
from ...cip.messages import MessageRouterRequest, Service
from ...cip.model import Access, AttributeSpec, Binding, CipObject, ClassSpec, Instance
from ...cip.router import RequestContext
from ...cip.status import CipError, GeneralStatus
from ...cip.types import BOOL, INT, UINT, USINT, CipType
from ...objects.identity import DeviceState, ExtendedDeviceStatus, IdentityInfo, IdentityObject, IdentityStatus
from ...objects.identity import identity_spec as standard_identity_spec
from ..registers import Register, RegisterAccess, RegisterError, RegisterRefusal
from . import registers as reg
from .drive import AcgDrive, DriveState, Trip

DriveSource = Callable[[], AcgDrive]
Clock = Callable[[], float]

MOTOR_DATA = 0x28
CONTROL_SUPERVISOR = 0x29
AC_DC_DRIVE = 0x2A
KEYPAD_PARAMETERS = 0x64

#: ACG-ET2 manual: Motor data, Control Supervisor, Drive Objects and class 0x64 tables: "Support for
#: Class: No"; instance: 0x0E Get Attribute Single and 0x10 Set Attribute Single.
GET_SET_SINGLE = frozenset({Service.GET_ATTRIBUTE_SINGLE, Service.SET_ATTRIBUTE_SINGLE})
NO_SERVICES: frozenset[int] = frozenset()

_REFUSAL_STATUS: Mapping[RegisterRefusal, GeneralStatus] = {
    RegisterRefusal.READ_ONLY: GeneralStatus.ATTRIBUTE_NOT_SETTABLE,
    RegisterRefusal.OUT_OF_RANGE: GeneralStatus.INVALID_ATTRIBUTE_VALUE,
    RegisterRefusal.NOT_WHILE_RUNNING: GeneralStatus.DEVICE_STATE_CONFLICT,
    RegisterRefusal.NO_SUCH_REGISTER: GeneralStatus.ATTRIBUTE_NOT_SUPPORTED,
    RegisterRefusal.SAVE_FAILED: GeneralStatus.STORE_OPERATION_FAILURE,   # the state file took no write
}


def cip_error(exc: RegisterError) -> CipError:
    """The CIP status of a refused register write."""
    return CipError(_REFUSAL_STATUS[exc.refusal], message=str(exc))


def _access(register: Register) -> Access:
    return Access.GET if register.access is RegisterAccess.READ else Access.GET_SET


def mirror_spec(attribute_id: int, name: str, register: Register, *, cip_type: CipType | None = None,
                access: Access | None = None, minimum: int | None = None, maximum: int | None = None) -> AttributeSpec:
    """An attribute that shows ``register``: its range, scale, unit and enumeration come from the
    register; the manual's table may narrow the range or state the CIP type and access."""
    where = (f"register 0x{register.address:04X}" if register.addressed else "no communication address") + (
        f" {register.code}" if register.code else "")
    return AttributeSpec(
        attribute_id, name, cip_type or register.type, access or _access(register), default=register.default,
        minimum=register.minimum if minimum is None else minimum,
        maximum=register.maximum if maximum is None else maximum,
        enum=register.enum, unit=register.unit, scale=register.scale,
        help=f"{register.name} ({where}); {register.source}".strip("; "))


@dataclass(frozen=True)
class DriveAttribute:
    """One attribute of a drive object: its declaration, how it reads and how it commands."""

    spec: AttributeSpec
    read: Callable[[AcgDrive], Any]
    write: Callable[[AcgDrive, Any, float], Any] | None = None
    #: The drive register the attribute shows, where it shows one.
    register: Register | None = None


def register_attribute(spec: AttributeSpec, register: Register,
                       write: Callable[[AcgDrive, Any, float], Any] | None = None) -> DriveAttribute:
    address = register.address

    def read(drive: AcgDrive) -> int:
        return drive.read(address)

    def write_register(drive: AcgDrive, value: Any, now: float) -> None:
        drive.write(address, int(value), now)

    settable = spec.access.settable
    return DriveAttribute(spec, read, (write or write_register) if settable else None, register)


class DriveObject(CipObject):
    """A class whose instance 1 attributes live in the drive."""

    def __init__(self, spec: ClassSpec, attributes: tuple[DriveAttribute, ...], drive: DriveSource,
                 clock: Clock) -> None:
        super().__init__(spec)
        self._drive = drive
        self._clock = clock
        self._bound = {a.spec.id: a for a in attributes}
        self.add_instance(1)

    def now(self, context: RequestContext | None) -> float:
        """The time of a request; never before the drive's present time."""
        now = context.now if context is not None and context.now else self._clock()
        return max(now, self._drive().time)

    def register_of(self, attribute: int) -> Register | None:
        """The drive register behind instance 1's ``attribute``, if it shows one."""
        bound = self._bound.get(attribute)
        return bound.register if bound is not None else None

    def read_attribute(self, instance: Instance, spec: AttributeSpec) -> Any:
        value = self._bound[spec.id].read(self._drive())
        return int(value) if isinstance(value, bool) else value

    def write_attribute(self, instance: Instance, spec: AttributeSpec, value: Any,
                        context: RequestContext | None = None) -> None:
        value = spec.validate(value)
        writer = self._bound[spec.id].write
        if writer is None:
            raise CipError(GeneralStatus.ATTRIBUTE_NOT_SETTABLE, message=spec.name)
        try:
            writer(self._drive(), value, self.now(context))
        except RegisterError as exc:
            raise cip_error(exc) from None


def _class_spec(class_id: int, name: str, attributes: tuple[DriveAttribute, ...]) -> ClassSpec:
    return ClassSpec(class_id, name, revision=1, instance_attributes=tuple(a.spec for a in attributes),
                     class_services=NO_SERVICES, instance_services=GET_SET_SINGLE)


# ---------------------------------------------------------------------------------------------
# Motor Data (class 0x28, instance 1)
# ---------------------------------------------------------------------------------------------

MOTOR_TYPES: Mapping[int, str] = {
    0: "Non-standard motor", 1: "PM DC Motor", 2: "FC DC Motor", 3: "PM Synchronous Motor",
    4: "FC Synchronous Motor", 5: "Switched Reluctance Motor", 6: "Wound Rotor Induction Motor",
    7: "Squirrel Cage Induction Motor", 8: "Stepper Motor", 9: "Sinusoidal PM BL Motor", 10: "Trapezoidal PM BL Motor",
}
#: The ACG drives induction motors; the manual lists the range and not the value it reports.
MOTOR_TYPE = 7

MOTOR_DATA_ATTRIBUTES: tuple[DriveAttribute, ...] = (
    DriveAttribute(AttributeSpec(3, "Motor Type", USINT, Access.GET, default=MOTOR_TYPE, minimum=0, maximum=10,
                                 enum=MOTOR_TYPES), lambda drive: MOTOR_TYPE),
    # "[Get] Reads the value at BAS-13 Rated Curr. [Set] Set value is reflected to BAS-13", scale 0.1.
    register_attribute(mirror_spec(6, "Motor Rated Curr", reg.RATED_CURRENT), reg.RATED_CURRENT),
    # "[Get] Reads the value of the BAS-15 Rated Voltage. [Set] ... reflected in the BAS-15", 0-690.
    register_attribute(mirror_spec(7, "Motor Rated Volt", reg.RATED_VOLTAGE), reg.RATED_VOLTAGE),
)
MOTOR_DATA_SPEC = _class_spec(MOTOR_DATA, "Motor Data", MOTOR_DATA_ATTRIBUTES)


# ---------------------------------------------------------------------------------------------
# Control Supervisor (class 0x29, instance 1)
# ---------------------------------------------------------------------------------------------

DRIVE_STATES: Mapping[int, str] = {
    DriveState.VENDOR_SPECIFIC: "Vendor Specific", DriveState.STARTUP: "Startup",
    DriveState.NOT_READY: "Not Ready (resetting in progress)", DriveState.READY: "Ready (stopping in progress)",
    DriveState.ENABLED: "Enabled (running, not applicable to deceleration stop)",
    DriveState.STOPPING: "Stopping (decelerating)", DriveState.FAULT_STOP: "Fault Stop",
}
FAULT_CODES: Mapping[int, str] = {0x0000: "None", **{
    code: " / ".join(t.label for t in Trip if t.fault_code == code) for code in sorted({t.fault_code for t in Trip})}}


def _flag(attribute_id: int, name: str, read: Callable[[AcgDrive], bool], help_text: str,
          write: Callable[[AcgDrive, Any, float], Any] | None = None) -> DriveAttribute:
    access = Access.GET_SET if write is not None else Access.GET
    return DriveAttribute(AttributeSpec(attribute_id, name, BOOL, access, default=0, help=help_text), read, write)


CONTROL_SUPERVISOR_ATTRIBUTES: tuple[DriveAttribute, ...] = (
    # 3/4: the card's command values, acted on by the "Drive Run" edge table.
    _flag(3, "Forward Run Cmd.", lambda d: d.control_supervisor.run_forward,
          "0: stopped, 1: forward run (Drive Run table)", lambda d, v, now: d.set_run_forward(bool(v), now)),
    _flag(4, "Reverse Run Cmd.", lambda d: d.control_supervisor.run_reverse,
          "0: stopped, 1: reverse run (Drive Run table)", lambda d, v, now: d.set_run_reverse(bool(v), now)),
    # 5 Net Control: Access "N/A", "Configurable only with the drive parameter" (ACG-ET2 manual). N/A
    # is the access, not a value: the card serves it neither to Get nor to Set, so it is not
    # declared and both answer 0x14 (attribute not supported). 14/15 "Control From Net." report drv.
    DriveAttribute(AttributeSpec(6, "Drive State", USINT, Access.GET, default=DriveState.READY, minimum=0, maximum=6,
                                 enum=DRIVE_STATES), lambda d: int(d.drive_state)),
    _flag(7, "Running Forward", lambda d: d.running_forward, "1: running forward"),
    _flag(8, "Running Reverse", lambda d: d.running_reverse, "1: running reverse"),
    _flag(9, "Drive Ready", lambda d: d.ready, "0: resetting in progress or trip occurred, 1: ready"),
    _flag(10, "Drive Fault", lambda d: d.faulted, "1: trip has occurred"),
    # 12: "Resetting will begin only when the value changes from FALSE to TRUE."
    _flag(12, "Drive Fault Reset", lambda d: d.control_supervisor.fault_reset, "trip reset on a 0 to 1 change",
          lambda d, v, now: d.set_fault_reset(bool(v), now)),
    DriveAttribute(AttributeSpec(13, "Drive Fault Codes", UINT, Access.GET, default=0, enum=FAULT_CODES),
                   lambda d: d.fault_code),
    # Control From Net is attribute 14 in the Control Supervisor table (ACG-ET2 manual) and attribute
    # 15 in the table of the input instances' bits (ACG-ET2 manual, "Ctrl From Net ... 0x29 15"); the
    # CIP Control Supervisor has CtrlFromNet at 15. A scanner may follow either table, so the card
    # serves the one value at both ids: 15 as CIP and the bit table say, 14 as the object table says.
    _flag(14, "Control From Net.", lambda d: d.control_from_net, "1: commands come from the ACG-ET2 (drv = 4)"),
    _flag(15, "Ctrl From Net", lambda d: d.control_from_net,
          "1: commands come from the ACG-ET2 (drv = 4); the same value as attribute 14"),
)
CONTROL_SUPERVISOR_SPEC = _class_spec(CONTROL_SUPERVISOR, "Control Supervisor", CONTROL_SUPERVISOR_ATTRIBUTES)


# ---------------------------------------------------------------------------------------------
# AC/DC Drive (class 0x2A, instance 1)
# ---------------------------------------------------------------------------------------------

DRIVE_MODES: Mapping[int, str] = {0: "Vendor Specific Mode", 1: "Open Loop Speed (Frequency)",
                                  2: "Closed Loop Speed Control", 3: "Torque Control", 4: "Process Control (e.g. PI)"}


def drive_mode(drive: AcgDrive) -> int:
    """Attribute 6, note 1: "Process Control" when APP-01 App Mode selects a process mode (any
    value but 0 "None"); "Torque Control" would follow DRV-10, which has no communication address
    on the ACG (ACG RS-485 manual lists no dr.10), so the mode is otherwise Open Loop Speed."""
    return 4 if drive.read(reg.APP_MODE.address) else 1


OUTPUT_RPM = reg.ACG_REGISTERS[0x0312]
RPM_COMMAND = reg.ACG_REGISTERS[0x0381]
OUTPUT_CURRENT = reg.ACG_REGISTERS[0x0009]
OUTPUT_FREQUENCY = reg.ACG_REGISTERS[0x000A]

AC_DC_DRIVE_ATTRIBUTES: tuple[DriveAttribute, ...] = (
    _flag(3, "At Reference", lambda d: d.at_reference, "1: the output frequency has reached the reference"),
    # 4 Net Reference: Access "N/A" (ACG-ET2 manual), like 0x29 attribute 5: not served, 0x14 to Get
    # and Set. The reference source is the drive parameter Frq, reported by 29 "Ref.From Network".
    DriveAttribute(AttributeSpec(6, "Drive Mode", USINT, Access.GET, default=1, minimum=0, maximum=4,
                                 enum=DRIVE_MODES), drive_mode),
    register_attribute(mirror_spec(7, "SpeedActual", OUTPUT_RPM, cip_type=INT, minimum=0, maximum=24000), OUTPUT_RPM),
    register_attribute(mirror_spec(8, "SpeedRef", RPM_COMMAND, cip_type=INT, minimum=0, maximum=24000), RPM_COMMAND,
                       lambda d, v, now: d.set_speed_reference_rpm(int(v), now)),
    register_attribute(mirror_spec(9, "Actual Current", OUTPUT_CURRENT, cip_type=INT, minimum=0, maximum=1110),
                       OUTPUT_CURRENT),
    _flag(29, "Ref.From Network", lambda d: d.reference_from_net, "1: the reference comes from the network (Frq = 8)"),
    register_attribute(mirror_spec(100, "Actual Hz", OUTPUT_FREQUENCY, maximum=40000), OUTPUT_FREQUENCY),
    register_attribute(mirror_spec(101, "Reference Hz", reg.SPEED_REFERENCE), reg.SPEED_REFERENCE),
    register_attribute(mirror_spec(102, "Acceleration Time", reg.ACCEL_TIME), reg.ACCEL_TIME),
    register_attribute(mirror_spec(103, "Deceleration Time", reg.DECEL_TIME), reg.DECEL_TIME),
)
AC_DC_DRIVE_SPEC = _class_spec(AC_DC_DRIVE, "AC/DC Drive", AC_DC_DRIVE_ATTRIBUTES)


class MotorDataObject(DriveObject):
    def __init__(self, drive: DriveSource, clock: Clock) -> None:
        super().__init__(MOTOR_DATA_SPEC, MOTOR_DATA_ATTRIBUTES, drive, clock)


class ControlSupervisorObject(DriveObject):
    def __init__(self, drive: DriveSource, clock: Clock) -> None:
        super().__init__(CONTROL_SUPERVISOR_SPEC, CONTROL_SUPERVISOR_ATTRIBUTES, drive, clock)


class AcDcDriveObject(DriveObject):
    def __init__(self, drive: DriveSource, clock: Clock) -> None:
        super().__init__(AC_DC_DRIVE_SPEC, AC_DC_DRIVE_ATTRIBUTES, drive, clock)


# ---------------------------------------------------------------------------------------------
# Class 0x64: the keypad parameters (instance = group, attribute = code number)
# ---------------------------------------------------------------------------------------------

def keypad_parameter_spec(register: Register) -> AttributeSpec:
    """The class 0x64 attribute of one keypad parameter: the register, numbered by its code."""
    path = reg.class64_path(register)
    assert path is not None
    return mirror_spec(path[1], register.name, register)


def _keypad_class_spec() -> ClassSpec:
    # One declaration per code number for the scanner's decoding: every keypad parameter is a
    # UINT word, so the attribute of a code number decodes the same in every group; access and
    # range are per parameter and checked against its register.
    numbers = sorted({path[1] for path in (reg.class64_path(r) for r in reg.ACG_REGISTERS.values())
                      if path is not None})
    attributes = tuple(AttributeSpec(n, f"Code {n}", UINT, Access.GET_SET, help="keypad parameter of the group")
                       for n in numbers)
    return ClassSpec(KEYPAD_PARAMETERS, "Keypad Parameters", revision=1, instance_attributes=attributes,
                     class_services=NO_SERVICES, instance_services=GET_SET_SINGLE,
                     max_instance=max(reg.CLASS_64_INSTANCES.values()))


KEYPAD_PARAMETERS_SPEC = _keypad_class_spec()


class KeypadParameterObject(CipObject):
    """Class 0x64 ("Manufacture Profile"): Get/Set of every keypad parameter of a group."""

    def __init__(self, drive: DriveSource, clock: Clock) -> None:
        super().__init__(KEYPAD_PARAMETERS_SPEC)
        self._drive = drive
        self._clock = clock
        for instance in sorted({*reg.CLASS_64_INSTANCES.values(), *reg.CLASS_64_ALIASES}):
            self.add_instance(instance)

    def parameter(self, instance: Instance, attribute: int | None) -> Register:
        if attribute is None:
            raise CipError(GeneralStatus.PATH_SEGMENT_ERROR, message="no attribute in the path")
        register = reg.class64_register(instance.instance_id, attribute)
        if register is None:
            raise CipError(GeneralStatus.ATTRIBUTE_NOT_SUPPORTED,
                           message=f"group instance {instance.instance_id} has no code {attribute}")
        return register

    def get_attribute_single(self, instance: Instance | None, path: ApplicationPath,
                             request: MessageRouterRequest, context: RequestContext) -> bytes:
        assert instance is not None  # class-level requests stop at the service check
        if request.data:
            raise CipError(GeneralStatus.TOO_MUCH_DATA)
        register = self.parameter(instance, path.attribute)
        return register.type.encode(self._drive().read(register.address))

    def set_attribute_single(self, instance: Instance | None, path: ApplicationPath,
                             request: MessageRouterRequest, context: RequestContext) -> bytes:
        assert instance is not None
        register = self.parameter(instance, path.attribute)
        spec = keypad_parameter_spec(register)
        if not spec.access.settable:
            raise CipError(GeneralStatus.ATTRIBUTE_NOT_SETTABLE, message=f"{register.code} is read only")
        value = spec.validate(spec.type.decode(request.data))
        drive = self._drive()
        now = context.now if context.now else self._clock()
        try:
            drive.write(register.address, value, max(now, drive.time))
        except RegisterError as exc:
            raise cip_error(exc) from None
        return b""


# ---------------------------------------------------------------------------------------------
# Identity (class 0x01, instance 1)
# ---------------------------------------------------------------------------------------------

#: ACG-ET2 manual Identity table: attributes 1-7; "Support for Class: No"; instance 0x0E, 0x05, 0x01.
IDENTITY_SPEC = standard_identity_spec(
    instance_services=frozenset({Service.GET_ATTRIBUTE_SINGLE, Service.RESET, Service.GET_ATTRIBUTES_ALL}),
    class_services=NO_SERVICES,
).replace(
    instance_attributes=tuple(a for a in standard_identity_spec().instance_attributes if a.id <= 7),
)
#: "Serial number uses the last 4 digits of the MAC ID"; "Product Name 4 Byte CENT".
PRODUCT_NAME = "CENT"
VENDOR_ID = 259
DEVICE_TYPE = 2
PRODUCT_CODE = 100
#: Trips the drive counts as hardware trips (status bit 10): the H/W diagnosis of 0x000F B10.
HARDWARE_TRIPS = frozenset({Trip.HW_DIAG})
#: Bits of attribute 5 that the I/O connections own (bit 0 and the extended status, bits 4-7).
_IO_BITS = int(IdentityStatus.OWNED) | 0x00F0


def identity_revision(drive: AcgDrive) -> tuple[int, int]:
    """Attribute 4 is the card's version shown in CM.6: high byte major, low byte minor."""
    version = drive.read(reg.ACG_REGISTERS.by_code("CM.6").address)
    return version >> 8, version & 0xFF


class AcgIdentityObject(IdentityObject):
    """Identity with the status bits of the manual's "Definition of status bits" table:

    ====  ==============================================================================
    0     connected to the master (an exclusive owner I/O connection)
    2     configured: fixed 0
    4-7   0 unknown, 2 faulty I/O connection, 3 no I/O connection, 5 major fault,
          6 I/O connection made
    8     minor recoverable fault: the drive is in warning status
    10    major recoverable fault: a drive H/W trip
    11    major recoverable fault: a drive trip other than H/W
    ====  ==============================================================================
    """

    def __init__(self, info: IdentityInfo, drive: DriveSource,
                 on_reset: Callable[[int], None] | None = None) -> None:
        CipObject.__init__(self, IDENTITY_SPEC)
        self.info = info
        self.on_reset = on_reset
        self._drive = drive
        self._io_status = 0
        self.add_instance(
            1, vendor_id=info.vendor_id, device_type=info.device_type, product_code=info.product_code,
            revision={"major": info.revision[0], "minor": info.revision[1]}, status=0,
            serial_number=info.serial_number, product_name=info.product_name)
        # Attribute 5 is made when read, from the drive (the table above); a write to it is the
        # device's I/O bookkeeping, which keeps only the bits the I/O connections own.
        self.bind(1, 5, Binding(self.status_word, self._set_io_status))

    def _set_io_status(self, value: int) -> None:
        self._io_status = int(value) & _IO_BITS

    def status_word(self) -> int:
        drive = self._drive()
        status = self._io_status & int(IdentityStatus.OWNED)
        extended = (self._io_status >> 4) & 0x0F
        if extended == ExtendedDeviceStatus.IO_CONNECTION_IDLE:
            extended = ExtendedDeviceStatus.IO_CONNECTION_RUNNING  # the table has no "idle": made is made
        trip = drive.trip
        if trip is not None:
            extended = ExtendedDeviceStatus.MAJOR_FAULT
            # The manual gives bit 10 to H/W trips and bit 11 (CIP's "major unrecoverable") to the others.
            status |= IdentityStatus.MAJOR_RECOVERABLE_FAULT if trip in HARDWARE_TRIPS else (
                IdentityStatus.MAJOR_UNRECOVERABLE_FAULT)
        if drive.warning:
            status |= IdentityStatus.MINOR_RECOVERABLE_FAULT
        return int(status) | extended << 4

    @property
    def status(self) -> int:
        return self.status_word()

    @property
    def state(self) -> int:
        """The device state of a ListIdentity reply (the table has no attribute 8)."""
        if self._drive().trip is not None:
            return DeviceState.MAJOR_RECOVERABLE_FAULT
        return DeviceState.OPERATIONAL


def acg_identity_info(drive: AcgDrive, serial_number: int) -> IdentityInfo:
    return IdentityInfo(VENDOR_ID, DEVICE_TYPE, PRODUCT_CODE, identity_revision(drive), serial_number, PRODUCT_NAME)


CATALOG_CLASSES: tuple[ClassSpec, ...] = (MOTOR_DATA_SPEC, CONTROL_SUPERVISOR_SPEC, AC_DC_DRIVE_SPEC,
                                          KEYPAD_PARAMETERS_SPEC)

__all__ = [
    "AC_DC_DRIVE",
    "AC_DC_DRIVE_SPEC",
    "CATALOG_CLASSES",
    "CONTROL_SUPERVISOR",
    "CONTROL_SUPERVISOR_SPEC",
    "IDENTITY_SPEC",
    "KEYPAD_PARAMETERS",
    "KEYPAD_PARAMETERS_SPEC",
    "MOTOR_DATA",
    "MOTOR_DATA_SPEC",
    "AcDcDriveObject",
    "AcgIdentityObject",
    "ControlSupervisorObject",
    "DriveAttribute",
    "DriveObject",
    "KeypadParameterObject",
    "MotorDataObject",
    "acg_identity_info",
    "cip_error",
    "keypad_parameter_spec",
    "mirror_spec",
]
