"""The CIP objects of the MX2/RX CompoNet option board (appendices C, D and E).

Each class is declared once (``ClassSpec``) with the attributes, data types, access and
services of its table; the runtime binds every attribute to the inverter simulation
(``Inverter``) through the ``OptionBoard`` the objects belong to (``board.py``: what the objects
share). The Modbus Register object (0x64) and the Function Code object (0x65, ``register_objects.py``)
address the inverter's registers by instance and attribute (sections E-2-2 and E-3-2), so they have
no declared attributes.

Errors are those of Table E-5: a refusal of the inverter (``RegisterError``) becomes 0x0E
(read only), 0x09 (out of range), 0x10 (not in this inverter mode or while running) or 0x14
(no such parameter); an unknown instance 0x16; a size mismatch 0x13/0x15; a broken link
between option board and inverter 0x02.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from ...cip.epath import LogicalSegment, LogicalType, decode_path, encode_path
from ...cip.messages import Service
from ...cip.model import Access, AttributeSpec, Binding, ClassSpec, Instance
from ...cip.router import RequestContext
from ...cip.status import CipError, GeneralStatus
from ...cip.types import BOOL, BYTE, INT, UINT, USINT, WORD, RemainingBytes
from ...objects.identity import IdentityInfo, IdentityObject, identity_spec
from .board import (
    _GET,
    AC_DC_DRIVE,
    COMPONET_LINK,
    CONNECTION,
    CONTROL_SUPERVISOR,
    DISCRETE_INPUT_POINT,
    DISCRETE_OUTPUT_POINT,
    FUNCTION_CODE,
    IDENTITY,
    MODBUS_REGISTER,
    MOTOR_DATA,
    UNIT_PARAMETER,
    BoundObject,
    OptionBoard,
    OptionBoardObject,
    _spec,
    inverter_access,
    refusal_status,
)
from .models import FIRMWARE_REVISION, Family
from .register_objects import (
    FUNCTION_CODE_GROUP_BASES,
    FUNCTION_CODE_SPEC,
    MODBUS_REGISTER_SPEC,
    FunctionCodeObject,
    ModbusRegisterObject,
    RegisterObject,
)
from .registers import FamilyTraits

# -- Identity (Table C-2) -------------------------------------------------------------------------

#: Identity status bit 0 of Table C-2: "Always ON" (bits 8-11 are the fault bits of ``IdentityStatus``).
STATUS_ALWAYS_ON = 0x0001

_IDENTITY_SPEC = identity_spec(
    extra=(AttributeSpec(9, "Configuration Consistency Value", UINT, default=0,
                         help="EEPROM saves through the option board (Table C-2)"),
           AttributeSpec(0x65, "Firmware Revision Option Board", WORD,
                         help="software version of the option board, major in the high byte")),
    instance_services=frozenset({Service.GET_ATTRIBUTE_SINGLE, Service.RESET}),   # Table C-1
    class_services=_GET,
)
#: Table C-2 (CompoNet manual) lists attributes 1-7, 9 and 65h: 8 (State) is not served (0x14).
IDENTITY_SPEC = _IDENTITY_SPEC.replace(instance_attributes=tuple(
    a for a in _IDENTITY_SPEC.instance_attributes if a.id != 8))


class OptionBoardIdentity(IdentityObject):
    """Identity of Table C-2: Get_Attribute_Single and Reset (Table C-1)."""

    def __init__(self, info: IdentityInfo, board: OptionBoard, on_reset: Callable[[int], None]) -> None:
        super().__init__(info, IDENTITY_SPEC, on_reset)
        self.board = board
        self.bind(1, 9, Binding(lambda: board.inverter.consistency_value))
        major, minor = FIRMWARE_REVISION
        self.instances[1].values[0x65] = major << 8 | minor
        self.set(1, 5, STATUS_ALWAYS_ON)

    def perform_reset(self, instance: Instance | None, reset_type: int, context: RequestContext) -> None:
        if instance is None:
            raise CipError(GeneralStatus.SERVICE_NOT_SUPPORTED)
        if reset_type not in (0, 1):
            # Table E-5: "20 Invalid parameter: the specified operation command data is not supported".
            raise CipError(GeneralStatus.INVALID_PARAMETER, message=f"reset type {reset_type}")
        if self.on_reset is not None:
            self.on_reset(reset_type)


# -- Connection (Table C-8) -----------------------------------------------------------------------

EPATH = RemainingBytes("EPATH")

CONNECTION_SPEC = _spec(CONNECTION, "Connection", (
    AttributeSpec(1, "State", USINT, default=1),
    AttributeSpec(2, "Instance Type", USINT, default=1),
    AttributeSpec(3, "TransportClass_Trigger", BYTE, default=0x83),
    AttributeSpec(7, "Produced Connection Size", UINT, default=16),
    AttributeSpec(8, "Consumed Connection Size", UINT, default=16),
    AttributeSpec(9, "Expected Packet Rate", UINT, Access.GET_SET, default=0, unit="ms", scale=10.0,
                  help="internal processing timeout, 10 ms units"),
    AttributeSpec(0x0C, "Watchdog Timeout Action", USINT, Access.GET_SET, default=0,
                  enum=MappingProxyType({0: "retain timeout status", 1: "cut connection automatically",
                                         2: "operate again with same connection"})),
    AttributeSpec(0x0D, "Produced Connection Path Length", UINT),
    AttributeSpec(0x0E, "Produced Connection Path", EPATH, Access.GET_SET),
    AttributeSpec(0x0F, "Consumed Connection Path Length", UINT),
    AttributeSpec(0x10, "Consumed Connection Path", EPATH, Access.GET_SET),
))


def assembly_path(instance: int) -> bytes:
    """Connection path to an assembly's data: class 4, the instance, attribute 3."""
    return encode_path([LogicalSegment(LogicalType.CLASS_ID, 4), LogicalSegment(LogicalType.INSTANCE_ID, instance),
                        LogicalSegment(LogicalType.ATTRIBUTE_ID, 3)])


def path_instance(path: bytes) -> int:
    """The assembly instance a connection path names (0x09 if it names anything else)."""
    try:
        segments = decode_path(path)
    except CipError:
        segments = []
    kinds = [(s.kind, s.value) for s in segments if isinstance(s, LogicalSegment)]
    well_formed = len(kinds) == len(segments) and len(kinds) in (2, 3) and kinds[0] == (LogicalType.CLASS_ID, 4) \
        and kinds[1][0] is LogicalType.INSTANCE_ID and (len(kinds) == 2 or kinds[2] == (LogicalType.ATTRIBUTE_ID, 3))
    if not well_formed:
        raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message="not a path to an assembly's data")
    return kinds[1][1]


def path_length(path: bytes) -> int:
    """Attributes 0Dh and 0Fh, in bytes. Table C-8 defines each as the "Number of bytes for produced
    [consumed] connection path" (CompoNet manual), as CIP's Connection object defines its
    produced/consumed connection path lengths, and the path it counts is an array of bytes (0Eh, 10h:
    ARRAY). Its default column's "3" fits no path to an assembly's data the board accepts (class 4,
    the instance and attribute 3 are six bytes, 20 04 24 nn 30 03; without the attribute four): it
    is the six bytes in 16-bit words. Two statements of the table and CIP against one figure: the
    length is served in bytes, 6 for the default path, and always agrees with the path read beside it."""
    return len(path)


class ConnectionObject(OptionBoardObject):
    """Instance 1, the poll I/O connection of Table C-8; its paths follow P046 at each start."""

    def __init__(self, outputs: frozenset[int], inputs: frozenset[int]) -> None:
        super().__init__(CONNECTION_SPEC)
        self.outputs = outputs
        self.inputs = inputs
        self.add_instance(1)
        self.select(21, 71)

    def select(self, output: int, input_: int) -> None:
        """The connection as the board starts it, at power-on and reset: Table C-8's defaults (what was
        set, the expected packet rate and the watchdog timeout action, is not kept: "retain timeout
        status (until reset or cleared)"), with the default connection path (P046, Table 10):
        produced = input assembly, consumed = output."""
        values = self.instances[1].values
        values.update({attribute.id: attribute.default for attribute in self.spec.instance_attributes})
        values[0x0E], values[0x10] = assembly_path(input_), assembly_path(output)
        values[0x0D], values[0x0F] = path_length(values[0x0E]), path_length(values[0x10])

    @property
    def pair(self) -> tuple[int, int]:
        values = self.instances[1].values
        return path_instance(values[0x10]), path_instance(values[0x0E])

    def write_attribute(self, instance: Instance, spec: AttributeSpec, value: Any,
                        context: RequestContext | None = None) -> None:
        if spec.id in (0x0E, 0x10):
            allowed = self.inputs if spec.id == 0x0E else self.outputs
            if path_instance(bytes(value)) not in allowed:
                raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message="no such assembly for this path")
            instance.values[spec.id - 1] = path_length(bytes(value))
        super().write_attribute(instance, spec, value, context)


# -- Discrete Input / Output Point (Tables C-10, C-12) --------------------------------------------

DISCRETE_INPUT_SPEC = _spec(DISCRETE_INPUT_POINT, "Discrete Input Point", (
    AttributeSpec(3, "Value", BOOL, help="input point value"),
    AttributeSpec(0x69, "Override", BOOL, Access.GET_SET, help="override the input point value"),
))
DISCRETE_OUTPUT_SPEC = _spec(DISCRETE_OUTPUT_POINT, "Discrete Output Point", (
    AttributeSpec(3, "Value", BOOL, Access.GET_SET, help="control the output point value"),
))
#: Table C-10: on the RX, instance 9 is the FW input terminal; its override travels in bit 8.
FW_TERMINAL_INSTANCE = 9


class DiscreteInputPointObject(BoundObject):
    """Instances 1-7 (MX2) / 1-8 and 9 = FW (RX): input terminal [n] and its network override."""

    def __init__(self, board: OptionBoard, traits: FamilyTraits) -> None:
        super().__init__(DISCRETE_INPUT_SPEC, board)
        for n in range(1, traits.discrete_inputs + 1):
            mask = 1 << (n - 1)
            if n == FW_TERMINAL_INSTANCE:
                def value(mask: int = mask) -> int:
                    inverter = board.inverter
                    return int(inverter.local_run > 0 or bool(inverter.option_command.input_overrides & mask))
            else:
                def value(mask: int = mask) -> int:
                    return int(bool(board.inverter.status().inputs & mask))
            def overridden(mask: int = mask) -> int:
                return int(bool(board.inverter.option_command.input_overrides & mask))

            def override(on: int, mask: int = mask) -> None:
                self._override(mask, on)

            self.add_instance(n, value=self.bound(value), override=self.bound(overridden, override))

    def _override(self, mask: int, on: int) -> None:
        current = self.board.inverter.option_command.input_overrides
        self.board.command(input_overrides=(current | mask) if on else (current & ~mask))


class DiscreteOutputPointObject(BoundObject):
    """Instances 1-3 (MX2: 11, 12, relay) / 1-6 (RX: 11-15, relay)."""

    def __init__(self, board: OptionBoard, traits: FamilyTraits) -> None:
        super().__init__(DISCRETE_OUTPUT_SPEC, board)
        for n in range(1, len(traits.output_terminals) + 1):
            mask = 1 << (n - 1)
            def value(mask: int = mask) -> int:
                return int(bool(board.inverter.option_command.outputs & mask))

            def set_value(on: int, mask: int = mask) -> None:
                self._set(mask, on)

            self.add_instance(n, value=self.bound(value, set_value))

    def _set(self, mask: int, on: int) -> None:
        current = self.board.inverter.option_command.outputs
        self.board.command(outputs=(current | mask) if on else (current & ~mask))


# -- Motor Data (Table D-2) -------------------------------------------------------------------------

MOTOR_TYPE_PM = 3
MOTOR_TYPE_INDUCTION = 7
MOTOR_DATA_SPEC = _spec(MOTOR_DATA, "Motor Data", (
    AttributeSpec(3, "Motor Type", USINT, Access.GET_SET, default=MOTOR_TYPE_INDUCTION,
                  enum=MappingProxyType({MOTOR_TYPE_PM: "PM synchronous motor",
                                         MOTOR_TYPE_INDUCTION: "squirrel cage induction motor"})),
    AttributeSpec(6, "Rated Current", UINT, Access.GET_SET, unit="A", scale=0.1),
    AttributeSpec(7, "Rated Voltage", UINT, Access.GET_SET, unit="V"),
    AttributeSpec(8, "Rated Power", UINT, Access.GET_SET, unit="W"),
    AttributeSpec(9, "Rated Frequency", UINT, Access.GET_SET, default=50, unit="Hz"),
    AttributeSpec(0x0B, "MaxSpeed", UINT, Access.GET_SET, default=50, unit="rpm"),
    AttributeSpec(0x0C, "PoleCount", UINT, Access.GET_SET, minimum=0, maximum=38,
                  help="motor poles for the RPM speed unit (P049); even numbers only"),
))


def rated_power(model_name: str) -> int:
    """Rated power in W from the capacity code of the model name ("A2015" = 1.5 kW, "B4750" = 75 kW);
    the codes ending in K (110 kW and more) exceed the UINT of Table D-2 and read 65535."""
    capacity = model_name.split("-")[1][2:]
    if capacity.endswith("K"):
        return 0xFFFF
    return min(int(capacity) * 100, 0xFFFF)


class MotorDataObject(BoundObject):
    def __init__(self, board: OptionBoard, model_name: str, voltage: int) -> None:
        super().__init__(MOTOR_DATA_SPEC, board)
        inverter = board.inverter
        self.add_instance(1, rated_voltage=voltage, rated_power=rated_power(model_name), rated_current=0,
                          motor_type=self.bound(self._motor_type, self._set_motor_type),
                          polecount=self.bound(lambda: inverter.read_code("P049"),
                                               lambda poles: inverter.write_code("P049", poles, board.now)))

    def _motor_type(self) -> int:
        # Table D-2: 3 when d060 = 3 (PM), else 7; fixed to 7 on the RX.
        return MOTOR_TYPE_PM if self.board.inverter.read_code("d060") == 3 else MOTOR_TYPE_INDUCTION

    def _set_motor_type(self, value: int) -> None:
        inverter, now = self.board.inverter, self.board.now
        if value not in (MOTOR_TYPE_PM, MOTOR_TYPE_INDUCTION) or (
                value == MOTOR_TYPE_PM and inverter.family is Family.RX):
            raise CipError(GeneralStatus.INVALID_ATTRIBUTE_VALUE, message=f"motor type {value}")
        if value == self._motor_type():
            return
        # Table D-2 (MX2): like setting b171 (inverter mode) and b180 (initialization); 3 selects PM
        # (d060 = 3), 7 leaves PM for the ND mode (d060 = 1); then the inverter and the board reset.
        if value == MOTOR_TYPE_PM:
            inverter.write_code("b171", 3, now)
        else:
            inverter.write_code("b171", 1, now)
            inverter.write_code("b049", 1, now)
        inverter.write_code("b180", 1, now)
        self.board.motor_type_changed()


# -- Control Supervisor (Tables D-4, D-5) ----------------------------------------------------------

CONTROL_SUPERVISOR_SPEC = _spec(CONTROL_SUPERVISOR, "Control Supervisor", (
    AttributeSpec(3, "Run1", BOOL, Access.GET_SET, default=0, help="run forward"),
    AttributeSpec(4, "Run2", BOOL, Access.GET_SET, default=0, help="run reverse"),
    AttributeSpec(5, "Net Ctrl", BOOL, Access.GET_SET, default=0, help="run command from the network"),
    AttributeSpec(6, "State", UINT, enum=MappingProxyType({1: "Startup", 2: "Not ready", 3: "Ready", 4: "Enabled",
                                                            5: "Stopping", 6: "Fault/trip stop",
                                                            7: "Faulted/tripped"})),
    AttributeSpec(7, "Running1", BOOL),
    AttributeSpec(8, "Running2", BOOL),
    AttributeSpec(9, "Ready", UINT),
    AttributeSpec(0x0A, "Faulted", BOOL),
    AttributeSpec(0x0B, "Warning", BOOL),
    AttributeSpec(0x0C, "Fault Rst", BOOL, Access.GET_SET, default=0, help="reset a trip when written to 1"),
    AttributeSpec(0x0D, "Fault Code", UINT, help="CIP fault code of the trip (Table D-5)"),
    AttributeSpec(0x0F, "Ctrl From Net", BOOL),
    AttributeSpec(0x10, "Net Fault Mode", UINT, Access.GET_SET, default=2, minimum=0, maximum=2,
                  enum=MappingProxyType({0: "fault/trip and stop (P045 = 1)", 1: "ignore (P045 = 2)",
                                         2: "vendor specific"})),
    AttributeSpec(0x11, "Force Fault", BOOL, Access.GET_SET, default=0, help="external trip on 0 to 1"),
    AttributeSpec(0x12, "Force Status", BOOL),
    AttributeSpec(0x14, "Net Idle Mode", USINT, Access.GET_SET, default=2, minimum=0, maximum=2,
                  enum=MappingProxyType({0: "stop (P048 = 4)", 1: "ignore (P048 = 2)", 2: "vendor specific"})),
    AttributeSpec(0x64, "Drive State Detail", USINT),
    AttributeSpec(0x65, "Trip Cause", USINT, help="n of the trip En, 0 when not tripped"),
    AttributeSpec(0x66, "Free Run", BOOL, Access.GET_SET, default=0),
))

#: Net Fault Mode <-> P045 and Net Idle Mode <-> P048 (Table D-4); 2 is any other (vendor) setting.
NET_FAULT_MODES: Mapping[int, int] = MappingProxyType({0: 1, 1: 2})
NET_IDLE_MODES: Mapping[int, int] = MappingProxyType({0: 4, 1: 2})
_VENDOR_SPECIFIC = 2


class ControlSupervisorObject(BoundObject):
    def __init__(self, board: OptionBoard) -> None:
        super().__init__(CONTROL_SUPERVISOR_SPEC, board)
        inverter = board.inverter

        def command(name: str) -> Binding:
            return self.bound(lambda: int(getattr(inverter.option_command, name)),
                              lambda value: board.command(**{name: bool(value)}))

        def status(name: str, cast: Callable[[Any], int] = int) -> Binding:
            return self.bound(lambda: cast(getattr(inverter.status(), name)))

        self.add_instance(
            1, run1=command("fwd"), run2=command("rev"), net_ctrl=command("net_ctrl"), state=status("drive_state"),
            running1=status("forward"), running2=status("reverse"), ready=status("ready"), faulted=status("faulted"),
            warning=status("warning"), fault_code=status("fault_code"),
            fault_rst=self.bound(lambda: int(inverter.option_command.fault_reset),
                                 lambda value: inverter.write_fault_reset(board.now, bool(value))),
            ctrl_from_net=status("ctrl_from_net"),
            net_fault_mode=self.bound(lambda: self._mode("P045", NET_FAULT_MODES),
                                      lambda value: self._set_mode("P045", NET_FAULT_MODES, value)),
            force_fault=command("force_fault"), force_status=status("force_status"),
            net_idle_mode=self.bound(lambda: self._mode("P048", NET_IDLE_MODES),
                                     lambda value: self._set_mode("P048", NET_IDLE_MODES, value)),
            drive_state_detail=status("drive_state_detail"), trip_cause=status("trip_cause"),
            free_run=command("free_run"))

    def _mode(self, code: str, modes: Mapping[int, int]) -> int:
        setting = self.board.inverter.read_code(code)
        return next((mode for mode, value in modes.items() if value == setting), _VENDOR_SPECIFIC)

    def _set_mode(self, code: str, modes: Mapping[int, int], mode: int) -> None:
        if mode == _VENDOR_SPECIFIC:
            if self._mode(code, modes) != _VENDOR_SPECIFIC:
                # "Vendor specific" asks for the option board's own action: its default, trip (P045/P048 = 0).
                self.board.inverter.write_code(code, 0, self.board.now)
            return
        self.board.inverter.write_code(code, modes[mode], self.board.now)


# -- AC/DC Drive (Table D-7) ------------------------------------------------------------------------

AC_DC_DRIVE_SPEC = _spec(AC_DC_DRIVE, "AC/DC Drive", (
    AttributeSpec(3, "At Reference", BOOL),
    AttributeSpec(4, "Net Ref", BOOL, Access.GET_SET, default=0, help="speed reference from the network"),
    AttributeSpec(6, "Drive Mode", USINT, Access.GET_SET, default=0, minimum=0, maximum=0,
                  enum=MappingProxyType({0: "vendor specific mode"})),
    AttributeSpec(7, "Speed Actual", INT, help="0.01 Hz, 0.1 Hz or RPM (P049, d060)"),
    AttributeSpec(8, "Speed Ref", INT, Access.GET_SET, default=0, minimum=0,
                  help="0.01 Hz, 0.1 Hz or RPM (P049, d060)"),
    AttributeSpec(9, "Current Actual", INT, unit="A", scale=0.1),
    AttributeSpec(0x0F, "Power Actual", INT, unit="W"),
    AttributeSpec(0x11, "Output Voltage", INT, unit="V"),
    AttributeSpec(0x12, "Accel Time", UINT, Access.GET_SET, default=10000, minimum=10, unit="ms"),
    AttributeSpec(0x13, "Decel Time", UINT, Access.GET_SET, default=10000, minimum=10, unit="ms"),
    AttributeSpec(0x1D, "Ref From Net", BOOL),
    AttributeSpec(0x77, "Torque Actual Rel", INT, Access.GET_SET, unit="%"),
    AttributeSpec(0x78, "Torque Ref Rel", INT, Access.GET_SET, default=0, minimum=0, maximum=200, unit="%"),
    AttributeSpec(0x79, "Torque Compensation Bias Rel", INT, Access.GET_SET, default=0, minimum=-200, maximum=200,
                  unit="%"),
    AttributeSpec(0x7A, "At Zero Speed", BOOL),
))


def speed_word(value: int) -> int:
    """A speed magnitude as the INT the wire carries: 400.00 Hz (40000) exceeds INT, so the word is
    sent as its 16-bit pattern (the master reads it as an unsigned word, section 4-2-5)."""
    value &= 0xFFFF
    return value - 0x10000 if value & 0x8000 else value


class AcDcDriveObject(BoundObject):
    """Table D-7. Output Voltage (11h) is simulated as a linear V/f: the Motor Data object's Rated
    Voltage (Table D-2 attribute 7: the model's voltage class) at its Rated Frequency (attribute 9,
    50 Hz), in proportion below it, at most the rated voltage above it, 0 while the output is off.
    Current Actual (09h), Power Actual (0Fh) and Torque Actual Rel (77h), like the assemblies' output
    current word, need a motor and its load, for which the CompoNet manual gives no figure: they are
    not simulated and read 0 (the docs and the front panel say so)."""

    def __init__(self, board: OptionBoard, motor_data: MotorDataObject) -> None:
        super().__init__(AC_DC_DRIVE_SPEC, board)
        inverter = board.inverter
        self._motor_data = motor_data

        def status(name: str) -> Binding:
            return self.bound(lambda: int(getattr(inverter.status(), name)))

        def ramp(code: str) -> Binding:
            # Table D-7 in ms; F002/F003 in 0.01 s.
            return self.bound(lambda: min(inverter.read_code(code) * 10, 0xFFFF),
                              lambda ms: inverter.write_code(code, max(1, round(ms / 10)), board.now))

        self.add_instance(
            1, at_reference=status("at_reference"),
            net_ref=self.bound(lambda: int(inverter.option_command.net_ref),
                               lambda value: board.command(net_ref=bool(value))),
            speed_actual=self.bound(lambda: speed_word(inverter.status().speed_actual)),
            speed_ref=self.bound(lambda: speed_word(inverter.option_command.speed_reference),
                                 lambda value: board.command(speed_reference=value)),
            current_actual=0, power_actual=0, output_voltage=self.bound(self._output_voltage),
            accel_time=ramp("F002"), decel_time=ramp("F003"), ref_from_net=status("ref_from_net"),
            # d012 is a monitor: writing it is refused by the inverter (0x0E).
            torque_actual_rel=self.bound(lambda: inverter.read_code("d012"),
                                         lambda value: inverter.write_code("d012", value, board.now)),
            torque_ref_rel=self.bound(lambda: inverter.option_command.torque_reference,
                                      lambda value: self._torque(torque_reference=value)),
            torque_compensation_bias_rel=self.bound(lambda: inverter.option_command.torque_bias,
                                                    lambda value: self._torque(torque_bias=value)),
            at_zero_speed=status("zero_speed"))

    def _output_voltage(self) -> int:
        status = self.board.inverter.status()
        if not status.running:
            return 0
        rated_voltage, rated_hz = int(self._motor_data.get(1, 7)), int(self._motor_data.get(1, 9))
        if rated_hz <= 0:
            return rated_voltage
        return round(rated_voltage * min(1.0, status.output_frequency / 100 / rated_hz))

    def _torque(self, **value: int) -> None:
        if self.board.inverter.read_code("d060") != 0:
            # Section 4-4 note: torque settings only in the constant-torque IM mode (Tables 22/23).
            raise CipError(GeneralStatus.DEVICE_STATE_CONFLICT, message="torque control needs d060 = 0")
        self.board.command(**value)


# -- Unit Parameter (Table C-14), CompoNet Link (Table C-16) ----------------------------------------

UNIT_PARAMETER_SPEC = _spec(UNIT_PARAMETER, "Unit Parameter", (
    AttributeSpec(0x64, "Default Connection Path", USINT, Access.GET_SET, default=1, minimum=0, maximum=7,
                  help="P046 (Table 10)"),
))


class UnitParameterObject(BoundObject):
    def __init__(self, board: OptionBoard) -> None:
        super().__init__(UNIT_PARAMETER_SPEC, board)
        inverter = board.inverter
        self.add_instance(1, default_connection_path=self.bound(
            lambda: inverter.read_code("P046"), lambda value: inverter.write_code("P046", value, board.now)))


BAUD_RATES: Mapping[int, str] = MappingProxyType({0: "93.75 kbit/s", 1: "reserved", 2: "1.5 Mbit/s",
                                                  3: "3 Mbit/s", 4: "4 Mbit/s"})
COMPONET_LINK_SPEC = _spec(COMPONET_LINK, "CompoNet Link", (
    AttributeSpec(1, "MAC ID", USINT, default=0, minimum=0, maximum=63, help="node address in use"),
    AttributeSpec(2, "Baud Rate", UINT, default=0, enum=BAUD_RATES),
    AttributeSpec(5, "Allocation Choice", WORD, default=2),
    AttributeSpec(6, "MAC ID Switch Changed", BOOL, default=0),
    AttributeSpec(8, "MAC ID Switch Value", UINT, default=0),
    AttributeSpec(0x0A, "Explicit Message Timer", UINT, Access.GET_SET, default=0),
))


@dataclass
class LinkState:
    """The option board's CompoNet link: node address in use and the setting behind it (section 2-1-4)."""

    #: Rotary switches (0-99); 64-99 hand the address to P190.
    rotary_switches: int = 0
    mac_id: int = 0
    baud_rate: int = 0


class CompoNetLinkObject(BoundObject):
    def __init__(self, board: OptionBoard, link: LinkState, setting: Callable[[], int]) -> None:
        super().__init__(COMPONET_LINK_SPEC, board)
        self.link = link
        self.add_instance(1, mac_id=Binding(lambda: link.mac_id), baud_rate=Binding(lambda: link.baud_rate),
                          mac_id_switch_changed=self.bound(lambda: int(setting() != link.mac_id)),
                          mac_id_switch_value=Binding(lambda: link.rotary_switches))


#: The declared classes, for the scanner's catalog and the EDS (0x64/0x65 have no fixed attributes).
CLASS_SPECS: tuple[ClassSpec, ...] = (
    IDENTITY_SPEC, CONNECTION_SPEC, DISCRETE_INPUT_SPEC, DISCRETE_OUTPUT_SPEC, MOTOR_DATA_SPEC,
    CONTROL_SUPERVISOR_SPEC, AC_DC_DRIVE_SPEC, MODBUS_REGISTER_SPEC, FUNCTION_CODE_SPEC, UNIT_PARAMETER_SPEC,
    COMPONET_LINK_SPEC,
)

__all__ = [
    "AC_DC_DRIVE",
    "CLASS_SPECS",
    "COMPONET_LINK",
    "CONNECTION",
    "CONTROL_SUPERVISOR",
    "DISCRETE_INPUT_POINT",
    "DISCRETE_OUTPUT_POINT",
    "FUNCTION_CODE",
    "FUNCTION_CODE_GROUP_BASES",
    "FUNCTION_CODE_SPEC",
    "IDENTITY",
    "MODBUS_REGISTER",
    "MODBUS_REGISTER_SPEC",
    "MOTOR_DATA",
    "UNIT_PARAMETER",
    "AcDcDriveObject",
    "BoundObject",
    "CompoNetLinkObject",
    "ConnectionObject",
    "ControlSupervisorObject",
    "DiscreteInputPointObject",
    "DiscreteOutputPointObject",
    "FunctionCodeObject",
    "LinkState",
    "ModbusRegisterObject",
    "MotorDataObject",
    "OptionBoard",
    "OptionBoardIdentity",
    "OptionBoardObject",
    "RegisterObject",
    "UnitParameterObject",
    "assembly_path",
    "inverter_access",
    "refusal_status",
    "speed_word",
]
