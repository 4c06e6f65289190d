"""The ACG family's declaration: what ``cipstack adapter --profile acg`` builds, and what every other
surface (scanner, EDS tool, fleet, models) reads of it. Registered by the ``cipstack.devices`` entry
point ``acg``."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...catalog import Catalog, Parameter
from ...cip.model import AttributeSpec
from ...objects.tcpip import NetworkInterface
from ..profiles import ModelInfo, Profile, ProfileOptions, SerialLink, acg_et2_identity

if TYPE_CHECKING:
    from ..base import Device, DeviceLimits
    from ..keypad import KeypadCodes

NAME = "acg"


def _build(interface: NetworkInterface, limits: DeviceLimits, options: ProfileOptions) -> Device:
    from .device import build_acg_device

    return build_acg_device(interface, limits, options.state_path, files=options.files)


def _catalog() -> Catalog:
    """From the declarations alone (no drive is built): the ACG classes and the assemblies whose
    layout no CM setting changes, the speed outputs 20/21/100/101 and inputs 70/71/110/111 (ACG-ET2 manual
    instance tables), made as the device makes them."""
    from .assemblies import HZ_INPUTS, HZ_OUTPUTS, speed_input, speed_output
    from .objects import (
        AC_DC_DRIVE,
        AC_DC_DRIVE_SPEC,
        CATALOG_CLASSES,
        KEYPAD_PARAMETERS,
        OUTPUT_FREQUENCY,
        keypad_parameter_spec,
    )
    from .registers import ACG_REGISTERS, MAX_FREQUENCY, SPEED_REFERENCE, class64_path, class64_register
    from .saving import SAVE_OVER_CIP

    outputs = [speed_output(i, SPEED_REFERENCE) for i in (20, 21, *HZ_OUTPUTS)]
    inputs = [speed_input(i, OUTPUT_FREQUENCY) for i in (70, 71, *HZ_INPUTS)]

    def keypad(instance: int, attribute: int) -> AttributeSpec | None:
        """Class 0x64 by the register behind it: its name, range, unit and scale (ACG-ET2 manual, class 0x64
        "Identical to the ACG Manual Code number"; ACG RS-485 manual tables)."""
        register = class64_register(instance, attribute)
        return keypad_parameter_spec(register) if register is not None and class64_path(register) else None

    # A recipe: the keypad parameters the save command keeps (ACG RS-485 manual, 0x03E0), Max Freq first (it
    # bounds every frequency parameter), the CM group last (it changes the network settings).
    saved = [(r, path) for r in ACG_REGISTERS.values()
             if r.saved and r.access.writable and (path := class64_path(r)) is not None]
    saved.sort(key=lambda item: (item[0] is not MAX_FREQUENCY, item[0].group == "CM"))
    parameters = [Parameter(r.code, KEYPAD_PARAMETERS, *path, keypad_parameter_spec(r)) for r, path in saved]
    # ACC and dEC are operation-group parameters with no class 0x64 address: AC/DC Drive attributes
    # 102/103 mirror them (ACG-ET2 manual, "Value at DRV-03 (Acc Time)", "DRV-04 (Dec Time)").
    ramps = [Parameter(code, AC_DC_DRIVE, 1, attribute, spec) for code, attribute in (("ACC", 102), ("dEC", 103))
             if (spec := AC_DC_DRIVE_SPEC.instance_attribute(attribute)) is not None]
    parameters[1:1] = ramps
    return Catalog(CATALOG_CLASSES, [*outputs, *inputs], {KEYPAD_PARAMETERS: keypad}, parameters=parameters,
                   profile=NAME, save=SAVE_OVER_CIP)


def _keypad() -> KeypadCodes:
    from .keypad import ACG_KEYPAD

    return ACG_KEYPAD


def _model_info() -> tuple[ModelInfo, ...]:
    from .drive import MODEL

    identity = acg_et2_identity()
    return (ModelInfo(MODEL, identity.product_code, identity.product_name),)


def _serial_link() -> SerialLink:
    from .modbus_rtu import MAX_DRIVES_PER_LINE

    # Station IDs 1-250 (CM.1) and up to 16 drives on one line: the ACG RS-485 manual's Communication
    # Standards.
    return SerialLink("the ACG's RS-485 port", "ACG drives", "CM.1", 250, MAX_DRIVES_PER_LINE,
                      "ACG RS-485 manual, Communication Standards")


_IDENTITY = acg_et2_identity()

PROFILE = Profile(NAME, "ACG drive with its ACG-ET2 EtherNet/IP card (the ACG-ET2 and ACG RS-485 manuals)", _build,
                  vendor_id=_IDENTITY.vendor_id, product_codes=frozenset({_IDENTITY.product_code}),
                  catalog=_catalog, keypad=_keypad, serial_link=_serial_link(), model_info=_model_info,
                  eds="cipstack.devices.acg.eds_file:acg_et2_description")
