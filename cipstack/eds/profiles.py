"""The EDS descriptions of the emulated devices, built from the devices themselves.

* ``acg_et2_description()``: the ACG drive with its ACG-ET2 EtherNet/IP card (ACG-ET2 manual) as
  ``build_acg_device()`` builds it at the factory settings: its Identity, the attributes of its
  Motor Data 0x28, Control Supervisor 0x29 and AC/DC Drive 0x2A objects, every keypad parameter
  through its class 0x64 path (instance = keypad group, attribute = code number), grouped by
  keypad group, all 24 assemblies (20/21/100/101/121-128 and 70/71/110/111/141-148 at the
  CM.31-CM.38 / CM.51-CM.58 factory addresses), the objects its message router serves, and its
  class 1 offer: the RPI range, heartbeat points and connection limit of its ``IoProfile``, with
  every CM.24/CM.23 pair (the card accepts the pair the settings select).
* ``omron_description(model_name)``: the 3G3AX-MX2-CRT-E / 3G3AX-RX-CRT-E CompoNet option board
  on one MX2 or RX inverter model (CompoNet manual) as ``build_omron_device`` builds it: its Identity
  (Table C-2 with the product code and name of Tables 2/3), the attributes of its drive objects,
  every function-code parameter through its class 0x65 path (Table E-3), its assemblies in the
  factory speed unit (the flexible 139/159 when the factory mapping makes them), its object
  classes and the ``[CompoNet_IO]`` sizes of the default connection path (P046, Table 10).
* ``eds_file_name(description)``: the file the description is written to; for the option
  board the name of Tables 2/3.

Nothing here is declared a second time: every value comes from the device modules.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence

from ..assemblies.schema import AssemblySchema
from ..devices.acg import registers as acg
from ..devices.acg.assemblies import INPUT_INSTANCES as ACG_INPUT_INSTANCES
from ..devices.acg.assemblies import OUTPUT_INSTANCES as ACG_OUTPUT_INSTANCES
from ..devices.acg.device import build_acg_device
from ..devices.acg.drive import MODEL as ACG_MODEL
from ..devices.acg.objects import AC_DC_DRIVE_SPEC, CONTROL_SUPERVISOR_SPEC, KEYPAD_PARAMETERS, MOTOR_DATA_SPEC
from ..devices.base import Device, DeviceLimits
from ..devices.omron import models as omron
from ..devices.omron.assemblies import INPUT_INSTANCES as OMRON_INPUT_INSTANCES
from ..devices.omron.assemblies import OUTPUT_INSTANCES as OMRON_OUTPUT_INSTANCES
from ..devices.omron.device import build_omron_device
from ..devices.omron.objects import AC_DC_DRIVE_SPEC as OMRON_AC_DC_DRIVE_SPEC
from ..devices.omron.objects import CLASS_SPECS as OMRON_CLASS_SPECS
from ..devices.omron.objects import CONTROL_SUPERVISOR_SPEC as OMRON_CONTROL_SUPERVISOR_SPEC
from ..devices.omron.objects import FUNCTION_CODE
from ..devices.omron.objects import MOTOR_DATA_SPEC as OMRON_MOTOR_DATA_SPEC
from ..devices.omron.registers import Parameter, function_code_path, register_set
from ..eip.wire.cm_spec import BACKPLANE_PORT
from ..objects.identity import IdentityInfo
from ..objects.tcpip import TCPIP_CLASS_ID
from .description import (
    EdsCapacity,
    EdsDescription,
    EdsObjectClass,
    EdsParameter,
    EdsPort,
    IoOffer,
    attribute_parameters,
)

#: ACG-ET2 manual gives vendor ID 259 (Identity Object, attribute 1) but no vendor name; the ODVA vendor
#: list that scanner libraries carry (pycomm3's among them) names 259 "LS ELECTRIC".
ACG_VENDOR_NAME = "LS ELECTRIC"
#: The card's catalog name, "ACG-ET2" (ACG-ET2 manual, appendix B title and overview): the drive model's name.
ACG_CATALOG = ACG_MODEL
#: ``ProdTypeStr`` of device type 2: the CIP AC drive profile (ACG-ET2 manual: "Device Type (drive) 2";
#: CompoNet manual, Table 1: "CompoNet Profile AC Drive (0x02)").
AC_DRIVE = "AC Drive"

#: Identity attribute 1 of the option board: "47 (OMRON Corporation)" (CompoNet manual, Table C-2).
OMRON_VENDOR_NAME = "OMRON Corporation"


def device_object_classes(device: Device) -> tuple[EdsObjectClass, ...]:
    """An object class section for every class the device's message router serves, with the
    instances it has (the generator leaves out Assembly and Connection Manager, which have
    sections of their own)."""
    return tuple(EdsObjectClass(obj.spec, len(obj.instances))
                 for _, obj in sorted(device.router.objects.items()))


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
        # Group names as ACG RS-485 manual "Total Memory Map for Communication" writes them ("dr Group").
        out.append(EdsParameter.from_register(register, (KEYPAD_PARAMETERS, *path), group=f"{register.group} Group"))
    return tuple(out)


def acg_attribute_parameters() -> tuple[EdsParameter, ...]:
    """The instance 1 attributes of Motor Data 0x28, Control Supervisor 0x29 and AC/DC Drive 0x2A
    (ACG-ET2 manual, "Supported Objects"), as the card declares them; the drive-profile assembly
    members refer to them."""
    return tuple(p for spec in (MOTOR_DATA_SPEC, CONTROL_SUPERVISOR_SPEC, AC_DC_DRIVE_SPEC)
                 for p in attribute_parameters(spec))


def acg_pairs(outputs: Iterable[AssemblySchema], inputs: Iterable[AssemblySchema]
              ) -> tuple[tuple[tuple[int, int], ...], dict[tuple[int, int], str], dict[int, str]]:
    """The exclusive-owner pairs of the ACG-ET2, and when each pair and each input is accepted.

    The card serves the output instance CM.24 selects and the input instance CM.23 selects
    (ACG-ET2 manual, "CIP Input Instance (CM.23)", "CIP Output Instance (CM.24)"). The pairs listed
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
    attributes: Sequence[EdsParameter] | None = None,
    io: IoOffer | None = None,
    object_classes: Sequence[EdsObjectClass] | None = None,
    limits: DeviceLimits | None = None,
) -> EdsDescription:
    """The ACG-ET2's description; each argument replaces what the device built by
    ``build_acg_device(limits=limits)`` gives.

    Defaults: the device's Identity; its 24 assemblies at the factory settings; the attributes
    of 0x28/0x29/0x2A (``acg_attribute_parameters``) before the keypad parameters; the class 1
    offer of its ``IoProfile`` (RPI range, heartbeat points, connection limit) with the pairs of
    ``acg_pairs``; the message connection limit of ``limits``; the classes its router serves.
    """
    device = build_acg_device(limits=limits, now=0.0)
    outputs = tuple(outputs) if outputs is not None else tuple(
        device.assembly_schema(i) for i in ACG_OUTPUT_INSTANCES)
    inputs = tuple(inputs) if inputs is not None else tuple(device.assembly_schema(i) for i in ACG_INPUT_INSTANCES)
    if io is None:
        pairs, notes, input_notes = acg_pairs(outputs, inputs)
        io = dataclasses.replace(IoOffer.from_io_profile(device.io_profile()), pairs=pairs, pair_notes=notes,
                                 input_notes=input_notes)
    attributes = acg_attribute_parameters() if attributes is None else tuple(attributes)
    if object_classes is None:
        object_classes = device_object_classes(device)
    return EdsDescription(
        identity=identity or device.identity_info,
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
        capacity=EdsCapacity(max_io_connections=io.max_connections,
                             max_msg_connections=device.limits.max_connections),
        object_classes=tuple(object_classes),
    )


# -- Omron MX2 / RX CompoNet option board ------------------------------------------------------------

def omron_parameter(parameter: Parameter) -> EdsParameter:
    """A function-code parameter through its class 0x65 path (Table E-3). F001 cannot be written
    by function code and b127 is two words there (section E-2-2)."""
    return EdsParameter.from_register(
        parameter, (FUNCTION_CODE, *function_code_path(parameter.code)),
        group=f"{parameter.group} Group",
        settable=parameter.access.writable and parameter.function_code_writable,
        words=parameter.function_code_words or None,
    )


def omron_parameters(family: omron.Family) -> tuple[EdsParameter, ...]:
    """Every parameter of ``family`` that has a function code, in declaration order."""
    return tuple(omron_parameter(p) for p in register_set(family).parameters if p.code)


def omron_attribute_parameters() -> tuple[EdsParameter, ...]:
    """The instance 1 attributes of the option board's Motor Data 0x28, Control Supervisor 0x29
    and AC/DC Drive 0x2A objects (appendix D); the assembly members refer to them."""
    return tuple(p for spec in (OMRON_MOTOR_DATA_SPEC, OMRON_CONTROL_SUPERVISOR_SPEC, OMRON_AC_DC_DRIVE_SPEC)
                 for p in attribute_parameters(spec))


def omron_description(
    model_name: str,
    *,
    outputs: Sequence[AssemblySchema] | None = None,
    inputs: Sequence[AssemblySchema] | None = None,
    attributes: Sequence[EdsParameter] | None = None,
    object_classes: Sequence[EdsObjectClass] | None = None,
) -> EdsDescription:
    """The option board on inverter ``model_name`` (Tables 2/3); ``UnknownModelError`` for a
    name the tables do not list. Each argument replaces what ``build_omron_device(model_name)``
    gives at the factory settings.

    Defaults: the device's Identity; its assemblies (``OmronDevice.schemas()``: speed words in
    the unit P049/d060 select, section 4-2-5, and 139/159 with the words of the flexible mapping
    when there is one); the attributes of 0x28/0x29/0x2A before the function codes; the classes
    of ``CLASS_SPECS`` with the instances the device has. ``[CompoNet_IO]`` gives the pair P046
    selects (Table 10), as the device applied it at power-on.
    """
    found = omron.model(model_name)
    family = found.family
    device = build_omron_device(found.name)
    schemas = device.schemas()
    outputs = tuple(outputs) if outputs is not None else tuple(
        schemas[i] for i in OMRON_OUTPUT_INSTANCES if i in schemas)
    inputs = tuple(inputs) if inputs is not None else tuple(schemas[i] for i in OMRON_INPUT_INSTANCES if i in schemas)
    attributes = omron_attribute_parameters() if attributes is None else tuple(attributes)
    if object_classes is None:
        objects = device.router.objects
        object_classes = tuple(EdsObjectClass(spec, len(objects[spec.class_id].instances) if spec.class_id in objects
                                              else 0) for spec in OMRON_CLASS_SPECS)
    names = " / ".join(m.name for m in omron.models_with_product_code(found.product_code))
    return EdsDescription(
        identity=device.identity_info,
        vendor_name=OMRON_VENDOR_NAME,
        product_type_name=AC_DRIVE,
        catalog=family.option_board,
        network="CompoNet",
        description=f"{family.option_board} CompoNet option board on the {names} inverter",
        parameters=(*attributes, *omron_parameters(family)),
        outputs=outputs,
        inputs=inputs,
        object_classes=tuple(object_classes),
        componet_io=device.default_pair,
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
    the revision as the ACG-ET2 shows its version, ACG-ET2 manual Identity attribute 4 note)."""
    if description.file_name:
        return description.file_name
    major, minor = description.identity.revision
    safe = "".join(char if char.isalnum() or char in "-_." else "_" for char in description.catalog)
    return f"{safe}_{major}.{minor:02d}.eds"
