"""The EDS description of the ACG drive with its ACG-ET2 EtherNet/IP card, built from the device itself
(the family's declaration names it: ``Profile.eds``).

``acg_et2_description()``: the drive (ACG-ET2 manual) as ``build_acg_device()`` builds it at the
factory settings: its Identity, the attributes of its Motor Data 0x28, Control Supervisor 0x29 and
AC/DC Drive 0x2A objects, every keypad parameter through its class 0x64 path (instance = keypad
group, attribute = code number), grouped by keypad group, all 24 assemblies (20/21/100/101/121-128
and 70/71/110/111/141-148 at the CM.31-CM.38 / CM.51-CM.58 factory addresses), the objects its
message router serves, and its class 1 offer: the RPI range, heartbeat points and connection limit
of its ``IoProfile``, with every CM.24/CM.23 pair (the card accepts the pair the settings select).

It uses the EDS tool's types, as a family from another distribution does; nothing of the device's
runtime imports it. Nothing here is declared a second time: every value comes from the device modules.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence

from ...assemblies.schema import AssemblySchema
from ...eds.description import (
    EdsCapacity,
    EdsDescription,
    EdsObjectClass,
    EdsParameter,
    EdsPort,
    IoOffer,
    attribute_parameters,
)
from ...eds.profiles import AC_DRIVE, device_object_classes
from ...eip.wire.cm_spec import BACKPLANE_PORT
from ...objects.identity import IdentityInfo
from ...objects.tcpip import TCPIP_CLASS_ID
from ..base import DeviceLimits
from . import registers as acg
from .assemblies import INPUT_INSTANCES as ACG_INPUT_INSTANCES
from .assemblies import OUTPUT_INSTANCES as ACG_OUTPUT_INSTANCES
from .device import build_acg_device
from .drive import MODEL as ACG_MODEL
from .objects import AC_DC_DRIVE_SPEC, CONTROL_SUPERVISOR_SPEC, KEYPAD_PARAMETERS, MOTOR_DATA_SPEC

#: ACG-ET2 manual gives vendor ID 259 (Identity Object, attribute 1) but no vendor name; the ODVA vendor
#: list that scanner libraries carry (pycomm3's among them) names 259 "LS ELECTRIC".
ACG_VENDOR_NAME = "LS ELECTRIC"
#: The card's catalog name, "ACG-ET2" (ACG-ET2 manual, appendix B title and overview): the drive model's name.
ACG_CATALOG = ACG_MODEL

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
