"""The Omron MX2 and RX families' declarations: the inverters with their CompoNet option boards (CompoNet
manual), served over EtherNet/IP. Registered by the ``cipstack.devices`` entry points ``mx2`` and ``rx``."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from ...catalog import Catalog, Parameter
from ...errors import BadRequest, NotFound
from ...objects.tcpip import NetworkInterface
from ..profiles import ModelInfo, Profile, ProfileOptions
from .models import MODELS, VENDOR_ID, Family, model

if TYPE_CHECKING:
    from ..base import Device, DeviceLimits
    from ..keypad import KeypadCodes

def _name(family: Family) -> str:
    return family.value.lower()


def _build(family: Family, default_model: str) -> Callable[[NetworkInterface, DeviceLimits, ProfileOptions], Device]:
    def build(interface: NetworkInterface, limits: DeviceLimits, options: ProfileOptions) -> Device:
        from .device import build_omron_device

        name = options.model or default_model
        if model(name).family is not family:
            raise BadRequest(f"{name} is not an {family.value} model (see `cipstack models`)")
        return build_omron_device(name, interface, limits, options.state_path, files=options.files)

    return build


def _catalog(family: Family, default_model: str) -> Callable[[], Catalog]:
    def catalog() -> Catalog:
        from .board import FUNCTION_CODE, MODBUS_REGISTER
        from .device import build_omron_device
        from .register_objects import register_attribute

        device = build_omron_device(default_model)
        registers = device.inverter.registers
        resolvers = {class_id: (lambda instance, attribute, c=class_id: register_attribute(registers, c, instance,
                                                                                          attribute))
                     for class_id in (MODBUS_REGISTER, FUNCTION_CODE)}
        # A recipe: the function codes the inverter keeps in its EEPROM (CompoNet manual, section E-2-2: class
        # 0x65 instance/attribute = the function code number), A004 (maximum frequency) first.
        parameters = []
        for number, parameter in sorted(registers.by_number.items(), key=lambda item: item[1].code != "A004"):
            if parameter.saved and parameter.access.writable and parameter.function_code_writable:
                spec = register_attribute(registers, FUNCTION_CODE, number >> 8, number & 0xFF)
                if spec is not None:
                    parameters.append(Parameter(parameter.code, FUNCTION_CODE, number >> 8, number & 0xFF, spec))
        return Catalog(device.catalog_classes(), device.schemas().values(), resolvers, parameters=parameters,
                       profile=_name(family))

    return catalog


def _keypad(family: Family) -> Callable[[], KeypadCodes]:
    def keypad() -> KeypadCodes:
        from .operator import operator_codes

        return operator_codes(family)

    return keypad


def _models(family: Family) -> Callable[[], tuple[str, ...]]:
    def models() -> tuple[str, ...]:
        return tuple(m.name for m in MODELS if m.family is family)

    return models


def _model_info(family: Family) -> Callable[[], tuple[ModelInfo, ...]]:
    def info() -> tuple[ModelInfo, ...]:
        return tuple(ModelInfo(m.name, m.product_code, m.product_name, m.eds_file) for m in MODELS
                     if m.family is family)

    return info


def _find_model(family: Family) -> Callable[[str], str]:
    def find(name: str) -> str:
        found = model(name)
        if found.family is not family:
            raise NotFound(f"{found.name} is not an {family.value} model (see `cipstack models`)")
        return found.name

    return find


def _componet_gateway(nodes: list[tuple[str, str, int]], interface: NetworkInterface) -> Device:
    """The CompoNet gateway with one option-board slave per node, MX2 and RX alike (CompoNet manual)."""
    from .device import build_componet_gateway

    return build_componet_gateway(nodes, interface)


def _profile(family: Family, description: str, default_model: str) -> Profile:
    return Profile(_name(family), description, _build(family, default_model), vendor_id=VENDOR_ID,
                   product_codes=frozenset(m.product_code for m in MODELS if m.family is family),
                   catalog=_catalog(family, default_model), keypad=_keypad(family), default_model=default_model,
                   models=_models(family), find_model=_find_model(family), model_info=_model_info(family),
                   componet_gateway=_componet_gateway, eds="cipstack.devices.omron.eds_file:omron_description")


MX2 = _profile(Family.MX2, "Omron MX2 with the 3G3AX-MX2-CRT-E CompoNet option board (--model, Tables 2/C-3)",
               "MX2-A2015-E")
RX = _profile(Family.RX, "Omron RX with the 3G3AX-RX-CRT-E CompoNet option board (--model, Tables 3/C-4)",
              "RX-A4055-E")
