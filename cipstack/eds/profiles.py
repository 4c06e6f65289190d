"""The EDS descriptions of the emulated devices, built from their declarations.

* ``acg_et2_description()``: the ACG drive with its ACG-ET2 EtherNet/IP card (seed 000): its
  Identity, every keypad parameter through its class 0x64 path (instance = keypad group,
  attribute = code number), grouped by keypad group, and the drive-profile assemblies.
* ``omron_description(model_name)``: the 3G3AX-MX2-CRT-E / 3G3AX-RX-CRT-E CompoNet option board
  on one MX2 or RX inverter model (seed 004): its Identity (Table C-2 with the product code and
  name of Tables 2/3), every function-code parameter through its class 0x65 path (Table E-3),
  the drive-profile assemblies and the ``[CompoNet_IO]`` sizes of the default connection path.
* ``eds_file_name(description)``: the file the description is written to; for the option
  board the name of Tables 2/3.

The device modules may pass their full assembly sets, class declarations and CIP attributes;
without them each description holds what the shared declarations give.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

from ..assemblies.drive_profile import (
    basic_speed_control_input,
    basic_speed_control_output,
    extended_speed_control_input,
    extended_speed_control_output,
)
from ..assemblies.schema import AssemblySchema
from ..devices.acg import registers as acg
from ..devices.base import DeviceLimits
from ..devices.omron import models as omron
from ..devices.omron.registers import (
    CONNECTION_PATHS,
    TRAITS,
    Parameter,
    SpeedUnit,
    function_code_path,
    register_set,
)
from ..devices.profiles import acg_et2_identity
from ..eip.connection_manager import BACKPLANE_PORT
from ..objects import message_router
from ..objects.identity import IdentityInfo, identity_spec
from ..objects.tcpip import ETHERNET_LINK_SPEC, TCPIP_CLASS_ID, TCPIP_SPEC
from .description import EdsCapacity, EdsDescription, EdsObjectClass, EdsParameter, EdsPort, IoOffer

#: Class of the ACG-ET2 keypad parameters: "Class 0x64 (Drive Object)" (seed 000).
ACG_KEYPAD_CLASS = 0x64
#: Seed 000 gives vendor ID 259 (Identity Object, attribute 1) but no vendor name: the EDS says
#: only the number rather than guess a company.
ACG_VENDOR_NAME = "Vendor 259"
#: The card's catalog name, "ACG-ET2" (seed 000, appendix B title and overview).
ACG_CATALOG = "ACG-ET2"
#: ``ProdTypeStr`` of device type 2: the CIP AC drive profile (seed 000: "Device Type (drive) 2";
#: seed 004, Table 1: "CompoNet Profile AC Drive (0x02)").
AC_DRIVE = "AC Drive"

#: Function Code object: "class 0x65" (seed 004, section E-3, Table E-3).
OMRON_FUNCTION_CODE_CLASS = 0x65
#: Identity attribute 1 of the option board: "47 (OMRON Corporation)" (seed 004, Table C-2).
OMRON_VENDOR_NAME = "OMRON Corporation"

#: Unit and scale of the rotational speed words for each speed unit (seed 004, section 4-2-5).
SPEED_UNITS: Mapping[SpeedUnit, tuple[str, float]] = {
    SpeedUnit.CENTIHERTZ: ("Hz", 0.01),
    SpeedUnit.DECIHERTZ: ("Hz", 0.1),
    SpeedUnit.RPM: ("rpm", 1.0),
}


# -- ACG-ET2 ---------------------------------------------------------------------------------------

def acg_keypad_parameters() -> tuple[EdsParameter, ...]:
    """Every keypad parameter with a class 0x64 path, by address (so by keypad group: dr, bA,
    Ad, Cn, In, OU, CM, AP, Pr, M2), each in the group of its keypad group."""
    out: list[EdsParameter] = []
    for address in acg.ACG_REGISTERS:
        register = acg.ACG_REGISTERS[address]
        path = acg.class64_path(register)
        if path is None:
            continue
        # Group names as seed 001 "Total Memory Map for Communication" writes them ("dr Group").
        out.append(EdsParameter.from_register(register, (ACG_KEYPAD_CLASS, *path), group=f"{register.group} Group"))
    return tuple(out)


def acg_pairs(outputs: Iterable[AssemblySchema], inputs: Iterable[AssemblySchema]
              ) -> tuple[tuple[tuple[int, int], ...], dict[tuple[int, int], str], dict[int, str]]:
    """The exclusive-owner pairs of the ACG-ET2, and when each pair and each input is accepted.

    The card serves the output instance CM.24 selects and the input instance CM.23 selects
    (seed 000, "CIP Input Instance (CM.23)", "CIP Output Instance (CM.24)"). The pairs listed
    are those of equal settings (20/70, 21/71, 100/110, ...), the pair of the factory settings
    first.
    """
    have_out = {schema.instance for schema in outputs}
    have_in = {schema.instance for schema in inputs}
    default_out = acg.ACG_REGISTERS.by_code("CM.24").default
    default_in = acg.ACG_REGISTERS.by_code("CM.23").default
    factory: list[tuple[int, int]] = []
    others: list[tuple[int, int]] = []
    notes: dict[tuple[int, int], str] = {}
    input_notes: dict[int, str] = {}
    for out_selection, in_selection in zip(acg.CIP_OUTPUT_INSTANCES, acg.CIP_INPUT_INSTANCES, strict=True):
        if out_selection.instance not in have_out or in_selection.instance not in have_in:
            continue
        pair = (out_selection.instance, in_selection.instance)
        notes[pair] = f"accepted while CM.24 = {out_selection.setting} and CM.23 = {in_selection.setting}"
        input_notes[in_selection.instance] = f"accepted while CM.23 = {in_selection.setting}"
        is_factory = out_selection.setting == default_out and in_selection.setting == default_in
        (factory if is_factory else others).append(pair)
    return (*factory, *others), notes, input_notes


def acg_et2_description(
    *,
    identity: IdentityInfo | None = None,
    outputs: Sequence[AssemblySchema] | None = None,
    inputs: Sequence[AssemblySchema] | None = None,
    attributes: Sequence[EdsParameter] = (),
    io: IoOffer | None = None,
    object_classes: Sequence[EdsObjectClass] | None = None,
    limits: DeviceLimits | None = None,
) -> EdsDescription:
    """The ACG-ET2's description.

    Defaults: the Identity of ``acg_et2_identity()``; outputs 20/21 and inputs 70/71 of the
    drive profile in rpm; ``attributes`` (parameters of the CIP objects, e.g. 0x28/0x29/0x2A)
    before the keypad parameters; the connections of ``acg_pairs`` with the class 1 limits
    ``IoProfile`` has by default; the message connection limit of ``DeviceLimits``; the
    Identity, Message Router, TCP/IP Interface and Ethernet Link classes.
    """
    outputs = tuple(outputs) if outputs is not None else (
        basic_speed_control_output(20, "rpm"), extended_speed_control_output(21, "rpm"))
    inputs = tuple(inputs) if inputs is not None else (
        basic_speed_control_input(70, "rpm"), extended_speed_control_input(71, "rpm"))
    if io is None:
        pairs, notes, input_notes = acg_pairs(outputs, inputs)
        io = IoOffer(pairs=pairs, pair_notes=notes, input_notes=input_notes)
    limits = limits or DeviceLimits()
    if object_classes is None:
        object_classes = tuple(EdsObjectClass(spec) for spec in (
            identity_spec(), message_router.SPEC, TCPIP_SPEC, ETHERNET_LINK_SPEC))
    return EdsDescription(
        identity=identity or acg_et2_identity(),
        vendor_name=ACG_VENDOR_NAME,
        product_type_name=AC_DRIVE,
        catalog=ACG_CATALOG,
        network="EtherNetIP",
        description="ACG drive with its ACG-ET2 EtherNet/IP communication board",
        parameters=(*attributes, *acg_keypad_parameters()),
        outputs=outputs,
        inputs=inputs,
        io=io,
        # Port 1 is the backplane (the device itself); the Ethernet port is the next one.
        ports=(EdsPort("TCP", "EtherNet/IP Port", (TCPIP_CLASS_ID, 1), BACKPLANE_PORT + 1),),
        capacity=EdsCapacity(max_io_connections=io.max_connections, max_msg_connections=limits.max_connections),
        object_classes=tuple(object_classes),
    )


# -- Omron MX2 / RX CompoNet option board ------------------------------------------------------------

def omron_parameter(parameter: Parameter) -> EdsParameter:
    """A function-code parameter through its class 0x65 path (Table E-3). F001 cannot be written
    by function code and b127 is two words there (section E-2-2)."""
    return EdsParameter.from_register(
        parameter, (OMRON_FUNCTION_CODE_CLASS, *function_code_path(parameter.code)),
        group=f"{parameter.group} Group",
        settable=parameter.access.writable and parameter.function_code_writable,
        words=parameter.function_code_words or None,
    )


def omron_parameters(family: omron.Family) -> tuple[EdsParameter, ...]:
    """Every parameter of ``family`` that has a function code, in declaration order."""
    return tuple(omron_parameter(p) for p in register_set(family).parameters if p.code)


def omron_speed_unit(family: omron.Family) -> tuple[str, float]:
    """Unit and scale of the speed words with the factory settings: P049 (motor poles) and d060
    (inverter mode) at their defaults select the unit (section 4-2-5)."""
    registers = register_set(family)
    unit = TRAITS[family].speed_unit(registers.by_code("P049").default, registers.by_code("d060").default)
    return SPEED_UNITS[unit]


def omron_description(
    model_name: str,
    *,
    outputs: Sequence[AssemblySchema] | None = None,
    inputs: Sequence[AssemblySchema] | None = None,
    attributes: Sequence[EdsParameter] = (),
    object_classes: Sequence[EdsObjectClass] | None = None,
) -> EdsDescription:
    """The option board on inverter ``model_name`` (Tables 2/3); ``UnknownModelError`` for a
    name the tables do not list.

    Defaults: outputs 20/21 and inputs 70/71 of the drive profile with speed words in the
    factory unit (``omron_speed_unit``); the Identity and Message Router classes. The
    ``[CompoNet_IO]`` sizes are those of the pair P046's factory setting selects (Table 10).
    """
    found = omron.model(model_name)
    family = found.family
    label, scale = omron_speed_unit(family)
    outputs = tuple(outputs) if outputs is not None else (
        basic_speed_control_output(20, label, scale), extended_speed_control_output(21, label, scale))
    inputs = tuple(inputs) if inputs is not None else (
        basic_speed_control_input(70, label, scale), extended_speed_control_input(71, label, scale))
    _, default_output, default_input = CONNECTION_PATHS[register_set(family).by_code("P046").default]
    if object_classes is None:
        object_classes = tuple(EdsObjectClass(spec) for spec in (identity_spec(), message_router.SPEC))
    names = " / ".join(m.name for m in omron.models_with_product_code(found.product_code))
    identity = IdentityInfo(
        vendor_id=omron.VENDOR_ID, device_type=omron.DEVICE_TYPE, product_code=found.product_code,
        revision=omron.REVISION, serial_number=0, product_name=found.product_name,
    )
    return EdsDescription(
        identity=identity,
        vendor_name=OMRON_VENDOR_NAME,
        product_type_name=AC_DRIVE,
        catalog=family.option_board,
        network="CompoNet",
        description=f"{family.option_board} CompoNet option board on the {names} inverter",
        parameters=(*attributes, *omron_parameters(family)),
        outputs=outputs,
        inputs=inputs,
        object_classes=tuple(object_classes),
        componet_io=(default_output, default_input),
        file_name=found.eds_file,
    )


def omron_models_by_file(family: omron.Family) -> tuple[omron.Model, ...]:
    """One model per EDS file of ``family`` (the first of a pair sharing a product code), in the
    order of Tables 2/3."""
    seen: dict[str, omron.Model] = {}
    for item in omron.models_of(family):
        seen.setdefault(item.eds_file, item)
    return tuple(seen.values())


def eds_file_name(description: EdsDescription) -> str:
    """The description's file name, else ``<catalog>_<major>.<minor>.eds`` (``ACG-ET2_1.01.eds``:
    the revision as the ACG-ET2 shows its version, seed 000 Identity attribute 4 note)."""
    if description.file_name:
        return description.file_name
    major, minor = description.identity.revision
    safe = "".join(char if char.isalnum() or char in "-_." else "_" for char in description.catalog)
    return f"{safe}_{major}.{minor:02d}.eds"
