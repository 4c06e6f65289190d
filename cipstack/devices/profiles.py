"""The device profiles `cipstack adapter --profile NAME` can emulate: what a family declares
(``Profile``), and every family installed (``PROFILES``, found by entry point: ``registry``)."""

from __future__ import annotations

import ipaddress
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..catalog import Catalog
from ..eip.wire.identity_items import IdentityRecord
from ..errors import BadRequest, NotFound
from ..objects.file import StoredFile
from ..objects.identity import IdentityInfo
from ..objects.tcpip import NetworkInterface
from .registry import FamilyRegistry

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


@dataclass(frozen=True)
class ModelInfo:
    """One model of a family as ``cipstack models`` lists it: what its Identity reports, and its EDS file."""

    name: str
    #: Identity attribute 3.
    product_code: int
    #: Identity attribute 7.
    product_name: str
    #: The name of the model's EDS file where the family's documents give one; empty otherwise.
    eds_file: str = ""


def _one_model() -> tuple[str, ...]:
    return ()


def _no_model_info() -> tuple[ModelInfo, ...]:
    return ()


@dataclass(frozen=True)
class Profile:
    name: str
    description: str
    build: Callable[[NetworkInterface, DeviceLimits, ProfileOptions], Device]
    #: (vendor id, product codes) a live device reports when it is of this profile.
    vendor_id: int = 0
    product_codes: frozenset[int] = frozenset()
    #: The device type (Identity attribute 2) it reports, where the family declares one: a device that
    #: reports another is not of this profile. None: any.
    device_type: int | None = None
    #: The declarations of the profile's objects and assemblies, for a scanner; None: what its device
    #: model serves (``catalog_for`` builds one and reads its classes).
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
    #: Its CompoNet port, where ``cipstack componet`` puts its devices as slaves behind a gateway: the
    #: gateway's builder, given every node (profile name, model, node address) and the gateway's
    #: EtherNet/IP interface. Families that share a gateway declare the same builder; None without one.
    componet_gateway: Callable[[list[tuple[str, str, int]], NetworkInterface], Device] | None = None
    #: What ``cipstack models`` lists: each model (one for a family of one model) with its identity.
    model_info: Callable[[], tuple[ModelInfo, ...]] = _no_model_info
    #: How the EDS tool describes the family: ``"module:function"`` of a function that returns the
    #: ``cipstack.eds.description.EdsDescription`` of a model, given the model's name (no argument for a
    #: family of one model). A reference, not a callable: the EDS tool sits above the devices, which never
    #: import it (docs/architecture.md); None for a family without an EDS file.
    eds: str | None = None

    def matches(self, identity: IdentityRecord) -> bool:
        return self.is_identity(identity.vendor_id, identity.product_code, identity.device_type)

    def is_identity(self, vendor_id: int, product_code: int, device_type: int | None = None) -> bool:
        """Whether a device that reports this vendor id, product code (and device type, where known) is
        of this profile."""
        return (vendor_id == self.vendor_id and product_code in self.product_codes
                and (device_type is None or self.device_type is None or device_type == self.device_type))


#: Every family installed, by name: cipstack's own and those of other distributions, found by the
#: ``cipstack.devices`` entry point and loaded when first asked for (``registry``).
PROFILES: FamilyRegistry = FamilyRegistry()
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


def families_having(has: Callable[[Profile], bool]) -> str:
    """The installed families a capability is declared by, for the message of a device without it:
    "profile acg, mx2 or rx" (read from the declarations, so that a family from another distribution
    is named too and no message lists cipstack's own by hand)."""
    names = [profile.name for profile in PROFILES.values() if has(profile)]
    if not names:
        return "no installed family"
    return "profile " + (names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}")


def keypad_families() -> str:
    """The families with a keypad: "profile acg, mx2 or rx"."""
    return families_having(lambda profile: profile.keypad is not None)


def parse_nodes(text: str) -> list[tuple[str, str, int]]:
    """``"mx2:MX2-A2015-E@3,rx:RX-A4055-E@5"`` -> [("mx2", "MX2-A2015-E", 3), ("rx", "RX-A4055-E", 5)]."""
    nodes = []
    for item in filter(None, (part.strip() for part in text.split(","))):
        try:
            profile, rest = item.split(":", 1)
            model_name, node = rest.rsplit("@", 1)
            nodes.append((profile.strip().lower(), model_name.strip(), int(node)))
        except ValueError:
            raise BadRequest(f"node {item!r} is not PROFILE:MODEL@NODE (e.g. mx2:MX2-A2015-E@3)") from None
    return nodes


def componet_gateway(nodes: list[tuple[str, str, int]], interface: NetworkInterface) -> Device:
    """The gateway of a CompoNet network of ``nodes`` (``parse_nodes``), as the nodes' families declare it
    (``Profile.componet_gateway``); ``BadRequest`` naming a family without a CompoNet port, or nodes whose
    families share no gateway."""
    if not nodes:
        raise BadRequest("--nodes names no node")
    builders = []
    for name, _, _ in nodes:
        try:
            profile = PROFILES[name]
        except KeyError:
            raise BadRequest(f"unknown profile {name!r} (known: {', '.join(sorted(PROFILES))})") from None
        if profile.componet_gateway is None:
            has = families_having(lambda p: p.componet_gateway is not None)
            raise BadRequest(f"profile {name!r} has no CompoNet port (one has: {has})")
        if profile.componet_gateway not in builders:
            builders.append(profile.componet_gateway)
    if len(builders) > 1:
        raise BadRequest(f"profiles {', '.join(sorted({name for name, _, _ in nodes}))} share no CompoNet gateway")
    return builders[0](nodes, interface)


def catalog_for_identity(identity: IdentityRecord) -> Catalog:
    """The declarations a scanner decodes with for a device that identified itself: those of
    the profile with the same vendor and product code, else the standard objects only."""
    return catalog_for(identity.vendor_id, identity.product_code, identity.device_type)


def profile_for(vendor_id: int, product_code: int, device_type: int | None = None) -> Profile | None:
    """The installed profile a device with this identity is (cipstack's or another distribution's), or
    None."""
    for profile in PROFILES.values():
        if profile.is_identity(vendor_id, product_code, device_type):
            return profile
    return None


def _served_catalog(profile: Profile) -> Catalog:
    """For a family that declares no catalog: the classes its device model serves (each object's
    declaration, as the router holds it) and the schemas of its assemblies, read from a device built
    with factory settings."""
    from .base import DeviceLimits

    device = profile.build(NetworkInterface(mac=DEFAULT_MAC), DeviceLimits(), ProfileOptions())
    try:
        classes = [obj.spec for obj in device.router.objects.values()]
        schemas = [schema for instance in device.assembly.points
                   if (schema := device.data_schema(instance)) is not None]
    finally:
        device.close()
    return Catalog(classes, schemas, profile=profile.name)


#: Each profile's catalog, built once per process (the Omron ones build a device model, ~0.1 s):
#: every scanner gets a copy of its own.
_BUILT: dict[str, Catalog] = {}


def catalog_for(vendor_id: int, product_code: int, device_type: int | None = None) -> Catalog:
    """The catalog of the installed profile of (vendor id, product code, device type where known); else
    the standard objects, with a ``source`` that says no profile is known for them."""
    profile = profile_for(vendor_id, product_code, device_type)
    if profile is None:
        return Catalog(source=f"the standard objects only: no profile for vendor {vendor_id} product code "
                              f"{product_code} (give eds= or catalog=)")
    built = _BUILT.get(profile.name)
    if built is None:
        built = _BUILT[profile.name] = profile.catalog() if profile.catalog is not None else _served_catalog(profile)
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
