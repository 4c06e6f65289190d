"""The EDS description of the 3G3AX-MX2-CRT-E / 3G3AX-RX-CRT-E CompoNet option board, built from the
device itself (the family's declaration names it: ``Profile.eds``).

``omron_description(model_name)``: the board on one MX2 or RX inverter model (CompoNet manual) as
``build_omron_device`` builds it: its Identity (Table C-2 with the product code and name of Tables
2/3), the attributes of its drive objects, every function-code parameter through its class 0x65 path
(Table E-3), its assemblies in the factory speed unit (the flexible 139/159 when the factory mapping
makes them), its object classes and the ``[CompoNet_IO]`` sizes of the default connection path
(P046, Table 10).

It uses the EDS tool's types, as a family from another distribution does; nothing of the device's
runtime imports it. Nothing here is declared a second time: every value comes from the device modules.
"""

from __future__ import annotations

from collections.abc import Sequence

from ...assemblies.schema import AssemblySchema
from ...eds.description import (
    EdsDescription,
    EdsObjectClass,
    EdsParameter,
    attribute_parameters,
)
from ...eds.profiles import AC_DRIVE
from . import models as omron
from .assemblies import INPUT_INSTANCES as OMRON_INPUT_INSTANCES
from .assemblies import OUTPUT_INSTANCES as OMRON_OUTPUT_INSTANCES
from .device import build_omron_device
from .objects import AC_DC_DRIVE_SPEC as OMRON_AC_DC_DRIVE_SPEC
from .objects import CLASS_SPECS as OMRON_CLASS_SPECS
from .objects import CONTROL_SUPERVISOR_SPEC as OMRON_CONTROL_SUPERVISOR_SPEC
from .objects import FUNCTION_CODE
from .objects import MOTOR_DATA_SPEC as OMRON_MOTOR_DATA_SPEC
from .registers import Parameter, function_code_path, register_set

#: Identity attribute 1 of the option board: "47 (OMRON Corporation)" (CompoNet manual, Table C-2).
OMRON_VENDOR_NAME = "OMRON Corporation"



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
