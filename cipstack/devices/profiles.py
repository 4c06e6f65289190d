"""The device profiles `cipstack adapter --profile NAME` can emulate."""

from __future__ import annotations

import ipaddress
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..catalog import Catalog, Parameter
from ..cip.model import AttributeSpec
from ..eip.wire.identity_items import IdentityRecord
from ..errors import BadRequest, NotFound
from ..objects.file import StoredFile
from ..objects.identity import IdentityInfo
from ..objects.tcpip import NetworkInterface

if TYPE_CHECKING:
    # The device model (router, Connection Manager, class 1 target) is loaded by what builds a
    # device: a scanner that only wants a profile's catalog does without it.
    from .base import Device, DeviceLimits
    from .keypad import KeypadCodes

#: Locally administered MAC of the emulated card (bit 1 of the first octet set).
DEFAULT_MAC = bytes.fromhex("02CA10000064")


def mac_for_address(address: str) -> bytes:
    """The MAC of an emulated card at IPv4 ``address``, for a fleet whose devices each need their own:
    the locally administered prefix of ``DEFAULT_MAC`` (02:CA) and the four octets of the address, so
    that the serial number, taken from the MAC's last four octets (``serial_from_mac``), is the address
    read as one 32-bit number (127.0.0.10 -> 02:CA:7F:00:00:0A -> serial 0x7F00000A)."""
    return DEFAULT_MAC[:2] + ipaddress.IPv4Address(address).packed


def serial_from_mac(mac: bytes) -> int:
    """ACG-ET2 Identity attribute 6: "Serial number uses the last 4 digits of the MAC ID"
    (ACG-ET2 manual, Identity Object table): the last four octets, most significant first."""
    return int.from_bytes(mac[-4:], "big")


def acg_et2_identity(mac: bytes = DEFAULT_MAC) -> IdentityInfo:
    """Identity of the ACG drive's ACG-ET2 card as it leaves the factory (ACG-ET2 manual, Identity Object):
    the values the ACG objects declare, the revision from CM.6's factory value."""
    from .acg.objects import DEVICE_TYPE, PRODUCT_CODE, PRODUCT_NAME, VENDOR_ID
    from .acg.registers import ACG_REGISTERS

    version = ACG_REGISTERS.by_code("CM.6").default
    return IdentityInfo(VENDOR_ID, DEVICE_TYPE, PRODUCT_CODE, (version >> 8, version & 0xFF),
                        serial_from_mac(mac), PRODUCT_NAME)


@dataclass(frozen=True)
class ProfileOptions:
    """What the command line passes to a profile's device."""

    #: State file of saved parameters (None: kept in memory for the life of the process).
    state_path: Path | None = None
    #: Model name, for families with several models.
    model: str | None = None
    #: Files the device serves through its File object (its EDS file); none by default.
    files: tuple[StoredFile, ...] = ()


@dataclass(frozen=True)
class SerialLink:
    """A family's RS-485 (Modbus-RTU) port, as a fleet puts its drives on one multi-drop line."""

    #: What the port is, in a message: "the ACG's RS-485 port".
    port: str
    #: What its devices are called on the line, plural: "ACG drives".
    drives: str
    #: The keypad code of the station ID, which the line gives each drive at start.
    station_code: str
    #: The highest station ID, and the most drives one line takes.
    max_station: int
    max_drives: int
    #: Where the bounds come from, for a message.
    source: str


def _one_model() -> tuple[str, ...]:
    return ()


@dataclass(frozen=True)
class Profile:
    name: str
    description: str
    build: Callable[[NetworkInterface, DeviceLimits, ProfileOptions], Device]
    #: (vendor id, product codes) a live device reports when it is of this profile.
    vendor_id: int = 0
    product_codes: frozenset[int] = frozenset()
    #: The declarations of the profile's objects and assemblies, for a scanner.
    catalog: Callable[[], Catalog] | None = None
    #: The codes of the drive's keypad, to check ``--param`` before a device is built (the device's
    #: ``keypad()`` uses the same declaration); None for a device without a keypad.
    keypad: Callable[[], KeypadCodes] | None = None
    #: The model built when none is given (families with several models).
    default_model: str | None = None
    #: The names of the family's models, for ``--model``; none for a family of one model.
    models: Callable[[], tuple[str, ...]] = _one_model
    #: The canonical name of a model of the family; the family's own error (``NotFound``) for another.
    find_model: Callable[[str], str] | None = None
    #: Its RS-485 port, where a fleet may put its drives on one line; None without one.
    serial_link: SerialLink | None = None

    def matches(self, identity: IdentityRecord) -> bool:
        return identity.vendor_id == self.vendor_id and identity.product_code in self.product_codes


def _acg(interface: NetworkInterface, limits: DeviceLimits, options: ProfileOptions) -> Device:
    from .acg.device import build_acg_device

    return build_acg_device(interface, limits, options.state_path, files=options.files)


def _acg_catalog() -> Catalog:
    """From the declarations alone (no drive is built): the ACG classes and the assemblies whose
    layout no CM setting changes, the speed outputs 20/21/100/101 and inputs 70/71/110/111 (ACG-ET2 manual
    instance tables), made as the device makes them."""
    from ..assemblies.acg import HZ_INPUTS, HZ_OUTPUTS, speed_input, speed_output
    from .acg.objects import (
        AC_DC_DRIVE,
        AC_DC_DRIVE_SPEC,
        CATALOG_CLASSES,
        KEYPAD_PARAMETERS,
        OUTPUT_FREQUENCY,
        keypad_parameter_spec,
    )
    from .acg.registers import ACG_REGISTERS, MAX_FREQUENCY, SPEED_REFERENCE, class64_path, class64_register
    from .acg.saving import SAVE_OVER_CIP

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
                   profile="acg", save=SAVE_OVER_CIP)


def _omron(family: str, default_model: str) -> Callable[[NetworkInterface, DeviceLimits, ProfileOptions], Device]:
    def build(interface: NetworkInterface, limits: DeviceLimits, options: ProfileOptions) -> Device:
        from .omron.device import build_omron_device
        from .omron.models import model

        name = options.model or default_model
        if model(name).family.value.lower() != family:
            raise BadRequest(f"{name} is not an {family.upper()} model (see `cipstack models`)")
        return build_omron_device(name, interface, limits, options.state_path, files=options.files)

    return build


def _omron_catalog(default_model: str) -> Callable[[], Catalog]:
    def catalog() -> Catalog:
        from .omron.board import FUNCTION_CODE, MODBUS_REGISTER
        from .omron.device import build_omron_device
        from .omron.register_objects import register_attribute

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
                       profile=default_model.split("-")[0].lower())

    return catalog


def _acg_keypad() -> KeypadCodes:
    from .acg.keypad import ACG_KEYPAD

    return ACG_KEYPAD


def _omron_keypad(family: str) -> Callable[[], KeypadCodes]:
    def keypad() -> KeypadCodes:
        from .omron.models import Family
        from .omron.operator import operator_codes

        return operator_codes(Family[family.upper()])

    return keypad


def _omron_models(family: str) -> Callable[[], tuple[str, ...]]:
    def models() -> tuple[str, ...]:
        from .omron.models import MODELS

        return tuple(m.name for m in MODELS if m.family.value.lower() == family)

    return models


def _omron_find_model(family: str) -> Callable[[str], str]:
    def find(name: str) -> str:
        from .omron.models import model

        found = model(name)
        if found.family.value.lower() != family:
            raise NotFound(f"{found.name} is not an {family.upper()} model (see `cipstack models`)")
        return found.name

    return find


def _acg_serial_link() -> SerialLink:
    from .acg.modbus_rtu import MAX_DRIVES_PER_LINE

    # Station IDs 1-250 (CM.1) and up to 16 drives on one line: the ACG RS-485 manual's Communication
    # Standards.
    return SerialLink("the ACG's RS-485 port", "ACG drives", "CM.1", 250, MAX_DRIVES_PER_LINE,
                      "ACG RS-485 manual, Communication Standards")


def _omron_product_codes(family: str) -> frozenset[int]:
    from .omron.models import MODELS

    return frozenset(m.product_code for m in MODELS if m.family.value.lower() == family)


PROFILES: dict[str, Profile] = {
    "acg": Profile("acg", "ACG drive with its ACG-ET2 EtherNet/IP card (the ACG-ET2 and ACG RS-485 manuals)", _acg,
                   vendor_id=acg_et2_identity().vendor_id, product_codes=frozenset({acg_et2_identity().product_code}),
                   catalog=_acg_catalog, keypad=_acg_keypad, serial_link=_acg_serial_link()),
    # The Omron inverters with the CompoNet option board (CompoNet manual), served over EtherNet/IP.
    "mx2": Profile("mx2", "Omron MX2 with the 3G3AX-MX2-CRT-E CompoNet option board (--model, Tables 2/C-3)",
                   _omron("mx2", "MX2-A2015-E"), vendor_id=47, product_codes=_omron_product_codes("mx2"),
                   catalog=_omron_catalog("MX2-A2015-E"), keypad=_omron_keypad("mx2"), default_model="MX2-A2015-E",
                   models=_omron_models("mx2"), find_model=_omron_find_model("mx2")),
    "rx": Profile("rx", "Omron RX with the 3G3AX-RX-CRT-E CompoNet option board (--model, Tables 3/C-4)",
                  _omron("rx", "RX-A4055-E"), vendor_id=47, product_codes=_omron_product_codes("rx"),
                  catalog=_omron_catalog("RX-A4055-E"), keypad=_omron_keypad("rx"), default_model="RX-A4055-E",
                  models=_omron_models("rx"), find_model=_omron_find_model("rx")),
}
DEFAULT_PROFILE = "acg"


def profile_of_model(name: str) -> Profile:
    """The profile of the family that has model ``name``: ``--model`` given without ``--profile``. A
    name no family knows raises the error of the first family with models (its close matches)."""
    first_error: NotFound | None = None
    for profile in PROFILES.values():
        if profile.find_model is None:
            continue
        try:
            profile.find_model(name)
        except NotFound as exc:
            first_error = first_error or exc
            continue
        return profile
    raise first_error or NotFound(f"--model {name}: no profile has models")


def check_model(profile: Profile, model: str | None) -> None:
    """``BadRequest`` where ``model`` is given to a family of one model."""
    if model is not None and profile.find_model is None:
        raise BadRequest(f"--model {model}: the {profile.name} profile has one model; --model names a model of "
                         f"{', '.join(p.name for p in PROFILES.values() if p.find_model is not None)}")


def catalog_for_identity(identity: IdentityRecord) -> Catalog:
    """The declarations a scanner decodes with for a device that identified itself: those of
    the profile with the same vendor and product code, else the standard objects only."""
    return catalog_for(identity.vendor_id, identity.product_code)


def profile_for(vendor_id: int, product_code: int) -> Profile | None:
    """The profile a device with this vendor id and product code is, or None."""
    for profile in PROFILES.values():
        if profile.catalog is not None and vendor_id == profile.vendor_id and product_code in profile.product_codes:
            return profile
    return None


#: Each profile's catalog, built once per process (the Omron ones build a device model, ~0.1 s):
#: every scanner gets a copy of its own.
_BUILT: dict[str, Catalog] = {}


def catalog_for(vendor_id: int, product_code: int) -> Catalog:
    """The catalog of the profile of (vendor id, product code); else the standard objects, with a
    ``source`` that says no profile is known for them."""
    profile = profile_for(vendor_id, product_code)
    if profile is None or profile.catalog is None:
        return Catalog(source=f"the standard objects only: no profile for vendor {vendor_id} product code "
                              f"{product_code} (give eds= or catalog=)")
    built = _BUILT.get(profile.name)
    if built is None:
        built = _BUILT[profile.name] = profile.catalog()
    return built.copy(f"profile {profile.name} (vendor {vendor_id} product code {product_code}: "
                      f"{profile.description})")


def build_device(name: str = DEFAULT_PROFILE, interface: NetworkInterface | None = None,
                 limits: DeviceLimits | None = None, options: ProfileOptions | None = None) -> Device:
    """The emulated device of profile ``name`` (``acg``, ``mx2``, ``rx``: ``PROFILES``), for an ``Adapter``
    to serve: ``Adapter(AdapterSettings(port=0), device=build_device("mx2"))``."""
    from .base import DeviceLimits

    try:
        profile = PROFILES[name]
    except KeyError:
        raise BadRequest(f"unknown profile {name!r} (known: {', '.join(sorted(PROFILES))})") from None
    return profile.build(interface or NetworkInterface(mac=DEFAULT_MAC), limits or DeviceLimits(),
                         options or ProfileOptions())


def identity_only_device(interface: NetworkInterface | None = None, limits: DeviceLimits | None = None) -> Device:
    """The ACG-ET2 identity with the standard objects only: the generic object model, no drive."""
    from .base import Device, DeviceLimits

    return Device(acg_et2_identity((interface or NetworkInterface(mac=DEFAULT_MAC)).mac),
                  interface or NetworkInterface(mac=DEFAULT_MAC), limits or DeviceLimits())
